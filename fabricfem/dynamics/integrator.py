"""The run loop shared by the time integrators ([Man2006, sec. 2.3.1.6]): `TimeIntegrator` holds the state
(d, v, a), the energy bookkeeping (external work and damping dissipation by the trapezoidal rule), the blow-up
check, the outputs (History, CSV, XDMF, progress) and the checkpoint state; the schemes (implicit Newmark,
fabricfem.dynamics.newmark; generalized-alpha, fabricfem.dynamics.ts; explicit central differences,
fabricfem.dynamics.explicit) implement `step`. SI units: s, m, J.

Rotations: the director base is NOT re-based during a dynamic run (model.rebase is set False): the angle
velocities/accelerations are then always measured about the same frame. This limits a run to angles below
pi/2 about the initial director base (the two-angle singularity).
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
from fabricfem.solvers.system import base_model, owned_dirichlet_rows

__all__ = ["DynamicsError", "History", "LoadFactor", "TimeIntegrator", "node_monitor", "progress_printer"]

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
        """(header, rows): one row per record, columns time [s], energies [J] and the monitors."""
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
    """lambda(t) of a callable or a finite constant load factor; ValueError on a non-finite constant."""
    if callable(load_factor):
        return load_factor
    value = float(load_factor)
    if not math.isfinite(value):
        raise ValueError(f"load_factor must be finite, got {load_factor!r}")
    return lambda t: value


def compiled_energy(model, jit_params: dict | None = None):
    """The compiled form of model.energy [J] (with dolfinx's `jit_params`, default its own), kept on the model while
    model.energy is the same UFL form (the JIT cache lookup costs milliseconds per integrator)."""
    cache = model.__dict__.setdefault("_compiled_energies", {})
    key = repr(jit_params)
    if key not in cache or cache[key][0] is not model.energy:
        cache[key] = (model.energy, fem.form(model.energy, jit_params=jit_params))
    return cache[key][1]


# [J] added to the blow-up check's bound so that a run from rest without work (round-off energies) is not stopped
ENERGY_FLOOR = 1e-300


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
        self._energy_form = compiled_energy(model)
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
        """Zero this rank's owned Dirichlet rows of vec (in place)."""
        vec.getArray()[self.bc_rows] = 0.0

    def _sync_model(self):
        """model.w = d, ghosts updated."""
        self.d.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def strain_energy(self) -> float:
        """Strain energy of the model's current state [J] (model.energy assembled, summed over ranks)."""
        return float(self.model.comm.allreduce(fem.assemble_scalar(self._energy_form)))

    def kinetic_energy(self) -> float:
        """Kinetic energy 1/2 v^T M v of the current velocity [J]."""
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
            should_stop: Callable[[], str] | None = None, stop_on_blowup: bool = False) -> History:
        """Integrate n_steps steps; record energies and monitors every `output_every` steps (and at 0).

        xdmf: write the displacement time series (fabricfem.io.SurfaceSeries, or an open one, left open);
        csv: write the History table (fabricfem.io.write_csv); progress: True for progress_printer on rank 0, or a
        callable. Raises DynamicsError (naming step and time) when the solve fails or the state blows up.

        Checkpoints: `history` continues a run whose records so far it holds, from the state of its last record
        restored by `restore` (a checkpoint's `state()`): step 0 is not recorded again and the steps continue
        after the restored user step. `after_record(history)` is called after every record (a checkpoint);
        `should_stop()` then too: a non-empty reason (an interrupt) ends the run there, in `history.stopped`.
        stop_on_blowup: a blow-up (`_check`) ends the run with its reason in `history.stopped` (and
        `self.blew_up` True) instead of raising; the history and the series then end at the last record before it.
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
            self._record(history, monitors, series, 0)

        def record(iterations: int) -> None:
            self._record(history, monitors, series, iterations)
            if after_record is not None:
                after_record(history)
        try:
            self._advance(int(n_steps), output_every, record, report, should_stop, history)
        except DynamicsError as exc:
            if not (stop_on_blowup and self.blew_up):
                raise
            history.stopped = str(exc)
        finally:
            if series is not None and series is not xdmf:
                series.close()
        if csv is not None:
            header, rows = history.columns()
            write_csv(csv, header, rows, comm=self.model.comm)
        return history

    def _record(self, history: History, monitors: dict[str, Callable[[], float]], series: SurfaceSeries | None,
                iterations: int) -> None:
        """Append the time [s], energies [J], work and dissipation [J], Newton iterations and monitors to `history`;
        the displacement to `series` (if any)."""
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

    def _advance(self, n_steps: int, output_every: int, record: Callable[[int], None],
                 report: Callable[[int, int, float, float], None] | None, should_stop: Callable[[], str] | None,
                 history: History) -> None:
        """The user steps after run_step up to n_steps: step, book the work and dissipation, check for blow-up,
        `record(iterations)` every output_every steps and at the last, report progress, and end early with the
        reason in history.stopped when should_stop() gives one after a record."""
        d_old = self.d.duplicate()
        cv_old = self._cv.duplicate()
        start = time.perf_counter()
        try:
            for k in range(self.run_step + 1, n_steps + 1):
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
                if record_and_ask(self.t, k, n_steps, output_every, lambda: record(iterations), report,
                                  should_stop, history, start):
                    break
        finally:
            d_old.destroy()
            cv_old.destroy()

    blew_up = False     # set by `_check` when it stops a run

    def blowup_advice(self) -> str:
        """What to change after a blow-up (appended to the reason of `_check`)."""
        return "use a smaller dt"

    def _check(self, energy0: float, max_work: float):
        """Stop with DynamicsError on a non-finite state or unbounded energy growth: kinetic + strain energy
        above energy_bound x (|initial energy| + largest |external work| so far) + ENERGY_FLOOR [J]."""
        d_norm, v_norm = self.d.norm(), self.v.norm()
        where = f"step {self.step_count} (t = {self.t:.6g} s, dt = {self.dt:.3g} s)"
        if not (math.isfinite(d_norm) and math.isfinite(v_norm)):
            self.blew_up = True
            raise DynamicsError(f"time integration blew up at {where}: non-finite displacement or velocity; "
                                f"{self.blowup_advice()}", self.step_count, self.t)
        if self.energy_bound is None:
            return
        energy = self.kinetic_energy() + self.strain_energy()
        scale = abs(energy0) + max_work
        if not math.isfinite(energy) or energy > self.energy_bound * scale + ENERGY_FLOOR:
            self.blew_up = True
            raise DynamicsError(
                f"time integration blew up at {where}: energy grows without a load, kinetic + strain energy "
                f"{energy:.4g} J exceeds {self.energy_bound:g} x (initial energy + |external work|) = "
                f"{self.energy_bound * scale:.4g} J; {self.blowup_advice()}", self.step_count, self.t)

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
        """Free the state vectors."""
        for vec in (self.d, self.v, self.a, self._work, self._cv):
            vec.destroy()


def record_and_ask(t: float, k: int, n_steps: int, output_every: int, record: Callable[[], None],
                   report: Callable | None, should_stop: Callable[[], str] | None, history, start: float) -> bool:
    """After step k of n_steps (time t [s]): a record every `output_every` steps and at the last, the progress
    report, and at a record before the last the `should_stop()` question; True when it answers a reason (written
    to history.stopped)."""
    recorded = k % output_every == 0 or k == n_steps
    if recorded:
        record()
    if report:
        report(k, n_steps, t, time.perf_counter() - start)
    if recorded and should_stop is not None and k < n_steps:
        reason = should_stop()
        if reason:
            history.stopped = f"{reason} at t = {t:.6g} s (step {k} of {n_steps})"
            return True
    return False
