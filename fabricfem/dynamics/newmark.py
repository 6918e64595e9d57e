"""Implicit Newmark time integration of the shell ([Man2006, sec. 2.3.1.6], eqs. 2.75-2.85, Box 2).

Each step solves the effective residual in the end-of-step displacement d = d^{n+1} with SNES Newton:

    G(d) = f_int(d) - lambda(t_{n+1}) F_ref + M a(d) + C v(d) = 0                         (eq. 2.84)
    a(d) = (d - d~) / (beta dt^2),  d~ = d^n + dt v^n + (1/2 - beta) dt^2 a^n            (eq. 2.76)
    v(d) = v~ + gamma dt a(d),      v~ = v^n + (1 - gamma) dt a^n                         (eq. 2.76)

with tangent K(d) + M / (beta dt^2) + gamma C / (beta dt) (eq. 2.85 written for d instead of a: the same
Newton iterates, scaled). The thesis calls gamma "alpha". M is constant (linearised director, see
fabricfem.dynamics.mass), C = a M + b K_M(d^n) + C_air is frozen during a step (eq. 2.85).
Trapezoidal rule: beta = 1/4, gamma = 1/2 (no numerical dissipation; energy-conserving for linear problems).

Rotations: the director base is NOT re-based during a dynamic run (model.rebase is set False): the angle
velocities/accelerations are then always measured about the same frame. This limits a run to angles below
pi/2 about the initial director base (the two-angle singularity).

Step halving (`StepHalving`, shared with fabricfem.dynamics.ts): when the Newton solve of a step fails, the
state is restored and the step halved and retried down to min_dt (default dt/64), then doubled again after
`grow_after` converged sub-steps (never above dt); outputs stay at multiples of dt. Below min_dt the run stops
with DynamicsError (time, dt, Newton reason) and the last converged state in the integrator and model.w.

The common run loop (energy bookkeeping, blow-up check, outputs, progress) lives in `TimeIntegrator`,
which the explicit central-difference scheme (Newmark with beta = 0) shares.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fabricfem.dynamics.mass import InertiaDamping
from fabricfem.io import SurfaceSeries, write_csv
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.solvers.system import add_term_jacobians, base_model, owned_dirichlet_rows

LoadFactor = Callable[[float], float] | float


class DynamicsError(RuntimeError):
    """A time integration that diverged or blew up; names the step and the time.

    Attributes: step (user step number), time [s] of the failure; for a failed Newton solve also dt [s] (the
    smallest step tried), reason (SNES converged reason) and last_converged_time [s] (the state the integrator
    and model.w were restored to).
    """

    def __init__(self, message: str, step: int, time: float, dt: float | None = None, reason: str | None = None,
                 last_converged_time: float | None = None):
        super().__init__(message)
        self.step = step
        self.time = time
        self.dt = dt
        self.reason = reason
        self.last_converged_time = last_converged_time


@dataclass
class History:
    """Monitored quantities per output step (time [s], energies [J], user monitors)."""
    time: list[float] = field(default_factory=list)
    kinetic: list[float] = field(default_factory=list)
    strain: list[float] = field(default_factory=list)
    external_work: list[float] = field(default_factory=list)
    dissipated: list[float] = field(default_factory=list)
    monitors: dict[str, list[float]] = field(default_factory=dict)
    newton_iterations: list[int] = field(default_factory=list)
    stopped: str = ""       # why `TimeIntegrator.run` ended before n_steps (an interrupt), "" otherwise

    @property
    def total(self) -> np.ndarray:
        """Kinetic + strain energy - external work [J] (constant without damping)."""
        return np.asarray(self.kinetic) + np.asarray(self.strain) - np.asarray(self.external_work)

    def columns(self) -> tuple[list[str], list[list[float]]]:
        header = ["time", "kinetic", "strain", "external_work", "dissipated", "total", *self.monitors]
        data = [self.time, self.kinetic, self.strain, self.external_work, self.dissipated, list(self.total),
                *self.monitors.values()]
        return header, [list(row) for row in zip(*data)]


def node_monitor(model, point: Sequence[float], field: str = "u", component: int = 2) -> Callable[[], float]:
    """Callable giving one component of u [m] or theta [rad] at a mesh node, on all ranks (dof looked up once)."""
    dof = model.owned_node_dof(point, field, component)

    def value() -> float:
        local = float(model.w.x.array[dof]) if dof is not None else 0.0
        return model.comm.allreduce(local)
    return value


def progress_printer(comm, every: int | None = None, stream=None) -> Callable[[int, int, float, float], None]:
    """Progress callback (step, n_steps, t, elapsed_s) printing step, time and the estimated time left on rank 0."""
    def report(step: int, n_steps: int, t: float, elapsed: float):
        interval = every or max(1, n_steps // 10)
        if comm.rank != 0 or (step % interval and step != n_steps):
            return
        left = elapsed / step * (n_steps - step) if step else float("nan")
        print(f"step {step}/{n_steps}  t = {t:.6g} s  elapsed {elapsed:.1f} s  left ~{left:.1f} s",
              file=stream or sys.stdout, flush=True)
    return report


def _owned(vec: PETSc.Vec) -> np.ndarray:
    """A copy of this rank's owned entries of `vec`."""
    return vec.getArray(readonly=True).copy()


def _as_load_function(load_factor: LoadFactor) -> Callable[[float], float]:
    if callable(load_factor):
        return load_factor
    value = float(load_factor)
    if not math.isfinite(value):
        raise ValueError(f"load_factor must be finite, got {load_factor!r}")
    return lambda t: value


class TimeIntegrator:
    """State (d, v, a), energy bookkeeping, blow-up check and outputs shared by the time integrators.

    Args:
        model: ShellModel (density > 0), or a CompositeSystem of one and ResidualTerms (e.g. contact with rigid
            obstacles, fabricfem.solvers.system): the terms' forces enter internal_force and the residual, their
            tangents the Jacobian. The shell's director re-basing is switched off.
        dt: time step [s] > 0.
        load_factor: lambda(t) scaling F_ref and prescribed displacements (callable of t [s], or a constant).
        rayleigh, air_drag, lumped: see fabricfem.dynamics.mass.InertiaDamping.
        energy_bound: a run stops (DynamicsError) when kinetic + strain energy exceeds energy_bound times
            (initial kinetic + strain energy + largest |external work| so far): a passive system cannot
            (the balance gives at most 1 times that). None disables the check (non-finite states are always
            caught). "auto" (default) is 10, or None when non-zero displacements are prescribed (the
            reactions' work is not counted).
    """

    def __init__(self, model, dt: float, load_factor: LoadFactor = 1.0, rayleigh: tuple[float, float] = (0.0, 0.0),
                 air_drag: float = 0.0, lumped: bool = False, energy_bound: float | str | None = "auto"):
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite time step [s], got {dt!r}")
        prescribed = bool(getattr(model, "_scaled_bcs", []))
        if energy_bound == "auto":
            energy_bound = None if prescribed else 10.0
        if energy_bound is not None and not (isinstance(energy_bound, (int, float)) and energy_bound > 1.0):
            raise ValueError(f"energy_bound must exceed 1 (or be None), got {energy_bound!r}")
        self.system = model  # the NonlinearSystem the forces come from: a ShellModel or a CompositeSystem of one
        self.model = model = base_model(model)  # the shell: forms, state w, mass
        model.compile()
        model.rebase = False  # see module docstring: the angles' rates need a fixed base
        self.dt = float(dt)
        self.load = _as_load_function(load_factor)
        self.ops = InertiaDamping(model, lumped=lumped, rayleigh=rayleigh, air_drag=air_drag)
        self.energy_bound = energy_bound
        self.d = model.create_vector()
        self.v = model.create_vector()
        self.a = model.create_vector()
        self._work = model.create_vector()
        self._cv = model.create_vector()
        model.w.vector.copy(self.d)
        for vec in (self.v, self.a, self._cv):
            vec.set(0.0)
        self.bc_rows = owned_dirichlet_rows(model)
        self._energy_form = fem.form(model.energy)
        self.t = 0.0
        self.t0 = 0.0
        self.step_count = 0
        self.run_step = 0  # user steps of the current `run` done
        self.external_work = 0.0
        self.dissipated = 0.0
        self._initialized = False
        self.accounts_substeps = False  # True: step() books work and dissipation per sub-step itself

    # ------------------------------------------------------------- helpers
    def zero_bc_rows(self, vec: PETSc.Vec):
        vec.getArray()[self.bc_rows] = 0.0

    def _sync_model(self):
        self.d.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def strain_energy(self) -> float:
        """Strain energy of the model's current state [J] (model.energy assembled, summed over ranks)."""
        return float(self.model.comm.allreduce(fem.assemble_scalar(self._energy_form)))

    def kinetic_energy(self) -> float:
        return self.ops.kinetic_energy(self.v)

    def _solve_initial_acceleration(self, rhs: PETSc.Vec):
        """a = M^-1 rhs on the free rows (0 on Dirichlet rows)."""
        self.zero_bc_rows(rhs)
        if self.ops.lumped:
            self.a.pointwiseDivide(rhs, self.ops.mass_diag)
        else:
            M = fem_petsc.assemble_matrix(fem.form(self.ops.mass_ufl), bcs=self.model.bcs)
            M.assemble()
            ksp = PETSc.KSP().create(self.model.comm)
            ksp.setOperators(M)
            ksp.setType("preonly")
            ksp.getPC().setType("lu")
            ksp.getPC().setFactorSolverType("mumps")
            ksp.solve(rhs, self.a)
            ksp.destroy()
            M.destroy()
        self.zero_bc_rows(self.a)

    def initialize(self, displacement: PETSc.Vec | None = None, velocity: PETSc.Vec | None = None, t0: float = 0.0):
        """Set d^0 (default: the model's state), v^0 (default 0) and compute a^0 from eq. 2.84 at t0."""
        if displacement is not None:
            displacement.copy(self.d)
        else:
            self.model.w.vector.copy(self.d)
        if velocity is not None:
            velocity.copy(self.v)
        else:
            self.v.set(0.0)
        self.t = float(t0)
        self.t0 = self.t
        self.step_count = 0
        self.external_work = self.dissipated = 0.0
        self.model.set_load_factor(self.load(self.t))
        self._sync_model()
        self.ops.freeze(self.d)
        rhs = self._work
        self.system.internal_force(self.d, rhs)  # f_int(d^0) (+ the terms' forces)
        rhs.scale(-1.0)
        rhs.axpy(float(self.model.load_factor.value), self.model.F_ref)
        self.ops.damping_action(self.v, self._cv)
        rhs.axpy(-1.0, self._cv)
        self._solve_initial_acceleration(rhs)
        self._initialized = True

    # --------------------------------------------------------------- loop
    def step(self) -> int:
        """Advance one time step; returns the number of Newton iterations (0 for explicit)."""
        raise NotImplementedError

    def _account(self, d_old: PETSc.Vec, lam_old: float, cv_old: PETSc.Vec):
        """External work and damping dissipation over the step by the trapezoidal rule."""
        lam_new = float(self.model.load_factor.value)
        dd = self._work
        self.d.copy(dd)
        dd.axpy(-1.0, d_old)
        self.external_work += 0.5 * (lam_old + lam_new) * self.model.F_ref.dot(dd)
        self.ops.damping_action(self.v, self._cv)
        if self.ops.has_damping:
            cv_mean = cv_old.copy()
            cv_mean.axpy(1.0, self._cv)
            self.dissipated += 0.5 * cv_mean.dot(dd)
            cv_mean.destroy()

    def run(self, n_steps: int, monitors: dict[str, Callable[[], float]] | None = None,
            xdmf: str | Path | SurfaceSeries | None = None, csv: str | Path | None = None, output_every: int = 1,
            progress: bool | Callable[[int, int, float, float], None] = False, history: History | None = None,
            after_record: Callable[[History], None] | None = None,
            should_stop: Callable[[], str] | None = None) -> History:
        """Integrate n_steps steps; record energies and monitors every `output_every` steps (and at 0).

        xdmf: write the displacement time series (fabricfem.io.SurfaceSeries, or an open one, left open);
        csv: write the History table (fabricfem.io.write_csv); progress: True for progress_printer on rank 0, or a
        callable. Raises DynamicsError (naming step and time) when the solve fails or the state blows up.

        Checkpoints: `history` continues a run whose records so far it holds, from the state of its last record
        restored by `restore` (a checkpoint's `state()`): step 0 is not recorded again and the steps continue
        after the restored user step. `after_record(history)` is called after every record (a checkpoint);
        `should_stop()` then too: a non-empty reason (an interrupt) ends the run there, in `history.stopped`.
        """
        if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
            raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
        if not (isinstance(output_every, (int, np.integer)) and output_every >= 1):
            raise ValueError(f"output_every must be a positive integer, got {output_every!r}")
        resumed = history is not None
        if not (resumed or self._initialized):
            self.initialize(t0=self.t)
        monitors = dict(monitors or {})
        report = progress_printer(self.model.comm) if progress is True else (progress or None)
        if not resumed:
            history = History(monitors={name: [] for name in monitors})
        history.stopped = ""
        series = None
        if isinstance(xdmf, SurfaceSeries):
            series = xdmf
        elif xdmf is not None:
            series = SurfaceSeries(xdmf, self.model.mesh)
        if not resumed:
            self.energy0 = self.kinetic_energy() + self.strain_energy()
            self.max_work = 0.0
            self.run_step = 0

        def record(iterations: int):
            history.time.append(self.t)
            history.kinetic.append(self.kinetic_energy())
            history.strain.append(self.strain_energy())
            history.external_work.append(self.external_work)
            history.dissipated.append(self.dissipated)
            history.newton_iterations.append(iterations)
            for name, fn in monitors.items():
                history.monitors[name].append(float(fn()))
            if series is not None:
                series.write(self.model.displacement(), self.t)

        if not resumed:
            record(0)
        d_old = self.d.duplicate()
        cv_old = self._cv.duplicate()
        start = time.perf_counter()
        try:
            for k in range(self.run_step + 1, int(n_steps) + 1):
                self.d.copy(d_old)
                self._cv.copy(cv_old)
                lam_old = float(self.model.load_factor.value)
                iterations = self.step()
                self.step_count += 1
                self.run_step = k
                if not self.accounts_substeps:
                    self._account(d_old, lam_old, cv_old)
                self.max_work = max(self.max_work, abs(self.external_work))
                self._check(self.energy0, self.max_work)
                recorded = k % output_every == 0 or k == n_steps
                if recorded:
                    record(iterations)
                    if after_record is not None:
                        after_record(history)
                if report:
                    report(k, int(n_steps), self.t, time.perf_counter() - start)
                if recorded and should_stop is not None and k < n_steps:
                    reason = should_stop()
                    if reason:
                        history.stopped = f"{reason} at t = {self.t:.6g} s (step {k} of {n_steps})"
                        break
        finally:
            d_old.destroy()
            cv_old.destroy()
            if series is not None and series is not xdmf:
                series.close()
        if csv is not None:
            header, rows = history.columns()
            write_csv(csv, header, rows, comm=self.model.comm)
        return history

    def _check(self, energy0: float, max_work: float):
        """Stop with DynamicsError on a non-finite state or unbounded energy growth."""
        d_norm, v_norm = self.d.norm(), self.v.norm()
        where = f"step {self.step_count} (t = {self.t:.6g} s, dt = {self.dt:.3g} s)"
        if not (math.isfinite(d_norm) and math.isfinite(v_norm)):
            raise DynamicsError(f"time integration blew up at {where}: non-finite displacement or velocity",
                                self.step_count, self.t)
        if self.energy_bound is None:
            return
        energy = self.kinetic_energy() + self.strain_energy()
        scale = abs(energy0) + max_work
        if not math.isfinite(energy) or energy > self.energy_bound * scale + 1e-300:
            raise DynamicsError(
                f"time integration blew up at {where}: kinetic + strain energy {energy:.4g} J exceeds "
                f"{self.energy_bound:g} x (initial energy + |external work|) = {self.energy_bound * scale:.4g} J",
                self.step_count, self.t)

    # ---------------------------------------------------------- checkpoint
    resumable = True    # whether `state` holds everything the next step reads (see GeneralizedAlphaIntegrator)

    def state(self) -> dict:
        """What the next step and the run loop read, this rank's part (a checkpoint; between steps of `run`):
        d, v, a, C v of the last step, the frozen damping state, t, t0, the step counts, the load factor, the
        work and dissipation so far and the blow-up check's reference energies."""
        state = {"d": _owned(self.d), "v": _owned(self.v), "a": _owned(self.a), "cv": _owned(self._cv),
                 "frozen": _owned(self.ops.w_frozen.vector) if self.ops.stiffness_ufl is not None else None}
        state.update({name: getattr(self, name, None) for name in self._state_scalars})
        state["load_factor"] = float(self.model.load_factor.value)
        return state

    _state_scalars = ("t", "t0", "step_count", "external_work", "dissipated", "energy0", "max_work", "run_step")

    def restore(self, state: dict):
        """Continue from a `state()` of an integrator built from the same model on the same ranks (then `run`
        with the saved history); the model's state w is set to d."""
        if not self.resumable:
            raise DynamicsError(f"{type(self).__name__}: {self.not_resumable}", self.step_count, self.t)
        for name, vec in (("d", self.d), ("v", self.v), ("a", self.a), ("cv", self._cv)):
            target = vec.getArray()
            if target.shape != state[name].shape:
                raise ValueError(f"resume: the checkpoint's state does not fit this run's mesh ({name})")
            target[:] = state[name]
        for name in self._state_scalars:
            setattr(self, name, state[name])
        self.model.set_load_factor(state["load_factor"])
        self._sync_model()
        if state["frozen"] is not None:
            frozen = self.d.duplicate()
            frozen.getArray()[:] = state["frozen"]
            self.ops.freeze(frozen)
            frozen.destroy()
        self._initialized = True

    def destroy(self):
        for vec in (self.d, self.v, self.a, self._work, self._cv):
            vec.destroy()


class _EffectiveSystem:
    """Model-like adapter giving NewtonSolver the effective residual and tangent of one Newmark step."""

    def __init__(self, integrator: "NewmarkIntegrator"):
        self.it = integrator
        model = integrator.model
        self.model = model
        self.comm = model.comm
        self.w = model.w
        self.F_ref = model.F_ref
        self.c_mass = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        self.c_damp = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        extra = integrator.ops.jacobian_form(self.c_mass, self.c_damp)
        jac = model.jacobian_form if extra is None else model.jacobian_form + extra
        self._J = fem.form(jac)
        self._acc = model.create_vector()
        self._vel = model.create_vector()
        self._tmp = model.create_vector()
        self._diag = None

    def compile(self):
        pass

    def set_state(self, x: PETSc.Vec):
        self.model.set_state(x)

    def set_coefficients(self, dt: float, beta: float, gamma: float):
        self.c_mass.value = 1.0 / (beta * dt ** 2)
        self.c_damp.value = gamma / (beta * dt)
        self._diag = self.it.ops.jacobian_diagonal(float(self.c_mass.value), float(self.c_damp.value))
        if self._diag is not None:
            self.it.zero_bc_rows(self._diag)

    def create_vector(self) -> PETSc.Vec:
        return self.model.create_vector()

    def create_matrix(self) -> PETSc.Mat:
        return fem_petsc.create_matrix(self._J)

    def residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """G(x) = f_int(x) - lambda F_ref + M a(x) + C v(x); Dirichlet rows x - lambda g."""
        it = self.it
        it.system.residual(x, b)
        x.copy(self._acc)  # a(x) = (x - d~) / (beta dt^2)
        self._acc.axpy(-1.0, it.d_pred)
        self._acc.scale(float(self.c_mass.value))
        it.v_pred.copy(self._vel)  # v(x) = v~ + gamma dt a(x)
        self._vel.axpy(it.gamma * it.dt, self._acc)
        it.ops.mass_action(self._acc, self._tmp)
        self.it.zero_bc_rows(self._tmp)
        b.axpy(1.0, self._tmp)
        if it.ops.has_damping:
            it.ops.damping_action(self._vel, self._tmp)
            self.it.zero_bc_rows(self._tmp)
            b.axpy(1.0, self._tmp)

    def jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        x.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self._J, bcs=self.model.bcs)
        A.assemble()
        if self._diag is not None:
            A.setDiagonal(self._diag, addv=PETSc.InsertMode.ADD_VALUES)
        add_term_jacobians(self.it.system, x, A)  # e.g. contact: they see the state x set above


@dataclass
class SubStep:
    """Outcome of one attempted sub-step: converged, the step size used [s], Newton iterations, SNES reason."""
    converged: bool
    dt: float
    iterations: int
    reason: str


class StepHalving:
    """Sub-stepping of an implicit integrator with step halving on Newton failure (mixed into TimeIntegrator).

    A user step advances the state from t0 + k dt to t0 + (k+1) dt (the output grid stays on multiples of dt).
    When the Newton solve of a sub-step fails, the state is restored, the sub-step is halved and retried, down
    to min_dt; after `grow_after` consecutive converged sub-steps it is doubled again (never above dt). Below
    min_dt the run stops with DynamicsError naming the time, the step and the Newton reason, with the last
    converged state restored in the integrator and in model.w. Work and dissipation are booked per sub-step.

    Subclasses implement `_substep(h) -> SubStep`, which advances (t, d, v, a) by h on success and leaves them
    (and model.w) untouched otherwise; `_substep` may itself halve (then SubStep.dt < h).
    """

    def _init_step_halving(self, min_dt: float | None, grow_after: int):
        min_dt = self.dt / 64.0 if min_dt is None else min_dt
        if not (isinstance(min_dt, (int, float, np.floating)) and math.isfinite(min_dt) and 0 < min_dt <= self.dt):
            raise ValueError(f"min_dt must be a time step [s] in (0, dt = {self.dt:.6g}], got {min_dt!r}")
        if not (isinstance(grow_after, (int, np.integer)) and grow_after >= 1):
            raise ValueError(f"grow_after must be a positive integer, got {grow_after!r}")
        self.min_dt = float(min_dt)
        self.grow_after = int(grow_after)
        self.current_dt = self.dt  # the sub-step size the next step starts with [s]
        self.substeps = 0  # converged sub-steps so far
        self.halvings = 0  # failed Newton solves that led to a smaller sub-step
        self.doublings = 0  # sub-step growths back towards dt
        self._successes = 0
        self.accounts_substeps = True
        self._sub_d_old = self.model.create_vector()
        self._sub_cv_old = self.model.create_vector()

    def _restore_last_converged(self):
        self.model.set_load_factor(self.load(self.t))
        self._sync_model()

    def _fail(self, name: str, t_fail: float, h: float, reason: str, iterations: int):
        self._restore_last_converged()
        raise DynamicsError(
            f"{name} step {self.step_count + 1}: Newton {reason} after {iterations} iterations at t = {t_fail:.6g} s "
            f"with dt = {h:.3g} s (min_dt = {self.min_dt:.3g} s); state restored to the last converged time "
            f"t = {self.t:.6g} s", self.step_count + 1, t_fail, dt=h, reason=reason, last_converged_time=self.t)

    def step(self) -> int:
        """Advance to the next output time t0 + (k+1) dt; returns the Newton iterations of all sub-steps."""
        t_target = self.t0 + (self.step_count + 1) * self.dt
        resolution = 1e-9 * self.dt
        iterations = 0
        while t_target - self.t > resolution:
            h = min(self.current_dt, t_target - self.t)
            if t_target - self.t - h <= resolution:
                h = t_target - self.t  # land on the grid, no sliver step
            self.d.copy(self._sub_d_old)
            self._cv.copy(self._sub_cv_old)
            lam_old = float(self.model.load_factor.value)
            outcome = self._substep(h)
            iterations += outcome.iterations
            if not outcome.converged:
                if outcome.dt / 2.0 < self.min_dt * (1.0 - 1e-12):
                    self._fail(type(self).__name__, self.t + outcome.dt, outcome.dt, outcome.reason, outcome.iterations)
                self.current_dt = outcome.dt / 2.0
                self.halvings += 1
                self._successes = 0
                continue
            if outcome.dt < h * (1.0 - 1e-12):  # halved inside _substep
                self.halvings += int(round(math.log2(h / outcome.dt)))
                self.current_dt = outcome.dt
                self._successes = 0
            self.substeps += 1
            self._account(self._sub_d_old, lam_old, self._sub_cv_old)
            self._successes += 1
            if self.current_dt < self.dt and self._successes >= self.grow_after:
                self.current_dt = min(2.0 * self.current_dt, self.dt)
                self.doublings += 1
                self._successes = 0
        self.t = t_target
        return iterations

    def _substep(self, h: float) -> SubStep:
        raise NotImplementedError

    _state_scalars = TimeIntegrator._state_scalars + ("current_dt", "substeps", "halvings", "doublings",
                                                      "_successes")

    def _destroy_step_halving(self):
        self._sub_d_old.destroy()
        self._sub_cv_old.destroy()


class NewmarkIntegrator(StepHalving, TimeIntegrator):
    """Implicit Newmark (beta, gamma) with SNES Newton per step ([Man2006, Box 2], eqs. 2.76, 2.84-2.85).

    Args:
        beta, gamma: Newmark parameters; unconditionally stable for gamma >= 1/2 and beta >= (gamma + 1/2)^2 / 4
            (Hughes, The Finite Element Method, sec. 9.1); other values raise ValueError. Default: trapezoidal.
        newton_options: PETSc options for the SNES (see fabricfem.solvers.newton.DEFAULT_OPTIONS).
        min_dt: smallest sub-step [s] of the step halving on Newton failure (default dt / 64; min_dt = dt
            disables halving); grow_after: converged sub-steps before the sub-step is doubled again (see
            StepHalving). Outputs stay at multiples of dt.
        Other arguments: see TimeIntegrator (consistent mass unless lumped=True).
    """

    def __init__(self, model, dt: float, beta: float = 0.25, gamma: float = 0.5, load_factor: LoadFactor = 1.0,
                 rayleigh: tuple[float, float] = (0.0, 0.0), air_drag: float = 0.0, lumped: bool = False,
                 newton_options: dict | None = None, energy_bound: float | str | None = "auto",
                 min_dt: float | None = None, grow_after: int = 4):
        for name, value in (("beta", beta), ("gamma", gamma)):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if gamma < 0.5:
            raise ValueError(f"gamma = {gamma} < 1/2: Newmark amplifies the solution (need gamma >= 1/2)")
        if beta < (gamma + 0.5) ** 2 / 4.0 - 1e-14:
            raise ValueError(f"beta = {beta} < (gamma + 1/2)^2 / 4 = {(gamma + 0.5) ** 2 / 4:.6g}: the implicit "
                             f"Newmark scheme would be only conditionally stable (use CentralDifference for beta = 0)")
        super().__init__(model, dt, load_factor, rayleigh, air_drag, lumped, energy_bound)
        self._init_step_halving(min_dt, grow_after)
        self.beta, self.gamma = float(beta), float(gamma)
        self.d_pred = model.create_vector()
        self.v_pred = model.create_vector()
        self.effective = _EffectiveSystem(self)  # the step's residual and tangent, what Newton drives
        self._coefficient_dt = self.dt
        self.effective.set_coefficients(self.dt, self.beta, self.gamma)
        # stol 1e-8: near round-off the residual of thin shells stagnates (ill-conditioned K) while the Newton
        # update is ~1e-9 of the solution; the full-step Newton only takes steps that small when converged.
        options = {"snes_atol": 1e-12 * max(model.F_ref.norm(), 1e-300), "snes_stol": 1e-8}
        options.update(newton_options or {})
        self.solver = NewtonSolver(self.effective, options)

    _state_scalars = StepHalving._state_scalars + ("_coefficient_dt",)

    def restore(self, state: dict):
        super().restore(state)
        self.effective.set_coefficients(self._coefficient_dt, self.beta, self.gamma)

    def _substep(self, h: float) -> SubStep:
        """One Newmark step of size h from (t, d, v, a); on Newton failure nothing but model.w is changed."""
        beta, gamma = self.beta, self.gamma
        if h != self._coefficient_dt:
            self.effective.set_coefficients(h, beta, gamma)
            self._coefficient_dt = h
        t_new = self.t + h
        # predictors d~, v~ (eq. 2.76 with a* = 0)
        self.d.copy(self.d_pred)
        self.d_pred.axpy(h, self.v)
        self.d_pred.axpy((0.5 - beta) * h ** 2, self.a)
        self.v.copy(self.v_pred)
        self.v_pred.axpy((1.0 - gamma) * h, self.a)
        self.ops.freeze(self.d)  # C = a M + b K_M(d^n) (eq. 2.85)
        self.model.set_load_factor(self.load(t_new))
        self.d_pred.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        try:
            result = self.solver.solve()
        except SolverError as refused:  # an absurd "converged" state (NewtonSolver guard): a failed sub-step
            self._restore_last_converged()
            return SubStep(False, h, self.solver.snes.getIterationNumber(), refused.reason)
        if not result.converged:
            self._restore_last_converged()
            return SubStep(False, h, result.iterations, result.reason)
        self.model.w.vector.copy(self.d)
        # a^{n+1} = (d - d~) / (beta dt^2), v^{n+1} = v~ + gamma dt a^{n+1}
        self.d.copy(self.a)
        self.a.axpy(-1.0, self.d_pred)
        self.a.scale(1.0 / (beta * h ** 2))
        self.v_pred.copy(self.v)
        self.v.axpy(gamma * h, self.a)
        self.t = t_new
        return SubStep(True, h, result.iterations, result.reason)

    def destroy(self):
        self.solver.destroy()
        for vec in (self.d_pred, self.v_pred):
            vec.destroy()
        self._destroy_step_halving()
        super().destroy()
