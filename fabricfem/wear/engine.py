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

    A non-finite displacement or velocity raises WearError naming the phase, the time and the step (or, with
    stop_on_failure=False, sets `history.failure` and returns). Returns the wall-time breakdown
    (`step_breakdown`) of the phases for which `timed(phase)` holds, with the process's CPU time per step;
    `on_phase_end(phase)` is called after each completed phase (the settling diagnostics of the sleeve).

    `steps_per_record` may be a callable, asked before every record interval (an adaptive step: it sets the
    integrator's dt and returns the number of steps of the interval).

    Resuming and stopping (phases that report each record): the first `start_record` record intervals are
    skipped (a restored state, fabricfem.wear.checkpoint); `after_record(n)` is called after the n-th interval's
    record (a checkpoint); `should_stop()` is asked then too: a non-empty reason (an interrupt) ends the run
    there, `history.failure` set to it, the outputs up to this record valid."""
    output_time, pending = 0.0, 0
    loop, cpu, steps_timed = 0.0, 0.0, 0
    internal = contact_hooks = pose = 0.0
    done = 0                     # record intervals run or skipped so far, over all phases
    for phase in phases:
        steps_run = 0
        clock = timed(phase)
        base_int, base_contact = dict(integrator.timings), dict(contact.timings)
        start, cpu_start = time.perf_counter(), time.process_time()
        output_phase = 0.0
        for k in range(phase.records):
            if done < start_record:
                done += 1
                continue
            contact.reset_means()
            n_steps = steps_per_record() if callable(steps_per_record) else steps_per_record
            try:
                for _ in range(n_steps):
                    integrator.step()
                    integrator.step_count += 1
                if not (math.isfinite(integrator.d.norm()) and math.isfinite(integrator.v.norm())):
                    raise ValueError("non-finite displacement or velocity")
            except ValueError as exc:
                message = (f"{label}: the explicit run stopped in phase {phase.name!r} before t = {integrator.t:.6g} s "
                           f"(step {integrator.step_count}, dt = {integrator.dt:.3g} s): {exc}")
                if stop_on_failure:
                    raise WearError(message, reason="EXPLICIT_BLOW_UP") from exc
                history.failure = message
                return {}
            pending += n_steps
            done += 1
            steps_run += n_steps
            if phase.report == "each":
                tic = time.perf_counter()
                record = make_record(phase, k, pending)
                pending = 0
                history.steps.append(record)
                if on_step:
                    on_step(record)
                if after_record is not None:
                    after_record(done)
                output_phase += time.perf_counter() - tic
                reason = should_stop() if should_stop is not None else ""
                if reason:
                    history.failure = f"{reason} at t = {integrator.t:.6g} s (record {done})"
                    return {}
        if phase.report == "end":
            if on_phase_end is not None:
                on_phase_end(phase)
            tic = time.perf_counter()
            record = make_record(phase, phase.records - 1, pending)
            pending = 0
            history.steps.append(record)
            if on_step:
                on_step(record)
            output_phase += time.perf_counter() - tic
        elif on_phase_end is not None:
            on_phase_end(phase)
        if clock:
            loop += time.perf_counter() - start
            cpu += time.process_time() - cpu_start
            steps_timed += steps_run
            internal += integrator.timings["internal_forces"] - base_int["internal_forces"]
            contact_hooks += integrator.timings["contact"] - base_int["contact"]
            pose += contact.timings["pose_torque"] - base_contact["pose_torque"]
            output_time += output_phase
    timings = step_breakdown(loop, internal, contact_hooks, pose, output_time, steps_timed)
    timings["cpu_s"] = cpu
    timings["cpu_ms_per_step"] = 1e3 * cpu / max(steps_timed, 1)
    return timings


def kinetic_ratio(kinetic: np.ndarray, strain: np.ndarray) -> float:
    """Largest kinetic / strain energy over the records with strain energy (0 if none)."""
    mask = strain > 0.0
    return float(np.max(kinetic[mask] / strain[mask])) if mask.any() else 0.0
