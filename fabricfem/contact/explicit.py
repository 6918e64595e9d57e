"""Forward-increment Lagrange multiplier contact for explicit time stepping (thesis sec. 3.3.2-3.3.3, Box 5).

In a central-difference step the trial positions x* of the next step are computed without contact. A
node that penetrates a body segment is projected back onto the surface along the gradient of the
segment's implicit function at x* (thesis Box 5: "the gradient at the penetrating trial position is
chosen as the projection direction"), and the correction gives the multiplier:

    d^c = proj(x*) - x*,   a^c = d^c / dt^2,   lambda = -M a^c                             (Box 5, step i)
    a^{n+1} = a* + a^c,    v^{n+1} = v* + dt/2 a^c                                          (Box 5, step j)

so that the next predictor d^{n+2} = d^{n+1} + dt v^{n+1} + dt^2/2 a^{n+1} = proj(x*) lies on the surface.
The functions act on numpy arrays of nodal positions [m], velocities [m/s], accelerations [m/s^2] and
lumped masses [kg] (shape (N,) or (N, 3)), so an explicit shell integrator can call them on its
translational dofs. f_c = M a^c = -lambda [N] is the contact force on the cloth.

`ExplicitBodyContact` applies this to the nodes of a shell in `fabricfem.dynamics.CentralDifference`
against ellipsoids that move with a Body (projection onto the pose at t_{n+2}, Coulomb friction with stick
points that move with the segments), with a penalty alternative.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.nodal import positive_parameter

MAX_PROJECTION_PASSES = 8
INSIDE_TOLERANCE = 1e-12   # relative to the smallest radius: rounding of a projected point is not "inside"


def _points(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (the explicit step diverged?)")
    return arr


def _masses(masses, n: int) -> np.ndarray:
    m = np.asarray(masses, dtype=float)
    if m.shape == (n,):
        m = np.repeat(m[:, None], 3, axis=1)
    if m.shape != (n, 3) or not np.all(np.isfinite(m)) or np.any(m <= 0.0):
        raise ValueError(f"masses must be positive with shape ({n},) or ({n}, 3), got shape {m.shape}")
    return m


def project_along_gradient(x, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """Move the points inside any ellipsoid onto its surface along grad f at the point (Box 5).

    The ray x + s grad f / |grad f| is intersected with the surface (`Ellipsoid.gap` with one cast);
    a point inside two overlapping segments is projected out of the deeper one first and re-checked
    (at most MAX_PROJECTION_PASSES passes). Returns (projected points (N, 3), moved mask (N,)).
    """
    out, moved, _ = project_with_segment(x, ellipsoids)
    return out, moved


def project_with_segment(x, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`project_along_gradient` that also returns the segment index (N,) each point was last projected
    out of (for points never inside: the segment of smallest gap)."""
    x = _points("x", x)
    out = x.copy()
    moved = np.zeros(len(x), dtype=bool)
    segment = np.zeros(len(x), dtype=np.int64)
    scale_of = np.array([e.radii.min() for e in ellipsoids])
    for k_pass in range(MAX_PROJECTION_PASSES):
        gaps = np.stack([e.gap(out, ray_casts=1)[0] for e in ellipsoids]) if len(out) else np.zeros((1, 0))
        deepest = np.argmin(gaps, axis=0)
        if k_pass == 0:
            segment = deepest.astype(np.int64)
        g = gaps[deepest, np.arange(len(out))]
        inside = g < -INSIDE_TOLERANCE * scale_of[deepest]
        if not inside.any():
            return out, moved, segment
        for k, e in enumerate(ellipsoids):  # loop over the few segments, vectorised over the points
            mask = inside & (deepest == k)
            if mask.any():
                direction = e.normal(out[mask])          # grad f / |grad f| at the trial point
                out[mask] = out[mask] - g[mask, None] * direction
        segment = np.where(inside, deepest, segment)
        moved |= inside
    raise ValueError("ellipsoids: points remain inside after repeated projections (overlapping segments "
                     "trap them); refine the time step")


@dataclass
class ExplicitContact:
    """Correction of one explicit step (Box 5, step i).

    Attributes:
        position: (N, 3) corrected positions proj(x*) [m].
        correction: (N, 3) d^c [m].
        acceleration: (N, 3) a^c [m/s^2].
        force: (N, 3) contact force on the nodes f_c = M a^c [N].
        multiplier: (N, 3) lambda = -M a^c [N] (thesis sign).
        active: (N,) nodes that were projected.
    """

    position: np.ndarray
    correction: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray
    multiplier: np.ndarray
    active: np.ndarray


def forward_increment_correction(x_trial, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> ExplicitContact:
    """Box 5 step i: project penetrating trial positions and return the multipliers."""
    dt = positive_parameter("dt", dt)
    x_trial = _points("x_trial", x_trial)
    m = _masses(masses, len(x_trial))
    projected, active = project_along_gradient(x_trial, ellipsoids)
    d_c = projected - x_trial
    a_c = d_c / dt ** 2
    force = m * a_c
    return ExplicitContact(projected, d_c, a_c, force, -force, active)


def box5_step(x, v, a, masses, dt: float, acceleration: Callable[[np.ndarray, float], np.ndarray],
              t: float, ellipsoids_at: Callable[[float], Sequence[Ellipsoid]]):
    """One step n -> n+1 of Box 5 for point masses (positions x = X + d).

    Args:
        x, v, a: (N, 3) state at t^n; x must be admissible.
        masses: lumped masses [kg], (N,) or (N, 3).
        dt: time step [s].
        acceleration: a*(x, t) = M^-1 (f_ext(t) - f_int(x)) [m/s^2] without contact.
        t: time t^n [s].
        ellipsoids_at: body segments posed at a given time.

    Returns:
        (x^{n+1}, v^{n+1}, a^{n+1}, ExplicitContact of the step).
    """
    dt = positive_parameter("dt", dt)
    x, v, a = _points("x", x), _points("v", v), _points("a", a)
    v_star = v + 0.5 * dt * a                               # Box 5 f
    x_next = x + dt * v + 0.5 * dt ** 2 * a                 # Box 5 f
    a_star = np.asarray(acceleration(x_next, t + dt), dtype=float)   # Box 5 g
    v_star = v_star + 0.5 * dt * a_star                     # Box 5 h
    x_trial = x_next + dt * v_star + 0.5 * dt ** 2 * a_star  # Box 5 i: trial for n+2
    contact = forward_increment_correction(x_trial, masses, dt, ellipsoids_at(t + 2.0 * dt))
    a_next = a_star + contact.acceleration                  # Box 5 j
    v_next = v_star + 0.5 * dt * contact.acceleration
    return x_next, v_next, a_next, contact


def initial_state(x, v, a_free, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """(v^0, a^0) of Box 5 step 1 for nodes that may start in contact: the first predictor
    x + dt v + dt^2/2 a is corrected as in step j (a^0 = a* + a^c, v^0 = v + dt/2 a^c), so that it lands
    on the surface instead of inside."""
    a_free = _points("a_free", a_free)
    v = _points("v", v)
    trial = _points("x", x) + dt * v + 0.5 * dt ** 2 * a_free
    a_c = forward_increment_correction(trial, masses, dt, ellipsoids).acceleration
    return v + 0.5 * dt * a_c, a_free + a_c


# ------------------------------------------------------------------------------------------------------------
# Explicit contact of a shell (CentralDifference) with moving rigid ellipsoids
# ------------------------------------------------------------------------------------------------------------
EXPLICIT_METHODS = ("lagrange", "penalty")


class ExplicitBodyContact:
    """Nodal frictional contact of a shell in explicit central differences (fabricfem.dynamics.explicit)
    against rigid ellipsoids that move with a `Body` (thesis ch. 3, Box 5; ch. 5). SI units.

    Nodes: the owned displacement nodes of the shell (fabricfem.contact.nodal.contact_nodes); nodes with a
    held displacement component carry no contact. Everything is vectorised over the nodes and local to a
    rank (owned nodes only), so the contact is parallel-correct as the shell's assembly is; reductions
    (torques, totals) are MPI sums.

    method = "lagrange" (default; forward-increment Lagrange multipliers, Box 5), called after the division
    a^{n+1} = rhs / (M + dt/2 C) of the step n -> n+1:

        x* = X + d^{n+1} + dt v~ + dt^2 a^{n+1}               the predictor of step n+2 (no contact)
        x^c = proj(x*) on the body posed at t_{n+2}           along grad f at x* (Box 5, step i)
        friction (eqs. 3.46-3.52, kinematic form): the stick point s (a material point of the segment,
            stored in its frame, so it moves with the body: the relative velocity is taken w.r.t. the
            body's surface velocity) pulls the node tangentially, d_T = P (s - x^c), P = I - n n^T;
            |m d_T / dt^2| <= mu |lambda_N| (return map, eq. 3.52): if exceeded, d_T is scaled to the
            limit (slip) and the stick point moves to the node's new position
        a^c = (x^c + d_T - x*) / dt^2,  a^{n+1} += a^c,  f_c = (M + dt/2 C) a^c      (Box 5, step j)

    f_c [N] is the contact force on the cloth node (normal part -lambda_N, tangential part the friction).

    method = "penalty": called before the division, adds f = w (k_N <-g> n + t_T) at d^{n+1} against the
    body at t_{n+1} (Box 3, friction by the return map of fabricfem.contact.friction with eps_T = k_N and
    stick points committed every step). Explicit stability needs the penalty frequency
    omega_p^2 = w k_N / m = k_N / (rho t) below the limit: (2 / dt)^2 > omega_max^2 + k_N / (rho t)
    (`penalty_frequency`); the integrator's dt must be chosen with it.

    Time-averaged output: every step adds its nodal forces and registered joint torques times dt to
    accumulators; `mean_torques()` / `mean_pressure()` return the means since the last `reset_means()`
    (the impulse over the interval divided by its length: the contact force of one explicit step is the
    change of momentum it imposes and oscillates from step to step).
    """

    def __init__(self, model, body, friction: float = 0.0, method: str = "lagrange",
                 penalty: float | None = None):
        from fabricfem.contact import friction as friction_law
        from fabricfem.contact import nodal
        if method not in EXPLICIT_METHODS:
            raise ValueError(f"method must be one of {EXPLICIT_METHODS}, got {method!r}")
        self.model = model
        self.body = body
        self.method = method
        self.mu = friction_law.friction_coefficient(friction)
        self.nodes = nodal.contact_nodes(model)
        self.penalty = (nodal.default_penalty(model, self.nodes.element_size) if penalty is None
                        else positive_parameter("penalty", penalty))
        self.comm = model.comm
        self.names = list(body.segments)
        held = self.nodes.constrained.any(axis=1)
        self.moving = ~held                                  # nodes that take contact
        self.dofs = self.nodes.dofs[self.moving]             # (M, 3) local rows in W
        self.reference = self.nodes.reference[self.moving]
        self.area = self.nodes.area[self.moving]
        M = len(self.area)
        self._stick_local = np.zeros((M, 3))
        self._stick_segment = np.full(M, -1, dtype=np.int64)
        # state of the last step (owned moving nodes)
        self.position = self.reference.copy()                # contact positions [m]
        self.force = np.zeros((M, 3))                        # contact force on the cloth [N]
        self.normal_force = np.zeros(M)                      # |normal part| [N]
        self.segment = np.zeros(M, dtype=np.int64)
        self.active = np.zeros(M, dtype=bool)
        self.slip = np.zeros(M, dtype=bool)
        self.time = 0.0
        self._monitors: dict[str, tuple[str, np.ndarray, list[int]]] = {}
        self._torque_impulse: dict[str, float] = {}
        self._normal_impulse = np.zeros(M)
        self._elapsed = 0.0

    # ------------------------------------------------------------------ set-up and output
    def penalty_frequency(self) -> float:
        """omega_p = sqrt(k_N / (rho t)) [rad/s] of the penalty spring on a node's lumped mass (0 for Lagrange)."""
        if self.method != "penalty":
            return 0.0
        return float(np.sqrt(self.penalty / self.model.fabric.areal_density))

    def track_torque(self, name: str, joint: str, axis, segments: Sequence[str]):
        """Accumulate the torque [N m] about `joint` along `axis` of the forces the cloth exerts on
        `segments` (fabricfem.contact.torque sign convention) under `name`."""
        unknown = [s for s in segments if s not in self.names]
        if unknown:
            raise ValueError(f"segments: unknown segment names {unknown} (known: {self.names})")
        a = np.asarray(axis, dtype=float)
        if a.shape != (3,) or not np.linalg.norm(a) > 0:
            raise ValueError(f"axis must be a non-zero 3-vector, got {axis!r}")
        self._monitors[name] = (joint, a / np.linalg.norm(a), [self.names.index(s) for s in segments])
        self._torque_impulse[name] = 0.0

    def torque(self, name: str) -> float:
        """The registered torque [N m] of the last step's forces (all ranks)."""
        from fabricfem.contact.torque import contact_torque
        joint, axis, segments = self._monitors[name]
        return contact_torque(self.position, -self.force, self.segment, segments,
                              self.body.joint_position(joint, self.time), axis, self.comm)

    def reset_means(self):
        for name in self._torque_impulse:
            self._torque_impulse[name] = 0.0
        self._normal_impulse[:] = 0.0
        self._elapsed = 0.0

    def mean_torques(self) -> dict[str, float]:
        """Time-averaged registered torques [N m] since the last reset (all ranks)."""
        if self._elapsed <= 0.0:
            return {name: self.torque(name) for name in self._monitors}
        names = list(self._torque_impulse)
        local = np.array([self._torque_impulse[n] for n in names])
        total = np.zeros_like(local)
        self.comm.Allreduce(local, total, op=MPI.SUM)
        return {n: float(v) / self._elapsed for n, v in zip(names, total)}

    def mean_pressure(self) -> np.ndarray:
        """(M,) time-averaged normal contact pressure |lambda_N| / w [Pa] since the last reset (owned
        moving nodes; the last step's when no step was accumulated)."""
        if self._elapsed <= 0.0:
            return self.normal_force / self.area
        return self._normal_impulse / self._elapsed / self.area

    def pressure_field(self, mean: bool = True):
        """Contact pressure [Pa] as a Q2 scalar Function (held nodes: 0), time-averaged or the last step's."""
        from dolfinx import fem
        f = fem.Function(self.nodes.scalar_space, name="contact_pressure")
        f.x.array[self.nodes.node_index[self.moving]] = self.mean_pressure() if mean else self.normal_force / self.area
        f.x.scatter_forward()
        return f

    def max_penetration(self, d: np.ndarray, t: float) -> float:
        """max(0, -min g) [m] of the nodes at displacements `d` (local array of W) against the body at t, all ranks."""
        from fabricfem.contact.nodal import nearest_gap
        g, _, _ = nearest_gap(self.reference + d[self.dofs], list(self.body.pose(t).values()))
        return float(self.comm.allreduce(float(np.max(-g, initial=0.0)), op=MPI.MAX))

    def min_gap(self, d: np.ndarray, t: float) -> float:
        """Smallest signed gap [m] of the nodes against the body at t (all ranks)."""
        from fabricfem.contact.nodal import nearest_gap
        g, _, _ = nearest_gap(self.reference + d[self.dofs], list(self.body.pose(t).values()))
        return float(self.comm.allreduce(float(np.min(g, initial=np.inf)), op=MPI.MIN))

    def total_force(self) -> np.ndarray:
        """Sum of the last step's contact forces on the cloth [N] (3,), all ranks."""
        return self.comm.allreduce(self.force.sum(axis=0), op=MPI.SUM)

    def _accumulate(self, dt: float):
        from fabricfem.body.motion import joint_torque
        for name, (joint, axis, segments) in self._monitors.items():
            mask = self.active & np.isin(self.segment, segments)
            if mask.any():
                J = self.body.joint_position(joint, self.time)
                self._torque_impulse[name] += dt * joint_torque(self.position[mask], -self.force[mask], J, axis)
        self._normal_impulse += dt * self.normal_force
        self._elapsed += dt

    def _stick_points(self, ellipsoids, segment: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stick points at the current pose (global) and the mask of nodes that have one on `segment`."""
        points = fallback.copy()
        known = np.zeros(len(segment), dtype=bool)
        for k, e in enumerate(ellipsoids):  # loop over the few segments
            mask = (self._stick_segment == k) & (segment == k)
            if mask.any():
                points[mask] = e.to_global(self._stick_local[mask])
            known |= mask
        return points, known

    def _store_stick_points(self, ellipsoids, points: np.ndarray, segment: np.ndarray, active: np.ndarray):
        self._stick_segment = np.where(active, segment, -1)
        for k, e in enumerate(ellipsoids):
            mask = active & (segment == k)
            if mask.any():
                self._stick_local[mask] = e.to_local(points[mask])

    # ------------------------------------------------------------------ integrator hooks
    def forces(self, integrator, t: float, rhs):
        """Penalty method: rhs += f(d^{n+1}) against the body at t = t_{n+1} (no-op for Lagrange)."""
        if self.method != "penalty":
            return
        from fabricfem.contact import friction as friction_law
        from fabricfem.contact.nodal import nearest_gap, normal_pressure
        self.time = float(t)
        ellipsoids = list(self.body.pose(t).values())
        d = integrator.d.getArray(readonly=True)
        x = self.reference + d[self.dofs]
        g, n, seg = nearest_gap(x, ellipsoids)
        p = normal_pressure(g, np.zeros(len(g)), self.penalty)
        active = p > 0.0
        force = (self.area * p)[:, None] * n
        traction = np.zeros_like(x)
        slip = np.zeros(len(x), dtype=bool)
        if self.mu > 0.0:
            stick, known = self._stick_points(ellipsoids, seg, x)
            fr = friction_law.return_map(x, stick, n, p, self.mu, self.penalty, self.penalty)
            traction = np.where(known[:, None], fr.traction, 0.0)
            slip = fr.slip & known
            force = force + self.area[:, None] * traction
            self._store_stick_points(ellipsoids, friction_law.updated_stick_point(x, traction, self.penalty), seg,
                                     active)
        rhs.getArray()[self.dofs] += force
        self._set_step(x, force, self.area * p, seg, active, slip, integrator.dt)

    def correct(self, integrator, t: float):
        """Lagrange method (Box 5 steps i-j with friction): a^{n+1} += a^c so that the predictor of
        step n+2 lies on the body posed at t_{n+2} = t + dt (no-op for penalty)."""
        if self.method != "lagrange":
            return
        dt = integrator.dt
        t_next = t + dt
        self.time = float(t)
        ellipsoids = list(self.body.pose(t_next).values())
        d = integrator.d.getArray(readonly=True)
        v = integrator.velocity_predictor.getArray(readonly=True)
        a = integrator.a.getArray()
        rows = self.dofs
        x_trial = self.reference + d[rows] + dt * v[rows] + dt ** 2 * a[rows]
        projected, active, seg = project_with_segment(x_trial, ellipsoids)
        m = integrator.denominator.getArray(readonly=True)[rows]            # M + dt/2 C (per component)
        normal_correction = projected - x_trial
        normal_force = np.linalg.norm(m * normal_correction, axis=1) / dt ** 2   # |lambda_N| [N]
        final = projected
        slip = np.zeros(len(x_trial), dtype=bool)
        if self.mu > 0.0 and active.any():
            stick, known = self._stick_points(ellipsoids, seg, projected)
            n = np.zeros_like(projected)
            for k, e in enumerate(ellipsoids):   # normals at the contact points, per segment
                mask = active & (seg == k)
                if mask.any():
                    n[mask] = e.normal(projected[mask])
            diff = stick - projected
            d_t = diff - np.sum(diff * n, axis=1)[:, None] * n                   # P (s - x^c)
            f_t = np.linalg.norm(m * d_t, axis=1) / dt ** 2
            limit = self.mu * normal_force                                       # eq. 3.52: |t| <= mu lambda_N
            slip = active & known & (f_t > limit)
            scale = np.where(slip, limit / np.where(f_t > 0.0, f_t, 1.0), 1.0)
            d_t = np.where((active & known)[:, None], d_t * scale[:, None], 0.0)
            final = projected + d_t
            # the stick point stays where it is on the segment when sticking, moves with the node when slipping
            # and is created at the contact point for a node touching down
            self._store_stick_points(ellipsoids, np.where((slip | ~known)[:, None], final, stick), seg, active)
        correction = np.where(active[:, None], final - x_trial, 0.0)
        a_c = correction / dt ** 2
        a[rows] += a_c
        self._set_step(final, m * a_c, np.where(active, normal_force, 0.0), seg, active, slip, dt)

    def _set_step(self, position, force, normal_force, segment, active, slip, dt: float):
        self.position, self.force, self.normal_force = position, force, normal_force
        self.segment, self.active, self.slip = segment, active, slip
        self._accumulate(dt)
