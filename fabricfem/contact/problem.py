"""Frictional contact of a ShellModel against a rigid body's skin, as a ResidualTerm for the implicit solvers.

`ContactProblem(model, obstacles, ...)` holds the contact state of a `fabricfem.shell.ShellModel` and is a
ResidualTerm (fabricfem.solvers.system): `add_residual` subtracts the nodal contact forces f_contact(x) of
fabricfem.contact.nodal / friction on the owned displacement nodes (ghost nodes are skipped, so nothing is
counted twice under MPI), `add_jacobian` adds the 3x3 nodal blocks, `commit` stores the friction history.
`problem.system` is `CompositeSystem(model, [problem])`, R_shell(x) - f_contact(x), which
`NewtonSolver(problem.system)` and `solve_load_path(problem.system, ...)` drive; the model's data (w, comm,
F_ref, load_factor, ...) read through the problem as well.

The geometry is the wearer's surface contract (fabricfem.body.skin) and nothing else: at the nodes x and the
contact's body time t [s] the skin's `query(x, t)` gives the signed gap g [m], the outward normal n and the segment
weights W (N, K). Against a `Body` the skin is the one the explicit engine uses, its segments joined by the smooth
blend of width `blend_width` [m] at the joints (fabricfem.body.blended.BlendedEllipsoids; not strict: a Newton
iterate deep inside a concave blend, where the closest point does not converge, gets the last iterate's foot, as
in the explicit projection, instead of stopping the solve), or any `skin` of the body (a rigged surface mesh,
fabricfem.body.mesh_skin); against fixed obstacles (planes, rounded boxes, ellipsoids) it is their union
(fabricfem.contact.obstacles.ObstacleSkin). The problem keeps the body time and asks the skin at it (the skin
poses the body itself): so every skin of the contract serves, and the contact's time is the one at which the torque
monitors pose the joints. A node's friction stick point is kept in the frame of the segment of largest weight (as
the explicit engine keeps it), and a node carries the share W_ik of its moment into a joint torque of segment k
(fabricfem.contact.torque.local_torques).

Normal methods: "penalty" ([Man2006, Box 3]: p = k_N <-g>) and "augmented" (eq. 3.69: p = <lambda - k_N g>, Uzawa
update lambda <- p between Newton solves, `solve_augmented`). Friction: Coulomb with coefficient
`friction` and tangential penalty eps_T (fabricfem.contact.friction); history committed in
`commit` (run by `system.after_converged_step`). Units: SI (m, N, Pa, Pa/m).

Active-set strategy (`active_set=True`, used through `solve`): the unilateral law p = <lambda - k_N g>
has a tangent that jumps at lambda - k_N g = 0, and Newton can cycle for ever when a few nodes leave
and re-enter contact from one iterate to the next. `solve` therefore fixes the set A of contact nodes
during one Newton solve (nodes in A carry the bilateral spring p = lambda - k_N g, the others p = 0: a
smooth problem; with friction the set S of sliding nodes is fixed as well: a node of S takes the slip
branch, the others the stick branch of the return map, because the switch between the two branches
cycles the same way), then recomputes A from the sign of lambda - k_N g and S from Phi* > 0 at the converged
state and repeats until neither changes (at most `max_active_set_updates` updates, else SolverError naming the
nodes that flip). When A is stable the converged state satisfies the unilateral law exactly, so the solution
is the plain penalty / augmented solution (tests/test_sleeve.py checks this to 1e-10). No segment is fixed: the
skin's gap and normal are continuous across the joints (the weights turn over the blend instead of the nearest
segment switching), so a node in a crease is pushed out of the skin, not out of one segment into the other.
With `tie_tolerance` = delta > 0 [m] a node whose trial pressure lambda - k_N g lies within k_N delta of
zero keeps its status in an update (`nodal.keep_ties`): a node on the switch can otherwise leave and
re-enter A at every update without end. The converged state then satisfies the law within a gap of delta:
a kept contact node carries a tension below k_N delta, a kept free node penetrates less than delta.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.body.blended import BLEND_WIDTH, BlendedEllipsoids, check_width
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.pose import Body
from fabricfem.body.skin import Skin, SkinQuery
from fabricfem.contact import friction as friction_law
from fabricfem.contact import nodal
from fabricfem.contact.obstacles import ObstacleSkin
from fabricfem.contact.torque import TorqueMonitor, adjacent_segments, local_torques
from fabricfem.meshes._validate import non_negative
from fabricfem.solvers.newton import NewtonResult, NewtonSolver, SolverError
from fabricfem.solvers.system import CompositeSystem

METHODS = ("penalty", "augmented")
# the system contract (fabricfem.solvers.system), which ContactProblem does not delegate to its model
_SYSTEM_CALLBACKS = frozenset({"residual", "jacobian", "set_state", "create_vector", "create_matrix",
                               "after_converged_step", "compile", "set_load_factor", "internal_force"})


@dataclass
class ContactState:
    """Contact quantities at the owned nodes for one configuration (forces on the cloth)."""

    position: np.ndarray      # (N, 3) deformed node positions x [m]
    gap: np.ndarray           # (N,) signed gaps g [m], positive outside
    normal: np.ndarray        # (N, 3) unit outward body normals
    segment: np.ndarray       # (N,) index of the segment of largest skin weight
    weights: np.ndarray       # (N, K) the skin's segment weights (fabricfem.body.skin)
    pressure: np.ndarray      # (N,) p of the contact law [Pa], per unit reference area
    traction: np.ndarray      # (N, 3) friction traction t_T [Pa]
    slip: np.ndarray          # (N,) sliding nodes
    force: np.ndarray         # (N, 3) f = w (p n + t_T) [N], zero on Dirichlet components
    stiffness: np.ndarray     # (N, 3, 3) -df/dx [N/m]


@dataclass
class AugmentationReport:
    augmentations: int
    max_penetration: float
    newton_iterations: list[int]


class ContactProblem:
    """Frictional node-to-skin contact added to a ShellModel (module docstring).

    Args:
        model: the ShellModel (quadrilateral mesh); add its loads and constraints before wrapping.
        obstacles: a Body (its skin queried at `time`), or a sequence of fixed Ellipsoid (or of
            fabricfem.contact.obstacles Plane / RoundedBox, which duck-type it): their union (ObstacleSkin).
        method: "penalty" or "augmented".
        penalty: k_N [Pa/m] (default nodal.default_penalty: 10 E t / h^2).
        friction: Coulomb coefficient mu >= 0.
        tangential_penalty: eps_T [Pa/m] (default k_N).
        time: body time t [s] when `obstacles` is a Body.
        active_set: solve with the active-set strategy (module docstring) in `solve` / `solve_augmented`.
        max_active_set_updates: cap on the active-set updates of one `solve`.
        tie_tolerance: delta [m] of the active-set ties (module docstring).
        skin: the Body's skin (anything with `query(x, t) -> SkinQuery` and the body's `segment_names`, e.g.
            fabricfem.body.mesh_skin.MeshSkin); default BlendedEllipsoids(body, blend_width). Body only.
        blend_width: w [m] of the default skin's blend at the joints (fabricfem.body.blended).
    """

    def __init__(self, model, obstacles: Sequence[Ellipsoid] | Body, method: str = "penalty",
                 penalty: float | None = None, friction: float = 0.0, tangential_penalty: float | None = None,
                 time: float = 0.0, active_set: bool = False, max_active_set_updates: int = 30,
                 tie_tolerance: float = 0.0, skin: Skin | None = None, blend_width: float = BLEND_WIDTH):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        if not (isinstance(max_active_set_updates, int) and max_active_set_updates >= 1):
            raise ValueError(f"max_active_set_updates must be a positive integer, got {max_active_set_updates!r}")
        self.active_set = bool(active_set)
        self.max_active_set_updates = max_active_set_updates
        self.tie_tolerance = non_negative("tie_tolerance", tie_tolerance)   # m
        self.blend_width = check_width(blend_width)                         # m
        # the fixed contact and slip sets during a solve with the active-set strategy (None: unilateral law
        # and return map)
        self.active: np.ndarray | None = None
        self.sliding: np.ndarray | None = None
        self.active_set_updates: list[int] = []   # set changes per update in the last `solve`
        self.model = model
        self.method = method
        self.torque_monitors: dict[str, TorqueMonitor] = {}
        self.mu = friction_law.friction_coefficient(friction)
        self.time = float(time)
        self._last_query: tuple | None = None   # (time, skin, x, SkinQuery) of the last skin query
        self.nodes = nodal.contact_nodes(model)
        self.penalty = (nodal.default_penalty(model, self.nodes.element_size) if penalty is None
                        else nodal.positive_parameter("penalty", penalty))
        self.tangential_penalty = (self.penalty if tangential_penalty is None
                                   else nodal.positive_parameter("tangential_penalty", tangential_penalty))
        self.set_obstacles(obstacles, skin)
        N = self.nodes.count
        self.multiplier = np.zeros(N)                        # lambda_i [Pa]
        # Stick points (segment frame) and their segment: the last converged node position where the node
        # was out of contact, so that a node touching down during a step slips relative to where it was.
        self._stick_local = np.zeros((N, 3))
        self._stick_segment = np.full(N, -1, dtype=np.int64)
        self._store_stick_points(self.nodes.reference, np.zeros((N, 3)))
        self._free = ~self.nodes.constrained
        self.state: ContactState | None = None
        self._current_areas: nodal.CurrentAreas | None = None   # compiled on the first `contact_pressure`
        self.system = CompositeSystem(model, [self])   # what the solvers drive: the shell plus this contact

    # ------------------------------------------------------------------ delegation
    def __getattr__(self, name):
        # the model's data (w, load_factor, F_ref, comm, ndofs, node_value, reaction, ...); not its solver
        # callbacks: this is a term, the system to solve is `self.system`
        model = self.__dict__.get("model")
        if model is None:
            raise AttributeError(name)
        if name in _SYSTEM_CALLBACKS:
            raise AttributeError(f"ContactProblem is a ResidualTerm, not a system: use ContactProblem.system.{name}")
        return getattr(model, name)

    # ------------------------------------------------------------------ obstacles
    def set_obstacles(self, obstacles: Sequence[Ellipsoid] | Body, skin: Skin | None = None):
        """Replace the obstacles: a Body and its `skin` (default: its blended ellipsoids, BlendedEllipsoids of
        `blend_width`), or fixed obstacles (their union, ObstacleSkin; no `skin`)."""
        self._last_query = None
        if isinstance(obstacles, Body):
            skin = BlendedEllipsoids(obstacles, self.blend_width, strict=False) if skin is None else skin
            if tuple(skin.segment_names) != tuple(obstacles.segments) or not callable(getattr(skin, "query", None)):
                raise ValueError(f"skin: a skin with a query(x, t) of the body's segments {list(obstacles.segments)} "
                                 f"is needed, got {getattr(skin, 'segment_names', skin)!r}")
            self.body, self.skin = obstacles, skin
            self.ellipsoids = list(obstacles.pose(self.time).values())   # the stick points' frames
            return
        if skin is not None:
            raise ValueError("skin: a skin needs a Body as obstacles (its segments carry the stick points and torques)")
        ellipsoids = list(obstacles)
        # any rigid obstacle with the Ellipsoid interface used here (gap, to_local, to_global), e.g. the
        # planes and rounded boxes of fabricfem.contact.obstacles
        if not ellipsoids or not all(isinstance(e, Ellipsoid) or all(callable(getattr(e, m, None)) for m in
                                     ("gap", "to_local", "to_global")) for e in ellipsoids):
            raise ValueError("obstacles must be a Body or a non-empty sequence of Ellipsoid (or obstacles with "
                             "gap, to_local and to_global, fabricfem.contact.obstacles)")
        self.body, self.skin, self.ellipsoids = None, ObstacleSkin(ellipsoids), ellipsoids

    def set_time(self, t: float):
        """Pose the Body at time t [s]: the skin is asked at t, the stick points follow their segments."""
        if self.body is None:
            raise ValueError("set_time needs a Body as obstacles")
        self.time = float(t)
        self.ellipsoids = list(self.body.pose(self.time).values())

    def query(self, x: np.ndarray) -> SkinQuery:
        """The skin's SkinQuery (fabricfem.body.skin) of the points x (N, 3) [m] at the contact's time. The last
        query is kept: the residual and the Jacobian of a Newton iterate, the active-set update and the monitors
        ask at the same state. ValueError for non-finite positions (a diverged solve)."""
        last = self._last_query
        if last is not None and last[0] == self.time and last[1] is self.skin and np.array_equal(last[2], x):
            return last[3]
        if not np.all(np.isfinite(x)):
            raise ValueError("x: the contact gap is not finite (positions contain NaN/inf: the solve diverged)")
        q = self.skin.query(x, self.time)
        self._last_query = (self.time, self.skin, np.array(x, copy=True), q)
        return q

    # ------------------------------------------------------------------ contact evaluation
    def _stick_points(self, x: np.ndarray, segment: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stick points at the current pose and a mask of the nodes that have one on their current segment of
        largest weight (the others -- that segment changed during the step -- get the node itself)."""
        points = x.copy()
        known = np.zeros(len(x), dtype=bool)
        for k, e in enumerate(self.ellipsoids):  # loop over the few segments
            mask = (self._stick_segment == k) & (segment == k)
            points[mask] = e.to_global(self._stick_local[mask])
            known |= mask
        return points, known

    def _store_stick_points(self, x: np.ndarray, traction: np.ndarray):
        """a = x + t_T / eps_T on the skin's segment of largest weight, in its frame (out of contact: t_T = 0,
        a = x)."""
        segment = self.query(x).segment
        stick = friction_law.updated_stick_point(x, traction, self.tangential_penalty)
        self._stick_segment = segment
        for k, e in enumerate(self.ellipsoids):
            mask = segment == k
            self._stick_local[mask] = e.to_local(stick[mask])

    def evaluate(self, state_array: np.ndarray | None = None) -> ContactState:
        """Contact state at the owned nodes for the local state array of model.w (owned + ghosts)."""
        arr = self.model.w.x.array if state_array is None else state_array
        x = self.nodes.reference + arr[self.nodes.dofs]
        skin = self.query(x)
        g, n, seg = skin.gap, skin.normal, skin.segment
        active = self.active
        p = nodal.normal_pressure(g, self.multiplier, self.penalty, active)
        force, stiffness = nodal.normal_force_and_tangent(self.nodes.area, p, n, self.penalty, active)
        traction = np.zeros_like(x)
        slip = np.zeros(len(x), dtype=bool)
        if self.mu > 0.0:
            stick, known = self._stick_points(x, seg)
            fr = friction_law.return_map(x, stick, n, p, self.mu, self.tangential_penalty, self.penalty, active,
                                         self.sliding)
            fr.tangent[~known] = 0.0   # stick point = x: no traction and no stiffness this step
            traction, slip = fr.traction, fr.slip
            w = self.nodes.area
            force = force + w[:, None] * traction
            stiffness = stiffness - w[:, None, None] * fr.tangent
        # components with a Dirichlet condition take no contact force (the support carries it): the force
        # reported (totals, torque) is the one that enters the residual
        force = np.where(self._free, force, 0.0)
        self.state = ContactState(x, g, n, seg, skin.weights, p, traction, slip, force, stiffness)
        return self.state

    # ------------------------------------------------------------------ ResidualTerm
    def add_residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """b -= f_contact at the model's current state (set from x by the model's residual): free displacement
        rows of the owned nodes only, so nothing is counted twice under MPI; Dirichlet rows untouched."""
        s = self.evaluate()
        free = self._free
        b.getArray()[self.nodes.dofs[free]] -= s.force[free]

    def add_jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        """A += the contact stiffness blocks K_i = -df_i/dx_i at the model's current state (free displacement
        rows/columns)."""
        s = self.evaluate()
        free = self._free.astype(float)
        blocks = s.stiffness * free[:, :, None] * free[:, None, :]
        rows = self.nodes.dofs.astype(PETSc.IntType)
        A.setValuesLocalRCV(rows, rows, blocks, addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()

    def commit(self):
        """Commit the friction history (stick points) of the converged state."""
        s = self.evaluate()
        if self.mu > 0.0:
            self._store_stick_points(s.position, s.traction)

    # ------------------------------------------------------------------ active-set strategy
    def contact_set(self) -> tuple[np.ndarray, np.ndarray]:
        """(contact, sliding): (N,) masks of the owned nodes that the unilateral law puts in contact and that the
        return map lets slide, at the current state."""
        fixed = self.active, self.sliding
        self.active = self.sliding = None
        try:
            s = self.evaluate()
        finally:
            self.active, self.sliding = fixed
        return s.pressure > 0.0, s.slip

    def solve(self, solver: NewtonSolver) -> NewtonResult:
        """Equilibrium at the current pose and multipliers from the current state: one Newton solve, or,
        with the active-set strategy, Newton solves on fixed contact / slip sets repeated
        until they are stable (module docstring). Returns the NewtonResult with the iterations of all
        solves; a failed Newton solve returns an unconverged result (state left as SNES left it), sets that
        keep changing after `max_active_set_updates` updates raise SolverError.

        The first slip-set guess is the return map's at the start state; if that sequence fails, it is
        retried from the start state with every contact node sticking (the "elastic predictor": a slip set
        taken over from the start state can keep a node on the slip branch while its trial traction
        reverses, where that branch has no solution; measured on the capstan strip)."""
        if not self.active_set:
            return solver.solve()
        start = self.model.w.x.array.copy()
        total, norms, reason = 0, [], ""
        for sticking in (False, True):
            self.model.w.x.array[:] = start
            result = self._solve_fixed_sets(solver, sticking)
            total += result.iterations
            norms += result.residual_norms
            if result.converged:
                return NewtonResult(True, total, result.reason, norms)
            reason = result.reason
        return NewtonResult(False, total, reason, norms)

    def _solve_fixed_sets(self, solver: NewtonSolver, sticking: bool) -> NewtonResult:
        self.active, self.sliding = self.contact_set()
        if sticking:
            self.sliding = np.zeros_like(self.sliding)
        self.active_set_updates = []
        total, norms = 0, []
        try:
            for _ in range(self.max_active_set_updates + 1):
                result = solver.solve()
                total += result.iterations
                norms += result.residual_norms
                if not result.converged:
                    return NewtonResult(False, total, result.reason, norms)
                active, sliding = self.contact_set()
                if self.tie_tolerance > 0.0:    # nodes on the switch within the tie keep their status
                    active = nodal.keep_ties(self.active, self.state.gap, self.multiplier, self.penalty,
                                             self.tie_tolerance)
                flips = (active != self.active) | (sliding != self.sliding)
                changed = self.comm.allreduce(int(np.count_nonzero(flips)), op=MPI.SUM)
                if changed == 0:
                    return NewtonResult(True, total, result.reason, norms)
                self.active_set_updates.append(changed)
                self.active, self.sliding = active, sliding
        finally:
            self.active = self.sliding = None
        raise SolverError(f"active set: the contact set still changed ({self.active_set_updates[-1]} nodes) after "
                          f"{self.max_active_set_updates} updates (changes per update: {self.active_set_updates})",
                          reason="ACTIVE_SET_NOT_STABLE")

    # ------------------------------------------------------------------ augmented Lagrangian
    def max_penetration(self) -> float:
        """max(0, -min g) over all nodes [m], same on all ranks."""
        s = self.evaluate()
        local = float(np.max(-s.gap, initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)

    def augment(self):
        """Uzawa update lambda <- < lambda - k_N g > (eq. 3.69)."""
        s = self.evaluate()
        self.multiplier = nodal.normal_pressure(s.gap, self.multiplier, self.penalty)

    def solve_augmented(self, solver: NewtonSolver | None = None, tolerance: float = 1e-6,
                        max_augmentations: int = 50) -> AugmentationReport:
        """Newton solves at fixed multipliers, each followed by an Uzawa update, until the largest
        penetration is below `tolerance` [m] ([Man2006, Box 6], outer loop). Raises SolverError on a failed
        Newton solve or when the tolerance is not met after `max_augmentations` updates."""
        if self.method != "augmented":
            raise ValueError("solve_augmented needs method='augmented'")
        tolerance = nodal.positive_parameter("tolerance", tolerance)
        solver = solver or NewtonSolver(self.system)
        iterations = []
        for k in range(int(max_augmentations) + 1):
            result = self.solve(solver)
            iterations.append(result.iterations)
            if not result.converged:
                raise SolverError(f"augmented Lagrangian: Newton {result.reason} after {result.iterations} "
                                  f"iterations at augmentation {k}", reason=result.reason)
            penetration = self.max_penetration()
            if penetration < tolerance:
                return AugmentationReport(k, penetration, iterations)
            self.augment()
        raise SolverError(f"augmented Lagrangian: penetration {penetration:.3e} m still above {tolerance:.1e} m "
                          f"after {max_augmentations} augmentations")

    # ------------------------------------------------------------------ output
    def total_force(self) -> np.ndarray:
        """Sum of the contact forces on the cloth [N] (3,), same on all ranks."""
        s = self.evaluate()
        return self.comm.allreduce(s.force.sum(axis=0), op=MPI.SUM)

    def contact_pressure(self, per: str = "current") -> np.ndarray:
        """(N,) normal contact pressure at the owned nodes [Pa]: per unit current (deformed) cloth area, the
        pressure on the body (`per="current"`), or per unit reference area, the p of the contact law
        (`per="reference"`); they differ by the area stretch a_i / w_i."""
        if self._current_areas is None and per == "current":
            self._current_areas = nodal.CurrentAreas(self.model, self.nodes)
        return nodal.pressure_on_body(self.evaluate().pressure, self.nodes.area, self._current_areas, per)

    def pressure_field(self, per: str = "current") -> fem.Function:
        """Contact pressure [Pa] (`contact_pressure`) as a Q2 scalar Function (for output)."""
        return nodal.pressure_function(self.nodes.scalar_space, self.nodes.node_index, self.contact_pressure(per))

    def joint_torque(self, joint: str, axis: Sequence[float]) -> float:
        """Torque [N m] about `joint` along `axis` of the contact forces that the cloth exerts on the
        segments adjacent to the joint (fabricfem.body.motion.joint_torque convention), all ranks."""
        if self.body is None:
            raise ValueError("joint_torque needs a Body as obstacles")
        return self._torque(TorqueMonitor.build(list(self.body.segments), joint, axis,
                                                adjacent_segments(self.body, joint)))

    def track_torque(self, name: str, joint: str, axis, segments: Sequence[str]):
        """Register the torque [N m] about `joint` along `axis` of the forces the cloth exerts on `segments`
        (fabricfem.contact.torque.TorqueMonitor) under `name`, read by `torque(name)`."""
        if self.body is None:
            raise ValueError("track_torque needs a Body as obstacles")
        self.torque_monitors[name] = TorqueMonitor.build(list(self.body.segments), joint, axis, segments)

    def torque(self, name: str) -> float:
        """The registered torque `name` [N m] at the current state (all ranks)."""
        return self._torque(self.torque_monitors[name])

    def _torque(self, monitor: TorqueMonitor) -> float:
        """The monitor's torque [N m] at the current state, all ranks: each node's moment shared among the segments
        by the skin's weights (fabricfem.contact.torque.local_torques)."""
        s = self.evaluate()
        local = local_torques([monitor], s.position, s.force, s.segment,
                              lambda joint: self.body.joint_position(joint, self.time), s.weights)[0]
        return float(self.comm.allreduce(local, op=MPI.SUM))
