"""Independent reference solutions for the verification cases (closed forms and ODEs)."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

# Clamped square plate, centre deflection coefficients (Timoshenko & Woinowsky-Krieger, Theory of
# Plates and Shells, Tables 35 and 55): w = c_q q a^4 / D and w = c_P P a^2 / D. The tables print
# the rounded values; the series give 0.00126532 and 0.0056120.
CLAMPED_PLATE_UNIFORM_ROUNDED = 0.00126
CLAMPED_PLATE_UNIFORM = 0.00126532
CLAMPED_PLATE_POINT = 0.0056120


def plate_rigidity(E: float, nu: float, t: float) -> float:
    """Flexural rigidity D = E t^3 / (12 (1 - nu^2)) [N m]."""
    return E * t ** 3 / (12.0 * (1.0 - nu ** 2))


def rollup_tip(L: float, curvature: float) -> np.ndarray:
    """Tip (x, z) of a clamped strip bent into a circle of the given curvature [1/m] (towards +z)."""
    if curvature == 0:
        return np.array([L, 0.0])
    R = 1.0 / curvature
    return np.array([R * np.sin(L / R), R * (1.0 - np.cos(L / R))])


def elastica_tip_load(lam: float) -> dict[str, float]:
    """Inextensible cantilever elastica under a dead transverse tip load, lam = P L^2 / EI.

    theta'' = -lam cos(theta) on s in [0, 1] (L = EI = 1), theta(0) = 0, theta'(1) = 0, solved by
    shooting on the root curvature with tight tolerances. Returns the tip deflection w/L
    (transverse), the axial shortening u/L = 1 - x_tip/L and the tip rotation [rad].
    """
    if lam == 0:
        return {"w": 0.0, "u": 0.0, "rotation": 0.0}

    def rhs(s, y):
        theta, kappa, x, w = y
        return [kappa, -lam * np.cos(theta), np.cos(theta), np.sin(theta)]

    def end_moment(kappa0):
        sol = solve_ivp(rhs, (0.0, 1.0), [0.0, kappa0, 0.0, 0.0], rtol=1e-12, atol=1e-14)
        return sol.y[1, -1]

    # The root curvature equals lam x_tip, so it lies in (0, lam]
    kappa0 = brentq(end_moment, 1e-12, lam, xtol=1e-14)
    sol = solve_ivp(rhs, (0.0, 1.0), [0.0, kappa0, 0.0, 0.0], rtol=1e-12, atol=1e-14)
    theta, _, x, w = sol.y[:, -1]
    return {"w": float(w), "u": float(1.0 - x), "rotation": float(theta)}
