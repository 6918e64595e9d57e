"""Forward-increment Lagrange multiplier contact for explicit time stepping ([Man2006, sec. 3.3.2-3.3.3], Box 5).

In a central-difference step the trial positions x* of the next step are computed without contact. A
node that penetrates a body segment is projected back onto the surface along the gradient of the
segment's implicit function at x* ([Man2006, Box 5]: "the gradient at the penetrating trial position is
chosen as the projection direction"), and the correction gives the multiplier:

    d^c = proj(x*) - x*,   a^c = d^c / dt^2,   lambda = -M a^c                             ([Man2006, Box 5], step i)
    a^{n+1} = a* + a^c,    v^{n+1} = v* + dt/2 a^c                                          ([Man2006, Box 5], step j)

so that the next predictor d^{n+2} = d^{n+1} + dt v^{n+1} + dt^2/2 a^{n+1} = proj(x*) lies on the surface.
The functions act on numpy arrays of nodal positions [m], velocities [m/s], accelerations [m/s^2] and
lumped masses [kg] (shape (N,) or (N, 3)), so an explicit shell integrator can call them on its
translational dofs. f_c = M a^c = -lambda [N] is the contact force on the cloth.

`ExplicitBodyContact` applies this to the nodes of a shell in `fabricfem.dynamics.CentralDifference`
against ellipsoids that move with a Body (projection onto the pose at t_{n+2}, Coulomb friction with stick
points that move with the segments), with a penalty alternative.
"""
from __future__ import annotations

import functools
import time
from contextlib import contextmanager
from typing import Callable, Iterator, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem.body.blend_kernel import implicit_values
from fabricfem.body.blended import BLEND_WIDTH, BlendedEllipsoids
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.skin import Skin
from fabricfem.contact import compiled, nodal
from fabricfem.contact import friction as friction_law
from fabricfem.contact.nodal import (
    CurrentAreas,
    normal_pressure,
    positive_parameter,
    pressure_function,
    pressure_on_body,
)
from fabricfem.contact.poses import PoseCache, unchecked_ellipsoid
from fabricfem.contact.projection import (  # noqa: F401 (the projections are public here too)
    INSIDE_TOLERANCE,
    MAX_PROJECTION_PASSES,
    PARKED_AT,
    ExplicitContact,
    SegmentStack,
    SkinProjection,
    as_points,
    box5_step,
    crease_points,
    forward_increment_correction,
    initial_state,
    normalised_radii,
    normalised_radius,
    project_along_gradient,
    project_compiled,
    project_onto_skin,
    project_with_segment,
    ray_gap,
    row_length,
    skin_gap,
)
from fabricfem.contact.torque import TorqueMonitor, local_torques
from fabricfem.forms.jit import pointer

# Whether ExplicitBodyContacts created now take the Lagrange step by the compiled loops (fabricfem.contact.compiled)
# or by numpy (`numpy_contact`: a benchmark's baseline, and the reference the compiled loops are tested against)
COMPILED_CONTACT = {"enabled": True}


@contextmanager
def numpy_contact() -> Iterator[None]:
    """ExplicitBodyContacts created inside the block take the Lagrange step by numpy (COMPILED_CONTACT)."""
    old = COMPILED_CONTACT["enabled"]
    COMPILED_CONTACT["enabled"] = False
    try:
        yield
    finally:
        COMPILED_CONTACT["enabled"] = old


EXPLICIT_METHODS = ("lagrange", "penalty")


class ExplicitBodyContact:
    """Nodal frictional contact of a shell in explicit central differences (fabricfem.dynamics.explicit)
    against the skin of a `Body` ([Man2006, ch. 3], Box 5; ch. 5): by default its rigid ellipsoids joined by the
    blend of width `blend_width` [m] in the creases (fabricfem.body.blended), or any `skin` of the surface contract
    (fabricfem.body.skin, e.g. a rigged surface mesh). SI units.

    Nodes: the owned displacement nodes of the shell (fabricfem.contact.nodal.contact_nodes); nodes with a
    held displacement component carry no contact. Everything is vectorised over the nodes and local to a
    rank (owned nodes only), so the contact is parallel-correct as the shell's assembly is; reductions
    (torques, totals) are MPI sums.

    method = "lagrange" (default; forward-increment Lagrange multipliers, Box 5), called after the division
    a^{n+1} = rhs / (M + dt/2 C) of the step n -> n+1:

        x* = X + d^{n+1} + dt v~ + dt^2 a^{n+1}               the predictor of step n+2 (no contact)
        x^c = proj(x*) on the body posed at t_{n+2}           along grad f at x* ([Man2006, Box 5], step i)
        friction (eqs. 3.46-3.52, kinematic form): the stick point s (a material point of the segment,
            stored in its frame, so it moves with the body: the relative velocity is taken w.r.t. the
            body's surface velocity) pulls the node tangentially, d_T = P (s - x^c), P = I - n n^T;
            |m d_T / dt^2| <= mu |lambda_N| (return map, eq. 3.52): if exceeded, d_T is scaled to the
            limit (slip) and the stick point moves to the node's new position
        a^c = (x^c + d_T - x*) / dt^2,  a^{n+1} += a^c,  f_c = (M + dt/2 C) a^c      ([Man2006, Box 5], step j)

    f_c [N] is the contact force on the cloth node (normal part -lambda_N, tangential part the friction).

    method = "penalty": called before the division, adds f = w (k_N <-g> n + t_T) at d^{n+1} against the
    body at t_{n+1} ([Man2006, Box 3], friction by the return map of fabricfem.contact.friction with eps_T = k_N and
    stick points committed every step). Explicit stability needs the penalty frequency
    omega_p^2 = w k_N / m = k_N / (rho t) below the limit: (2 / dt)^2 > omega_max^2 + k_N / (rho t)
    (`penalty_frequency`); the integrator's dt must be chosen with it.

    Time-averaged output: every step adds its nodal forces and registered joint torques times dt to
    accumulators; `mean_torques()` / `mean_pressure()` return the means since the last `reset_means()`
    (the impulse over the interval divided by its length: the contact force of one explicit step is the
    change of momentum it imposes and oscillates from step to step).

    Cost: per step one pose of the body (`PoseCache`: the pose at t_{n+2} of one step is the
    joint position at t_{n+1} of the next), the normalised radius q of every node against every segment, and
    ray casts, friction and torque sums on the nodes in contact only (numpy, no loop over nodes; the segments
    stacked once per step, `SegmentStack`, so that the ray casts, normals and frames of all (node, segment) pairs
    are one evaluation, not one per segment).
    `timings["pose_torque"]` [s] accumulates the time spent posing the body and summing torques.
    """

    def __init__(self, model, body, friction: float = 0.0, method: str = "lagrange",
                 penalty: float | None = None, blend_width: float = BLEND_WIDTH, skin: Skin | None = None):
        if method not in EXPLICIT_METHODS:
            raise ValueError(f"method must be one of {EXPLICIT_METHODS}, got {method!r}")
        self.model = model
        self.body = body
        self.poses = PoseCache(body)
        self.method = method
        self.mu = friction_law.friction_coefficient(friction)
        self.nodes = nodal.contact_nodes(model)
        self.penalty = (nodal.default_penalty(model, self.nodes.element_size) if penalty is None
                        else positive_parameter("penalty", penalty))
        self.comm = model.comm
        self.names = list(body.segments)
        blended = BlendedEllipsoids(body, blend_width)     # the default skin (fabricfem.body.blended)
        self.blend_width = blended.width                   # m
        self.widths = np.ascontiguousarray(blended.widths)  # (K, K) m: the pairs' blend widths at the rest pose
        # another skin of the body (fabricfem.body.skin, e.g. a rigged surface mesh) instead of the blended segments:
        # its gap, foot, normal and weights by its query; the segments' frames still carry the stick points
        if skin is not None and tuple(skin.segment_names) != tuple(body.segments):
            raise ValueError(f"skin: its segments {list(skin.segment_names)} are not the body's {list(body.segments)}")
        self.skin = skin
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
        self._monitors: dict[str, TorqueMonitor] = {}
        self._torque_impulse: dict[str, float] = {}
        self._normal_impulse = np.zeros(M)
        self._elapsed = 0.0
        self._lumped: tuple[object, float, np.ndarray] | None = None   # (integrator, dt, (M, 3) of M + dt/2 C)
        self.timings = {"pose_torque": 0.0}
        self._current_areas = None                          # nodal.CurrentAreas, compiled on first use
        # optional diagnostics (off by default: they cost a gap evaluation / a list append per step)
        self.monitor_penetration = False     # track the largest penetration of d^{n+1} at t_{n+1} every step
        self.max_penetration_seen = 0.0      # m, owned nodes (reduce with max_penetration_all)
        self.trace: list[tuple[float, ...]] | None = None   # per step: (t, torque of each monitor, sum |lambda_N|)
        # donning (fabricfem.wear.donning): t -> factor on the segments' transverse radii (r2, r3), and
        # t -> (K,) bool of the segments that take contact (an inactive segment is parked far from the garment),
        # t -> (K,) size factor on all three radii (a removed segment regrowing: fabricfem.body.schedule)
        self.transverse_scale: Callable[[float], float] | None = None
        self.segment_active: Callable[[float], np.ndarray] | None = None
        self.segment_size: Callable[[float], np.ndarray] | None = None
        # the Lagrange step by the compiled loops (fabricfem.contact.compiled) or by numpy (COMPILED_CONTACT)
        self.compiled = COMPILED_CONTACT["enabled"] and method == "lagrange" and skin is None
        # the compiled loops are built here, by every rank together (fabricfem.forms.jit.compile_c waits for all
        # ranks): built on first use instead, a rank with crease nodes in its penetration monitor built them alone
        # while another waited in the step's build, and the run hung
        compiled.module(self.comm)
        self._rows: np.ndarray | None = None      # (M, 3) int64 rows of the nodes in W (compiled loops)
        self._monitor_arrays: tuple | None = None  # the monitors' segment flags and axes (compiled loops)
        self._buffers: compiled.StepBuffers | None = None   # the compiled step's work arrays

    # ------------------------------------------------------------------ set-up and output
    def penalty_frequency(self) -> float:
        """omega_p = sqrt(k_N / (rho t)) [rad/s] of the penalty spring on a node's lumped mass (0 for Lagrange)."""
        if self.method != "penalty":
            return 0.0
        return float(np.sqrt(self.penalty / self.model.fabric.areal_density))

    def track_torque(self, name: str, joint: str, axis, segments: Sequence[str]):
        """Accumulate the torque [N m] about `joint` along `axis` of the forces the cloth exerts on
        `segments` (fabricfem.contact.torque.TorqueMonitor) under `name`."""
        self._monitors[name] = TorqueMonitor.build(self.names, joint, axis, segments)
        self._torque_impulse[name] = 0.0
        self._monitor_arrays = None

    def torque(self, name: str) -> float:
        """The registered torque [N m] of the last step's forces (all ranks)."""
        monitor = self._monitors[name]
        return monitor.value(self.position, self.force, self.segment,
                             lambda: self.poses.joint(monitor.joint, self.time), self.comm)

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

    def state(self) -> dict:
        """What a checkpoint keeps of the contact: the friction's stick points (local coordinates and segments)."""
        return {"stick_local": self._stick_local.copy(), "stick_segment": self._stick_segment.copy()}

    def restore(self, state: dict) -> None:
        """Continue from a checkpoint's `state` (ValueError if it belongs to another mesh or partition)."""
        if state["stick_local"].shape != self._stick_local.shape:
            raise ValueError(f"resume: the checkpoint's contact has {len(state['stick_local'])} nodes on this rank, "
                             f"this run {len(self._stick_local)}")
        self._stick_local[:] = state["stick_local"]
        self._stick_segment[:] = state["stick_segment"]
        self._buffers = None      # the compiled step clears every node's contact state first (not only the last step's)

    def current_areas(self) -> np.ndarray:
        """(M,) lumped area [m^2] of the owned moving nodes on the current (deformed) cloth, for the state in
        model.w."""
        if self._current_areas is None:
            self._current_areas = CurrentAreas(self.model, self.nodes)
        return self._current_areas()[self.moving]

    def pressure_field(self, mean: bool = True, per: str = "current"):
        """Contact pressure [Pa] as a Q2 scalar Function (held nodes: 0), time-averaged or the last step's,
        per unit current cloth area for the state in model.w (the pressure on the body) or per unit
        reference area (`per="reference"`, as `mean_pressure`)."""
        current = self.current_areas if per == "current" else None
        pressure = pressure_on_body(self.mean_pressure() if mean else self.normal_force / self.area, self.area,
                                    current, per)
        return pressure_function(self.nodes.scalar_space, self.nodes.node_index[self.moving], pressure)

    def max_penetration(self, d: np.ndarray, t: float) -> float:
        """max(0, -min g) [m] of the nodes at displacements `d` (local array of W) against the body at t, all ranks."""
        return float(self.comm.allreduce(self._penetration(self.reference + d[self.dofs], t, self.body_at(t)),
                                         op=MPI.MAX))

    def _penetration(self, x: np.ndarray, t: float, ellipsoids: list[Ellipsoid]) -> float:
        """max(0, -min g) [m] of the points x (N, 3) against the skin at t: on the blended segments the gaps of
        the points inside only (phi < 0, `implicit_values`, whose sign is the gap's), the skin's query else."""
        if self.skin is None and len(x) and len(ellipsoids):
            inside = implicit_values(x, *compiled.stacked(ellipsoids), self.widths) < 0.0
            x = x[inside]
        g, *_ = self.gaps(x, t, ellipsoids)
        return float(np.max(-g, initial=0.0))

    def min_gap(self, d: np.ndarray, t: float) -> float:
        """Smallest signed gap [m] of the nodes against the body at t (all ranks)."""
        g, *_ = self.gaps(self.reference + d[self.dofs], t, self.body_at(t))
        return float(self.comm.allreduce(float(np.min(g, initial=np.inf)), op=MPI.MIN))

    def gaps(self, x: np.ndarray, t: float, ellipsoids: list[Ellipsoid]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The skin seen from the points x (N, 3) [m] at time t [s] (the segments posed as `ellipsoids`): signed gap
        [m], unit outward normal, segment index and segment weights (N, K) (fabricfem.body.skin): the blended
        segments' (`skin_gap`) or the given skin's query."""
        if self.skin is None:
            return skin_gap(x, ellipsoids, self.widths)
        q = self.skin.query(x, t)
        return q.gap, q.normal, q.segment, q.weights

    def project(self, x: np.ndarray, t: float, ellipsoids: list[Ellipsoid], stack: SegmentStack) -> SkinProjection:
        """The points x (N, 3) [m] inside the skin at time t [s] moved onto it (`project_onto_skin` for the blended
        segments; the given skin's closest points otherwise, all with the skin's normal and weights)."""
        if self.skin is None:
            return project_onto_skin(x, ellipsoids, self.widths, segments=stack)
        q = self.skin.query(x, t)
        moved = q.gap < 0.0
        return SkinProjection(np.where(moved[:, None], q.foot, x), moved, q.segment, np.ones(len(x), dtype=bool),
                              q.normal, q.weights)

    def start_trace(self):
        """Record every step's time, registered torques (instantaneous, not averaged) and total normal force."""
        self.trace = []

    def trace_array(self) -> np.ndarray:
        """(steps, 2 + monitors) array of the trace: t [s], the torques [N m] in registration order, sum of the
        normal forces [N]; torques and forces summed over the ranks (all ranks call this)."""
        local = np.array(self.trace if self.trace else np.zeros((0, 2 + len(self._monitors))), dtype=float)
        total = np.zeros_like(local)
        self.comm.Allreduce(local, total, op=MPI.SUM)
        if len(total):
            total[:, 0] = local[:, 0]
        return total

    def max_penetration_all(self) -> float:
        """Largest penetration [m] seen by the per-step monitor (monitor_penetration), all ranks."""
        return float(self.comm.allreduce(self.max_penetration_seen, op=MPI.MAX))

    def _monitor_penetration(self, x: np.ndarray, ellipsoids):
        """max(0, -g) of the points x against the skin at the time of the last step."""
        self.max_penetration_seen = max(self.max_penetration_seen, self._penetration(x, self.time, ellipsoids))

    def total_force(self) -> np.ndarray:
        """Sum of the last step's contact forces on the cloth [N] (3,), all ranks."""
        return self.comm.allreduce(self.force.sum(axis=0), op=MPI.SUM)

    def _lumped_mass(self, integrator) -> np.ndarray:
        """(M, 3) diagonal M + dt/2 C of the contact nodes' translations [kg] (cached per integrator and dt)."""
        cached = self._lumped
        if cached is None or cached[0] is not integrator or cached[1] != integrator.dt:
            m = integrator.denominator.getArray(readonly=True)[self.dofs].copy()
            self._lumped = cached = (integrator, integrator.dt, m)
        return cached[2]

    def _local_torques(self, position: np.ndarray, force: np.ndarray, segment: np.ndarray,
                       weights: np.ndarray) -> list[float]:
        """This rank's torques [N m] of the monitors for the nodes in contact (their positions, forces on the cloth,
        segments and the skin's segment weights)."""
        tic = time.perf_counter()
        torques = local_torques(list(self._monitors.values()), position, force, segment,
                                lambda joint: self.poses.joint(joint, self.time), weights)
        self.timings["pose_torque"] += time.perf_counter() - tic
        return torques

    def _accumulate(self, dt: float, index: np.ndarray, normal_force: np.ndarray, step_torques: Sequence[float]):
        """Add dt x (the monitors' torques of this step, the normal forces of the nodes `index` in contact) to the
        interval's impulses."""
        tic = time.perf_counter()
        for name, tau in zip(self._monitors, step_torques):
            self._torque_impulse[name] += dt * tau
        if self.trace is not None:
            self.trace.append((self.time, *step_torques, float(normal_force.sum())))
        self._normal_impulse[index] += dt * normal_force
        self._elapsed += dt
        self.timings["pose_torque"] += time.perf_counter() - tic

    def _stick_points(self, stack: SegmentStack, index: np.ndarray, segment: np.ndarray,
                      fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stick points at the current pose (global) [m] of the nodes `index` touching `segment` (the posed
        segments stacked), and the mask of those that have one on that segment (the others get `fallback`)."""
        points = fallback.copy()
        known = self._stick_segment[index] == segment
        if known.any():
            points[known] = stack.to_global(self._stick_local[index[known]], segment[known])
        return points, known

    def _store_stick_points(self, stack: SegmentStack, index: np.ndarray, points: np.ndarray, segment: np.ndarray):
        """Stick points (global) [m] of the nodes `index` in contact with `segment`, kept in the segments' frames;
        every other node loses its."""
        self._stick_segment[:] = -1
        self._stick_segment[index] = segment
        self._stick_local[index] = stack.to_local(points, segment)

    def body_at(self, t: float) -> list[Ellipsoid]:
        """The segments as the contact sees them at time t [s]: posed, grown by `transverse_scale` and
        `segment_size`, and with the inactive ones (`segment_active`) parked at PARKED_AT, far from any garment."""
        ellipsoids = self.poses.ellipsoids(t)
        if self.transverse_scale is None and self.segment_active is None and self.segment_size is None:
            return ellipsoids
        scale = 1.0 if self.transverse_scale is None else float(self.transverse_scale(t))
        active = np.ones(len(ellipsoids), dtype=bool) if self.segment_active is None else self.segment_active(t)
        size = np.ones(len(ellipsoids)) if self.segment_size is None else self.segment_size(t)
        return [unchecked_ellipsoid(e.center, e.rotation, e.radii * np.array([1.0, scale, scale]) * g) if on
                else unchecked_ellipsoid(PARKED_AT + 10.0 * k, np.eye(3), np.full(3, 1e-3))
                for k, (e, on, g) in enumerate(zip(ellipsoids, active, size))]

    def _posed(self, t: float) -> list[Ellipsoid]:
        tic = time.perf_counter()
        ellipsoids = self.body_at(t)
        self.timings["pose_torque"] += time.perf_counter() - tic
        return ellipsoids

    # ------------------------------------------------------------------ integrator hooks
    def forces(self, integrator, t: float, rhs):
        """Penalty method: rhs += f(d^{n+1}) against the body at t = t_{n+1} (no-op for Lagrange).
        Only the nodes with q < 1 for some segment (inside: g < 0) can carry a force; the gaps, friction
        and forces are evaluated on those."""
        if self.method != "penalty":
            return
        self.time = float(t)
        ellipsoids = self._posed(t)
        d = integrator.d.getArray(readonly=True)
        x_all = as_points("x", self.reference + d[self.dofs])
        q = normalised_radii(x_all, ellipsoids)
        segment = np.argmin(q, axis=0).astype(np.int64)
        near = (q.min(axis=0) < 1.0) | crease_points(q, SegmentStack(ellipsoids).scale, self.widths)
        if self.skin is not None:      # another skin: its own query decides
            near[:] = True
        index = np.flatnonzero(near)
        x = x_all[index]
        g, n, seg, weights = self.gaps(x, t, ellipsoids)
        segment[index] = seg
        p = normal_pressure(g, np.zeros(len(g)), self.penalty)
        inside = p > 0.0
        if self.monitor_penetration and inside.any():
            self.max_penetration_seen = max(self.max_penetration_seen, float(np.max(-g[inside])))
        area = self.area[index]
        force = (area * p)[:, None] * n
        slip = np.zeros(len(x), dtype=bool)
        if self.mu > 0.0:
            stack = SegmentStack(ellipsoids)
            stick, known = self._stick_points(stack, index, seg, x)
            fr = friction_law.return_map(x, stick, n, p, self.mu, self.penalty, self.penalty)
            traction = np.where(known[:, None], fr.traction, 0.0)
            slip = fr.slip & known
            force = force + area[:, None] * traction
            stick_new = friction_law.updated_stick_point(x, traction, self.penalty)
            self._store_stick_points(stack, index[inside], stick_new[inside], seg[inside])
        rhs.getArray()[self.dofs[index]] += force
        contact = index[inside]
        self._set_step(x_all, contact, force[inside], area[inside] * p[inside], segment, slip[inside],
                       integrator.dt, weights[inside])

    def correct(self, integrator, t: float):
        """Lagrange method ([Man2006, Box 5] steps i-j with friction): a^{n+1} += a^c so that the predictor of
        step n+2 lies on the body posed at t_{n+2} = t + dt (no-op for penalty)."""
        if self.method != "lagrange":
            return
        dt = integrator.dt
        t_next = t + dt
        self.time = float(t)
        ellipsoids = self._posed(t_next)
        d = integrator.d.getArray(readonly=True)
        v = integrator.velocity_predictor.getArray(readonly=True)
        a = integrator.a.getArray()
        rows = self.dofs
        if self.monitor_penetration:   # the positions d^{n+1} against the body at t_{n+1} (posed last step)
            self._monitor_penetration(self.reference + d[rows], self.body_at(t))
        if self.compiled:
            self._correct_compiled(integrator, ellipsoids, d, v, a)
            return
        x_trial = self.reference + d[rows] + dt * v[rows] + dt ** 2 * a[rows]
        if self.skin is not None and COMPILED_CONTACT["enabled"]:   # the skin's query, then the compiled friction
            # no SegmentStack: `project` asks only the skin (stacking the segments cost 11 us a step)
            projected = self.project(x_trial, t_next, ellipsoids, None)
            self._correct_compiled(integrator, ellipsoids, d, v, a, (x_trial, projected))
            return
        stack = SegmentStack(ellipsoids)
        skin = self.project(x_trial, t_next, ellipsoids, stack)
        seg = skin.segment
        index = np.flatnonzero(skin.moved)                               # nodes in contact
        m = self._lumped_mass(integrator)[index]                          # M + dt/2 C (per component)
        trial, final, segment = x_trial[index], skin.position[index], seg[index]
        crease = skin.crease[index]
        weights = np.zeros((len(index), len(ellipsoids)))
        weights[np.arange(len(index)), segment] = 1.0
        weights[crease] = skin.weights[index[crease]]
        normal_force = row_length(m * (final - trial)) / dt ** 2             # |lambda_N| [N]
        slip = np.zeros(len(index), dtype=bool)
        # also without a node in contact: _store_stick_points then clears the stick points of the nodes that just
        # lost contact. Skipping it for an empty `index` left them stale, and a node touching down again later
        # took the old stick point as its own (friction from a stale anchor instead of a fresh touch-down); the
        # emptiness is per rank, so this also made 2 ranks differ from 1 (the pants' knee torque by 4e-4 at the
        # first contact record).
        if self.mu > 0.0:
            projected_c = final
            stick, known = self._stick_points(stack, index, segment, projected_c)
            n = stack.normal(stack.to_local(projected_c, segment), segment)   # normals at the contact points
            n[crease] = skin.normal[index[crease]]                            # the blended skin's in a crease
            diff = stick - projected_c
            d_t = diff - (diff * n).sum(axis=1)[:, None] * n                  # P (s - x^c)
            f_t = row_length(m * d_t) / dt ** 2
            limit = self.mu * normal_force                                       # eq. 3.52: |t| <= mu lambda_N
            slip = known & (f_t > limit)
            scale = np.where(slip, limit / np.where(f_t > 0.0, f_t, 1.0), 1.0)
            d_t = np.where(known[:, None], d_t * scale[:, None], 0.0)
            final = projected_c + d_t
            # the stick point stays where it is on the segment when sticking, moves with the node when slipping
            # and is created at the contact point for a node touching down
            self._store_stick_points(stack, index, np.where((slip | ~known)[:, None], final, stick), segment)
        a_c = (final - trial) / dt ** 2
        a[rows[index]] += a_c
        position = x_trial
        position[index] = final
        self._set_step(position, index, m * a_c, normal_force, seg, slip, dt, weights)

    def _correct_compiled(self, integrator, ellipsoids: list[Ellipsoid], d: np.ndarray, v: np.ndarray, a: np.ndarray,
                          projected: tuple[np.ndarray, SkinProjection] | None = None):
        """`correct` by the compiled loops of fabricfem.contact.compiled: the same projection (with the blended skin's
        closest point in the creases), friction and correction node by node, in one call (`contact_step`, its work
        arrays kept from step to step); `projected`: the trial points and their projection onto another skin (its
        normals and weights are used for every node, crease = True), then `friction` alone."""
        lib, ffi = compiled.module(self.comm)
        dt = integrator.dt
        if self._rows is None:
            self._rows = np.ascontiguousarray(self.dofs, dtype=np.int64)
        segments = compiled.stacked(ellipsoids)
        M, K = len(self._rows), len(ellipsoids)
        if self._buffers is None or self._buffers.K != K:
            self._buffers = compiled.StepBuffers(ffi, M, K)
        buffers, p = self._buffers, functools.partial(pointer, ffi)
        c = buffers.cached
        monitors, torques = self._monitor_pointers(buffers)
        mass = c("mass", self._lumped_mass(integrator), "double")
        if projected is None:
            position, segment = np.empty((M, 3)), np.empty(M, dtype=np.int64)
            trial_p, *work = buffers.work()
            n_trapped = lib.contact_step(
                M, c("reference", self.reference, "double"), c("rows", self._rows, "int64_t"), p(d, "double"),
                p(v, "double"), p(a, "double"), dt, K, *(p(array, "double") for array in segments), INSIDE_TOLERANCE,
                MAX_PROJECTION_PASSES, c("widths", self.widths, "double"), trial_p, p(position, "double"),
                p(segment, "int64_t"), c("active", self.active, "uint8_t"), *work, mass, self.mu,
                c("stick_segment", self._stick_segment, "int64_t"),
                c("stick_local", self._stick_local, "double"), c("force", self.force, "double"),
                c("normal_force", self.normal_force, "double"), c("slip", self.slip, "uint8_t"), *monitors)
            if n_trapped:
                raise RuntimeError(f"contact: {n_trapped} points near one segment only remain inside it after "
                                   f"{MAX_PROJECTION_PASSES} projections")
            index = buffers.index[:int(buffers.count[0])]
        else:
            trial, skin = projected
            skin = SkinProjection(*(np.ascontiguousarray(getattr(skin, f)) for f in
                                    ("position", "moved", "segment", "crease", "normal", "weights")))
            position, segment, moved = skin.position, skin.segment, skin.moved
            index = np.flatnonzero(moved)
            for buffer in (self.force, self.normal_force, self.slip):
                buffer.fill(0)
            lib.friction(len(index), p(index, "int64_t"), p(self._rows, "int64_t"), p(trial, "double"),
                         p(position, "double"), p(segment, "int64_t"), mass, dt, self.mu,
                         *(p(array, "double") for array in segments), p(self._stick_segment, "int64_t"),
                         p(self._stick_local, "double"), p(a, "double"), p(self.force, "double"),
                         p(self.normal_force, "double"), p(self.slip.view(np.uint8), "uint8_t"), K, *monitors,
                         p(skin.crease.view(np.uint8), "uint8_t"), p(skin.normal, "double"), p(skin.weights, "double"))
            if self.mu > 0.0:      # every node not in contact loses its stick point (as `_store_stick_points`)
                self._stick_segment[~moved] = -1
            self.active[:] = moved
        self.position, self.segment = position, segment
        self._accumulate(dt, index, self.normal_force[index], torques.tolist())

    def _monitor_pointers(self, buffers: compiled.StepBuffers) -> tuple[tuple, np.ndarray]:
        """(number of monitors, pointers of their segment flags, joint positions at self.time [m], axes and this
        step's torques [N m]) for the compiled loops, and the torques' array."""
        monitors = list(self._monitors.values())
        if self._monitor_arrays is None:
            if len(monitors) > compiled.MAX_MONITORS:
                raise ValueError(f"compiled contact: at most {compiled.MAX_MONITORS} torque monitors")
            self._monitor_arrays = (np.ascontiguousarray([m.on_segments for m in monitors], dtype=np.uint8),
                                    np.ascontiguousarray([m.axis for m in monitors], dtype=float).reshape(-1, 3))
        on_segments, axes = self._monitor_arrays
        joints = np.array([self.poses.joint(m.joint, self.time) for m in monitors], dtype=float).reshape(-1, 3)
        torques = np.zeros(len(monitors))
        ffi = buffers.ffi
        return (len(monitors), buffers.cached("on_segments", on_segments, "uint8_t"), pointer(ffi, joints, "double"),
                buffers.cached("axes", axes, "double"), pointer(ffi, torques, "double")), torques

    def _set_step(self, position: np.ndarray, index: np.ndarray, force: np.ndarray, normal_force: np.ndarray,
                  segment: np.ndarray, slip: np.ndarray, dt: float, weights: np.ndarray):
        """State of the step: positions (M, 3) and segments (M,) of all nodes; contact forces on the cloth,
        normal forces, slip flags and the skin's segment weights (fabricfem.body.skin) of the nodes `index` in
        contact (zero / False elsewhere)."""
        self.position, self.segment = position, segment
        for buffer, values in ((self.force, force), (self.normal_force, normal_force), (self.slip, slip)):
            buffer.fill(0)           # the state arrays are overwritten in place every step
            buffer[index] = values
        self.active.fill(False)
        self.active[index] = True
        self._accumulate(dt, index, normal_force, self._local_torques(position[index], force, segment[index],
                                                                      weights))
