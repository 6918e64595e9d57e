"""Run a garment on a moving wearer by its route, through the wearer contract (fabricfem.wear.contract)."""
from __future__ import annotations

import os
import signal
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.contract import PA_PER_MMHG, WearHistory, WearRun, WearStep
from fabricfem.wear.engine import format_breakdown
from fabricfem.wear.quasistatic import build_sleeve
from fabricfem.wear.recorder import WearRecorder
from fabricfem.wear.sleeve import build_explicit
from fabricfem.wear.sleeve_implicit import build_implicit
from fabricfem.wear.statistics import PEAK_PERCENTILE, default_windows, motion_statistics, statistics_rows
from fabricfem.wear.verdict import DEFAULT_FAILURE_STRAIN, Bounds, verdict, wear_checks

_RUNS_MADE: list[str] = []   # the wear runs of this process so far (the first one's setup includes the imports)

# route name ([route] solver) -> builder of the sleeve's WearRun from its configuration; the Newton routes' builders
# also take the skin's blend_width [m] (the explicit one has it from the scene: fabricfem.scenes.build.tube_scene_run)
ROUTES: dict[str, Callable[..., WearRun]] = {
    "explicit": build_explicit, "implicit": build_implicit, "quasistatic": build_sleeve}


def build_run(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> WearRun:
    """The WearRun of `config.route.solver` (ROUTES)."""
    return ROUTES[config.route.solver](config, comm)


def run_sleeve(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
               on_step: Callable[[WearStep], None] | None = None, stop_on_failure: bool = True) -> WearHistory:
    """Build and flex one sleeve configuration by its route; returns its history."""
    t0 = time.perf_counter()
    run = build_run(config, comm)
    history = run.run(on_step=on_step, stop_on_failure=stop_on_failure)
    run.destroy()
    history.wall = time.perf_counter() - t0
    return history


def run_wear(run: WearRun, out: Path, headline: str, render_at: list[float], render: bool = True,
             body_samples: int = 24, checkpoint=None, resume: bool = False,
             report: Callable[[WearRun, WearHistory], dict | None] | None = None, bounds: Bounds = Bounds(),
             failure_strain: float = DEFAULT_FAILURE_STRAIN, windows: list | None = None,
             started: float | None = None):
    """Run any WearRun with progress lines (rank 0), write the WearRecorder's outputs under `out`, print the
    closing summary (peak and final torque per monitor, pressures, strain, penetration, seam gap) and return the
    history. The explicit engine's runs also take a `checkpoint` (fabricfem.wear.checkpoint.Checkpoint), `resume`
    from it, and stop at the next record on Ctrl-C (SIGINT, on any rank) with valid outputs and a checkpoint.
    `history.wall_split` (`wall_split`): its setup counted from the process's start for the process's first run,
    else from `started` (time.perf_counter() when the run's building began; default: this call)."""
    comm = run.comm
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    t0 = time.perf_counter()
    say(headline)
    resuming = bool(resume and checkpoint is not None and checkpoint.exists())
    recorder = WearRecorder(run, out, [float(a) for a in render_at], render, body_samples)
    clock = fio.Progress()

    def on_step(step):
        recorder.record(step)
        say(f"  {step.line()}  {clock(run.fraction(step), step.phase)}")
        cloth = getattr(run, "self_contact", None)
        if getattr(cloth, "zones", False):           # the impact zones' counts so far (fabricfem.contact.impact_zones)
            say(f"    impact zones: {cloth.zone_totals}")

    loop_start = time.perf_counter()
    if checkpoint is None:
        history = run.run(on_step=on_step, stop_on_failure=False)
    else:
        with interrupt_flag(comm) as interrupted:
            history = run.run(on_step=on_step, stop_on_failure=False, checkpoint=checkpoint, resume=resuming,
                              recorder=recorder, should_stop=interrupted)
    loop_end = time.perf_counter()
    output = recorder.seconds + getattr(checkpoint, "seconds", 0.0)
    if checkpoint is not None and history.failure.startswith("interrupted"):
        checkpoint.save(run, history, len(history.steps), recorder)   # one record interval per record
    history.wall = time.perf_counter() - t0
    checks = wear_checks(history, bounds, failure_strain)
    history.verdict = verdict(checks)
    windows = default_windows(history, "[deg]" in run.axis_label) if windows is None else windows
    history.statistics = motion_statistics(history, [tuple(w) for w in windows])
    if history.statistics:
        fio.write_csv(out / "statistics.csv", ("quantity", "window_start", "window_end", "window_mean",
                                               f"p{PEAK_PERCENTILE:g}_abs", "max_abs"),
                      statistics_rows(history.statistics), comm)
    recorder.close(history)
    if report is not None:          # the scene's own report of the final state (e.g. the compression profile)
        history.report = report(run, history) or {}
    run.destroy()
    say(f"done: {len(history.steps)} records, {history.work()}, {history.wall:.1f} s; start clearance "
        f"{history.initial_gap * 1e3:.2f} mm")
    for line in format_summary(history.summary()):
        say(line)
    if "ms_per_step" in history.timings:
        say(f"time per part: {format_breakdown(history.timings)}")
    for line in format_statistics(history.statistics, run.axis_label):
        say(line)
    for check in checks:
        if not check.passed:
            say(check.line())
    if history.failure:
        say(f"STOPPED EARLY: {history.failure}")
    say(f"wrote {out}/cloth.xdmf, body.pvd (+ body_*.vtp), torque.csv, torque.sto, torque.png"
        + "".join(f", {name}" for name in recorder.renders))
    first = not _RUNS_MADE
    _RUNS_MADE.append(run.name)
    setup = process_age(loop_start) if first else loop_start - (t0 if started is None else started)
    history.wall_split = wall_split(setup, loop_end - loop_start, output, time.perf_counter() - loop_end,
                                    recorder.writer.cpu if recorder.writer is not None else 0.0)
    history.wall_split["setup_from"] = "process start" if first else "run start"
    say(f"wall time: {format_wall_split(history.wall_split)}")
    return history


def process_age(at: float | None = None) -> float:
    """Wall time [s] from the start of this process to the time.perf_counter() value `at` (default now): Linux's
    start time of the process (/proc/self/stat, 10 ms ticks) against the boot clock; elsewhere NaN."""
    now = time.perf_counter()
    at = now if at is None else at
    try:
        with open("/proc/self/stat") as f:
            ticks = float(f.read().rsplit(")", 1)[1].split()[19])
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return float("nan")
    return age - (now - at)


def wall_split(setup: float, loop: float, output: float, after: float, writer_cpu: float = 0.0) -> dict:
    """The wall time of a `fabricfem run` by phase [s] (rank 0's clock): setup (from the process's start to the
    first step: interpreter, imports, scene, mesh, forms, recorder), loop (the time loop, its output included),
    output_in_loop (the records written and the checkpoints, inside the loop), after (checks, statistics, the
    files written at the end: CSV, STO, plots and renders); the total, outside_loop_share = (setup + after) /
    total and output_share_of_loop = output_in_loop / loop; writer_cpu_s: the CPU time of the writer thread (rank 0,
    fabricfem.wear.writer: files written beside the loop and at the end; on a busy core it slows the loop too)."""
    total = setup + loop + after
    return {"setup_s": setup, "loop_s": loop, "output_in_loop_s": output, "after_s": after, "total_s": total,
            "outside_loop_share": (setup + after) / total if total > 0 else float("nan"),
            "output_share_of_loop": output / loop if loop > 0 else float("nan"), "writer_cpu_s": writer_cpu}


def format_wall_split(split: dict) -> str:
    """One line of `wall_split`: the phases [s] and the two shares."""
    return (f"setup {split['setup_s']:.2f} s, time loop {split['loop_s']:.2f} s (output in it "
            f"{split['output_in_loop_s']:.2f} s = {split['output_share_of_loop']:.1%}), after {split['after_s']:.2f} s; "
            f"outside the loop {split['outside_loop_share']:.1%} of {split['total_s']:.2f} s")


INTERRUPTS = (signal.SIGINT, signal.SIGTERM)   # the signals that stop a run at its next record


@contextmanager
def interrupt_flag(comm: MPI.Comm):
    """While inside: Ctrl-C (SIGINT) or a kill (SIGTERM, as a batch scheduler sends at its time limit) on any rank
    sets a flag instead of ending the process; the yielded callable returns "interrupted (SIGINT)" or "interrupted
    (SIGTERM)" once any rank got one (all ranks agree: an MPI reduction per call; SIGTERM wins), "" before."""
    got = [0]

    def handler(signum, frame):
        got[0] = max(got[0], 1 + INTERRUPTS.index(signum))

    previous = {number: signal.signal(number, handler) for number in INTERRUPTS}
    try:
        def interrupted() -> str:
            code = comm.allreduce(got[0], op=MPI.MAX)
            return f"interrupted ({signal.Signals(INTERRUPTS[code - 1]).name})" if code else ""
        yield interrupted
    finally:
        for number, before in previous.items():
            signal.signal(number, before)


def format_statistics(stats: dict, axis_label: str) -> list[str]:
    """The printed lines of the windowed means and percentile peaks (fabricfem.wear.statistics)."""
    if not stats:
        return []
    unit = axis_label.split("[")[-1].rstrip("]") if "[" in axis_label else ""
    windows = ", ".join(f"{a:g}-{b:g} {unit}" for a, b in stats["windows"])
    lines = []
    for key, entry in stats.items():
        if key.startswith("torque_"):
            means = ", ".join(f"{m:.4e}" for m in entry["mean_Nm"])
            lines.append(f"torque {key[7:]}: mean over {windows}: {means} N m; p{PEAK_PERCENTILE:g} |torque| "
                         f"{entry['p95_abs_Nm']:.4e} N m (largest {entry['max_abs_Nm']:.4e})")
    return lines


def format_summary(summary: dict) -> list[str]:
    """The printed lines of a history's summary (peak and final torques, pressure, strain, penetration, gap)."""
    lines = []
    for key, value in summary.items():
        if key.startswith("torque_"):
            where = {k: v for k, v in value.items() if not k.endswith("Nm")}
            at = ", ".join(f"{k.replace('_', ' ')} {v:.4g}" for k, v in where.items())
            lines.append(f"torque {key[7:]}: peak {value['peak_Nm']:.4e} N m, final {value['final_Nm']:.4e} N m ({at})")
    p = summary.get("pressure")
    if p:
        position = ", ".join(f"{v:.3f}" for v in p["peak_position_m"])
        lines.append(f"contact pressure on the body: peak {p['peak_Pa']:.4g} Pa = {p['peak_kPa']:.4g} kPa = "
                     f"{p['peak_mmHg']:.4g} mmHg on {p['peak_segment'] or '-'} at ({position}) m, t = "
                     f"{p['peak_time_s']:.3g} s; mean over the contact {p['mean_Pa']:.4g} Pa = {p['mean_kPa']:.4g} kPa = "
                     f"{p['mean_mmHg']:.4g} mmHg")
        if p.get("sensor_peak_Pa") is not None and p.get("sensor_diameter_m"):
            lines.append(f"contact pressure on a sensor's disc (diameter {p['sensor_diameter_m'] * 100:.3g} cm): peak "
                         f"{p['sensor_peak_kPa']:.4g} kPa = {p['sensor_peak_Pa'] / PA_PER_MMHG:.4g} mmHg")
    if "max_strain" in summary:
        local = (f" (at a quadrature point {summary['max_local_strain']:.3e})" if "max_local_strain" in summary
                 else "")
        lines.append(f"largest fabric strain {summary['max_strain']:.3e}{local}, largest penetration "
                     f"{summary['max_penetration_m']:.2e} m, largest seam gap after sewing "
                     f"{summary['max_seam_gap_after_sewing_m']:.2e} m")
    return lines
