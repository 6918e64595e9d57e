"""The arm in a sleeve by Newton solves: the quasi-static route (a Newton solve per elbow angle) and what the
implicit route (fabricfem.wear.sleeve_implicit) shares with it [Man2006, sec. 5.3].

The quasi-static route: a sequence of Newton solves at increasing angle alpha_k with the body posed at
t_k = alpha_k / omega, each starting from the previous equilibrium; the friction history (stick points) is
committed after each converged step (`ContactProblem.after_converged_step`). A step whose Newton solve fails is
undone and split in two (down to `min_angle_step`), otherwise `SleeveError` names the angle. It stalls where the
tube buckles (20.25 deg at mu = 0.1, 17 deg at mu = 0.5 on mesh I, 10 x 13) and is kept as the static reference
of the explicit route at small angles and for the moment-balance test. Gravity is off by default on this route.

Newton at one angle uses two devices, neither of which changes the converged solution:
* the active-set strategy of ContactProblem (`active_set`, default on): contact set and slip set are fixed
  during one Newton solve and updated from the converged state until they no longer change, which removes the
  leave / re-enter cycling of the non-smooth contact law;
* a damped Newton step (`StepLimiter`): each update is scaled so that no director angle changes by more than
  `max_rotation_step` and no displacement by more than `max_displacement_step` per iteration.
The viscous drag of `Stabilized` remains the fallback of a failed solve.

Both routes are WearRuns (fabricfem.wear.contract) built from the same garment (`sleeve_shell`), body
(`default_arm` with `elbow_flexion`), skin (the arm's segments joined by the blend of width `blend_width` at the
elbow, fabricfem.body.blended.BlendedEllipsoids, asked through the skin contract by ContactProblem) and torque
monitors (ARM_MONITORS, the nodes' moments shared by the skin's segment weights) as the explicit engine's sleeve
(fabricfem.wear.sleeve.build_explicit); their records are WearSteps with the elbow angle as axis.
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
from fabricfem.body.blended import BLEND_WIDTH
from fabricfem.body.motion import ElbowFlexion, rotation_about
from fabricfem.body.pose import Body
from fabricfem.contact.problem import ContactProblem
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.solvers.system import CompositeSystem
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.sleeve import ARM_MONITORS, ELBOW_AXIS, sleeve_shell, track_elbow_torques


class Stabilized:
    """Viscous regularisation of the quasi-static steps, a ResidualTerm (fabricfem.solvers.system): the residual
    gets a nodal drag

        r_i = c w_i (x_i - x_i^n)      [N]   (backward-Euler viscous force eta v with c = eta / dt)

    on the free displacement components of every node (w_i: lumped area [m^2], x^n: the last converged
    positions, set by `commit`), and the Jacobian c w_i I. Tube buckling makes the elastic tangent indefinite on
    the way to 57 degrees and an unregularised Newton step then fails; the drag keeps the step's tangent positive
    definite and follows the stable branch, at the price of a fictitious force that is reported (`drag_force`,
    compared with the contact force in WearStep.drag_ratio). c = 0 switches it off.
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
    """The wearer contract's outputs shared by the Newton routes of the sleeve (fabricfem.wear.contract.WearRun):
    needs `config`, `contact`, `body` and `flexion`."""

    axis_label = "elbow angle [deg]"
    torques = ARM_MONITORS

    @property
    def name(self) -> str:
        return self.config.name

    def pressure_field(self):
        """Contact pressure on the body [Pa] per unit deformed cloth area, a Q2 Function (explicit route:
        time-averaged over the last record)."""
        return self.contact.pressure_field()

    def posed_bodies(self, angle: float) -> list:
        """The arm's ellipsoids at elbow angle `angle` [deg]."""
        return list(self.body.pose(self.flexion.time_at(math.radians(angle))).values())

    def fraction(self, step) -> float:
        """The done fraction of the run at record `step` (its angle over the final angle)."""
        return step.coordinate / self.config.motion.final_angle

    def body_time(self, step) -> float:
        """The body time [s] of record `step` (the flexion's time at its angle)."""
        return self.flexion.time_at(math.radians(step.coordinate))

    def motion_time(self, t: float) -> float:
        """The motion's own time [s] at body time t [s]: the flexion runs on the body clock."""
        return float(t)


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
        return -self.contact.torque("elbow")

    def resisting_torque_all(self) -> float:
        """-tau [N m] about the elbow of the forces the sleeve exerts on both arm segments (all ranks)."""
        return -self.contact.torque("elbow_both_segments")

    # the wearer contract (fabricfem.wear.contract.WearRun)
    def describe(self) -> str:
        return f"{self.config.motion.angle_steps} quasi-static steps"

    def run(self, on_step: Callable[[WearStep], None] | None = None,
            stop_on_failure: bool = True) -> WearHistory:
        return run_quasistatic(self, on_step=on_step, stop_on_failure=stop_on_failure)

    def destroy(self) -> None:
        self.solver.destroy()

    def min_gap(self) -> float:
        """Smallest signed gap [m] over all nodes and ranks (negative: penetration)."""
        s = self.contact.evaluate()
        return self.comm.allreduce(float(np.min(s.gap, initial=np.inf)), op=MPI.MIN)



def build_sleeve(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
                 petsc_options: dict | None = None, blend_width: float = BLEND_WIDTH) -> SleeveProblem:
    """Mesh, fabric, shoulder support, arm body and contact of a sleeve computation; the contact against the arm's
    blended skin of width `blend_width` [m] (the scene's [body] blend_width, fabricfem.body.blended)."""
    model = sleeve_shell(config, comm)
    flexion = elbow_flexion(config.arm, angular_velocity=math.radians(config.motion.angular_velocity),
                            final_angle=math.radians(config.motion.final_angle))
    body = default_arm(flexion, config.arm)
    contact = ContactProblem(model, body, method=config.contact.method, penalty=config.contact.penalty,
                             friction=config.contact.friction, time=flexion.t_start,
                             active_set=config.contact.active_set, blend_width=blend_width)
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



def solve_once(problem: SleeveProblem) -> tuple[bool, int, str]:
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
    ok, total, reason = solve_once(problem)
    if ok or cfg.contact.stabilization == 0.0:
        return ok, total, reason, 0.0
    system.w.x.array[:] = saved
    problem.contact.multiplier = saved_multiplier.copy()
    coefficient = cfg.contact.stabilization * cfg.membrane_modulus * cfg.fabric.thickness / cfg.tube.radius ** 2
    ratio = math.inf
    for _ in range(cfg.contact.relaxation_steps):
        drag.coefficient = coefficient
        ok, its, reason = solve_once(problem)
        total += its
        if not ok:
            drag.coefficient = 0.0
            return False, total, f"stabilised: {reason}", ratio
        ratio = _drag_ratio(problem)
        drag.commit()
        relaxed = system.w.x.array.copy()
        relaxed_multiplier = problem.contact.multiplier.copy()
        drag.coefficient = 0.0
        ok, its, reason = solve_once(problem)
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
    """Predictor for the step angle_from -> angle_to [deg]: the nodes near the forearm (the skin's forearm weight
    w > 0, gap below `touching` [m]) follow its rigid rotation about the elbow by their weight,
    x <- x + w (J + R (x - J) - x), as the skin's material points move (fabricfem.body.skin.skin_velocity), so
    that the step starts without the penetration the moving body would otherwise cause."""
    contact = problem.contact
    s = contact.evaluate()
    share = s.weights[:, list(problem.body.segments).index("forearm")]
    moving = (share > 0.0) & (s.gap < touching) & ~contact.nodes.constrained.any(axis=1)
    if not moving.any():
        return
    elbow = problem.body.joint_position("elbow", contact.time)
    rotation = rotation_about(ELBOW_AXIS, math.radians(angle_to - angle_from))
    x = s.position[moving]
    x_new = x + share[moving, None] * (elbow + (x - elbow) @ rotation.T - x)
    dofs = contact.nodes.dofs[moving]
    contact.w.x.array[dofs] = x_new - contact.nodes.reference[moving]
    contact.w.x.scatter_forward()


def newton_record(problem: SleeveProblem, angle: float, iterations: int, t0: float, drag_ratio: float = 0.0,
                  torque: float | None = None, penetration: float | None = None, time_steps: int = 0,
                  energies: tuple[float, float] = (0.0, 0.0)) -> WearStep:
    """The WearStep of a Newton route at elbow angle `angle` [deg] (phase "settle" at 0, the start state;
    "motion" after): the elbow torques of ARM_MONITORS (the forearm's `torque` [N m] may be a mean over the record
    interval), the peak and mean contact pressure [Pa] of the contact's pressure field, penetration [m], Newton
    iterations, time steps and (kinetic, strain) energies [J]."""
    contact, comm = problem.contact, problem.comm
    elbow = problem.resisting_torque() if torque is None else torque
    if not math.isfinite(elbow):
        raise SleeveError(f"sleeve: the torque is not finite at {angle} deg")
    pressure = problem.pressure_field().x.array
    peak = comm.allreduce(float(pressure.max(initial=0.0)), op=MPI.MAX)
    on = pressure > 0.0
    sums = comm.allreduce(np.array([float(pressure[on].sum()), float(on.sum())]), op=MPI.SUM)
    return WearStep(phase="motion" if angle > 0.0 else "settle", time=problem.time_at(angle),
                    torques={"elbow": elbow, "elbow_both_segments": problem.resisting_torque_all()},
                    peak_pressure=peak, peak_segment="", peak_position=(math.nan,) * 3,
                    mean_pressure=sums[0] / sums[1] if sums[1] else 0.0,
                    max_penetration=contact.max_penetration() if penetration is None else penetration,
                    contact_force=float(np.linalg.norm(contact.total_force())), seam_gap=0.0, seam_forces={},
                    max_strain=0.0, time_steps=time_steps, kinetic_energy=energies[0], strain_energy=energies[1],
                    wall=time.perf_counter() - t0, axis_value=angle, newton_iterations=iterations,
                    drag_ratio=drag_ratio)


def _give_up(problem: SleeveProblem, history: WearHistory, message: str, reason: str, current: float,
             iterations: int, t0: float, ratio: float, stop_on_failure: bool) -> WearHistory:
    """End the flexion at the last converged angle `current` [deg]: SleeveError, or (stop_on_failure=False) the
    history with a record there and `failure` set."""
    if stop_on_failure:
        raise SleeveError(message, last_converged_load_factor=current, reason=reason)
    if current > history.steps[-1].coordinate:
        history.steps.append(newton_record(problem, current, iterations, t0, ratio))
    history.failure = message
    history.wall = time.perf_counter() - t0
    return history


def run_quasistatic(problem: SleeveProblem, angles: np.ndarray | None = None,
                    on_step: Callable[[WearStep], None] | None = None,
                    stop_on_failure: bool = True, max_wall_time: float | None = None) -> WearHistory:
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
    history = WearHistory(cfg.name, ndofs=problem.model.ndofs)
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
    start = newton_record(problem, 0.0, its, t0, ratio)
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
                return _give_up(problem, history, message, "WALL_TIME", current, iterations, t0, worst_ratio,
                                stop_on_failure)
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
                return _give_up(problem, history, message, reason, current, iterations, t0, worst_ratio,
                                stop_on_failure)
        record = newton_record(problem, target, iterations, t0, worst_ratio)
        history.steps.append(record)
        if on_step:
            on_step(record)
    history.wall = time.perf_counter() - t0
    return history


