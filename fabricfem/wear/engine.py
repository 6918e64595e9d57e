"""The explicit wear engine: a garment on a moving wearer by central differences, phase by phase [Man2006, ch. 5].

A run is a sequence of phases on one body clock t [s] (sewing, donning, settling, motion); each phase is a
number of record intervals of `steps_per_record` central-difference steps (fabricfem.dynamics.explicit with the
body contact and the seams as its hooks). A phase reports every record ("each") or only its last ("end": a
settling phase whose end state is the start record of the motion). The record maker of the caller turns the
state into a step record (fabricfem.wear.contract.WearStep); `run_phases` owns the loop, the
blow-up check and the wall-time breakdown, so that every explicit wear run shares them.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from mpi4py import MPI

from fabricfem.contact.self_contact import BLOW_UP_SPEED, node_speeds
from fabricfem.solvers.newton import SolverError


class WearError(SolverError):
    """A wear run could not proceed (the explicit state blew up, a phase failed)."""


@dataclass(frozen=True)
class Phase:
    """One phase of a wear run: `records` record intervals; `report` = "each" (a record after every interval)
    or "end" (one record after the last interval, also when `records` is 0: the state at the phase's start);
    `coordinate(k)` the record coordinate after interval k (0-based; an angle [deg] or a time [s])."""

    name: str
    records: int
    report: str = "each"
    coordinate: Callable[[int], float] = field(default=lambda k: math.nan)

    def __post_init__(self):
        if self.report not in ("each", "end"):
            raise ValueError(f"report must be 'each' or 'end', got {self.report!r}")
        if not (isinstance(self.records, int) and self.records >= 0):
            raise ValueError(f"records must be an integer >= 0, got {self.records!r}")


TIMING_PARTS = ("internal_forces", "contact", "pose_torque", "output", "other")


def step_breakdown(total: float, internal_forces: float, contact_hooks: float, pose_torque: float,
                   output: float, steps: int) -> dict:
    """Wall-time breakdown [s] of an explicit loop of `total` seconds and `steps` steps:
    internal_forces (FFCx assembly of f_int, with the copy of d into the model), contact (search, projection,
    friction and seam corrections: the hooks minus posing and torque sums), pose_torque (posing the body,
    torque and pressure impulses), output (records: energies, penetration, the on_step callback) and other
    (the rest of the central-difference step in Python/PETSc: vector updates, boundary rows, checks);
    `<part>_share` = part / total, `ms_per_step` = 1e3 total / steps."""
    parts = {"internal_forces": internal_forces, "contact": contact_hooks - pose_torque, "pose_torque": pose_torque,
             "output": output}
    parts["other"] = total - sum(parts.values())
    out = {"loop_s": total, "steps": steps, "ms_per_step": 1e3 * total / steps if steps else math.nan}
    for name in TIMING_PARTS:
        out[f"{name}_s"] = parts[name]
        out[f"{name}_share"] = parts[name] / total if total > 0 else math.nan
    return out


def format_breakdown(timings: dict) -> str:
    """One line: ms per step and the shares of the parts of `step_breakdown`."""
    shares = ", ".join(f"{name.replace('_', ' ')} {timings[name + '_share']:.0%}" for name in TIMING_PARTS)
    return f"{timings['ms_per_step']:.2f} ms/step over {timings['steps']} steps ({shares})"


def run_phases(integrator, contact, phases: list[Phase], steps_per_record: int | Callable[[], int],
               make_record: Callable[[Phase, int, int], object], history,
               on_step: Callable[[object], None] | None = None, stop_on_failure: bool = True,
               timed: Callable[[Phase], bool] = lambda phase: phase.report == "each",
               on_phase_end: Callable[[Phase], None] | None = None, label: str = "wear", start_record: int = 0,
               after_record: Callable[[int], None] | None = None,
               should_stop: Callable[[], str] | None = None) -> dict:
    """Run `phases` with `integrator` (initialised) and append the records of `make_record(phase, k, steps)`
    (k: the interval index in the phase, steps: central-difference steps since the previous record) to
    `history.steps`; `on_step(record)` after each. Before each record interval the contact's time averages are
    reset (`contact.reset_means()`): a record is the mean over its interval.

    A non-finite displacement or velocity, or a node faster than BLOW_UP_SPEED, raises WearError naming the
    phase, the time and the step (or, with stop_on_failure=False, sets `history.failure` and returns). Returns the
    wall-time breakdown (`step_breakdown`) of the phases for which `timed(phase)` holds, with the process's CPU time
    per step; `on_phase_end(phase)` is called after each completed phase (the settling diagnostics of the sleeve).

    `steps_per_record` may be a callable, asked before every record interval (an adaptive step: it sets the
    integrator's dt and returns the number of steps of the interval).

    Resuming and stopping (phases that report each record): the first `start_record` record intervals are
    skipped (a restored state, fabricfem.wear.checkpoint); `after_record(n)` is called after the n-th interval's
    record (a checkpoint); `should_stop()` is asked then too: a non-empty reason (an interrupt) ends the run
    there, `history.failure` set to it, the outputs up to this record valid."""
    loop = _Loop(integrator, contact, history, make_record, on_step, steps_per_record, start_record, after_record,
                 should_stop)
    for phase in phases:
        base_int, base_contact = dict(integrator.timings), dict(contact.timings)
        start, cpu_start = time.perf_counter(), time.process_time()
        try:
            steps_run, output_phase, stopped = loop.phase(phase, label)
        except WearError:
            if stop_on_failure:
                raise
            return {}
        if stopped:
            return {}
        if on_phase_end is not None:
            on_phase_end(phase)
        if phase.report == "end":
            output_phase += loop.report(phase, phase.records - 1)
        if timed(phase):
            loop.add_timings(time.perf_counter() - start, time.process_time() - cpu_start, steps_run, output_phase,
                             integrator.timings, base_int, contact.timings["pose_torque"] - base_contact["pose_torque"])
    return loop.timings()


class _Loop:
    """The record intervals of `run_phases` and their timing sums (internal forces, contact hooks, pose and
    torque, output [s], CPU [s], steps)."""

    def __init__(self, integrator, contact, history, make_record, on_step, steps_per_record, start_record,
                 after_record, should_stop):
        self.integrator, self.contact, self.history = integrator, contact, history
        self.make_record, self.on_step = make_record, on_step
        self.steps_per_record, self.start_record = steps_per_record, start_record
        self.after_record, self.should_stop = after_record, should_stop
        self.translation_rows = np.asarray(contact.nodes.dofs)    # (n, 3) the owned nodes' displacement rows
        self.pending = self.done = 0
        self.sums = {"loop": 0.0, "cpu": 0.0, "steps": 0, "internal": 0.0, "hooks": 0.0, "pose": 0.0, "output": 0.0}

    def phase(self, phase: Phase, label: str) -> tuple[int, float, bool]:
        """Run the record intervals of `phase`: (steps run, output time [s], stopped by should_stop). A non-finite
        state or a node faster than BLOW_UP_SPEED (after each interval), or a ValueError of a step, sets
        history.failure and raises WearError naming the phase, the time and the step."""
        steps_run, output = 0, 0.0
        integ = self.integrator
        for k in range(phase.records):
            if self.done < self.start_record:
                self.done += 1
                continue
            self.contact.reset_means()
            n_steps = self.steps_per_record() if callable(self.steps_per_record) else self.steps_per_record
            try:
                for _ in range(n_steps):
                    integ.step()
                    integ.step_count += 1
                _check_state(integ, self.translation_rows)
            except ValueError as exc:
                message = (f"{label}: the explicit run stopped in phase {phase.name!r} before t = {integ.t:.6g} s "
                           f"(step {integ.step_count}, dt = {integ.dt:.3g} s): {exc}")
                self.history.failure = message
                raise WearError(message, reason="EXPLICIT_BLOW_UP") from exc
            self.pending += n_steps
            self.done += 1
            steps_run += n_steps
            if phase.report == "each":
                output += self.report(phase, k)
                if self.after_record is not None:
                    self.after_record(self.done)
                reason = self.should_stop() if self.should_stop is not None else ""
                if reason:
                    self.history.failure = f"{reason} at t = {integ.t:.6g} s (record {self.done})"
                    return steps_run, output, True
        return steps_run, output, False

    def report(self, phase: Phase, k: int) -> float:
        """Append the record after interval k of `phase` and call on_step; returns the time it took [s]."""
        tic = time.perf_counter()
        record = self.make_record(phase, k, self.pending)
        self.pending = 0
        self.history.steps.append(record)
        if self.on_step:
            self.on_step(record)
        return time.perf_counter() - tic

    def add_timings(self, loop: float, cpu: float, steps: int, output: float, integ_timings: dict, base_int: dict,
                    pose: float) -> None:
        s = self.sums
        s["loop"] += loop
        s["cpu"] += cpu
        s["steps"] += steps
        s["output"] += output
        s["internal"] += integ_timings["internal_forces"] - base_int["internal_forces"]
        s["hooks"] += integ_timings["contact"] - base_int["contact"]
        s["pose"] += pose

    def timings(self) -> dict:
        s = self.sums
        out = step_breakdown(s["loop"], s["internal"], s["hooks"], s["pose"], s["output"], s["steps"])
        out["cpu_s"] = s["cpu"]
        out["cpu_ms_per_step"] = 1e3 * s["cpu"] / max(s["steps"], 1)
        return out


def _check_state(integrator, rows: np.ndarray) -> None:
    """ValueError unless the state is finite and no node moves faster than BLOW_UP_SPEED [m/s]: the largest speed
    |v| of the owned nodes, `rows` (n, 3) their local displacement rows, over the ranks. A blown-up state
    can stay finite for many steps while its numbers grow. (The rotation rates are left out: rad/s, not a speed.)"""
    if not (math.isfinite(integrator.d.norm()) and math.isfinite(integrator.v.norm())):
        raise ValueError("non-finite displacement or velocity")
    local = float(node_speeds(integrator.v.getArray(readonly=True)[rows]).max(initial=0.0))
    speed = integrator.v.comm.tompi4py().allreduce(local, op=MPI.MAX)
    if not speed <= BLOW_UP_SPEED:
        raise ValueError(f"a node moves at {speed:.3g} m/s (above {BLOW_UP_SPEED:g} m/s: the steps diverged)")


def kinetic_ratio(kinetic: np.ndarray, strain: np.ndarray) -> float:
    """Largest kinetic / strain energy over the records with strain energy (0 if none)."""
    mask = strain > 0.0
    return float(np.max(kinetic[mask] / strain[mask])) if mask.any() else 0.0
