"""A membrane strain-energy function fitted to homogenized unit-cell data [Man2006, sec. 4.3.6, 6.2.2].

The thesis leaves the link between the unit cell (ch. 4) and the garment-scale shell (ch. 2) open:
the homogenized relations "can not be applied to the clothing simulation unless they are cast as a
strain energy function definition" (sec. 4.3.6); sec. 6.2.2 calls this the hierarchical multiscale
approach. This module does exactly that for the in-plane (membrane) response.

Data model (SI):
    strains     eps = (E11, E22, gamma12 = 2 E12): in-plane Green-Lagrange strain (eq. 4.59) in the
                warp/weft frame, Voigt form with the engineering shear, dimensionless.
    resultants  N = (N11, N22, N12) [N/m]: membrane second Piola-Kirchhoff stress resultants per unit
                reference length. The unit cell returns the homogenized S [Pa] averaged over the
                bounding box |Y| = A_cell h_cell with the volume fraction (eqs. 4.64-4.65), so
                N = h_cell S_ab, h_cell being the fabric thickness (the cell height) [m].
    energy      W(eps) [J/m^2] per unit reference area with N = dW/deps, i.e. N11 = dW/dE11,
                N22 = dW/dE22, N12 = dW/dgamma12 (forms.fitted.polynomial_energy).

Fit: W is a polynomial even in gamma12 (warp/weft symmetry of the weave: shearing one way or the
other costs the same), with no constant and no linear term (W(0) = 0, N(0) = 0). Its coefficients
enter N linearly, so they solve a linear least-squares problem on the resultants (S = dW/dE).
Convexity: the Hessian of W must be positive definite on a grid covering the data (their convex hull,
mirrored in gamma12, plus the origin); if it is not, the fit is repaired by cutting planes (convex
quadratic programme: least squares subject to v.H(x)v >= margin at the offending points x along
their offending directions v) and rejected with ValueError if the repaired fit no longer matches the
data within `max_residual`. That polynomial is convex only where it was checked (the data hull).

ConvexMembraneLaw (fit_convex_law) is convex at EVERY strain by construction: W = 1/2 eps.A0.eps plus a
non-negative combination of convex C2 ridge functions phi(l.eps) (Macaulay powers and ramps, even powers),
fitted by non-negative least squares; its Hessian is >= A0 everywhere (see its docstring). Both laws offer
energy/resultants/tangent (numpy), initial_stiffness, to_dict/from_dict (the fabric JSON "membrane" entry, told
apart by "type": membrane_law_from_dict) and parameters/ufl_energy for fabricfem.shell.ShellModel.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import Delaunay, QhullError

from fabricfem.forms import fitted as fitted_forms
from fabricfem.materials import Fabric, KawabataBending, SquareRootBending

LAW_TYPE = "polynomial-even-shear"


# ----------------------------------------------------------------------------------------- data
@dataclass(frozen=True)
class MembraneSamples:
    """n in-plane states: strains (n, 3) = (E11, E22, 2 E12) and resultants (n, 3) = (N11, N22, N12) [N/m]."""

    strains: np.ndarray
    resultants: np.ndarray

    def __post_init__(self):
        for name in ("strains", "resultants"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.ndim != 2 or a.shape[1] != 3 or len(a) == 0:
                raise ValueError(f"{name} must be an (n, 3) array with n >= 1, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                bad = int(np.sum(~np.all(np.isfinite(a), axis=1)))
                raise ValueError(f"{name} contains non-finite values ({bad} of {len(a)} samples)")
            object.__setattr__(self, name, a)
        if len(self.strains) != len(self.resultants):
            raise ValueError(f"resultants: {len(self.resultants)} rows for {len(self.strains)} strains")

    def __len__(self) -> int:
        return len(self.strains)

    def __add__(self, other: "MembraneSamples") -> "MembraneSamples":
        return MembraneSamples(np.vstack([self.strains, other.strains]),
                               np.vstack([self.resultants, other.resultants]))


def membrane_state(E: np.ndarray, S: np.ndarray, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """In-plane Voigt strain (E11, E22, 2 E12) and resultant h (S11, S22, S12) [N/m] of a 3x3 Green-Lagrange
    strain E and homogenized second Piola-Kirchhoff stress S [Pa] (eqs. 4.59, 4.64)."""
    E, S = np.asarray(E, dtype=float), np.asarray(S, dtype=float)
    return (np.array([E[0, 0], E[1, 1], 2.0 * E[0, 1]]),
            thickness * np.array([S[0, 0], S[1, 1], S[0, 1]]))


def samples_from_steps(steps: Iterable, thickness: float) -> MembraneSamples:
    """MembraneSamples of unit-cell steps (fabricfem.weave.homogenize.UnitCellStep: Phi, E, S); N = thickness S.

    Every Phi must be in-plane (Phi_13 = Phi_23 = Phi_31 = Phi_32 = 0): the membrane law knows
    nothing of transverse shear.
    """
    thickness = _positive("thickness", thickness)
    strains, resultants = [], []
    for step in steps:
        Phi = np.asarray(step.Phi, dtype=float)
        if np.any(np.abs(Phi[[0, 1, 2, 2], [2, 2, 0, 1]]) > 1e-12):
            raise ValueError(f"steps: Phi must be in-plane (no 13, 23, 31, 32 components), got {Phi.tolist()}")
        e, n = membrane_state(step.E, step.S, thickness)
        strains.append(e)
        resultants.append(n)
    if not strains:
        raise ValueError("steps must contain at least one unit-cell step")
    return MembraneSamples(np.array(strains), np.array(resultants))


def sample_unit_cell(problem, Phis: Sequence[np.ndarray], thickness: float, steps: int = 1) -> MembraneSamples:
    """Run a fabricfem.weave.homogenize.UnitCellProblem from the undeformed cell to each in-plane Phi in `steps`
    increments (every converged increment is a sample) and return the MembraneSamples (N = thickness S)."""
    collected = []
    for Phi in Phis:
        problem.u.x.array[:] = 0.0  # each path starts from the undeformed cell
        collected.extend(problem.solve(np.asarray(Phi, dtype=float), steps).steps)
    return samples_from_steps(collected, thickness)


# --------------------------------------------------------------------------------- polynomial
def energy_exponents(degree: int) -> tuple[tuple[int, int, int], ...]:
    """Monomials E11^a E22^b gamma12^p with p even and 2 <= a + b + p <= degree, by total degree."""
    if isinstance(degree, bool) or int(degree) != degree or degree < 2:
        raise ValueError(f"degree must be an integer >= 2 (W has no linear term), got {degree!r}")
    out = []
    for total in range(2, int(degree) + 1):
        for p in range(0, total + 1, 2):
            for a in range(total - p, -1, -1):
                out.append((a, total - p - a, p))
    return tuple(out)


def _power_derivative(x: np.ndarray, power: int, order: int) -> np.ndarray:
    """d^order/dx^order x^power, vectorized (zero when order > power)."""
    if order > power:
        return np.zeros_like(x)
    return math.perm(power, order) * x ** (power - order)


def _monomial_derivative(X: np.ndarray, exponents: np.ndarray, orders: Sequence[int]) -> np.ndarray:
    """(n, K) derivative of order `orders` = (i, j, l) of every monomial at the strains X (n, 3)."""
    out = np.ones((len(X), len(exponents)))
    for component in range(3):
        for k, power in enumerate(exponents[:, component]):
            out[:, k] *= _power_derivative(X[:, component], int(power), orders[component])
    return out


def gradient_basis(X: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """(n, 3, K): d(monomial_k)/d eps_j at the strains X, so that N(X) = basis @ c."""
    unit = np.eye(3, dtype=int)
    return np.stack([_monomial_derivative(X, exponents, unit[j]) for j in range(3)], axis=1)


def hessian_basis(X: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """(n, 3, 3, K): second derivatives of every monomial at the strains X."""
    out = np.empty((len(X), 3, 3, len(exponents)))
    for i, j in itertools.combinations_with_replacement(range(3), 2):
        orders = [0, 0, 0]
        orders[i] += 1
        orders[j] += 1
        out[:, i, j] = out[:, j, i] = _monomial_derivative(X, exponents, orders)
    return out


# -------------------------------------------------------------------------------------- law
@dataclass(frozen=True)
class FittedMembraneLaw:
    """W(eps) = sum_k c_k E11^a E22^b gamma12^p [J/m^2], eps = (E11, E22, 2 E12) (forms.fitted).

    exponents: K triples (a, b, p), p even, a + b + p >= 2; coefficients: K values [J/m^2];
    strain_min, strain_max: range of the fitted data per Voigt component (the law is an extrapolation
    outside); relative_rms_residual: sqrt(sum |N_fit - N|^2 / sum |N|^2) over the data;
    min_eigenvalue, max_eigenvalue: extreme Hessian eigenvalues [N/m] on the convexity grid;
    n_samples: number of data states; repaired: whether the convexity repair was active.
    """

    exponents: tuple[tuple[int, int, int], ...]
    coefficients: tuple[float, ...]
    strain_min: tuple[float, float, float] = (0.0, 0.0, 0.0)
    strain_max: tuple[float, float, float] = (0.0, 0.0, 0.0)
    relative_rms_residual: float = 0.0
    min_eigenvalue: float = float("nan")
    max_eigenvalue: float = float("nan")
    n_samples: int = 0
    repaired: bool = False

    def __post_init__(self):
        exps = tuple(tuple(int(v) for v in e) for e in self.exponents)
        if not exps or any(len(e) != 3 or min(e) < 0 or e[2] % 2 or sum(e) < 2 for e in exps):
            raise ValueError(f"exponents must be non-empty triples (a, b, p) >= 0 with p even and "
                             f"a + b + p >= 2, got {self.exponents!r}")
        coefficients = tuple(float(c) for c in self.coefficients)
        if len(coefficients) != len(exps) or not all(math.isfinite(c) for c in coefficients):
            raise ValueError(f"coefficients must be {len(exps)} finite numbers (one per exponent triple), "
                             f"got {self.coefficients!r}")
        object.__setattr__(self, "exponents", exps)
        object.__setattr__(self, "coefficients", coefficients)
        object.__setattr__(self, "strain_min", tuple(float(v) for v in self.strain_min))
        object.__setattr__(self, "strain_max", tuple(float(v) for v in self.strain_max))

    @property
    def degree(self) -> int:
        return max(sum(e) for e in self.exponents)

    def _X(self, strains) -> np.ndarray:
        X = np.atleast_2d(np.asarray(strains, dtype=float))
        if X.shape[1] != 3 or not np.all(np.isfinite(X)):
            raise ValueError(f"strains must be finite (n, 3) Voigt strains (E11, E22, 2 E12), got shape {X.shape}")
        return X

    def energy(self, strains) -> np.ndarray:
        """W [J/m^2] at the strains (n, 3)."""
        X = self._X(strains)
        return _monomial_derivative(X, np.array(self.exponents), (0, 0, 0)) @ np.array(self.coefficients)

    def resultants(self, strains) -> np.ndarray:
        """N = dW/deps = (N11, N22, N12) [N/m] at the strains (n, 3), shape (n, 3)."""
        X = self._X(strains)
        return gradient_basis(X, np.array(self.exponents)) @ np.array(self.coefficients)

    def tangent(self, strains) -> np.ndarray:
        """d^2W/deps^2 [N/m] at the strains (n, 3), shape (n, 3, 3)."""
        X = self._X(strains)
        return hessian_basis(X, np.array(self.exponents)) @ np.array(self.coefficients)

    @property
    def initial_stiffness(self) -> np.ndarray:
        """A0 = d^2W/deps^2 at eps = 0 [N/m] (3x3 Voigt): the small-strain membrane stiffness t Q."""
        return self.tangent(np.zeros((1, 3)))[0]

    @property
    def parameters(self) -> np.ndarray:
        """Values for the fem.Constant of ufl_energy: the coefficients (K,) [J/m^2]."""
        return np.array(self.coefficients)

    def ufl_energy(self, strain_voigt, parameters):
        """UFL W(eps) [J/m^2] of the Voigt strain (forms.fitted.polynomial_energy); `parameters` is a
        fem.Constant (or sequence) holding self.parameters, so new values do not recompile forms."""
        return fitted_forms.polynomial_energy(strain_voigt, self.exponents, parameters)

    def to_dict(self) -> dict:
        return {"type": LAW_TYPE,
                "variables": "eps = (E11, E22, gamma12 = 2 E12), Green-Lagrange strain in the warp/weft frame",
                "energy": "W = sum_k c_k E11^a E22^b gamma12^p [J/m^2]; N = dW/deps [N/m]",
                "exponents": [list(e) for e in self.exponents],
                "coefficients": list(self.coefficients),
                "strain_min": list(self.strain_min), "strain_max": list(self.strain_max),
                "relative_rms_residual": self.relative_rms_residual,
                "min_eigenvalue": self.min_eigenvalue, "max_eigenvalue": self.max_eigenvalue,
                "n_samples": self.n_samples, "repaired": self.repaired}

    @classmethod
    def from_dict(cls, data: dict) -> "FittedMembraneLaw":
        if data.get("type") != LAW_TYPE:
            raise ValueError(f"membrane law type must be {LAW_TYPE!r}, got {data.get('type')!r}")
        for key in ("exponents", "coefficients"):
            if key not in data:
                raise ValueError(f"membrane law: missing key {key!r}")
        fields = ("strain_min", "strain_max", "relative_rms_residual", "min_eigenvalue", "max_eigenvalue",
                  "n_samples", "repaired")
        return cls(exponents=tuple(tuple(e) for e in data["exponents"]),
                   coefficients=tuple(data["coefficients"]),
                   **{k: (tuple(data[k]) if isinstance(data[k], list) else data[k]) for k in fields if k in data})


# ----------------------------------------------------------------------------------- fitting
def convexity_points(strains: np.ndarray, n_grid: int = 9) -> np.ndarray:
    """Points where the Hessian is checked: an n_grid^3 grid over the bounding box of the data (mirrored
    in gamma12, with the origin), kept where it lies in their convex hull, plus the data themselves.
    With data spanning fewer than three dimensions the whole box grid (collapsed axes) is used."""
    X = np.asarray(strains, dtype=float)
    cloud = np.vstack([X, X * np.array([1.0, 1.0, -1.0]), np.zeros((1, 3))])
    lower, upper = cloud.min(axis=0), cloud.max(axis=0)
    axes = [np.linspace(lo, hi, n_grid) if hi > lo else np.array([lo]) for lo, hi in zip(lower, upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    active = upper > lower
    if active.sum() >= 2:
        try:
            hull = Delaunay(cloud[:, active])
            span = (upper - lower)[active]
            inside = hull.find_simplex(grid[:, active], tol=1e-9 * float(span.max())) >= 0
            grid = grid[inside]
        except QhullError:
            pass  # flat data (e.g. all on a plane through E space): keep the box grid
    return np.vstack([cloud, grid])


def fit_membrane_law(samples: MembraneSamples, degree: int = 4, *, min_curvature_ratio: float = 1e-6,
                     repair: bool = True, max_residual: float = 0.05, n_grid: int = 9,
                     max_rounds: int = 30, initial_stiffness: np.ndarray | None = None) -> FittedMembraneLaw:
    """Least-squares polynomial W of `degree` (>= 2) whose gradient matches the resultants.

    min_curvature_ratio: the Hessian counts as positive definite where its smallest eigenvalue is at
        least this fraction of the largest eigenvalue seen on the convexity grid.
    repair: if the plain fit is not convex there, re-fit with cutting-plane convexity constraints
        (otherwise raise ValueError). max_residual: largest acceptable relative RMS residual of the
        repaired fit (the data are then judged non-convex: ValueError naming `resultants`).
    n_grid: grid points per axis of the convexity check; max_rounds: cutting-plane rounds.
    initial_stiffness: optional measured small-strain stiffness A0 [N/m] (3x3 Voigt, orthotropic: A13 =
        A23 = 0, symmetric); the Hessian of W at eps = 0 is then held equal to it (the quadratic
        coefficients are fixed: c_200 = A11/2, c_110 = A12, c_020 = A22/2, c_002 = A33/2) and only the
        higher-order terms are fitted. Without it the quadratic terms are fitted like the others.
    """
    if not isinstance(samples, MembraneSamples):
        raise ValueError(f"samples must be MembraneSamples, got {type(samples).__name__}")
    exps = np.array(energy_exponents(degree))
    for name, value in (("min_curvature_ratio", min_curvature_ratio), ("max_residual", max_residual)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    if isinstance(n_grid, bool) or int(n_grid) != n_grid or n_grid < 2:
        raise ValueError(f"n_grid must be an integer >= 2, got {n_grid!r}")
    X, N = samples.strains, samples.resultants
    b = N.reshape(-1)
    if not np.any(b):
        raise ValueError("resultants are all zero: nothing to fit")
    c_fixed = np.zeros(len(exps))
    free = np.ones(len(exps), dtype=bool)
    if initial_stiffness is not None:
        c_fixed, free = _quadratic_from_stiffness(initial_stiffness, exps)
    K = int(free.sum())
    G_all = gradient_basis(X, exps).reshape(-1, len(exps))  # rows: sample i, component j
    G = G_all[:, free]
    b = b - G_all @ c_fixed  # what the free (higher-order) terms must supply
    scale = np.linalg.norm(G, axis=0)  # column scaling for conditioning
    rank = int(np.linalg.matrix_rank(G / np.where(scale > 0, scale, 1.0), tol=1e-10)) if np.all(scale > 0) else 0
    if G.shape[0] < K or rank < K:
        raise ValueError(
            f"samples: {len(X)} strain states give {G.shape[0]} stress equations of rank {rank}, fewer than the "
            f"{K} free coefficients of a degree-{int(degree)} energy; add states (biaxial and shear) or lower degree")
    Gs = G / scale
    cs, *_ = np.linalg.lstsq(Gs, b, rcond=None)

    points = convexity_points(X, n_grid)
    H_all = hessian_basis(points, exps)
    H_basis = H_all[..., free] / scale  # acts on the scaled free coefficients
    H_offset = H_all @ c_fixed  # (m, 3, 3): the fixed quadratic part (constant)
    eigval, eigvec = _hessian_eigen(H_basis, cs, H_offset)
    reference = float(eigval[:, -1].max())
    if not reference > 0:
        raise ValueError("resultants: the fitted energy has no positive curvature on the data (stress does "
                         "not increase with strain anywhere); check the sign convention N = dW/deps")
    margin = min_curvature_ratio * reference
    repaired = False
    if eigval[:, 0].min() < margin:
        if not repair:
            raise ValueError(f"resultants: the fitted energy is not convex on the data hull (min Hessian "
                             f"eigenvalue {eigval[:, 0].min():.4g} N/m < {margin:.4g} N/m) and repair=False")
        cs = _repair_convexity(Gs, b, cs, H_basis, margin, max_rounds, H_offset)
        repaired = True
        eigval, _ = _hessian_eigen(H_basis, cs, H_offset)
    residual = _relative_rms(Gs, cs, b, N.reshape(-1))
    if repaired and residual > max_residual:
        raise ValueError(f"resultants: the data are not representable by a convex degree-{int(degree)} energy: the "
                         f"convexity-repaired fit leaves a relative RMS residual {residual:.3g} > max_residual = "
                         f"{max_residual:.3g}")
    c = c_fixed.copy()
    c[free] = cs / scale
    return FittedMembraneLaw(exponents=tuple(map(tuple, exps.tolist())), coefficients=tuple(c.tolist()),
                             strain_min=tuple(X.min(axis=0)), strain_max=tuple(X.max(axis=0)),
                             relative_rms_residual=residual, min_eigenvalue=float(eigval[:, 0].min()),
                             max_eigenvalue=float(eigval[:, -1].max()), n_samples=len(X), repaired=repaired)


def _orthotropic_stiffness(A0, definite: bool) -> np.ndarray:
    """A0 [N/m] (3x3 Voigt) checked: finite, symmetric, non-zero, A13 = A23 = 0 (W even in the shear strain),
    positive definite (`definite`) or semi-definite; ValueError naming initial_stiffness otherwise."""
    A = np.array(A0, dtype=float)
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ValueError(f"initial_stiffness must be a finite 3x3 matrix [N/m], got {A0!r}")
    size = float(np.abs(A).max())
    if not size > 0 or np.abs(A - A.T).max() > 1e-12 * size:
        raise ValueError(f"initial_stiffness must be symmetric and non-zero, got {A.tolist()}")
    if abs(A[0, 2]) > 1e-12 * size or abs(A[1, 2]) > 1e-12 * size:
        raise ValueError("initial_stiffness: A13 and A23 must vanish (W is even in the shear strain)")
    lowest = np.linalg.eigvalsh(A)[0]
    if lowest < 0 or (definite and lowest <= 0):
        raise ValueError(f"initial_stiffness must be positive {'definite' if definite else 'semi-definite'} "
                         f"(eigenvalues {np.linalg.eigvalsh(A).tolist()} N/m), got {A.tolist()}")
    return A


def _quadratic_from_stiffness(A0, exps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fixed coefficients (K,) and the mask of free ones for W = 1/2 eps.A0 eps + higher order terms."""
    A0 = _orthotropic_stiffness(A0, definite=False)
    values = {(2, 0, 0): A0[0, 0] / 2, (1, 1, 0): A0[0, 1], (0, 2, 0): A0[1, 1] / 2, (0, 0, 2): A0[2, 2] / 2}
    c_fixed = np.zeros(len(exps))
    free = np.ones(len(exps), dtype=bool)
    for k, e in enumerate(map(tuple, exps.tolist())):
        if e in values:
            c_fixed[k], free[k] = values[e], False
    return c_fixed, free


def _hessian_eigen(H_basis: np.ndarray, c: np.ndarray, offset: np.ndarray | float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (m, 3) ascending and eigenvectors (m, 3, 3) of H(x_i) = H_basis_i @ c + offset_i."""
    return np.linalg.eigh(H_basis @ c + offset)


def _relative_rms(G: np.ndarray, c: np.ndarray, b: np.ndarray, total: np.ndarray | None = None) -> float:
    """|G c - b| / |total| (total: the full resultants; b by default)."""
    nb = float(np.linalg.norm(b if total is None else total))
    r = float(np.linalg.norm(G @ c - b))
    return r / nb if nb > 0 else r


def _least_squares_with_inequalities(Gs: np.ndarray, b: np.ndarray, C: np.ndarray, h: np.ndarray) -> np.ndarray:
    """min |Gs c - b| subject to C c >= h (Lawson & Hanson, Solving Least Squares Problems, ch. 23: LSI
    reduced to least distance programming, solved by NNLS); ValueError if the constraints are infeasible."""
    Q, R = np.linalg.qr(Gs)
    f = Q.T @ b
    # c = R^-1 (z + f): min |z| subject to (C R^-1) z >= h - C R^-1 f
    CR = np.linalg.solve(R.T, C.T).T
    rhs = h - CR @ f
    E = np.vstack([CR.T, rhs[None, :]])
    target = np.zeros(E.shape[0])
    target[-1] = 1.0
    u, _ = nnls(E, target, maxiter=50 * E.shape[1])
    r = E @ u - target
    if np.linalg.norm(r) <= 1e-12 or abs(r[-1]) <= 1e-300:
        raise ValueError("resultants: the convexity constraints are infeasible for an energy of this degree")
    z = -r[:-1] / r[-1]
    return np.linalg.solve(R, z + f)


def _repair_convexity(Gs: np.ndarray, b: np.ndarray, cs: np.ndarray, H_basis: np.ndarray, margin: float,
                      max_rounds: int, H_offset: np.ndarray | float = 0.0) -> np.ndarray:
    """Least squares subject to v.H(x)v >= 2 margin at the cut points (x, v), H = H_basis c + H_offset, cuts
    added where the smallest eigenvalue falls below margin (cutting planes on a convex quadratic programme).
    The margin keeps its ratio to the largest eigenvalue of the current fit."""
    cuts, rhs = np.empty((0, len(cs))), np.empty(0)
    offset = np.broadcast_to(np.asarray(H_offset, dtype=float), H_basis.shape[:3])
    ratio = margin / float(_hessian_eigen(H_basis, cs, offset)[0][:, -1].max())
    for _ in range(max_rounds):
        eigval, eigvec = _hessian_eigen(H_basis, cs, offset)
        margin = ratio * float(eigval[:, -1].max())  # relative to the current fit's stiffest curvature
        bad = np.flatnonzero(eigval[:, 0] < margin)
        if len(bad) == 0:
            return cs
        bad = bad[np.argsort(eigval[bad, 0])][:60]  # the worst points first
        v = eigvec[bad, :, 0]
        new = np.einsum("mi,mijk,mj->mk", v, H_basis[bad], v) / margin  # rows: v.H_k v / margin
        fixed = np.einsum("mi,mij,mj->m", v, offset[bad], v) / margin
        cuts = np.vstack([cuts, new])
        rhs = np.concatenate([rhs, 2.0 - fixed])
        cs = _least_squares_with_inequalities(Gs, b, cuts, rhs)
    raise ValueError(f"resultants: the convexity repair did not converge in max_rounds = {max_rounds} rounds")


# ------------------------------------------------------------------------------- fabric link
def _positive(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) \
            or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def fitted_fabric(law: "FittedMembraneLaw | ConvexMembraneLaw", thickness: float, density: float = 0.0, *,
                  bending_rigidity: tuple[float, float] | None = None,
                  bending_law: KawabataBending | SquareRootBending | None = None,
                  G13: float | None = None, name: str = "fitted fabric") -> Fabric:
    """A Fabric whose membrane energy is the fitted law (ShellModel uses W instead of 1/2 eps.A eps).

    E1, E2, G12, nu12 are those of the law's small-strain stiffness A0 = t Q (Voigt, N/m), used for the
    default bending rigidity t^3/12 Q, the transverse shear default G13 = G12 and linearised
    operators: Q = A0 / t, nu12 = Q12 / Q22, E1 = Q11 - Q12^2 / Q22, E2 = Q22 - Q12^2 / Q11, G12 = Q33.
    """
    if not isinstance(law, (FittedMembraneLaw, ConvexMembraneLaw)):
        raise ValueError(f"law must be a FittedMembraneLaw or ConvexMembraneLaw, got {type(law).__name__}")
    t = _positive("thickness", thickness)
    Q = law.initial_stiffness / t
    if abs(Q[0, 2]) > 1e-12 * abs(Q[0, 0]) or abs(Q[1, 2]) > 1e-12 * abs(Q[1, 1]):
        raise ValueError("law: the small-strain stiffness couples stretch and shear (not orthotropic)")
    if not (Q[0, 0] > 0 and Q[1, 1] > 0 and Q[2, 2] > 0 and Q[0, 0] * Q[1, 1] > Q[0, 1] ** 2):
        raise ValueError(f"law: the small-strain stiffness A0 = {law.initial_stiffness.tolist()} N/m is not "
                         "positive definite; the fabric needs a positive initial stiffness")
    return Fabric(E1=float(Q[0, 0] - Q[0, 1] ** 2 / Q[1, 1]), E2=float(Q[1, 1] - Q[0, 1] ** 2 / Q[0, 0]),
                  G12=float(Q[2, 2]), nu12=float(Q[0, 1] / Q[1, 1]), thickness=t, density=density, G13=G13,
                  bending_rigidity=bending_rigidity, bending_law=bending_law, name=name, membrane_law=law)


# ----------------------------------------------------------------- convex by construction
CONVEX_LAW_TYPE = "convex-ridge"
# directions l in strain space (E11, E22, gamma12), before normalization; each stands for itself and its
# gamma-mirror (l1, l2, -l3), which share one coefficient (W even in gamma12)
DEFAULT_DIRECTIONS: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 0.0), (1.0, -1.0, 0.0),
    (1.0, 0.0, 1.0), (0.0, 1.0, 1.0), (1.0, 1.0, 1.0), (1.0, -1.0, 1.0))
MACAULAY_POWERS: tuple[int, ...] = (3, 4, 5, 6)  # <x>^n = max(x, 0)^n: tension stiffening
EVEN_POWERS: tuple[int, ...] = (4, 6)  # x^n on directions with a shear component: shear locking
# onsets s of shifted cubic ramps <x - s>^3 (the contact of the crossovers sets in at a finite stretch:
# the stored samples stiffen from ~1.8e5 N/m to ~4e6 N/m between E = 0.02 and 0.06, which powers of x
# alone cannot follow with the small-strain tangent held to A0)
RAMP_ONSETS: tuple[float, ...] = (0.01, 0.02, 0.03, 0.04, 0.05)


def _profile(kind: str, power: int, shift: float, x: np.ndarray, order: int) -> np.ndarray:
    """d^order/dx^order of phi(x) = <x - shift>^power (kind "macaulay") or x^power (kind "even"), vectorized."""
    if kind == "macaulay":
        x = np.maximum(x - shift, 0.0)
    return _power_derivative(x, power, order)


def _mirror_group(direction: np.ndarray) -> np.ndarray:
    """(m, 3) unit directions of a term: l and, if different, its gamma-mirror (l1, l2, -l3)."""
    l = direction / np.linalg.norm(direction)
    if l[2] == 0.0:
        return l[None, :]
    return np.stack([l, l * np.array([1.0, 1.0, -1.0])])


def default_convex_terms(directions: Sequence[Sequence[float]] = DEFAULT_DIRECTIONS,
                         onsets: Sequence[float] = RAMP_ONSETS) -> tuple[tuple[int, str, int, float], ...]:
    """Terms (direction index, kind, power, shift): every Macaulay power <x>^n on every direction, a cubic
    ramp <x - s>^3 for every onset s, and the even powers only on directions with a shear component (an
    even power of a stretch direction would stiffen the fabric in compression, where it buckles)."""
    out = []
    for j, l in enumerate(directions):
        out.extend((j, "macaulay", n, 0.0) for n in MACAULAY_POWERS)
        out.extend((j, "macaulay", 3, float(s)) for s in onsets)
        if l[2] != 0.0:
            out.extend((j, "even", n, 0.0) for n in EVEN_POWERS)
    return tuple(out)


@dataclass(frozen=True, eq=False)
class ConvexMembraneLaw:
    """W(eps) = 1/2 eps.A0.eps + sum_k c_k sum_{l in L_k} phi_k(l.eps) [J/m^2], c_k >= 0, eps = (E11, E22, 2 E12).

    Convex by construction, globally: A0 is symmetric positive definite, every phi_k is convex and C2
    (the Macaulay power <x - s>^n = max(x - s, 0)^n with n >= 3 and onset s >= 0, or an even power x^n),
    so phi_k(l.eps) is a
    convex function of eps (a convex function of a linear form) and a non-negative combination of convex
    functions plus a positive-definite quadratic is convex; its Hessian
        H(eps) = A0 + sum_k c_k sum_l phi_k''(l.eps) l l^T >= A0   (every added term is c phi'' l l^T >= 0)
    at EVERY strain, inside the fitted data or not. L_k is the unit direction l of term k and its
    gamma-mirror (l1, l2, -l3) with one shared coefficient, so W(E11, E22, -g) = W(E11, E22, g) (warp/weft
    weave symmetry). W(0) = 0, N(0) = 0 and H(0) = A0 (every phi has phi(0) = phi'(0) = phi''(0) = 0).

    initial_stiffness: A0 [N/m] (3x3 Voigt, symmetric positive definite); directions: the un-normalized l
    (n_dir, 3); terms: K tuples (direction index, "macaulay" | "even", power, onset s [-]; s = 0 for
    "even"; a triple means s = 0); coefficients: K values
    c_k >= 0 [J/m^2]; strain_min/max, relative_rms_residual, n_samples: as FittedMembraneLaw.
    """

    initial_stiffness: np.ndarray
    directions: tuple[tuple[float, float, float], ...]
    terms: tuple[tuple[int, str, int, float], ...]
    coefficients: tuple[float, ...]
    strain_min: tuple[float, float, float] = (0.0, 0.0, 0.0)
    strain_max: tuple[float, float, float] = (0.0, 0.0, 0.0)
    relative_rms_residual: float = 0.0
    n_samples: int = 0

    def __post_init__(self):
        A0 = _orthotropic_stiffness(self.initial_stiffness, definite=True)
        A0 = 0.5 * (A0 + A0.T)
        A0.setflags(write=False)
        dirs = np.array(self.directions, dtype=float)
        if dirs.ndim != 2 or dirs.shape[1] != 3 or len(dirs) == 0 or not np.all(np.isfinite(dirs)) \
                or np.any(np.linalg.norm(dirs, axis=1) == 0):
            raise ValueError(f"directions must be a non-empty list of finite non-zero 3-vectors, got {self.directions!r}")
        terms = []
        for term in self.terms:
            term = tuple(term) + ((0.0,) if len(term) == 3 else ())
            if len(term) != 4 or term[1] not in ("macaulay", "even") or not (0 <= int(term[0]) < len(dirs)) \
                    or int(term[2]) != term[2] or (term[1] == "macaulay" and term[2] < 3) \
                    or (term[1] == "even" and (term[2] < 2 or term[2] % 2 or term[3] != 0)) \
                    or not (math.isfinite(float(term[3])) and float(term[3]) >= 0):
                raise ValueError(f"terms: each term must be (direction index < {len(dirs)}, 'macaulay' with power "
                                 f">= 3 (C2) and onset >= 0 | 'even' with an even power >= 2 and onset 0, onset), "
                                 f"got {term!r}")
            terms.append((int(term[0]), str(term[1]), int(term[2]), float(term[3])))
        c = tuple(float(v) for v in self.coefficients)
        if len(c) != len(terms) or not all(math.isfinite(v) and v >= 0 for v in c):
            raise ValueError(f"coefficients must be {len(terms)} finite numbers >= 0 (one per term; c >= 0 "
                             f"makes W convex), got {self.coefficients!r}")
        object.__setattr__(self, "initial_stiffness", A0)
        object.__setattr__(self, "directions", tuple(tuple(float(v) for v in l) for l in dirs))
        object.__setattr__(self, "terms", tuple(terms))
        object.__setattr__(self, "coefficients", c)
        object.__setattr__(self, "strain_min", tuple(float(v) for v in self.strain_min))
        object.__setattr__(self, "strain_max", tuple(float(v) for v in self.strain_max))

    # ------------------------------------------------------------------------ numpy evaluation
    def _X(self, strains) -> np.ndarray:
        X = np.atleast_2d(np.asarray(strains, dtype=float))
        if X.ndim != 2 or X.shape[1] != 3 or not np.all(np.isfinite(X)):
            raise ValueError(f"strains must be finite (n, 3) Voigt strains (E11, E22, 2 E12), got shape {X.shape}")
        return X

    def groups(self) -> list[np.ndarray]:
        """Per term, the (m, 3) unit directions sharing its coefficient (l and its gamma-mirror)."""
        return [_mirror_group(np.array(self.directions[j])) for j, _, _, _ in self.terms]

    def energy(self, strains) -> np.ndarray:
        """W [J/m^2] at the strains (n, 3)."""
        X = self._X(strains)
        return 0.5 * np.einsum("ni,ij,nj->n", X, self.initial_stiffness, X) + energy_basis(self, X) @ self.c

    def resultants(self, strains) -> np.ndarray:
        """N = dW/deps = A0 eps + sum_k c_k sum_l phi_k'(l.eps) l [N/m] at the strains (n, 3), shape (n, 3)."""
        X = self._X(strains)
        return X @ self.initial_stiffness + convex_gradient_basis(self, X) @ self.c

    def tangent(self, strains) -> np.ndarray:
        """H = A0 + sum_k c_k sum_l phi_k''(l.eps) l l^T [N/m] at the strains (n, 3), shape (n, 3, 3)."""
        X = self._X(strains)
        H = np.broadcast_to(self.initial_stiffness, (len(X), 3, 3)).copy()
        for ck, group, (_, kind, power, shift) in zip(self.c, self.groups(), self.terms):
            if ck:
                curv = _profile(kind, power, shift, X @ group.T, 2)  # (n, m)
                H += ck * np.einsum("nm,mi,mj->nij", curv, group, group)
        return H

    @property
    def c(self) -> np.ndarray:
        return np.array(self.coefficients)

    @property
    def min_eigenvalue(self) -> float:
        """Smallest eigenvalue of A0: a lower bound of every Hessian eigenvalue at every strain [N/m]."""
        return float(np.linalg.eigvalsh(self.initial_stiffness)[0])

    # ----------------------------------------------------------------------------- UFL
    @property
    def parameters(self) -> np.ndarray:
        """Values for the fem.Constant of ufl_energy: A0 row-major (9) then the coefficients (K) [N/m, J/m^2]."""
        return np.concatenate([self.initial_stiffness.reshape(-1), self.c])

    def ufl_energy(self, strain_voigt, parameters):
        """UFL W(eps) [J/m^2] of the Voigt strain (forms.fitted.convex_ridge_energy); `parameters` is a
        fem.Constant (or sequence) holding self.parameters, so new values do not recompile forms."""
        return fitted_forms.convex_ridge_energy(strain_voigt, [g.tolist() for g in self.groups()],
                                                [(kind, power, shift) for _, kind, power, shift in self.terms],
                                                parameters)

    # ---------------------------------------------------------------------------- storage
    def to_dict(self) -> dict:
        return {"type": CONVEX_LAW_TYPE,
                "variables": "eps = (E11, E22, gamma12 = 2 E12), Green-Lagrange strain in the warp/weft frame",
                "energy": "W = 1/2 eps.A0.eps + sum_k c_k sum_(l = d_k/|d_k| and its gamma-mirror) phi_k(l.eps) "
                          "[J/m^2], term k = [direction index, kind, n, s]: phi = <x - s>^n (macaulay) or x^n "
                          "(even), c_k >= 0: convex everywhere; "
                          "N = dW/deps [N/m]",
                "initial_stiffness": self.initial_stiffness.tolist(),
                "directions": [list(l) for l in self.directions],
                "terms": [list(t) for t in self.terms],
                "coefficients": list(self.coefficients),
                "strain_min": list(self.strain_min), "strain_max": list(self.strain_max),
                "relative_rms_residual": self.relative_rms_residual, "n_samples": self.n_samples}

    @classmethod
    def from_dict(cls, data: dict) -> "ConvexMembraneLaw":
        if data.get("type") != CONVEX_LAW_TYPE:
            raise ValueError(f"membrane law type must be {CONVEX_LAW_TYPE!r}, got {data.get('type')!r}")
        for key in ("initial_stiffness", "directions", "terms", "coefficients"):
            if key not in data:
                raise ValueError(f"membrane law: missing key {key!r}")
        fields = ("strain_min", "strain_max", "relative_rms_residual", "n_samples")
        return cls(initial_stiffness=np.array(data["initial_stiffness"], dtype=float),
                   directions=tuple(tuple(l) for l in data["directions"]),
                   terms=tuple(tuple(t) for t in data["terms"]), coefficients=tuple(data["coefficients"]),
                   **{k: (tuple(data[k]) if isinstance(data[k], list) else data[k]) for k in fields if k in data})


def energy_basis(law: ConvexMembraneLaw, X: np.ndarray) -> np.ndarray:
    """(n, K): sum_l phi_k(l.eps) of every term at the strains X (n, 3)."""
    return np.column_stack([_profile(kind, power, shift, X @ g.T, 0).sum(axis=1)
                            for g, (_, kind, power, shift) in zip(law.groups(), law.terms)])


def convex_gradient_basis(law: ConvexMembraneLaw, X: np.ndarray) -> np.ndarray:
    """(n, 3, K): d/deps of sum_l phi_k(l.eps) = sum_l phi_k'(l.eps) l, so that N = A0 eps + basis @ c."""
    return np.stack([_profile(kind, power, shift, X @ g.T, 1) @ g
                     for g, (_, kind, power, shift) in zip(law.groups(), law.terms)], axis=-1)


def fit_convex_law(samples: MembraneSamples, initial_stiffness: np.ndarray,
                   directions: Sequence[Sequence[float]] = DEFAULT_DIRECTIONS,
                   terms: Sequence[tuple] | None = None, prune: bool = True) -> ConvexMembraneLaw:
    """ConvexMembraneLaw with Hessian A0 = initial_stiffness [N/m] at eps = 0 whose c_k >= 0 minimise
    |N_fit - N| over the samples: N is linear in c, so this is non-negative least squares
    (scipy.optimize.nnls, Lawson & Hanson ch. 23) on N - A0 eps, columns scaled to unit norm (a positive
    scaling keeps c >= 0). No convexity repair is needed: every c >= 0 gives a convex W.
    terms: default default_convex_terms(directions); prune: drop the terms whose coefficient is zero
    (NNLS leaves most at zero; the UFL form then holds only the active ones)."""
    if not isinstance(samples, MembraneSamples):
        raise ValueError(f"samples must be MembraneSamples, got {type(samples).__name__}")
    X, N = samples.strains, samples.resultants
    if not np.any(N):
        raise ValueError("resultants are all zero: nothing to fit")
    terms = default_convex_terms(directions) if terms is None else tuple(terms)
    if isinstance(prune, bool) is False:
        raise ValueError(f"prune must be a bool, got {prune!r}")
    law = ConvexMembraneLaw(initial_stiffness, tuple(map(tuple, directions)), terms, (0.0,) * len(terms))
    G = convex_gradient_basis(law, X).reshape(-1, len(terms))  # rows: sample i, component j
    b = (N - X @ law.initial_stiffness).reshape(-1)  # what the higher-order terms must supply
    scale = np.linalg.norm(G, axis=0)
    used = scale > 0  # a term never active on the data (e.g. <x>^n with x <= 0 everywhere) stays zero
    c = np.zeros(len(terms))
    if used.any():
        cs, _ = nnls(G[:, used] / scale[used], b, maxiter=100 * len(terms))
        c[used] = cs / scale[used]
    residual = float(np.linalg.norm(G @ c - b) / np.linalg.norm(N))
    keep = c > 0 if prune else np.ones(len(c), dtype=bool)
    if not keep.any():
        keep[0] = True  # W = 1/2 eps.A0.eps: one (zero) term keeps the law well-formed
    terms, c = tuple(t for t, k in zip(law.terms, keep) if k), c[keep]
    return ConvexMembraneLaw(law.initial_stiffness, law.directions, terms, tuple(c.tolist()),
                             strain_min=tuple(X.min(axis=0)), strain_max=tuple(X.max(axis=0)),
                             relative_rms_residual=residual, n_samples=len(X))


MEMBRANE_LAW_TYPES = {LAW_TYPE: FittedMembraneLaw, CONVEX_LAW_TYPE: ConvexMembraneLaw}


def membrane_law_from_dict(data: dict) -> FittedMembraneLaw | ConvexMembraneLaw:
    """The membrane law of a stored fabric's "membrane" entry, by its "type"."""
    kind = data.get("type")
    if kind not in MEMBRANE_LAW_TYPES:
        raise ValueError(f"membrane.type must be one of {sorted(MEMBRANE_LAW_TYPES)}, got {kind!r}")
    return MEMBRANE_LAW_TYPES[kind].from_dict(data)
