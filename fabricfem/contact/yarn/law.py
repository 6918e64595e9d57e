"""The yarn contact law: symmetrized augmented Lagrangian of Laursen with Coulomb friction ([Man2006, Box 7],
eqs. 3.25, 3.69, 3.74, 3.75), its parameters, and the nodal forces of one contact element as functions of the
stencil positions (the functions the consistent tangent differentiates). Units: m, N, Pa.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fabricfem.contact.yarn.geometry import foot_and_normal
from fabricfem.meshes._validate import positive

__all__ = ["ContactParameters", "normal_forces", "smooth_ramp", "symmetric_return_map", "tangential_forces"]


@dataclass(frozen=True)
class ContactParameters:
    """Parameters of the yarn contact law.

    Attributes:
        penalty: eps_N [Pa/m], normal penalty (eq. 3.69), > 0
        friction: Coulomb coefficient mu >= 0
        tangential_penalty: eps_T [Pa/m] (eq. 3.74), > 0; None = penalty
        tolerance: [m] augmentation stops when max penetration and max stick slip are below it, > 0
        max_augmentations: Uzawa updates per load step (>= 1)
        augmented: False = pure penalty law (no multipliers, one Newton solve per step)
        margin: [m] Verlet margin of the contact search; None = median master facet edge length
        smoothing: [m] >= 0, width delta of a C1 quadratic rounding of the Macaulay bracket of eq. 3.69
            (smooth_ramp with w = eps_N delta): removes the kink of the pressure where a node enters
            or leaves contact (Newton then does not cycle on the active set); 0 = the exact bracket.
            The rounding pushes with at most eps_N delta / 4 at zero gap, so delta is meant to be
            far below the penetration tolerance
        consistent_tangent: True = the tangent by central differences of the exact nodal forces over each
            contact element's stencil (YarnContact.add_jacobian, fabricfem.contact.yarn.tangent): includes the
            rotation of the master normals and the sliding of the foot point, which the closed form
            omits (a relative error ~ p / (eps_N h), measured 25% on the unit cell, where Newton then
            only converges linearly); False = the closed form (tangent.closed_form)
        penalty_growth: factor (>= 1) on eps_N and eps_T when the violation max(penetration, stick slip)
            has grown in two successive augmentations (`solve_with_contact`); 1 = never
    """

    penalty: float
    friction: float = 0.0
    tangential_penalty: float | None = None
    tolerance: float = 1e-9
    max_augmentations: int = 30
    augmented: bool = True
    margin: float | None = None
    smoothing: float = 0.0
    consistent_tangent: bool = False
    penalty_growth: float = 10.0

    def __post_init__(self) -> None:
        positive("penalty", self.penalty)
        if not (isinstance(self.penalty_growth, (int, float)) and np.isfinite(self.penalty_growth)
                and self.penalty_growth >= 1.0):
            raise ValueError(f"penalty_growth must be a finite factor >= 1, got {self.penalty_growth!r}")
        try:
            mu = float(self.friction)
        except (TypeError, ValueError):
            raise ValueError(f"friction (Coulomb coefficient) must be a number >= 0, got {self.friction!r}") from None
        if not (np.isfinite(mu) and mu >= 0.0):
            raise ValueError(f"friction (Coulomb coefficient) must be finite and >= 0, got {self.friction!r}")
        if self.tangential_penalty is not None:
            positive("tangential_penalty", self.tangential_penalty)
        positive("tolerance", self.tolerance)
        if isinstance(self.max_augmentations, bool) or int(self.max_augmentations) != self.max_augmentations \
                or self.max_augmentations < 1:
            raise ValueError(f"max_augmentations must be an integer >= 1, got {self.max_augmentations!r}")
        if self.margin is not None:
            positive("margin", self.margin)
        if not (isinstance(self.smoothing, (int, float)) and np.isfinite(self.smoothing) and self.smoothing >= 0.0):
            raise ValueError(f"smoothing must be a finite length >= 0 [m], got {self.smoothing!r}")

    @property
    def eps_T(self) -> float:
        """The tangential penalty eps_T [Pa/m] in use: tangential_penalty, or the normal penalty when None."""
        return float(self.penalty if self.tangential_penalty is None else self.tangential_penalty)


def symmetric_return_map(trial: np.ndarray, limit: np.ndarray, eps_T: float, projector: np.ndarray,
                         branch: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coulomb return mapping with a fixed friction limit ([Man2006, Box 7], eq. 3.75), n nodes, vectorized.

    trial: (n, 3) tangential trial tractions t* [Pa]; limit: (n,) mu lambda_N [Pa] >= 0;
    eps_T [Pa/m]; projector: (n, 3, 3) P = 1 - n n^T; branch: optional (n,) int, the branch imposed
    on a node (0 = stick, 1 = slip, -1 = the Coulomb test |t*| > limit decides): the fixed slip set of
    the active-set strategy (solve_with_fixed_sets).
    Returns (t_T (n, 3), D = dt_T/d(slip displacement) (n, 3, 3) [Pa/m], slip (n,) bool)."""
    norm = np.linalg.norm(trial, axis=1)
    slip = norm > limit
    if branch is not None:
        slip = np.where(branch >= 0, branch == 1, slip)
    safe = np.where(norm > 0.0, norm, 1.0)
    tau = trial / safe[:, None]
    traction = np.where(slip[:, None], limit[:, None] * tau, trial)                       # eq. 3.75
    stick_D = -eps_T * projector
    slip_D = -(limit * eps_T / safe)[:, None, None] * (projector - tau[:, :, None] * tau[:, None, :])
    return traction, np.where(slip[:, None, None], slip_D, stick_D), slip


def smooth_ramp(z: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """C1 rounding of the Macaulay bracket <z> = max(z, 0) and its slope, vectorized:
    0 for z <= -w, (z + w)^2 / (4 w) for |z| < w, z for z >= w (w = width >= 0; w = 0: the bracket)."""
    z = np.asarray(z, dtype=float)
    if width <= 0.0:
        return np.maximum(z, 0.0), (z > 0.0).astype(float)
    inner = np.abs(z) < width
    zi = np.where(inner, z, 0.0)
    value = np.where(z >= width, z, np.where(inner, (zi + width) ** 2 / (4.0 * width), 0.0))
    slope = np.where(z >= width, 1.0, np.where(inner, (zi + width) / (2.0 * width), 0.0))
    return value, slope


def normal_forces(params: ContactParameters, xs: np.ndarray, xp: np.ndarray, ql: np.ndarray, pql: np.ndarray,
                  pmask: np.ndarray, member: np.ndarray, lam: np.ndarray, area: np.ndarray,
                  tri: np.ndarray | None = None) -> np.ndarray:
    """Normal contact forces (m, 5, 3) [N] on (slave, 4 vertices of its master facet) as functions of
    the slave position xs (m, 3) [m] and the patch vertex positions xp (m, 16, 3) [m], exactly as
    YarnContact.evaluate computes them for a fixed master facet (projection, interpolated nodal normal,
    eq. 3.69): f_s = A_s p n, f_i = -N_i A_s p n. lam: (m,) lambda_N [Pa]; area: (m,) A_s [m^2]; ql, pql,
    pmask, member: the patch arrays of each slave's facet (geometry.facet_patches); tri: fixed triangle or -1."""
    point, w, n = foot_and_normal(xs, xp, ql, pql, pmask, member, tri)
    gap = ((xs - point) * n).sum(1)                                           # eq. 3.25
    p, _ = smooth_ramp(lam - params.penalty * gap, params.penalty * params.smoothing)  # eq. 3.69
    f = (area * p)[:, None] * n
    return np.concatenate([f[:, None, :], -w[:, :, None] * f[:, None, :]], axis=1)


def tangential_forces(params: ContactParameters, xs: np.ndarray, xp: np.ndarray, xr: np.ndarray, ql: np.ndarray,
                      pql: np.ndarray, pmask: np.ndarray, member: np.ndarray, lam: np.ndarray, lam_T: np.ndarray,
                      ref_w: np.ndarray, area: np.ndarray, slip: np.ndarray,
                      tri: np.ndarray | None = None) -> np.ndarray:
    """Friction forces (m, 5, 3) [N] on (slave, 4 vertices of its reference facet) as functions of the
    slave position xs (m, 3), the patch vertices xp (m, 16, 3) of its current master facet (they set
    the normal n, hence P = 1 - n n^T) and the reference facet vertices xr (m, 4, 3) [m], exactly as
    YarnContact.evaluate computes them with the friction branch `slip` (m,) fixed (eqs. 3.74-3.75):
    f_s = A_s t_T, f_i = -N_i(xi_n) A_s t_T. lam: (m,) lambda_N [Pa]; lam_T: (m, 3) lambda_T [Pa]; ref_w: (m, 4)
    reference weights N_i(xi_n); area: (m,) A_s [m^2]; the other arguments as for normal_forces."""
    point, _, n = foot_and_normal(xs, xp, ql, pql, pmask, member, tri)
    P = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    x_ref = (ref_w[:, :, None] * xr).sum(1)
    trial = np.einsum("mij,mj->mi", P, lam_T - params.eps_T * (xs - x_ref))     # eq. 3.74
    if params.augmented:
        limit = params.friction * lam
    else:
        gap = ((xs - point) * n).sum(1)
        limit = params.friction * smooth_ramp(-params.penalty * gap, params.penalty * params.smoothing)[0]
    t, _, _ = symmetric_return_map(trial, limit, params.eps_T, P, slip.astype(np.int64))  # eq. 3.75
    f = area[:, None] * t
    return np.concatenate([f[:, None, :], -ref_w[:, :, None] * f[:, None, :]], axis=1)
