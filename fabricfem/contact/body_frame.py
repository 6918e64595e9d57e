"""Mass damping relative to the body: C = alpha M_L acting on the cloth's velocity relative to the skin under it.

The explicit engine's Rayleigh damping C = alpha M_L [1/s] ([Man2006, eq. 2.84]) drags every node towards rest in the
ground frame, so a garment carried by a moving limb feels a force -alpha m v even when it does not deform at all:
a drag on the rigid motion that grows with the motion's speed. `BodyFrameDamping` makes the same damping act on the
velocity relative to the body instead,

    f_d = -alpha M_L (v - v_b(x)),        v_b(x) = sum_k W_k(x) (c_k' + omega_k x (x - c_k))

with v_b the rigid velocity of the body's segments at the node's position x, blended by the weights W_k (below).
The integrator keeps treating -alpha M_L v implicitly (the division by M_L + dt/2 C_L, [Man2006, eq. 2.84]); this
hook adds the other part, +alpha M_L v_b(x^{n+1}, t_{n+1}), to the right-hand side before the division, so that the
step solves M_L a^{n+1} + C_L (v^{n+1} - v_b) = f exactly as the ground-frame step solves it with v_b = 0. The
stable step is unchanged (the added force depends on the position only, not on the velocity).

The segment velocities come from the posed frames at the step's neighbours t_n and t_{n+2} (central differences of a
material point of each segment, x(t) = c_k(t) + R_k(t) R_k(t_{n+1})^T (x - c_k(t_{n+1}))), so a rigid translation is
exact and a rotation at omega is off by the factor sin(omega dt) / (omega dt), 1 - 2e-11 on the sleeve. The weights:
a smooth partition of unity over the segments from a cheap surrogate of each segment's gap, the normalised radius q
([Man2006, eq. 3.61], fabricfem.contact.projection) over its slope, s_k = (sqrt(q_k) - 1) / |grad sqrt(q_k)|
[m] (the gap itself for a sphere and along an ellipsoid's axes, no Newton iteration; the skin's exact gaps are the
contact's, fabricfem.body.blended), W_k proportional to max(0, 1 - (s_k - min_j s_j) / w)^2 with w the body's blend
width: the
nearest segment alone away from the joints, a continuous share of both across a joint (the elbow), so that the
reference velocity has no jump where the nearest segment changes. Inactive segments (a schedule) take no weight; a
node with no active segment is damped against the ground.

Only the translations are referred to the body; the rotational dofs keep the ground-frame damping (their lumped
inertia is s t^2 / 12 of the translational one per unit area: 8e-6 m^2 on the sleeve, so their drag moments are
negligible). Dirichlet nodes are left out. Units: SI. Cost per step: one pose of the body (its own cache of three
poses: one new pose per step), the (3K, N) rigid fields blended by the weights, and every WEIGHT_STEPS steps the
weights; numpy without a loop over nodes, the points kept as three contiguous rows (about 0.1-0.15 ms per step on
the sleeve's 20x26 mesh, 2173 nodes). A run resumed from a checkpoint recomputes the weights at its first step (the
same run to the weights' drift over fewer than WEIGHT_STEPS steps, not bit for bit).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from fabricfem.body.blended import BLEND_WIDTH, check_width
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact import nodal
from fabricfem.contact.poses import PoseCache

DAMPING_FRAMES = ("ground", "body")   # [route] damping_frame: what the mass damping's velocity is relative to
# steps between refreshes of the segment weights: a node moves relative to the body by |v_rel| WEIGHT_STEPS dt in
# between (0.2 mm on the sleeve at 45 deg/s) against the blend width of 50 mm; rigid motion stays exact (any weights
# that sum to 1 give the same v_b when all segments move together)
WEIGHT_STEPS = 10


def segment_velocity_fields(before: list[Ellipsoid], now: list[Ellipsoid], after: list[Ellipsoid],
                            span: float) -> tuple[np.ndarray, np.ndarray]:
    """(L (K, 3, 3) [1/s], b (K, 3) [m/s]) of the segments' rigid velocity fields v_k(x) = L_k x + b_k: the central
    difference over `span` [s] of a material point's path x(t) = c(t) + R(t) R_now^T (x - c_now) between the poses
    `before` and `after` (module docstring)."""
    c0, c1, c2 = (np.array([e.center for e in pose]) for pose in (before, now, after))
    r0, r1, r2 = (np.array([e.rotation for e in pose]) for pose in (before, now, after))
    L = np.matmul(r2 - r0, np.transpose(r1, (0, 2, 1))) / span
    b = (c2 - c0) / span - np.matmul(L, c1[:, :, None])[:, :, 0]
    return L, b


def segment_weights(x: np.ndarray, ellipsoids: list[Ellipsoid], width: float,
                    active: np.ndarray | None = None) -> np.ndarray:
    """(N, K) weights W >= 0 of the segments at the points x (N, 3) [m] (module docstring): rows summing to 1, or
    to 0 where no segment is active; `width` [m] the blend width, `active` (K,) bool (None: all)."""
    return weight_columns(np.ascontiguousarray(np.asarray(x, dtype=float).T), ellipsoids, width, active).T


def weight_columns(xt: np.ndarray, ellipsoids: list[Ellipsoid], width: float,
                   active: np.ndarray | None = None) -> np.ndarray:
    """`segment_weights` of the points as columns xt (3, N) [m], as (K, N): numpy's products of (N, 3) rows with
    small matrices are slow (no BLAS), so the points are kept as three contiguous rows."""
    surrogate = np.empty((len(ellipsoids), xt.shape[1]))
    for k, e in enumerate(ellipsoids):            # the few segments, vectorised over the points
        z = (e.rotation.T / e.radii[:, None]) @ (xt - e.center[:, None])     # (3, N) y_i / r_i
        root = np.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2])             # sqrt(q)
        z /= e.radii[:, None]
        slope = np.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2])            # sqrt(q) |grad sqrt(q)| [1/m]
        surrogate[k] = (root - 1.0) * root / np.maximum(slope, 1e-300)      # [m]
    if active is not None:
        surrogate[~np.asarray(active, dtype=bool)] = np.inf
    nearest = surrogate.min(axis=0)
    nearest[~np.isfinite(nearest)] = 0.0                                    # no active segment: all h = 0
    h = np.clip(1.0 - (surrogate - nearest) / width, 0.0, 1.0) ** 2
    total = h.sum(axis=0)
    return h / np.where(total > 0.0, total, 1.0)


def blended_velocity(xt: np.ndarray, L: np.ndarray, b: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """v_b (3, N) [m/s] = sum_k W_k (L_k x + b_k) at the points xt (3, N) [m], weights (K, N)."""
    rigid = np.concatenate(L) @ xt + b.reshape(-1, 1)                      # (3K, N)
    v = weights[0] * rigid[0:3]
    for k in range(1, len(b)):
        v += weights[k] * rigid[3 * k:3 * k + 3]
    return v


class BodyFrameDamping:
    """An explicit hook (fabricfem.solvers.system.ExplicitHook) that refers the integrator's mass damping alpha M_L
    of the translations to the body's motion (module docstring). Put it with the other hooks of CentralDifference;
    `alpha` is read from the integrator (its Rayleigh a, on the physical mass also under mass scaling).

    Args:
        model: the ShellModel of the cloth.
        body: the posed Body (its kinematics on the integrator's clock).
        blend_width: w [m] of the weights' blend (the body's blend width).
        active: t [s] -> (K,) bool of the segments that count (None: all).
    """

    def __init__(self, model, body, blend_width: float = BLEND_WIDTH,
                 active: Callable[[float], np.ndarray] | None = None):
        nodes = nodal.contact_nodes(model)
        free = ~nodes.constrained.any(axis=1)
        self.dofs = np.ascontiguousarray(nodes.dofs[free])          # (N, 3) local rows of the free nodes
        self.reference = nodes.reference[free]                      # (N, 3) X [m]
        self._rows = np.ascontiguousarray(self.dofs.T)              # (3, N): the columns of the hot path
        self._reference_t = np.ascontiguousarray(self.reference.T)
        self.poses = PoseCache(body)
        self.width = check_width(blend_width)
        self.active = active
        self._coefficient: np.ndarray | None = None                 # (3, N) alpha m [kg/s] of the physical mass
        self._weights: np.ndarray | None = None                     # (K, N) segment weights of the last refresh

    def _fields(self, t: float, t_before: float, t_after: float) -> tuple[np.ndarray, np.ndarray]:
        return segment_velocity_fields(self.poses.ellipsoids(t_before), self.poses.ellipsoids(t),
                                       self.poses.ellipsoids(t_after), t_after - t_before)

    def body_velocity(self, x: np.ndarray, t: float, t_before: float, t_after: float) -> np.ndarray:
        """v_b (N, 3) [m/s] at the points x (N, 3) [m] at time t [s], from the poses at t_before < t_after [s]."""
        xt = np.ascontiguousarray(np.asarray(x, dtype=float).T)
        weights = weight_columns(xt, self.poses.ellipsoids(t), self.width,
                                 None if self.active is None else self.active(t))
        return blended_velocity(xt, *self._fields(t, t_before, t_after), weights).T

    def coefficient(self, integrator) -> np.ndarray:
        """(3, N) alpha m_i [kg/s]: the integrator's mass damping of the free nodes' translations."""
        if self._coefficient is None:
            mass = integrator.ops.mass_diag.getArray(readonly=True)[self._rows] / integrator.mass_scale
            self._coefficient = integrator.ops.a * mass
        return self._coefficient

    def forces(self, integrator, t: float, rhs) -> None:
        """rhs += alpha M_L v_b(x^{n+1}, t_{n+1}) on the free translations (t = t_{n+1}; the poses at t_n, the
        integrator's time, and t_{n+1} + dt); the weights refreshed every WEIGHT_STEPS steps."""
        if integrator.ops.a == 0.0 or len(self.dofs) == 0:
            return
        xt = self._reference_t + integrator.d.getArray(readonly=True)[self._rows]
        t = float(t)
        if self._weights is None or integrator.step_count % WEIGHT_STEPS == 0:
            self._weights = weight_columns(xt, self.poses.ellipsoids(t), self.width,
                                           None if self.active is None else self.active(t))
        v_b = blended_velocity(xt, *self._fields(t, float(integrator.t), t + integrator.dt), self._weights)
        rhs.getArray()[self._rows] += self.coefficient(integrator) * v_b

    def correct(self, integrator, t: float) -> None:
        """Nothing after the division (the force is all)."""
