"""The arm-in-sleeve problem [Man2006, sec. 5.3]: a tube of fabric over a flexing two-ellipsoid arm.

Setup (SI units): the sleeve is an open cylinder of length L [m] and radius R [m] along +x
(`fabricfem.meshes.tube`), its shoulder end (tag end0, x = 0) held (all displacement components zero,
rotations free: "boundary conditions are specified to restrain the motion of fabric nodes around the
shoulder", sec. 5.3), its wrist end free. The arm is `fabricfem.body.default_arm` of
`SleeveConfig.arm` (lengths and girths; default ANSUR II medians, scene keys body.*): upper arm fixed,
forearm flexing about the elbow (+z axis through x = 0.335 m) at constant angular velocity up to
57 degrees. Contact: `fabricfem.contact.ContactProblem` (nodal penalty or augmented Lagrangian,
Coulomb friction with stick points that move with the segments).

Solution routes (SleeveConfig.solver, scene key motion.solver):

* "explicit" (default, as the thesis did, ch. 5): central differences with the sleeve's own mass
  (`build_explicit`, `run_explicit`; fabricfem.dynamics.CentralDifference, lumped mass eq. 2.82 with the
  rotational masses scaled by `rotary_inertia_scale`, so that the thickness-shear modes do not set the
  step: on mesh I the estimated critical step grows from 4.1e-5 s to 2.0e-4 s at s = 100), mass-proportional
  damping C = alpha M (alpha = `mass_damping` = 10 1/s) for a quasi-static flexion, and the explicit
  forward-increment Lagrange-multiplier contact of [Man2006, Box 5] against the moving arm with Coulomb friction
  (fabricfem.contact.explicit.ExplicitBodyContact; penalty as an option). The torque of a record is the
  contact torque averaged over the record interval (`output_angle_step`). The drag alpha rho t v of the
  damping on the sleeve moving with the forearm (v <= 0.13 m/s at 45 deg/s) is about 2e-3 N m of elbow
  torque: a few per cent of the torque at 57 degrees, but comparable with the torque in the first degrees
  of contact (measured on mesh I at 8 deg: explicit 1.1e-2 N m at 45 deg/s, 5.4e-3 N m at 15 deg/s,
  quasi-static 4.5e-3 N m).
* dynamic similarity (SleeveConfig.dynamic_similarity, scene key motion.dynamic_similarity, explicit route):
  stiff fabrics (II: E = 350 MPa, III: 7.2 GPa) would need c_k / c_I = 17 and 60 times the steps of fabric I
  at the same flexion speed; with similarity the flexion runs at omega c_k / c_ref and the mass damping is
  alpha c_k / c_ref (c = sqrt(E / rho), c_ref of fabric I), which keeps the steps per degree and the
  dimensionless inertia and damping of fabric I and scales the torque with E exactly
  (`SleeveConfig.flexion_speed` derives it).
* "quasistatic": a sequence of Newton solves at increasing angle alpha_k with the body posed at
  t_k = alpha_k / omega, each starting from the previous equilibrium; the friction history (stick points)
  is committed after each converged step (`ContactProblem.after_converged_step`). A step whose Newton solve
  fails is undone and split in two (down to `min_angle_step`), otherwise `SleeveError` names the angle. It
  stalls where the tube buckles (20.25 deg at mu = 0.1, 17 deg at mu = 0.5 on mesh I) and is kept as the
  static reference of the explicit route at small angles and for the moment-balance test.
* "implicit" (fabricfem.wear.sleeve_implicit): the explicit route's equations (lumped mass, mass damping, gravity,
  rest, flexion) by backward Euler, steps of angle_step / omega solved by Newton with the augmented Lagrangian
  (Uzawa updates, eq. 3.69) or penalty; the inertia and damping regularise the buckling steps (it reaches 57 deg).

Newton at one angle (the plain solve stalled at 20.2 deg, mu = 0.1, and 12.6 deg, mu = 0.5, on
mesh I) uses two devices, neither of which changes the converged solution:
* the active-set strategy of ContactProblem (`active_set`, default on): contact set, slip set and body
  segment of every node are fixed during one Newton solve and updated from the converged state until
  they no longer change, which removes the leave / re-enter cycling of the non-smooth contact law;
* a damped Newton step (`StepLimiter`): the linearised step of the nearly free director rotations is
  radians long from an out-of-balance start and the iterates ran away (residual 1e1 -> 1e10 N) even on a
  fixed contact set; each update is scaled so that no director angle changes by more than
  `max_rotation_step` and no displacement by more than `max_displacement_step` per iteration.
The viscous drag of `Stabilized` remains the fallback of a failed solve.

Gravity: on by default on the explicit route, g = 9.81 m/s^2 along -y, opposite to the flexion (the
forearm "rotates upward"), and the arm first rests for `settle_time` = 0.4 s while the sleeve settles on it
under its weight (rho t g = 4.3 Pa for fabric I, 0.81 N for the whole sleeve). Reasons: (1) the thesis's
sleeve has weight: at mu = 0.1 it "slips down as the forearm rotates upward", at mu = 0.5 friction "prevents
the sleeve from falling down onto the elbow joint" (sec. 5.3.1-5.3.2), which only a weight along -y does;
(2) without it the sleeve floats concentric around the arm (4.3 mm clearance, no contact before 5 degrees)
and the only forces that press it on the forearm are its inertia and the mass-damping drag, so the torque
depends on the flexion rate (mesh I, mu = 0.5, mean over 1-57 deg: 40 % higher at 45 than at 15 deg/s; the
non-monotonic, noisy curves of the first study), whereas with the weight it changes by 6.4 % between 45
and 15 deg/s (tests/test_explicit_sleeve.py checks 45 vs 22.5 deg/s against the drag + inertia bound).
The rest lets the sleeve's fall (about 12 mm onto the forearm; damping time 1 / alpha = 0.1 s) die out
before the flexion: the start record is the torque at rest (the weight the forearm carries, 0.023 N m on
mesh I). The quasi-static route keeps gravity off by default (its start-pose solve of the floating sleeve
under its weight did not finish within 600 s on mesh I; not investigated further).

Elbow torque ([Man2006, ch. 5] intro): the moment about the elbow of all contact forces (normal + friction)
that the sleeve exerts on the forearm,

    tau = a . sum_{i on forearm} (x_i - J_elbow) x f_i          (fabricfem.body.motion.joint_torque)

and the resisting torque reported is -tau [N m], positive when the sleeve opposes flexion.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.body.arm import default_arm, elbow_flexion
from fabricfem.body.motion import ElbowFlexion, rotation_about
from fabricfem.body.pose import Body
from fabricfem.contact.explicit import ExplicitBodyContact
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics import stability
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.meshes import tube
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.solvers.system import CompositeSystem
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.engine import Phase, RunHistory, WearError, run_phases

GRAVITY = 9.81                       # m/s^2
ELBOW_AXIS = (0.0, 0.0, 1.0)          # flexion axis of the default arm


class Stabilized:
    """Viscous regularisation of the quasi-static steps, a ResidualTerm (fabricfem.solvers.system): the residual
    gets a nodal drag

        r_i = c w_i (x_i - x_i^n)      [N]   (backward-Euler viscous force eta v with c = eta / dt)

    on the free displacement components of every node (w_i: lumped area [m^2], x^n: the last converged
    positions, set by `commit`), and the Jacobian c w_i I. Tube buckling makes the elastic tangent indefinite on
    the way to 57 degrees and an unregularised Newton step then fails; the drag keeps the step's tangent positive
    definite and follows the stable branch, at the price of a fictitious force that is reported (`drag_force`,
    compared with the contact force in SleeveStep.drag_ratio). c = 0 switches it off.
    """

    def __init__(self, contact: ContactProblem, coefficient: float):
        self.contact = contact
        self.coefficient = float(coefficient)
        nodes = contact.nodes
        self._free = ~nodes.constrained
        self._dofs = nodes.dofs
        self._area = nodes.area
        self.commit()

    def commit(self):
        """Remember the current (converged) nodal displacements as x^n."""
        self._previous = self.contact.w.x.array[self._dofs].copy()

    def drag(self) -> np.ndarray:
        """(N, 3) drag forces c w (x - x^n) [N] on the owned nodes (zero on held components)."""
        u = self.contact.w.x.array[self._dofs]
        return np.where(self._free, self.coefficient * self._area[:, None] * (u - self._previous), 0.0)

    def drag_force(self) -> float:
        """Largest nodal drag [N] over all ranks."""
        local = float(np.max(np.linalg.norm(self.drag(), axis=1), initial=0.0))
        return self.contact.comm.allreduce(local, op=MPI.MAX)

    def add_residual(self, x, b):
        """b += the drag on the free displacement rows of the owned nodes."""
        if self.coefficient > 0.0:
            arr = b.getArray()
            f = self.drag()
            arr[self._dofs[self._free]] += f[self._free]

    def add_jacobian(self, x, A):
        """A += c w_i I on the free displacement rows and columns."""
        if self.coefficient > 0.0:
            n = len(self._area)
            blocks = (self.coefficient * self._area)[:, None, None] * np.broadcast_to(np.eye(3), (n, 3, 3))
            free = self._free.astype(float)
            blocks = blocks * free[:, :, None] * free[:, None, :]
            rows = self._dofs.astype(PETSc.IntType)
            A.setValuesLocalRCV(rows, rows, blocks, addv=PETSc.InsertMode.ADD_VALUES)
            A.assemble()


class StepLimiter:
    """Damped Newton for the sleeve: every Newton update dw is scaled by one factor s <= 1 so that no
    director-angle increment exceeds `max_rotation` [rad] and no displacement increment `max_displacement` [m]
    (s = min(1, max_rotation / |dtheta|_inf, max_displacement / |du|_inf), all ranks).

    Why: the sleeve's rotation dofs are nearly free (bending stiffness E t^3 / 12 = 1e-4 N m, transverse
    shear G t), so from an out-of-balance start the linearised step turns directors by radians (measured on
    mesh I at 6 -> 9 deg: 0.95 rad, then 4.4, 11 rad, ...) where the two-angle director map is far from
    linear, and the iterates run away (residual 1e1 -> 1e10 N) whatever the contact set does. A limited step
    changes only the path of the iterates, not the solution, and near convergence s = 1 (full Newton,
    quadratic rate). Installed as the SNES line-search pre-check.
    """

    def __init__(self, model: ShellModel, max_rotation: float, max_displacement: float):
        self.max_rotation = float(max_rotation)
        self.max_displacement = float(max_displacement)
        n_owned = model.W.dofmap.index_map.size_local * model.W.dofmap.index_map_bs
        u_dofs = np.asarray(model.W.sub(0).collapse()[1])
        theta_dofs = np.asarray(model.W.sub(1).collapse()[1])
        self._u = u_dofs[u_dofs < n_owned]
        self._theta = theta_dofs[theta_dofs < n_owned]
        self.comm = model.comm
        self.scalings = 0   # limited steps since construction (diagnostics)

    def factor(self, step: np.ndarray) -> float:
        """s for the owned part `step` of a Newton update (same on all ranks)."""
        local = np.array([np.max(np.abs(step[self._theta]), initial=0.0), np.max(np.abs(step[self._u]), initial=0.0)])
        largest = np.empty(2)
        self.comm.Allreduce(local, largest, op=MPI.MAX)
        theta, u = largest
        s = 1.0
        if theta > self.max_rotation:
            s = self.max_rotation / theta
        if u > self.max_displacement:
            s = min(s, self.max_displacement / u)
        return s

    def __call__(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        s = self.factor(y.array)
        if s < 1.0:
            y.scale(s)
            self.scalings += 1
            return True
        return False


class SleeveError(SolverError):
    """The quasi-static flexion could not proceed (Newton failed below the minimum angle step)."""


class ArmOutputs:
    """The wearer contract's outputs shared by every sleeve route (fabricfem.wear.contract.WearRun): needs
    `contact`, `body` and `flexion`."""

    def pressure_field(self):
        """Contact pressure on the body [Pa] per unit deformed cloth area, a Q2 Function (explicit route:
        time-averaged over the last record)."""
        return self.contact.pressure_field()

    def posed_bodies(self, angle: float) -> list:
        """The arm's ellipsoids at elbow angle `angle` [deg]."""
        return list(self.body.pose(self.flexion.time_at(math.radians(angle))).values())

    def fraction(self, step) -> float:
        """The done fraction of the run at record `step` (its angle over the final angle)."""
        return step.angle / self.config.motion.final_angle

    def body_time(self, step) -> float:
        """The body time [s] of record `step` (the flexion's time at its angle)."""
        return self.flexion.time_at(math.radians(step.angle))


@dataclass
class SleeveProblem(ArmOutputs):
    """The assembled sleeve problem."""

    config: SleeveConfig
    model: ShellModel
    contact: ContactProblem
    body: Body
    flexion: ElbowFlexion
    solver: NewtonSolver
    system: CompositeSystem      # the shell + [contact, drag (Stabilized) or inertia]

    @property
    def comm(self):
        return self.model.comm

    @property
    def drag(self) -> Stabilized:
        """The last term of `system`: the viscous drag of the quasi-static route."""
        return self.system.terms[-1]

    def time_at(self, angle_deg: float) -> float:
        """Body time t [s] at which the flexion reaches `angle_deg`."""
        return self.flexion.time_at(math.radians(angle_deg))

    def resisting_torque(self) -> float:
        """-tau [N m] about the elbow along +z of the forces the sleeve exerts on the forearm (all ranks)."""
        return -self.contact.torque("forearm")

    def resisting_torque_all(self) -> float:
        """-tau [N m] about the elbow of the forces the sleeve exerts on both arm segments (all ranks)."""
        return -self.contact.torque("both")

    # the wearer contract (fabricfem.wear.contract.WearRun)
    def describe(self) -> str:
        return f"{self.config.motion.angle_steps} quasi-static steps"

    def run(self, on_step: Callable[[SleeveStep], None] | None = None,
            stop_on_failure: bool = True) -> "SleeveHistory":
        return run_quasistatic(self, on_step=on_step, stop_on_failure=stop_on_failure)

    def destroy(self) -> None:
        self.solver.destroy()

    def min_gap(self) -> float:
        """Smallest signed gap [m] over all nodes and ranks (negative: penetration)."""
        s = self.contact.evaluate()
        return self.comm.allreduce(float(np.min(s.gap, initial=np.inf)), op=MPI.MIN)


def track_elbow_torques(contact, body: Body) -> None:
    """Register the sleeve's two torque monitors about the elbow (+z): "forearm" (the thesis's resisting
    torque) and "both" (both arm segments)."""
    contact.track_torque("forearm", "elbow", ELBOW_AXIS, ["forearm"])
    contact.track_torque("both", "elbow", ELBOW_AXIS, list(body.segments))


def sleeve_shell(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> ShellModel:
    """The sleeve's tube shell: shoulder end (end0) held, optional gravity along -y."""
    # second-order geometry: the Q2 mid-side nodes lie on the circle (on a first-order mesh they sit on the
    # chords, at R cos(pi / n_around): 1.4 mm closer to the arm on mesh I, a third of the 4.3 mm clearance)
    t = config.tube
    fmesh = tube(t.length, t.radius, t.n_around, t.n_along, cell="quadrilateral", order=2,
                 comm=comm)
    # no director re-basing: re-basing moves the discrete equilibrium by O(h^2) between steps (measured on
    # mesh I: a residual of 10% of the contact forces after every step); the rotations stay far from the
    # two-angle singularity (|theta1| = pi/2) during a 57-degree flexion
    model = ShellModel(fmesh, config.fabric, rebase=False, psri_degrees=config.tube.quadrature)
    model.constrain("end0", u=(0.0, 0.0, 0.0), theta=(0.0, 0.0) if config.tube.hold_rotations else None)
    if config.route.gravity:
        model.add_gravity((0.0, -GRAVITY, 0.0))
    return model


def build_sleeve(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
                 petsc_options: dict | None = None) -> SleeveProblem:
    """Mesh, fabric, shoulder support, arm body and contact of a sleeve computation."""
    model = sleeve_shell(config, comm)
    flexion = elbow_flexion(config.arm, angular_velocity=math.radians(config.motion.angular_velocity),
                            final_angle=math.radians(config.motion.final_angle))
    body = default_arm(flexion, config.arm)
    contact = ContactProblem(model, body, method=config.contact.method, penalty=config.contact.penalty,
                             friction=config.contact.friction, time=flexion.t_start,
                             active_set=config.contact.active_set)
    track_elbow_torques(contact, body)
    system = CompositeSystem(model, [contact, Stabilized(contact, 0.0)])
    options = {"snes_max_it": config.route.newton_max_iterations}
    options.update(petsc_options or {})
    solver = NewtonSolver(system, options)
    solver.snes.setLineSearchPreCheck(StepLimiter(model, config.route.max_rotation_step,
                                                  config.route.max_displacement_step))
    if not config.route.gravity:
        # no dead load: F_ref = 0, the absolute tolerance would be 1e-12 N; use the scale of the contact
        # forces instead (1e-10 of E t L, a force unit of the sleeve)
        solver.snes.setTolerances(atol=1e-10 * config.membrane_modulus * config.fabric.thickness * config.tube.length)
    return SleeveProblem(config, model, contact, body, flexion, solver, system)


@dataclass
class SleeveStep:
    angle: float            # deg
    torque: float           # N m, resisting (positive opposes flexion)
    torque_all: float       # N m, resisting torque of the contact forces on both segments about the elbow
    newton_iterations: int
    max_penetration: float  # m
    contact_force: float    # N, |sum of contact forces on the cloth|
    wall: float             # s since the start of the flexion
    drag_ratio: float = 0.0  # fictitious drag / contact force left in an accepted relaxed state (0: exact)
    time_steps: int = 0      # explicit: central-difference steps since the previous record
    kinetic_energy: float = 0.0   # J, explicit: 1/2 v.M v (with the scaled rotary inertia)
    strain_energy: float = 0.0    # J, explicit

    @property
    def coordinate(self) -> float:
        """The record's coordinate (the elbow angle [deg])."""
        return self.angle

    @property
    def output_time(self) -> float:
        """The record's time coordinate in the output files (the elbow angle [deg])."""
        return self.angle

    def line(self) -> str:
        """The record's progress line."""
        return (f"angle {self.angle:6.2f} deg  torque {self.torque:+.4e} N m  {self.work()}  "
                f"penetration {self.max_penetration:.1e} m")

    @property
    def torques(self) -> dict[str, float]:
        """Resisting torques [N m] by monitor name."""
        return {"elbow": self.torque, "elbow_both_segments": self.torque_all}

    def work(self) -> str:
        """The solver work of this record for a progress line: time steps and KE/SE of a time-stepping record,
        Newton iterations of a quasi-static one."""
        if self.time_steps:
            ratio = self.kinetic_energy / self.strain_energy if self.strain_energy else 0.0
            return f"steps {self.time_steps:5d}  KE/SE {ratio:.1e}"
        return f"Newton {self.newton_iterations:3d}"


@dataclass
class SleeveHistory(RunHistory):
    """The records (SleeveStep) of a sleeve flexion."""

    config: SleeveConfig

    @property
    def angles(self) -> np.ndarray:
        return np.array([s.angle for s in self.steps])

    @property
    def torques(self) -> np.ndarray:
        return np.array([s.torque for s in self.steps])

    def torque_at(self, angle: float) -> float:
        """Resisting torque [N m] at `angle` [deg] (linear interpolation of the history)."""
        return float(np.interp(angle, self.angles, self.torques))

    @property
    def header(self) -> tuple[str, ...]:
        return self.HEADER

    @property
    def monitors(self) -> list[str]:
        """The torque monitors of a record (SleeveStep.torques)."""
        return ["elbow", "elbow_both_segments"]

    def torque_curves(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Resisting torque [N m] against the elbow angle [deg], one curve."""
        return {f"mu = {self.config.contact.friction}": (self.angles, self.torques)}

    def summary(self) -> dict:
        """Peak and final resisting torque with their angles."""
        if not self.steps:
            return {"records": 0}
        k = int(np.argmax(np.abs(self.torques)))
        return {"records": len(self.steps), "torque_elbow": {
            "peak_Nm": float(self.torques[k]), "peak_at": float(self.angles[k]),
            "final_Nm": float(self.torques[-1]), "final_at": float(self.angles[-1])}}

    HEADER = ("angle_deg", "torque_Nm", "torque_both_segments_Nm", "newton_iterations", "max_penetration_m",
              "contact_force_N", "wall_s", "drag_ratio", "time_steps", "kinetic_energy_J", "strain_energy_J")

    def rows(self) -> list[list[float]]:
        return [[s.angle, s.torque, s.torque_all, s.newton_iterations, s.max_penetration, s.contact_force, s.wall,
                 s.drag_ratio, s.time_steps, s.kinetic_energy, s.strain_energy] for s in self.steps]

    def work(self) -> str:
        """The solver work of the whole run for a summary line."""
        steps = sum(s.time_steps for s in self.steps)
        newton = sum(s.newton_iterations for s in self.steps)
        if steps and not newton:
            return f"{steps} explicit steps, largest KE/SE {self.kinetic_ratio():.2e}"
        return f"{newton} Newton iterations" + (f" in {steps} time steps" if steps else "")

    def kinetic_ratio(self) -> float:
        """Largest kinetic / strain energy over the records with strain energy (explicit runs; 0 otherwise)."""
        ratios = [s.kinetic_energy / s.strain_energy for s in self.steps if s.strain_energy > 0.0]
        return max(ratios, default=0.0)


def _solve_once(problem: SleeveProblem) -> tuple[bool, int, str]:
    """One Newton solve (augmented: Newton + Uzawa updates) at the current pose and drag coefficient."""
    contact, cfg = problem.contact, problem.config
    if cfg.contact.method == "augmented":
        try:
            report = contact.solve_augmented(problem.solver, tolerance=cfg.contact.augmentation_tolerance)
        except SolverError as exc:
            return False, 0, str(exc)
        return True, sum(report.newton_iterations), "augmented"
    try:
        result = contact.solve(problem.solver)
    except SolverError as exc:
        return False, 0, str(exc)
    return result.converged, result.iterations, result.reason


def _drag_ratio(problem: SleeveProblem) -> float:
    """sum |drag| / sum |contact force| over all nodes (0 when no drag acts)."""
    term, contact = problem.drag, problem.contact
    if term.coefficient == 0.0:
        return 0.0
    comm = problem.comm
    drag = comm.allreduce(float(np.linalg.norm(term.drag(), axis=1).sum()), op=MPI.SUM)
    force = comm.allreduce(float(np.linalg.norm(contact.evaluate().force, axis=1).sum()), op=MPI.SUM)
    return drag / force if force > 0.0 else (0.0 if drag == 0.0 else math.inf)


def _equilibrate(problem: SleeveProblem) -> tuple[bool, int, str, float]:
    """Equilibrium at the current pose, starting from the last converged state.

    A plain Newton solve first; if it fails, stabilised solves (viscous drag, `Stabilized`) in pseudo-time
    at the same pose, each restarting the drag from the last one (dynamic relaxation), until a plain
    Newton solve converges from the relaxed state or the drag falls below drag_tolerance x contact force.
    Returns (converged, Newton iterations, reason, remaining drag ratio).
    """
    cfg, system, drag = problem.config, problem.system, problem.drag
    saved = system.w.x.array.copy()
    saved_multiplier = problem.contact.multiplier.copy()
    drag.coefficient = 0.0
    ok, total, reason = _solve_once(problem)
    if ok or cfg.contact.stabilization == 0.0:
        return ok, total, reason, 0.0
    system.w.x.array[:] = saved
    problem.contact.multiplier = saved_multiplier.copy()
    coefficient = cfg.contact.stabilization * cfg.membrane_modulus * cfg.fabric.thickness / cfg.tube.radius ** 2
    ratio = math.inf
    for _ in range(cfg.contact.relaxation_steps):
        drag.coefficient = coefficient
        ok, its, reason = _solve_once(problem)
        total += its
        if not ok:
            drag.coefficient = 0.0
            return False, total, f"stabilised: {reason}", ratio
        ratio = _drag_ratio(problem)
        drag.commit()
        relaxed = system.w.x.array.copy()
        relaxed_multiplier = problem.contact.multiplier.copy()
        drag.coefficient = 0.0
        ok, its, reason = _solve_once(problem)
        total += its
        if ok:
            return True, total, reason, 0.0
        system.w.x.array[:] = relaxed
        problem.contact.multiplier = relaxed_multiplier
        if ratio < cfg.contact.drag_tolerance:
            # accept the relaxed state: its fictitious drag is below the tolerance (reported)
            drag.coefficient = coefficient
            drag.commit()
            drag.coefficient = 0.0
            return True, total, "relaxed", ratio
    drag.coefficient = 0.0
    reason = f"no equilibrium after {cfg.contact.relaxation_steps} relaxations (drag ratio {ratio:.2e})"
    return False, total, reason, ratio


def _predict(problem: SleeveProblem, angle_from: float, angle_to: float, touching: float = 1e-3):
    """Predictor for the step angle_from -> angle_to [deg]: the nodes on the forearm (nearest segment,
    gap below `touching` [m]) follow its rigid rotation about the elbow, x <- J + R (x - J), so that the
    step starts without the penetration the moving body would otherwise cause."""
    contact = problem.contact
    s = contact.evaluate()
    names = list(problem.body.segments)
    moving = (s.segment == names.index("forearm")) & (s.gap < touching) & contact._free.all(axis=1)
    if not moving.any():
        return
    elbow = problem.body.joint_position("elbow", contact.time)
    rotation = rotation_about(ELBOW_AXIS, math.radians(angle_to - angle_from))
    x_new = elbow + (s.position[moving] - elbow) @ rotation.T
    dofs = contact.nodes.dofs[moving]
    contact.w.x.array[dofs] = x_new - contact.nodes.reference[moving]
    contact.w.x.scatter_forward()


def _record(problem: SleeveProblem, angle: float, iterations: int, t0: float, drag_ratio: float) -> SleeveStep:
    contact = problem.contact
    return SleeveStep(angle=angle, torque=problem.resisting_torque(), torque_all=problem.resisting_torque_all(),
                      newton_iterations=iterations, max_penetration=contact.max_penetration(),
                      contact_force=float(np.linalg.norm(contact.total_force())), wall=time.perf_counter() - t0,
                      drag_ratio=drag_ratio)


def run_quasistatic(problem: SleeveProblem, angles: np.ndarray | None = None,
                    on_step: Callable[[SleeveStep], None] | None = None,
                    stop_on_failure: bool = True, max_wall_time: float | None = None) -> SleeveHistory:
    """Flex the elbow through `angles` [deg] (default: `angle_steps` equal steps to `final_angle`) by
    Newton solves at the posed body; returns the torque history (the first entry is the start pose).

    `on_step(step)` is called after every requested angle (progress, output). Failed steps are halved
    down to `config.motion.min_angle_step`; then SleeveError, or, with stop_on_failure=False, the history up to
    the last converged angle with `history.failure` set (the model stays in that last converged state).
    `max_wall_time` [s]: stop the same way (SleeveError / failure) once the flexion has run that long.
    """
    cfg, contact, system = problem.config, problem.contact, problem.system
    if angles is None:
        angles = np.linspace(0.0, cfg.motion.final_angle, cfg.motion.angle_steps + 1)[1:]
    angles = np.asarray(angles, dtype=float)
    if np.any(np.diff(angles) <= 0.0) or angles[0] <= 0.0 or angles[-1] > cfg.motion.final_angle + 1e-9:
        raise ValueError(f"angles must increase strictly within (0, {cfg.motion.final_angle}] deg, got {angles}")
    t0 = time.perf_counter()
    history = SleeveHistory(cfg, ndofs=problem.model.ndofs)
    contact.set_time(problem.time_at(0.0))
    gap0 = problem.min_gap()
    if gap0 <= 0.0:
        raise ValueError(f"radius: the arm penetrates the undeformed sleeve (min gap {gap0:.3e} m)")
    history.initial_gap = gap0
    # start pose: the load factor 1 switches on the dead load (gravity) if any
    system.set_load_factor(1.0)
    ok, its, reason, ratio = _equilibrate(problem)
    if not ok:
        raise SleeveError(f"sleeve: the start pose did not converge ({reason})")
    system.after_converged_step()
    start = _record(problem, 0.0, its, t0, ratio)
    history.steps.append(start)
    if on_step:
        on_step(start)
    current = 0.0
    for target in angles:
        step = target - current
        iterations, worst_ratio = 0, 0.0
        while current < target - 1e-12:
            if max_wall_time is not None and time.perf_counter() - t0 > max_wall_time:
                message = (f"sleeve: wall-time budget of {max_wall_time:g} s used up at elbow angle {current:.4g} deg "
                           f"(last converged)")
                if stop_on_failure:
                    raise SleeveError(message, last_converged_load_factor=current, reason="WALL_TIME")
                if current > history.steps[-1].angle:
                    history.steps.append(_record(problem, current, iterations, t0, worst_ratio))
                history.failure = message
                history.wall = time.perf_counter() - t0
                return history
            trial = min(current + step, target)
            saved = system.w.x.array.copy()
            saved_multiplier = contact.multiplier.copy()
            if cfg.contact.predictor:
                _predict(problem, current, trial)
            contact.set_time(problem.time_at(trial))
            ok, its, reason, ratio = _equilibrate(problem)
            iterations += its
            if ok:
                system.after_converged_step()
                current = trial
                worst_ratio = max(worst_ratio, ratio)
                continue
            system.w.x.array[:] = saved
            contact.multiplier = saved_multiplier
            contact.set_time(problem.time_at(current))
            step *= 0.5
            if step < cfg.motion.min_angle_step:
                message = (f"sleeve: Newton failed at elbow angle {trial:.4g} deg ({reason}); the angle step fell "
                           f"below min_angle_step = {cfg.motion.min_angle_step} deg; last converged angle "
                           f"{current:.4g} deg")
                if stop_on_failure:
                    raise SleeveError(message, last_converged_load_factor=current, reason=reason)
                if current > history.steps[-1].angle:
                    history.steps.append(_record(problem, current, iterations, t0, worst_ratio))
                history.failure = message
                history.wall = time.perf_counter() - t0
                return history
        record = _record(problem, target, iterations, t0, worst_ratio)
        if not np.isfinite(record.torque):
            raise SleeveError(f"sleeve: the torque is not finite at {target} deg")
        history.steps.append(record)
        if on_step:
            on_step(record)
    history.wall = time.perf_counter() - t0
    return history


# ---------------------------------------------------------------------------------------- explicit route
@dataclass
class ExplicitSleeve(ArmOutputs):
    """The sleeve set up for explicit central differences (`build_explicit`)."""

    config: SleeveConfig
    model: ShellModel
    contact: ExplicitBodyContact
    body: Body
    flexion: ElbowFlexion
    integrator: CentralDifference
    dt: float                  # s, the time step used
    dt_estimate: float         # s, estimated critical step with the rotary scaling (and penalty, if any)
    dt_estimate_unscaled: float  # s, the element formula's critical step without rotary scaling (s = 1)
    steps_per_record: int
    settle_records: int = 0    # record intervals of rest before the flexion starts (t_start = this x record time)

    @property
    def comm(self):
        return self.model.comm

    # the wearer contract (fabricfem.wear.contract.WearRun)
    def describe(self) -> str:
        config = self.config
        return (f"explicit central differences, dt = {self.dt:.3g} s (critical step {self.dt_estimate:.3g} s by "
                f"{config.critical_step} "
                f"with rotary-inertia scale {config.route.rotary_inertia_scale:g}"
                + (f" and mass scale {config.route.mass_scale:g}" if config.route.mass_scale != 1.0 else "")
                + f"; the element formula gives {self.dt_estimate_unscaled:.3g} s "
                f"without it), mass damping {config.damping:g} 1/s, records every {config.motion.output_angle_step:g} deg"
                + (f", dynamic similarity: flexion at {config.flexion_speed:.4g} deg/s (c / c_ref = "
                   f"{config.similarity_factor:.4g})" if config.route.dynamic_similarity else ""))

    def run(self, on_step: Callable[[SleeveStep], None] | None = None,
            stop_on_failure: bool = True) -> SleeveHistory:
        return run_explicit(self, on_step=on_step, stop_on_failure=stop_on_failure)

    def destroy(self) -> None:
        self.integrator.destroy()


def build_explicit(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> ExplicitSleeve:
    """Sleeve, arm and explicit contact for `run_explicit`; the time step is

        dt = safety x 2 / omega_max,   omega_max^2 = omega_shell^2(s) + omega_p^2      [Man2006, eq. 2.86]

    with omega_shell from fabricfem.dynamics.stability for rotary-inertia scale s and omega_p the penalty
    spring's frequency (0 for Lagrange multipliers), reduced for the mass damping, then shortened so that
    every record interval (output_angle_step degrees) holds a whole number of steps."""
    if config.fabric.density <= 0.0:
        raise ValueError("density: the explicit sleeve needs a positive fabric density [kg/m^3]")
    model = sleeve_shell(config, comm)
    model.compile()
    record_time = math.radians(config.motion.output_angle_step) / math.radians(config.flexion_speed)
    # rest before the flexion: settle_time in fabric I's time units under dynamic similarity (x c_ref / c)
    settle_records = (math.ceil(config.motion.settle_time / config.similarity_factor / record_time - 1e-9)
                      if config.route.gravity else 0)
    flexion = elbow_flexion(config.arm, angular_velocity=math.radians(config.flexion_speed),
                            final_angle=math.radians(config.motion.final_angle), t_start=settle_records * record_time)
    body = default_arm(flexion, config.arm)
    contact = ExplicitBodyContact(model, body, friction=config.contact.friction, method=config.contact.method,
                                  penalty=config.contact.penalty)
    track_elbow_torques(contact, body)
    rayleigh = (config.damping, 0.0)
    omega_p = contact.penalty_frequency()
    omega = math.hypot(stability.max_frequency(model, config.route.rotary_inertia_scale, config.critical_step),
                       omega_p)
    omega_1 = math.hypot(stability.max_frequency_estimate(model, 1.0), omega_p)   # for the description only
    mass_scale = config.route.mass_scale
    dt_estimate = stability.critical_time_step(model, rayleigh, omega_max=omega, mass_scale=mass_scale)
    dt_unscaled = stability.critical_time_step(model, rayleigh, omega_max=omega_1)
    steps_per_record = math.ceil(record_time / (config.time_step_safety * dt_estimate))
    dt = record_time / steps_per_record
    integrator = CentralDifference(model, dt, rayleigh=rayleigh, dt_crit=dt_estimate, energy_bound=None,
                                   rotary_inertia_scale=config.route.rotary_inertia_scale, contact=contact,
                                   mass_scale=mass_scale)
    return ExplicitSleeve(config, model, contact, body, flexion, integrator, dt, dt_estimate, dt_unscaled,
                          steps_per_record, settle_records)


def run_explicit(problem: ExplicitSleeve, on_step: Callable[[SleeveStep], None] | None = None,
                 stop_on_failure: bool = True) -> SleeveHistory:
    """Flex the elbow at constant angular velocity by explicit central differences ([Man2006, ch. 5]: the
    sleeve's own mass, explicit Lagrange-multiplier contact, Box 5).

    Damping: mass-proportional C = alpha M (alpha = config.route.mass_damping [1/s]; on the translations a drag
    alpha rho t v per unit area, like air drag) so that the flexion is quasi-static; each record reports the
    kinetic and strain energies (SleeveStep) so that this can be checked. The torque of a record is the
    time average of the contact torque over the record interval (ExplicitBodyContact: the impulse of the
    contact forces over the interval divided by its length). A non-finite state raises SleeveError naming
    the angle (or, with stop_on_failure=False, ends the history there with `failure` set).
    `history.timings` gets the wall-time breakdown of the loop (`step_breakdown`: internal forces, contact,
    pose/torque, output, other; and the process's CPU time per step).
    """
    cfg, contact, integ, flexion = problem.config, problem.contact, problem.integrator, problem.flexion
    t0 = time.perf_counter()
    history = SleeveHistory(cfg, ndofs=problem.model.ndofs)
    integ.initialize(t0=0.0)
    gap0 = contact.min_gap(integ.d.getArray(readonly=True), 0.0)
    if gap0 <= 0.0:
        raise ValueError(f"radius: the arm penetrates the undeformed sleeve (min gap {gap0:.3e} m)")
    history.initial_gap = gap0
    history.timings = {"dt": problem.dt, "dt_estimate": problem.dt_estimate,
                       "dt_estimate_unscaled": problem.dt_estimate_unscaled}
    step_angle = cfg.motion.output_angle_step

    def record(phase: Phase, k: int, steps: int) -> SleeveStep:
        # the nominal angle of the record (the body angle at this time up to the rounding of t = n dt)
        torques = contact.mean_torques()
        d = integ.d.getArray(readonly=True)
        return SleeveStep(angle=phase.coordinate(k), torque=-torques["forearm"], torque_all=-torques["both"],
                          newton_iterations=0, max_penetration=contact.max_penetration(d, integ.t),
                          contact_force=float(np.linalg.norm(contact.total_force())),
                          wall=time.perf_counter() - t0, time_steps=steps,
                          kinetic_energy=integ.kinetic_energy(), strain_energy=integ.strain_energy())

    def settled(phase: Phase) -> None:
        if phase.name == "settle" and phase.records:
            history.timings.update(settle_s=flexion.t_start, settle_kinetic_energy=integ.kinetic_energy(),
                                   settle_strain_energy=integ.strain_energy())

    n_records = round(cfg.motion.final_angle / step_angle)
    if not math.isclose(n_records * step_angle, cfg.motion.final_angle, rel_tol=1e-9):
        n_records = math.ceil(cfg.motion.final_angle / step_angle)
    # rest: the arm holds still (the flexion angle is 0 before t_start) while the sleeve settles on it; the
    # start record's torque is the mean over the last record interval of the rest
    phases = [Phase("settle", problem.settle_records, report="end", coordinate=lambda k: 0.0),
              Phase("flexion", n_records, coordinate=lambda k: min((k + 1) * step_angle, cfg.motion.final_angle))]
    try:
        timings = run_phases(integ, contact, phases, problem.steps_per_record, record, history, on_step,
                             stop_on_failure, on_phase_end=settled, label="sleeve")
    except WearError as exc:
        raise SleeveError(str(exc), last_converged_load_factor=history.steps[-1].angle if history.steps else 0.0,
                          reason="EXPLICIT_BLOW_UP") from exc
    history.timings.update(timings)
    history.wall = time.perf_counter() - t0
    return history
