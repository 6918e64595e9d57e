"""Implicit route of the arm-in-sleeve flexion (SleeveConfig.solver = "implicit"): backward Euler + Newton.

The same equations as the explicit route (fabricfem.wear.sleeve.build_explicit / run_explicit): the sleeve's lumped
translational mass M (HRZ lumping, [Man2006, eq. 2.82], fabricfem.dynamics.mass.lumped_mass), mass damping C = alpha M
(alpha = SleeveConfig.damping [1/s]), gravity g along -y (on by default), the arm resting for `settle_time`
while the sleeve settles on it, then the elbow flexion at `flexion_speed` [deg/s] to `final_angle`. Units: SI.

Time stepping: backward Euler with steps dt = (angle step) / omega (angle step = final_angle / angle_steps),

    M (x - x^n - dt v^n) / dt^2 + alpha M (x - x^n) / dt + R_shell(x) - f_contact(x) = 0,   v = (x - x^n) / dt,

i.e. M a + C v + f_int = F_gravity + f_contact at t^{n+1} ([Man2006, eq. 2.84] with the accelerations and velocities
of backward Euler): the term fabricfem.dynamics.backward_euler.BackwardEulerInertia (shared with the tablecloth drop
of fabricfem.verify.drape), M ((x - x^n) (1 / dt^2 + alpha / dt) - v^n / dt) with tangent (1 / dt^2 + alpha / dt) M
on the free displacement rows, in `CompositeSystem(model, [contact, inertia])`. The director rotations carry no
inertia here (the explicit route's rotary inertia, scaled x100, is t^2 s / 12 = 8e-6 of the translational).

Why backward Euler (not the trapezoidal Newmark rule): the flexion is meant to be quasi-static (damping time
1 / alpha = 0.1 s, flexion 1.27 s), so second-order accuracy of the inertia is not needed, whereas the
buckling wrinkles of the tube and the contact switches excite modes far above 1 / dt that the trapezoidal rule
keeps undamped (they would ring in the contact forces, the bounce this study measures); backward Euler is
L-stable and damps them (amplification -> 0 as omega dt -> inf). Its numerical dissipation acts on the
resolved motion as an extra damping of order omega^2 dt / 2 (at the flexion frequency omega = 0.79 rad/s and
dt = 5.6 ms: 2e-3 1/s, against alpha = 10 1/s). The inertia term regularises the step's tangent: the bending
stiffness scale D / R^4 ~ 8 N/m^3 (D = E t^3 / 12 = 1e-4 N m, R = 0.06 m) is small beside rho t / dt^2
(1.4e4 N/m^3 at dt = 5.6 ms) and alpha rho t / dt (780 N/m^3), so a step stays positive definite where the
static tube buckles (the quasi-static route stalled at 16-20 degrees).

Each step: predictor x = x^n + dt v^n, the body posed at t^{n+1}, Newton (ContactProblem.solve with the
active-set strategy on the contact set only, `ReturnMapContact`, nodes on the contact switch within
TIE_FRACTION x augmentation_tolerance keeping their status, the arm's skin as the obstacle: the explicit engine's,
the two segments joined by the blend of width `blend_width` at the elbow (fabricfem.body.blended); StepLimiter;
backtracking line search; a plain
semi-smooth Newton solve as fallback, `_solve_step`) and, for method "augmented", Uzawa updates of eq. 3.69 until
the largest penetration is below `augmentation_tolerance` (ContactProblem.solve_augmented); the multipliers
carry over to the next step. Coulomb friction: the stick points are committed after every converged step
(ContactProblem.after_converged_step). A failed step is undone and halved down to `min_angle_step` / omega,
then SleeveError names the time and the elbow angle.

Records (WearHistory of WearSteps, as the explicit route): every `output_angle_step` degrees; the torque of a record is the
dt-weighted mean of the per-step resisting torques over the record interval (the explicit route averages over
the interval too); the start record (angle 0) is the mean over the last record interval of the rest. The
per-step values are kept in `ImplicitSleeve.trace` (`trace_array`: t [s], angle [deg], torque [N m],
penetration [m], Newton iterations, dt [s]).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fabricfem.body.arm import default_arm, elbow_flexion
from fabricfem.body.blended import BLEND_WIDTH
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics.backward_euler import BackwardEulerInertia
from fabricfem.dynamics.mass import lumped_mass
from fabricfem.materials import positive_number
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.solvers.system import CompositeSystem
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.quasistatic import SleeveError, SleeveProblem, StepLimiter, newton_record, solve_once
from fabricfem.wear.sleeve import sleeve_shell, track_elbow_torques

# active-set ties (ContactProblem.tie_tolerance) = this x augmentation_tolerance: a node on the contact switch keeps
# its status within a gap of 1e-6 m (default tolerance 1e-5 m), an order below what the Uzawa loop accepts
TIE_FRACTION = 0.1
ACTIVE_SET_MAX_ITERATIONS = 30   # Newton iterations of one active-set solve before the plain fallback (_solve_step)
TRACE_COLUMNS = ("t_s", "angle_deg", "torque_Nm", "max_penetration_m", "newton_iterations", "dt_s")


class ReturnMapContact(ContactProblem):
    """ContactProblem whose active-set strategy freezes the contact set during a Newton solve but not the slip
    set: friction takes the return map (eqs. 3.51-3.52) at every iterate.

    Why: on a frozen slip branch the traction mu p t* / |t*| is discontinuous at x = a, and a node at the Coulomb
    limit whose slip |x - a| is of the order of mu p / eps_T (~1e-6 m, below one Newton update) flips its
    direction from one iterate to the next: measured on mesh I while the sleeve settles, Newton stalled at the
    residual 2 mu p w of that one node, on the slip and the all-stick sequences alike, and the steps had to be
    halved below min_angle_step (smaller steps make the slips per step smaller, hence worse). The return map is
    continuous in x (the stick and slip branches meet on the cone), so that node converges. The converged state
    satisfies the same unilateral law and return map (ContactProblem docstring): the solution is unchanged.
    """

    def evaluate(self, state_array: np.ndarray | None = None):
        sliding, self.sliding = self.sliding, None      # return map at this state, whatever the frozen slip set
        try:
            return super().evaluate(state_array)
        finally:
            self.sliding = sliding

    def contact_set(self) -> tuple[np.ndarray, np.ndarray]:
        """(contact, sliding) as ContactProblem's, with no slip set (`sliding` all False: never frozen, so slip
        changes do not count as set changes)."""
        active, sliding = super().contact_set()
        return active, np.zeros_like(sliding)


@dataclass
class ImplicitSleeve(SleeveProblem):
    """The sleeve set up for backward Euler (`build_implicit`); system is the shell + [contact, inertia]."""

    dt: float = 0.0               # s, nominal step = angle step / omega
    settle_steps: int = 0         # steps of rest before the flexion (t_start = settle_steps x dt)
    record_time: float = 0.0      # s, duration of a record interval (output_angle_step / omega)
    trace: list = field(default_factory=list)   # per accepted step: TRACE_COLUMNS
    energy_form: object = None

    @property
    def inertia(self) -> BackwardEulerInertia:
        """The backward-Euler inertia term of `system`."""
        return self.system.terms[-1]

    def trace_array(self) -> np.ndarray:
        """(steps, 6) array of the per-step TRACE_COLUMNS (rest steps have angle 0)."""
        return np.array(self.trace, dtype=float).reshape(-1, len(TRACE_COLUMNS))

    def strain_energy(self) -> float:
        """Strain energy [J] of the current state (all ranks)."""
        return float(self.comm.allreduce(fem.assemble_scalar(self.energy_form), op=MPI.SUM))

    def describe(self) -> str:
        return (f"backward Euler, dt = {self.dt:.3g} s, {self.settle_steps} settling steps, records every "
                f"{self.config.motion.output_angle_step:g} deg")

    def run(self, on_step: Callable[[WearStep], None] | None = None,
            stop_on_failure: bool = True) -> WearHistory:
        return run_implicit(self, on_step=on_step, stop_on_failure=stop_on_failure)


def build_implicit(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
                   petsc_options: dict | None = None, blend_width: float = BLEND_WIDTH) -> ImplicitSleeve:
    """Sleeve, arm, contact, lumped masses and Newton solver of the backward-Euler route (module docstring); the
    contact against the arm's blended skin of width `blend_width` [m] (the scene's [body] blend_width).

    Raises ValueError naming the parameter: solver not "implicit", density not positive, final_angle /
    angle_steps / angular_velocity giving a non-positive step."""
    if config.route.solver != "implicit":
        raise ValueError(f"solver: build_implicit needs solver='implicit', got {config.route.solver!r}")
    if config.fabric.density <= 0.0:
        raise ValueError("density: the implicit sleeve needs a positive fabric density [kg/m^3] (its inertia)")
    omega = math.radians(config.flexion_speed)                 # rad/s
    angle_step = config.motion.final_angle / config.motion.angle_steps       # deg
    dt = positive_number("dt (angle step / angular_velocity)", math.radians(angle_step) / omega)
    record_time = math.radians(config.motion.output_angle_step) / omega
    # rest before the flexion: settle_time (in fabric I's time units under dynamic similarity), whole steps
    settle_steps = (math.ceil(config.motion.settle_time / config.similarity_factor / dt - 1e-9)
                    if config.route.gravity else 0)
    model = sleeve_shell(config, comm)
    flexion = elbow_flexion(config.arm, angular_velocity=omega, final_angle=math.radians(config.motion.final_angle),
                            t_start=settle_steps * dt)
    body = default_arm(flexion, config.arm)
    contact = ReturnMapContact(model, body, method=config.contact.method, penalty=config.contact.penalty,
                               friction=config.contact.friction,
                               time=0.0, active_set=config.contact.active_set,
                               tie_tolerance=TIE_FRACTION * config.contact.augmentation_tolerance,
                               blend_width=blend_width)
    track_elbow_torques(contact, body)
    model.compile()
    inertia = BackwardEulerInertia(model, lumped_mass(model, rotational=False), config.damping, dt)
    system = CompositeSystem(model, [contact, inertia])
    # backtracking line search on the residual norm: without it Newton 2-cycled (residual alternating between
    # 1.2e-2 and 1.4e-2 N for 60 iterations) on nodes switching between stick and slip while the sleeve settles on
    # the arm (mesh I, 4 steps per degree), and the steps were halved below min_angle_step; with it the settling
    # and the flexion converge (measured: 459 Newton iterations for the 72 steps of the rest on mesh I)
    options = {"snes_max_it": config.route.newton_max_iterations, "snes_linesearch_type": "bt"}
    if not config.route.gravity:
        # no dead load: F_ref = 0; absolute tolerance on the scale of the contact forces as build_sleeve does
        options["snes_atol"] = 1e-10 * config.membrane_modulus * config.fabric.thickness * config.tube.length
    options.update(petsc_options or {})
    solver = NewtonSolver(system, options)
    solver.snes.setLineSearchPreCheck(StepLimiter(model, config.route.max_rotation_step,
                                                  config.route.max_displacement_step))
    return ImplicitSleeve(config, model, contact, body, flexion, solver, system, dt=dt, settle_steps=settle_steps,
                          record_time=record_time, energy_form=fem.form(model.energy))


def _solve_step(problem: ImplicitSleeve) -> tuple[bool, int, str]:
    """One step's equilibrium: Newton with the active-set strategy of ReturnMapContact (frozen contact set) and, if
    that fails (sets that keep changing, or a stalled solve, cut at ACTIVE_SET_MAX_ITERATIONS), once more from the
    same start with the plain semi-smooth Newton on the unilateral law and return map (the contact set may then
    change between iterates). Both solve the same equations; (converged, its, reason)."""
    contact, snes = problem.contact, problem.solver.snes
    if not contact.active_set:
        return solve_once(problem)
    start, multiplier = problem.system.w.x.array.copy(), contact.multiplier.copy()
    # the converged active-set solves of the settling sleeve took <= 22 iterations (mesh I); a stalled one is
    # cut at ACTIVE_SET_MAX_ITERATIONS instead of newton_max_iterations (a stall costs that per sequence)
    snes.setTolerances(max_it=min(ACTIVE_SET_MAX_ITERATIONS, problem.config.route.newton_max_iterations))
    try:
        ok, its, reason = solve_once(problem)
    finally:
        snes.setTolerances(max_it=problem.config.route.newton_max_iterations)
    if ok:
        return ok, its, reason
    # restart from the step's start (measured on mesh I: continuing from the stalled iterate took more
    # iterations in all, 871 against 657 for the settling)
    problem.system.w.x.array[:] = start
    contact.multiplier = multiplier
    contact.active_set = False
    try:
        ok, more, plain = solve_once(problem)
    finally:
        contact.active_set = True
    return ok, its + more, f"active set: {reason}; plain Newton: {plain}"


class _March:
    """The backward-Euler march of `run_implicit`: steps (halved on failure down to min_angle_step / omega), the
    body time `t` [s] reached, and the records (the torque averaged over the steps of a record interval)."""

    def __init__(self, problem: ImplicitSleeve, t0: float, max_wall_time: float | None):
        self.problem, self.t0, self.max_wall_time = problem, t0, max_wall_time
        cfg = problem.config
        self.min_dt = math.radians(cfg.motion.min_angle_step) / math.radians(cfg.flexion_speed)
        self.t = 0.0

    def angle_at(self, t: float) -> float:
        return math.degrees(self.problem.flexion.angle(t))

    def step_once(self, h: float) -> tuple[bool, int, str]:
        """One backward-Euler step of `h` [s]; undone when Newton fails. (converged, iterations, reason)"""
        problem = self.problem
        system, contact = problem.system, problem.contact
        saved = system.w.x.array.copy()
        saved_multiplier = contact.multiplier.copy()
        problem.inertia.set_time_step(h)
        problem.inertia.predict()
        contact.set_time(self.t + h)
        ok, its, reason = _solve_step(problem)
        if ok:
            self.t += h
            system.after_converged_step()    # friction stick points, then v^{n+1}, x^n
            problem.trace.append((self.t, self.angle_at(self.t), problem.resisting_torque(),
                                  contact.max_penetration(), its, h))
            return True, its, reason
        system.w.x.array[:] = saved
        contact.multiplier = saved_multiplier
        contact.set_time(self.t)
        return False, its, reason

    def advance_to(self, target: float) -> int:
        """Steps of dt (halved on failure, down to min_dt) until t = target [s]; returns the Newton iterations."""
        problem, total = self.problem, 0
        h = problem.dt
        while self.t < target - 1e-12 * max(1.0, target):
            if self.max_wall_time is not None and time.perf_counter() - self.t0 > self.max_wall_time:
                raise SleeveError(f"sleeve: wall-time budget of {self.max_wall_time:g} s used up at t = {self.t:.4g} "
                                  f"s, elbow angle {self.angle_at(self.t):.4g} deg (last converged)",
                                  last_converged_load_factor=self.angle_at(self.t), reason="WALL_TIME")
            trial = min(h, target - self.t)
            ok, its, reason = self.step_once(trial)
            total += its
            if ok:
                h = min(problem.dt, 2.0 * h)    # back towards the nominal step after a halving
                continue
            h = 0.5 * trial
            if h < self.min_dt * (1.0 - 1e-9):
                raise SleeveError(f"sleeve: backward-Euler step failed at t = {self.t + trial:.4g} s, elbow angle "
                                  f"{self.angle_at(self.t + trial):.4g} deg ({reason}); the step fell below "
                                  f"min_angle_step = {problem.config.motion.min_angle_step} deg; last converged "
                                  f"angle {self.angle_at(self.t):.4g} deg",
                                  last_converged_load_factor=self.angle_at(self.t), reason="STEP_TOO_SMALL")
        return total

    def record(self, angle: float, iterations: int, since: float) -> WearStep:
        """The record at `angle` [deg]: torque and penetration over the steps after body time `since` [s]."""
        problem = self.problem
        trace = problem.trace_array()
        window = trace[trace[:, 0] > since + 1e-12] if len(trace) else trace
        if len(window):
            torque = float(np.sum(window[:, 2] * window[:, 5]) / np.sum(window[:, 5]))
            penetration = float(window[:, 3].max())
        else:
            torque, penetration = problem.resisting_torque(), problem.contact.max_penetration()
        return newton_record(problem, angle, iterations, self.t0, torque=torque, penetration=penetration,
                             time_steps=len(window),
                             energies=(problem.inertia.kinetic_energy(), problem.strain_energy()))


def run_implicit(problem: ImplicitSleeve, on_step: Callable[[WearStep], None] | None = None,
                 stop_on_failure: bool = True, max_wall_time: float | None = None) -> WearHistory:
    """Rest (settle_steps steps) and flexion to final_angle by backward-Euler steps (module docstring); returns
    the torque history with a record every output_angle_step degrees (the first: angle 0, the settled sleeve).

    A failed step is halved down to min_angle_step / omega; then SleeveError naming the time and angle, or,
    with stop_on_failure=False, the history up to the last record with `history.failure` set. `max_wall_time`
    [s] stops the same way. `history.timings` gets cpu_s (time.process_time of the run) and steps."""
    cfg, flexion = problem.config, problem.flexion
    t0, cpu0 = time.perf_counter(), time.process_time()
    history = WearHistory(cfg.name, ndofs=problem.model.ndofs)
    problem.contact.set_time(0.0)
    gap0 = problem.min_gap()
    if gap0 <= 0.0:
        raise ValueError(f"radius: the arm penetrates the undeformed sleeve (min gap {gap0:.3e} m)")
    history.initial_gap = gap0
    problem.system.set_load_factor(1.0)             # gravity (the dead load) on
    march = _March(problem, t0, max_wall_time)
    step_angle = cfg.motion.output_angle_step
    n_records = round(cfg.motion.final_angle / step_angle)
    if not math.isclose(n_records * step_angle, cfg.motion.final_angle, rel_tol=1e-9):
        n_records = math.ceil(cfg.motion.final_angle / step_angle)
    try:
        its = march.advance_to(flexion.t_start)
        if problem.settle_steps:
            history.timings.update(settle_s=flexion.t_start, settle_kinetic_energy=problem.inertia.kinetic_energy())
        records = [(0.0, flexion.t_start, flexion.t_start - problem.record_time)]
        records += [(a, problem.time_at(a), None) for a in
                    (min((k + 1) * step_angle, cfg.motion.final_angle) for k in range(n_records))]
        for angle, until, since in records:
            since = march.t if since is None else since
            its = march.advance_to(until) if angle > 0.0 else its
            history.steps.append(march.record(angle, its, since))
            if on_step:
                on_step(history.steps[-1])
    except SleeveError as exc:
        if stop_on_failure:
            raise
        history.failure = str(exc)
        if not history.steps:
            history.steps.append(march.record(0.0, 0, -math.inf))
    history.timings.update(dt=problem.dt, steps=len(problem.trace), cpu_s=time.process_time() - cpu0)
    history.wall = time.perf_counter() - t0
    return history
