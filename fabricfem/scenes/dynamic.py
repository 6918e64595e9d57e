"""Dynamic scenes ([dynamics]): time integration from rest, with obstacles, monitors, strain limiting and
checkpoints.

Outputs of a dynamic scene <name>: <dir>/<name>.xdmf (displacement time series), <dir>/<name>.csv (time [s],
energies [J], monitors, max vertex Green strain [-], Newton iterations), <dir>/<name>.png (monitors and energies
over time) and <dir>/summary.json.
"""
from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from mpi4py import MPI

from fabricfem import io
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics.strain_limit import FastProjection, attach
from fabricfem.scenes.build import (
    INTEGRATORS,
    StrainMeter,
    build_integrator,
    build_model,
    build_monitors,
    build_obstacles,
    monitor_unit,
    output_dir,
    scene_name,
    scene_sha256,
)
from fabricfem.scenes.schema import Scene, SceneError
from fabricfem.scenes.sections import (
    DynamicsSection,
    section,
)
from fabricfem.wear.run import interrupt_flag
from fabricfem.wear.verdict import DEFAULT_FAILURE_STRAIN, Check, bounded_check, verdict

CHECKPOINT_EVERY = 25       # records between the checkpoints of a dynamic scene or a wear run (explicit engine)


@dataclass
class DynamicRun:
    """Result of `run_dynamic_scene`: the recorded history, step data, wall time [s], peak memory [MiB]."""
    history: object
    steps: int
    dt: float
    dt_crit: float | None
    wall_s: float
    peak_memory_mib: float
    summary: dict = field(default_factory=dict)
    outputs: dict[str, Path] = field(default_factory=dict)
    failure: str = ""           # why the run stopped before end_time (an interrupt, a blow-up), "" when it completed

    @property
    def warnings(self) -> list[str]:
        """The names of the failed plausibility checks (`dynamic_checks`)."""
        return list(self.summary.get("verdict", {}).get("failed", []))


# |KE + SE + D - W| / max(W, KE + SE + D) at the end of a dynamic run: the shipped scenes close it to 2e-4 (the
# strain-limited corner-pinned cloth at 0.1 s) and below; the same cloth on 6 x 6 to 0.6 s, 349 projections later,
# to 1.04 % (the projection's dissipation is booked per step); 5 % flags a step that drifts (unstable or too long)
ENERGY_BALANCE_TOLERANCE = 0.05


def dynamic_checks(summary: dict, failure_strain: float) -> list[Check]:
    """The plausibility checks of a dynamic run's summary: the energy balance at the end (kinetic + strain +
    dissipated = external work, relative, ENERGY_BALANCE_TOLERANCE) and the largest recorded Green strain against
    the fabric's failure_strain."""
    stored = summary["kinetic_J"] + summary["strain_J"] + summary["dissipated_J"]
    scale = max(abs(summary["external_work_J"]), abs(stored), 1e-300)
    balance = abs(stored - summary["external_work_J"]) / scale
    return [bounded_check("energy balance", "relative energy imbalance |KE + SE + D - W| / W at the end", balance,
                          ENERGY_BALANCE_TOLERANCE, ""),
            bounded_check("fabric strain", "largest recorded Green strain (fabric failure_strain)",
                          summary["max_strain_recorded"], failure_strain, "")]


def _progress(comm, n_steps: int, say):
    """Progress callback of TimeIntegrator.run: about 10 lines with the estimated time left (rank 0)."""
    every = max(1, math.ceil(n_steps / 10))
    clock = io.Progress()

    def report(step: int, total: int, t: float, elapsed: float):
        if step == 1 or step % every == 0 or step == total:
            line = clock(step / total)
            if step != 1:
                say(f"  step {step:6d}/{total}  t = {t:.5g} s  {line}")
    return report


def run_dynamic_scene(scene: Scene, comm=MPI.COMM_WORLD, resume: bool = False, sha: str = "") -> DynamicRun:
    """Integrate a [dynamics] scene from rest to end_time; write <name>.xdmf/.csv/.png and summary.json.

    Checkpoints (`DynamicCheckpoint`) every [dynamics] checkpoint_every records (default CHECKPOINT_EVERY);
    `resume` continues from the output folder's checkpoint; Ctrl-C or a kill (SIGINT, SIGTERM; any rank) stops the
    run at the next record with valid outputs and a checkpoint there (`DynamicRun.failure` says so). `sha`: the
    scene's hash the checkpoint is checked against (default scene_sha256(scene))."""
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    spec = scene["dynamics"]
    d = section(DynamicsSection, spec)
    name = scene_name(scene)
    out = output_dir(scene)
    t0 = time.perf_counter()
    checkpoint = DynamicCheckpoint(out, comm, sha or scene_sha256(scene), d.checkpoint_every)
    # before meshing: an integrator that cannot resume, a missing or a foreign checkpoint fail fast
    saved = checkpoint.read(INTEGRATORS.get(d.integrator)) if resume else None
    obstacles = build_obstacles(d.obstacles)
    model = build_model(scene, comm)
    system, contact = model, None
    if obstacles:   # penalty contact with the fixed rigid obstacles: a ResidualTerm of the shell
        model.compile()
        contact = ContactProblem(model, obstacles, penalty=d.contact_penalty)
        system = contact.system
    integrator, n_steps, dt, dt_crit = build_integrator(spec, system)
    limit = d.strain_limit
    # the projection's strain form also measures the strains (limit 1 when nothing is limited, as in
    # fabricfem.verify.strain_limit)
    projection = FastProjection(model, float(limit) if limit else 1.0, tol=float(d.strain_limit_tol))
    log = attach(projection, integrator) if limit else []
    meter = StrainMeter(projection, integrator)
    monitors = build_monitors(d.monitors, model, meter)
    monitors["max_strain"] = meter.max_strain
    output_every = int(d.output_every if d.output_every is not None else max(1, n_steps // 100))
    xdmf = out / f"{name}.xdmf"
    checkpoint.attach(xdmf, integrator, log, contact)
    history = checkpoint.restore(saved) if resume else None
    say(f"{name}: {model.model} model, {model.ndofs} dofs, {comm.size} rank(s); {d.integrator} "
        f"dt = {dt:.4g} s" + (f" (critical {dt_crit:.4g} s)" if dt_crit else "") +
        f", {n_steps} steps to t = {float(d.end_time):g} s" + (f", strain limit {limit:g}" if limit else "")
        + (f", {len(obstacles)} obstacle(s)" if obstacles else "")
        + (f"; resumed at t = {history.time[-1]:.6g} s (record {len(history.time) - 1})" if resume else ""))
    series = io.SurfaceSeries(xdmf, model.mesh, append=resume)
    checkpoint.series = series
    start = time.perf_counter()
    try:
        with interrupt_flag(comm) as interrupted:
            history = _run_to_end(integrator, float(d.end_time), n_steps, history,
                                  {"monitors": monitors, "xdmf": series, "output_every": output_every,
                                   "progress": _progress(comm, n_steps, say), "after_record": checkpoint.after_record,
                                   "should_stop": interrupted, "stop_on_blowup": True})
        if history.stopped and not integrator.blew_up and checkpoint.records != len(history.time) - 1:
            checkpoint.save(history)        # the interrupted run resumes from its last record
    finally:
        series.close()
    run_wall = time.perf_counter() - start
    n_steps = max(n_steps, integrator.run_step)      # the steps a shortened step added
    summary, outputs = _write_outputs(scene, history, model, integrator, n_steps, dt, dt_crit, run_wall, t0, log,
                                      comm)
    if history.stopped:
        say(f"STOPPED EARLY: {history.stopped}" + ("" if integrator.blew_up else "; continue with --resume"))
    integrator.destroy()
    projection.destroy()
    return DynamicRun(history, n_steps, dt, dt_crit, summary["wall_s"], summary["peak_memory_mib"], summary, outputs,
                      history.stopped)


def _run_to_end(integrator, end_time: float, n_steps: int, history, options: dict):
    """integrator.run(n_steps, history=history, **options), continued while a shortened step (the explicit safe
    step, CentralDifference.step_reductions) leaves t short of end_time [s]: the rest in equal steps no longer than
    the current one. Returns the History."""
    history = integrator.run(n_steps, history=history, **options)
    while not history.stopped and integrator.t < end_time * (1.0 - 1e-12):
        rest = math.ceil((end_time - integrator.t) / integrator.dt * (1.0 - 1e-12))
        integrator.set_time_step((end_time - integrator.t) / rest)
        history = integrator.run(integrator.run_step + rest, history=history, **options)
    return history


def _write_outputs(scene: Scene, history, model, integ, n_steps: int, dt: float, dt_crit: float | None,
                   run_wall: float, t0: float, log: list, comm) -> tuple[dict, dict]:
    """The CSV, the PNG and summary.json of a finished (or interrupted) dynamic run of the integrator `integ`
    (its final step dt [s] and, explicit, the safe step's reductions), and the closing lines; returns
    (summary, {kind: path})."""
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    d = section(DynamicsSection, scene["dynamics"])
    name, out, limit = scene_name(scene), output_dir(scene), d.strain_limit
    xdmf = out / f"{name}.xdmf"
    header, rows = history.columns()
    header.append("newton_iterations")
    rows = [row + [its] for row, its in zip(rows, history.newton_iterations)]
    io.write_csv(out / f"{name}.csv", header, rows, comm)
    user = [m["name"] for m in d.monitors]
    panels = {f"{m['name']} [{monitor_unit(m)}]": {m["name"]: history.monitors[m["name"]]} for m in d.monitors}
    panels["energy [J]"] = {"kinetic": history.kinetic, "strain": history.strain, "total": list(history.total)}
    panels["max strain [-]"] = {"max vertex Green strain": history.monitors["max_strain"]}
    io.plot_time_series(out / f"{name}.png", history.time, panels, title=name, comm=comm)
    wall = time.perf_counter() - t0
    memory = io.peak_memory_mib(comm)
    iterations = [r.iterations for r in log]
    summary = {"scene": name, "kind": "dynamic", "integrator": d.integrator, "ranks": comm.size,
               "ndofs": model.ndofs, "steps": n_steps, "dt_s": dt, "dt_crit_s": dt_crit,
               "step_reductions": getattr(integ, "step_reductions", 0), "dt_final_s": integ.dt,
               "end_time_s": history.time[-1], "wall_s": wall, "time_integration_wall_s": run_wall,
               "kinetic_J": history.kinetic[-1], "strain_J": history.strain[-1],
               "external_work_J": history.external_work[-1], "dissipated_J": history.dissipated[-1],
               "max_strain_final": history.monitors["max_strain"][-1],
               "max_strain_recorded": max(history.monitors["max_strain"]),
               "newton_iterations": int(sum(history.newton_iterations)),
               "projection_iterations": int(sum(iterations)), "max_projection_iterations": max(iterations, default=0),
               "peak_memory_mib": memory["max_mib"], "peak_memory_total_mib": memory["total_mib"],
               "peak_memory_per_rank_mib": memory["per_rank_mib"],
               **{f"final_{m}": float(history.monitors[m][-1]) for m in user}}
    outputs = {"xdmf": xdmf, "csv": out / f"{name}.csv", "png": out / f"{name}.png",
               "summary": out / "summary.json"}
    checks = dynamic_checks(summary, scene.parsed.fabric.get("failure_strain", DEFAULT_FAILURE_STRAIN))
    summary["verdict"] = verdict(checks)
    io.write_json(outputs["summary"], summary, comm)
    for check in checks:
        if not check.passed:
            say(check.line())
    say(f"done: {n_steps} steps in {run_wall:.1f} s (total {wall:.1f} s); final kinetic {summary['kinetic_J']:.4g} J, "
        f"strain {summary['strain_J']:.4g} J, external work {summary['external_work_J']:.4g} J, dissipated "
        f"{summary['dissipated_J']:.4g} J; max strain {summary['max_strain_final']:.4g}"
        + (f"; projection iterations {sum(iterations)} (max {max(iterations, default=0)} per step)" if limit else "")
        + f"; peak memory {memory['max_mib']:.0f} MiB (max over {comm.size} rank(s))")
    say(f"wrote {', '.join(str(p) for p in outputs.values())}")
    return summary, outputs


class DynamicCheckpoint:
    """The checkpoints of a dynamic scene's run (fabricfem.io.Checkpoint files under <out>/checkpoint/).

    Every `every` records (default CHECKPOINT_EVERY) each rank saves the integrator's `state()` (d, v, a, t, step
    counts, work and dissipation, the step-halving state of Newmark; fabricfem.dynamics.newmark.TimeIntegrator)
    and its current step dt [s] with the explicit safe step's reductions,
    the strain-limit projection's log (its iterations per step; the projection keeps nothing else between steps),
    the obstacle contact's multipliers and stick points, the History so far and the record count; the XDMF series
    is closed and copied beside it (series_<records>.xdmf/.h5, rank 0; io.SurfaceSeries.snapshot) before the
    state is written, and older copies are removed after. `read()` checks the files (before the model is built),
    `restore(state)` puts the copy back as <name>.xdmf/.h5 (a kill may have left a broken HDF5 file) and
    restores the state: the run appends the later records to it. An
    integrator whose state cannot be saved exactly (PETSc TS, generalized-alpha) is refused naming it, and its
    runs write no checkpoints."""

    CONTACT_STATE = ("multiplier", "_stick_local", "_stick_segment", "active", "sliding", "segment", "time")

    def __init__(self, out: Path, comm, sha: str, every: int | None):
        every = CHECKPOINT_EVERY if every is None else every
        try:
            self.files = io.Checkpoint(out, comm, sha, every)
        except ValueError as exc:
            raise SceneError(f"dynamics.checkpoint_every: {exc}") from None
        self.out, self.comm, self.every = Path(out), comm, every
        self.xdmf, self.integrator, self.log, self.contact = None, None, [], None
        self.series: io.SurfaceSeries | None = None
        self.records = 0            # records of the last checkpoint written or read

    def attach(self, xdmf: Path, integrator, log: list, contact=None) -> None:
        """The run's XDMF file, integrator, strain-limit log (fabricfem.dynamics.strain_limit.attach) and
        obstacle contact (or None) whose state the checkpoints hold."""
        self.xdmf, self.integrator, self.log, self.contact = Path(xdmf), integrator, log, contact

    def after_record(self, history) -> None:
        if self.integrator.resumable and (len(history.time) - 1) % self.every == 0:
            self.save(history)

    def save(self, history) -> None:
        """Write the checkpoint of the run's state after its last record (all ranks)."""
        if not self.integrator.resumable:
            return
        records = len(history.time) - 1
        tag = f"series_{records}"
        self.series.snapshot(self.files.folder, tag)
        contact = {k: copy.deepcopy(getattr(self.contact, k)) for k in self.CONTACT_STATE
                   if self.contact is not None and hasattr(self.contact, k)}
        self.files.write({"records": records, "history": history, "integrator": self.integrator.state(),
                          "dt": self.integrator.dt, "step_reductions": getattr(self.integrator, "step_reductions", 0),
                          "projection_log": list(self.log), "contact": contact, "series": tag})
        if self.comm.rank == 0:
            for old in self.files.folder.glob("series_*"):
                if old.stem != tag:
                    old.unlink()
        self.records = records

    def read(self, integrator_class=None) -> dict:
        """This rank's saved state; SceneError when the run's `integrator_class` cannot resume, when there is no
        checkpoint or it is of another scene or rank count."""
        if integrator_class is not None and not integrator_class.resumable:
            raise SceneError(f"resume: the {integrator_class.__name__} integrator cannot resume from a checkpoint: "
                             f"{integrator_class.not_resumable}")
        if not self.files.exists():
            raise SceneError(f"resume: no checkpoint in {self.files.folder} (run the scene without --resume first)")
        try:
            return self.files.read()
        except ValueError as exc:
            raise SceneError(str(exc)) from None

    def restore(self, state: dict):
        """Restore a `read` state into the attached run (class docstring); returns the History of its records."""
        integ = self.integrator
        if not integ.resumable:
            raise SceneError(f"resume: the {type(integ).__name__} integrator cannot resume from a checkpoint: "
                             f"{integ.not_resumable}")
        integ.restore(state["integrator"])
        if state.get("dt", integ.dt) != integ.dt:     # the explicit safe step shortened it (older layouts: not saved)
            integ.set_time_step(state["dt"])
            integ.step_reductions = state["step_reductions"]
        self.log[:] = state["projection_log"]
        for key, value in state["contact"].items():
            setattr(self.contact, key, copy.deepcopy(value))
        io.SurfaceSeries.restore(self.xdmf, self.files.folder, state["series"], self.comm)
        self.records = state["records"]
        return state["history"]


