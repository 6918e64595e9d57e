"""External virtual work of dead loads on the reference surface (SI units).

Each function returns the form delta W_ext(v) for a test function v of the displacement (or of
the director); the solver multiplies the sum by the load factor. All are linear in the state except
the moment, whose work depends on the current director.
"""
from __future__ import annotations

import ufl


def body_force(v, areal_density, gravity, dx):
    """Weight of the sheet: int rho_A g . v dA, rho_A [kg/m^2], gravity [m/s^2] (a vector)."""
    return areal_density * ufl.dot(gravity, v) * dx


def edge_traction(v, traction, ds):
    """Force per unit reference edge length [N/m] on the tagged edge: int T . v dS."""
    return ufl.dot(traction, v) * ds


def surface_pressure(v, pressure, normal, dx):
    """Dead pressure [Pa] along the reference normal: int q n0 . v dA."""
    return pressure * ufl.dot(normal, v) * dx


def moment_work(moment, d, delta_d, ds):
    """Virtual work of a moment vector m per unit edge length [N m/m] on the unit director d:
    int m . (d x delta d) dS [Man2006, eqs. 2.47-2.51].

    A virtual rotation delta phi moves the director by delta d = delta phi x d, so
    d x delta d = delta phi - (d . delta phi) d: the work is m . delta phi for any axis of m and any
    finite rotation, less the drilling part along d, which a director cannot carry. With m fixed in
    space (a dead moment) the form depends on d; its derivative is the consistent, non-symmetric tangent.
    """
    return ufl.dot(moment, ufl.cross(d, delta_d)) * ds
