"""The polynomial membrane law ([Man2006, sec. 4.3.6, 6.2.2]; fabricfem.materials.fitted, module docstring): W a
polynomial even in gamma12 without constant and linear terms, fitted by linear least squares on the resultants and
made convex on the data hull by cutting planes. Strains (E11, E22, gamma12 = 2 E12) [-], W [J/m^2], N [N/m].
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import Delaunay, QhullError

from fabricfem.forms import fitted as fitted_forms
from fabricfem.materials.membrane_samples import MembraneSamples, orthotropic_stiffness

__all__ = ["LAW_TYPE", "FittedMembraneLaw", "convexity_points", "energy_exponents", "fit_membrane_law",
           "gradient_basis", "hessian_basis", "power_derivative"]

LAW_TYPE = "polynomial-even-shear"


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


def power_derivative(x: np.ndarray, power: int, order: int) -> np.ndarray:
    """d^order/dx^order x^power, vectorized (zero when order > power)."""
    if order > power:
        return np.zeros_like(x)
    return math.perm(power, order) * x ** (power - order)


def _monomial_derivative(X: np.ndarray, exponents: np.ndarray, orders: Sequence[int]) -> np.ndarray:
    """(n, K) derivative of order `orders` = (i, j, l) of every monomial at the strains X (n, 3)."""
    out = np.ones((len(X), len(exponents)))
    for component in range(3):
        for k, power in enumerate(exponents[:, component]):
            out[:, k] *= power_derivative(X[:, component], int(power), orders[component])
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
        """The total degree of W (largest a + b + p)."""
        return max(sum(e) for e in self.exponents)

    def _X(self, strains) -> np.ndarray:
        """The strains as a finite (n, 3) array; ValueError otherwise."""
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
        """The fabric JSON "membrane" entry (fabricfem.fabrics): type, exponents, coefficients and fit record."""
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
        """The law of a to_dict entry; ValueError on another type or a missing key."""
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


def _quadratic_from_stiffness(A0, exps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fixed coefficients (K,) and the mask of free ones for W = 1/2 eps.A0 eps + higher order terms."""
    A0 = orthotropic_stiffness(A0, definite=False)
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
