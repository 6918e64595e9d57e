"""Run a garment on a moving wearer by its route, through the wearer contract (fabricfem.wear.contract)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.contract import WearRun
from fabricfem.wear.engine import format_breakdown
from fabricfem.wear.recorder import WearRecorder
from fabricfem.wear.sleeve import SleeveHistory, SleeveStep, build_explicit, build_sleeve
from fabricfem.wear.sleeve_implicit import build_implicit

# route name (SleeveConfig.solver) -> builder of its WearRun
ROUTES: dict[str, Callable[[SleeveConfig, MPI.Comm], WearRun]] = {
    "explicit": build_explicit, "implicit": build_implicit, "quasistatic": build_sleeve}


def build_run(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> WearRun:
    """The WearRun of `config.route.solver` (ROUTES)."""
    return ROUTES[config.route.solver](config, comm)


def run_sleeve(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
               on_step: Callable[[SleeveStep], None] | None = None, stop_on_failure: bool = True) -> SleeveHistory:
    """Build and flex one sleeve configuration by its route; returns its torque history."""
    t0 = time.perf_counter()
    run = build_run(config, comm)
    history = run.run(on_step=on_step, stop_on_failure=stop_on_failure)
    run.destroy()
    history.wall = time.perf_counter() - t0
    return history


def run_sleeve_scene(config: SleeveConfig, out: Path, render: bool = True, render_angles: list[float] | None = None,
                     body_samples: int = 24, comm: MPI.Comm = MPI.COMM_WORLD) -> SleeveHistory:
    """`fabricfem run` for sleeve scenes: flex the arm and write the WearRecorder's outputs under `out`
    (pressure renders at `render_angles` [deg], default the thirds of the flexion), with progress lines
    (rank 0) and a closing summary."""
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    final = config.motion.final_angle
    render_angles = [final / 3, 2 * final / 3, final] if render_angles is None else [float(a) for a in render_angles]
    t0 = time.perf_counter()
    run = build_run(config, comm)
    say(f"sleeve: {config.tube.n_around} x {config.tube.n_along} Q2 tube, {run.model.ndofs} dofs, {comm.size} rank(s); "
        f"mu = {config.contact.friction}, {config.contact.method} contact, "
        f"gravity {'on' if config.route.gravity else 'off'}; "
        f"flexion to {config.motion.final_angle} deg by {run.describe()}")
    recorder = WearRecorder(run, out, render_angles, render, body_samples)
    clock = fio.Progress()

    def on_step(step: SleeveStep):
        recorder.record(step)
        say(f"  angle {step.angle:6.2f} deg  torque {step.torque:+.4e} N m  {step.work()}  "
            f"penetration {step.max_penetration:.1e} m  {clock(step.angle / config.motion.final_angle)}")

    history = run.run(on_step=on_step, stop_on_failure=False)
    history.wall = time.perf_counter() - t0
    recorder.close(history)
    run.destroy()
    last = history.steps[-1]
    say(f"done: {len(history.steps) - 1} records to {last.angle:.2f} deg, {history.work()}, {history.wall:.1f} s; "
        f"torque at {last.angle:.2f} deg: {last.torque:.4e} N m; largest penetration "
        f"{max(s.max_penetration for s in history.steps):.2e} m; start clearance {history.initial_gap * 1e3:.2f} mm")
    if "ms_per_step" in history.timings:
        say(f"time per part: {format_breakdown(history.timings)}")
    if history.failure:
        say(f"STOPPED EARLY: {history.failure}")
    say(f"wrote {out}/cloth.xdmf, body.pvd (+ body_*.vtp), torque.csv, torque.png"
        + "".join(f", {name}" for name in recorder.renders))
    return history
