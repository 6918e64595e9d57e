"""The membrane law convex by construction ([Man2006, sec. 4.3.6]; fabricfem.materials.fitted, module docstring):
W = 1/2 eps.A0.eps plus a non-negative combination of convex C2 ridge functions phi(l.eps), fitted by non-negative
least squares. Strains (E11, E22, gamma12 = 2 E12) [-], W [J/m^2], N [N/m].
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import nnls

from fabricfem.forms import fitted as fitted_forms
from fabricfem.materials.membrane_samples import MembraneSamples, orthotropic_stiffness
from fabricfem.materials.polynomial_law import power_derivative

__all__ = ["CONVEX_LAW_TYPE", "DEFAULT_DIRECTIONS", "EVEN_POWERS", "MACAULAY_POWERS", "RAMP_ONSETS",
           "ConvexMembraneLaw", "convex_gradient_basis", "default_convex_terms", "energy_basis", "fit_convex_law"]

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
    return power_derivative(x, power, order)


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
        A0 = orthotropic_stiffness(self.initial_stiffness, definite=True)
        A0 = 0.5 * (A0 + A0.T)
        A0.setflags(write=False)
        dirs = np.array(self.directions, dtype=float)
        if dirs.ndim != 2 or dirs.shape[1] != 3 or len(dirs) == 0 or not np.all(np.isfinite(dirs)) \
                or np.any(np.linalg.norm(dirs, axis=1) == 0):
            raise ValueError(f"directions must be a non-empty list of finite non-zero 3-vectors, "
                             f"got {self.directions!r}")
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
        """The strains as a finite (n, 3) array; ValueError otherwise."""
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
        """The coefficients c_k (K,) [J/m^2] as an array."""
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
        """The fabric JSON "membrane" entry (fabricfem.fabrics): type, A0, directions, terms, coefficients, record."""
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
        """The law of a to_dict entry; ValueError on another type or a missing key."""
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
