"""`fabricfem run SCENE`: build the model a scene describes, solve it, write the outputs.

Static scenes (load stepping to the solver targets) and dynamic scenes ([dynamics]: time integration
from rest) are run here; progress is shown on rank 0 with an estimated time left and the run ends with a
summary that includes the peak resident memory (max over ranks). Outputs of a static scene:
<dir>/solution.xdmf (ParaView), <dir>/history.csv (load factor, Newton iterations, probe displacement),
<dir>/final.png and <dir>/summary.json. Outputs of a dynamic scene <name>: <dir>/<name>.xdmf (displacement
time series), <dir>/<name>.csv (time [s], energies [J], monitors, max vertex Green strain [-], Newton
iterations), <dir>/<name>.png (monitors and energies over time) and <dir>/summary.json.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.body.arm import ArmDimensions
from fabricfem.contact.obstacles import Plane, RoundedBox, table_top
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics import CentralDifference, NewmarkIntegrator, critical_time_step, node_monitor
from fabricfem.dynamics.strain_limit import FastProjection, attach
from fabricfem.dynamics.ts import GeneralizedAlphaIntegrator
from fabricfem.scenes import wear
from fabricfem.scenes.build import build_fabric, build_mesh, sleeve_config
from fabricfem.scenes.schema import ALL_NODES, Scene, SceneError
from fabricfem.scenes.sections import (
    DynamicsSection,
    ModelSection,
    MonitorSection,
    OutputSection,
    SceneSection,
    SolverSection,
    from_table,
    section,
)
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import LoadStep, solve_load_path
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.solvers.system import base_model
from fabricfem.wear.checkpoint import Checkpoint
from fabricfem.wear.config import ContactSpec, FlexionSpec, RouteSpec, TubeSpec, check_fit
from fabricfem.wear.contract import WearHistory
from fabricfem.wear.garment import GarmentRun, build_garment_run
from fabricfem.wear.run import ROUTES, interrupt_flag, run_wear
from fabricfem.wear.sleeve import tube_flexion_run


def _components(values, n: int, where: str):
    if values is None:
        return None
    if len(values) != n:
        raise SceneError(f"{where}: expected {n} components, got {values!r}")
    out = []
    for v in values:
        if v == "free":
            out.append(None)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(float(v))
        else:
            raise SceneError(f"{where}: components are numbers or \"free\", got {v!r}")
    return out


def _node_locator(model: ShellModel, point, where: str):
    """Geometric locator of the mesh node at `point` (SceneError naming `where` if there is none)."""
    try:
        model.owned_node_dof(point, "u", 0)
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None
    p = np.asarray(point, dtype=float)
    return lambda x: np.linalg.norm(x.T - p, axis=1) < 1e-8 * max(1.0, float(np.abs(p).max()))


def build_model(scene: Scene, comm=MPI.COMM_WORLD) -> ShellModel:
    fabric = build_fabric(scene["fabric"])
    model_spec = section(ModelSection, scene.get("model"))
    kind = model_spec.kind
    fmesh = build_mesh(scene["mesh"], comm)
    model = ShellModel(fmesh, fabric, model=kind, rebase=model_spec.rebase)
    for i, support in enumerate(scene.get("support", [])):
        if "point" in support:
            where = _node_locator(model, support["point"], f"support[{i}].point")
        elif support["edge"] == ALL_NODES:
            where = lambda x: np.full(x.shape[1], True)   # noqa: E731 (every node)
        elif support["edge"] not in fmesh.tags:
            raise SceneError(f"support[{i}].edge: unknown edge {support['edge']!r}; available: {sorted(fmesh.tags)}")
        else:
            where = support["edge"]
        try:
            model.constrain(where, u=_components(support.get("u"), 3, f"support[{i}].u"),
                            theta=_components(support.get("theta"), 2, f"support[{i}].theta"))
        except ValueError as exc:
            if isinstance(exc, SceneError):
                raise
            raise SceneError(f"support[{i}]: {exc}") from None
    if "gravity" in scene.get("dynamics", {}):
        model.add_gravity(scene["dynamics"]["gravity"])
    for i, load in enumerate(scene.get("load", [])):
        where = f"load[{i}]"
        kind, value = load["type"], load.get("value")
        edge = load.get("edge")
        if kind in ("edge_traction", "edge_moment") and edge not in fmesh.tags:
            raise SceneError(f"{where}.edge: unknown edge {edge!r}; available: {sorted(fmesh.tags)}")
        if kind == "gravity":
            model.add_gravity(value if value is not None else (0.0, 0.0, -9.81))
        elif kind == "body_force":
            model.add_body_force(value)
        elif kind == "edge_traction":
            model.add_edge_traction(edge, value)
        elif kind == "pressure":
            model.add_pressure(float(value))
        elif kind == "edge_moment":
            model.add_edge_moment(edge, value)
        elif kind == "point":
            if "point" not in load:
                raise SceneError(f"{where}: a point load needs 'point' = [x, y, z]")
            model.add_point_load(load["point"], value)
    return model


@dataclass
class SceneOutcome:
    """What `fabricfem run` did: the runner's result, its status ("completed" or "stopped early: <why>") and the
    output folder; `exit_code` is 0 only for a completed run."""

    result: object
    status: str
    out: Path

    @property
    def exit_code(self) -> int:
        return 0 if self.status == "completed" else 1


def scene_sha256(scene: Scene) -> str:
    """SHA-256 of the scene's data (canonical JSON): identifies the scene a summary belongs to."""
    return hashlib.sha256(json.dumps(scene.data, sort_keys=True, default=str).encode()).hexdigest()


def run_scene(scene: Scene, comm=MPI.COMM_WORLD, out: Path | None = None, resume: bool = False) -> SceneOutcome:
    """Run a scene by its kind (RUNNERS: static load stepping, dynamic, wear) into its output folder (`out`,
    default [output] dir; io.OutputFolder: the previous run's outputs are removed first, summary.json records the
    status). A wear scene on the explicit engine and a dynamic scene write checkpoints (every CHECKPOINT_EVERY
    records, [dynamics] checkpoint_every) and, with `resume`, continue from the folder's checkpoint
    (fabricfem.wear.checkpoint, `run_dynamic_scene`)."""
    if out is not None:
        scene = Scene({**scene.data, "output": {**scene.data.get("output", {}), "dir": str(out)}}, scene.path,
                      scene.kind)
    out = output_dir(scene)
    sha = scene_sha256(Scene({k: v for k, v in scene.data.items() if k != "output"}, None, scene.kind))
    folder = io.OutputFolder(out, scene_sha256(scene), comm, keep=resume)
    try:
        result = RUNNERS[scene.kind](scene, out, comm, resume, sha)
    except Exception as exc:
        folder.finish(f"failed: {' '.join(str(exc).split())}")
        raise
    failure = result.failure if isinstance(result, (WearHistory, DynamicRun)) else ""
    status = f"stopped early: {failure}" if failure else "completed"
    folder.finish(status, result.summary() if isinstance(result, WearHistory) else None)
    return SceneOutcome(result, status, out)


CHECKPOINT_EVERY = 25       # records between the checkpoints of a wear run (explicit engine) or a dynamic scene


def run_wear_scene(scene: Scene, out: Path, comm=MPI.COMM_WORLD, resume: bool = False, sha: str = ""):
    """`fabricfem run` of a wear scene: its WearRun (`build_wear_run`) with progress, the recorder's outputs and
    the summary (fabricfem.wear.run.run_wear); the explicit engine checkpoints and resumes."""
    run, headline, render_at, output = build_wear_run(scene, comm)
    checkpoint = None
    if isinstance(run, GarmentRun):
        checkpoint = Checkpoint(out, comm, sha or scene_sha256(scene), CHECKPOINT_EVERY)
        if resume and not checkpoint.exists():
            raise SceneError(f"resume: no checkpoint in {out}/checkpoint (run the scene without --resume first)")
    return run_wear(run, out, headline, render_at, output.get("render", True), output.get("body_samples", 24),
                    checkpoint, resume)


def build_wear_run(scene: Scene, comm=MPI.COMM_WORLD):
    """The WearRun of a wear scene, its headline, the render coordinates and [output]: an arm in a tube flexing at
    the elbow by its [route] solver (fabricfem.wear.sleeve.tube_flexion_run on the explicit engine, the Newton
    routes of fabricfem.wear.run.ROUTES), any other garment on the explicit engine (`build_garment_run`)."""
    data = scene.data
    if wear.is_tube_flexion(data):
        run = tube_scene_run(scene, comm)
    else:
        run = garment_scene_run(scene, comm)
    output = data.get("output", {})
    render_at = output.get("render_at")
    if render_at is None:
        end = run.duration if isinstance(run, GarmentRun) else None
        render_at = ([run.axis_at(run.motion_start + f * (end - run.motion_start)) if run.axis is not None
                      else f * end for f in (1 / 3, 2 / 3, 1.0)] if end is not None else
                     [f * data["motion"].get("final_angle", 57.0) for f in (1 / 3, 2 / 3, 1.0)])
    body = list(run.body.segments)
    headline = (f"{run.name}: {run.model.ndofs} dofs, body {body}, {comm.size} rank(s); "
                f"mu = {data.get('contact', {}).get('friction', 0.1 if wear.is_tube_flexion(data) else 0.0)}; "
                f"{run.describe()}")
    return run, headline, render_at, output


def tube_scene_run(scene: Scene, comm):
    """The arm-in-tube sleeve of a wear scene by its [route] solver: the explicit engine's run of the scene's
    sections (any fabric) or a Newton route of its SleeveConfig (E1 = E2)."""
    data = scene.data
    solver = wear.route_of(data)
    if solver != "explicit":
        return ROUTES[solver](sleeve_config(data), comm)
    fabric = wear.wear_fabric(data, build_fabric)
    garment = {k: v for k, v in data["garment"].items() if k in TubeSpec.__dataclass_fields__}
    if "quadrature" in garment:
        garment["quadrature"] = tuple(garment["quadrature"])
    try:
        tube_spec = TubeSpec(**garment)
        arm = from_table(ArmDimensions, {k: v for k, v in data["body"].items() if k in ArmDimensions.__dataclass_fields__})
        motion = from_table(FlexionSpec, {k: v for k, v in data["motion"].items() if k in FlexionSpec.__dataclass_fields__})
        contact = from_table(ContactSpec, data.get("contact", {}))
        route = from_table(RouteSpec, {k: v for k, v in data.get("route", {}).items()
                                       if k in RouteSpec.__dataclass_fields__})
        check_fit(tube_spec.radius, arm)
    except ValueError as exc:
        raise SceneError(f"garment: {exc}") from None
    return tube_flexion_run(scene_name(scene), fabric, tube_spec, arm, motion, contact, route, comm)


def garment_scene_run(scene: Scene, comm) -> GarmentRun:
    """The explicit engine's GarmentRun of a wear scene (fabricfem.scenes.wear.plan and garment_mesh)."""
    data = scene.data
    fabric = wear.wear_fabric(data, build_fabric)
    plan = wear.plan(data, fabric, scene.path)
    fmesh, seams, holds, pattern_garment = wear.garment_mesh(data, scene.path, comm)
    if plan.handles and pattern_garment is None:
        raise SceneError("donning: pull_edges and belt_edges name pattern edges; this garment is a tube")
    handles = wear.edge_handles(plan.handles, pattern_garment) if plan.handles else []
    garment = section(wear.GarmentSection, data["garment"])
    return build_garment_run(scene_name(scene), fmesh, fabric, plan.body, seams=seams, holds=holds,
                             torques=plan.torques, timeline=plan.timeline, settings=plan.settings,
                             contact_method=plan.contact.method or "lagrange", friction=plan.contact.friction,
                             penalty=plan.contact.penalty,
                             psri_degrees=tuple(garment.quadrature) if garment.quadrature else (4, 2),
                             axis=plan.axis, handles=handles)


def run_static_scene(scene: Scene, comm=MPI.COMM_WORLD) -> list[LoadStep]:
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    out = output_dir(scene)
    output = section(OutputSection, scene.get("output"))
    probe = output.probe
    solver_spec = section(SolverSection, scene["solver"])
    targets = list(np.atleast_1d(solver_spec.targets).astype(float))
    t0 = time.perf_counter()
    model = build_model(scene, comm)
    say(f"{model.model} shell, {model.ndofs} dofs, {model.comm.size} rank(s); solving to load factor {targets[-1]:g}")
    solver = NewtonSolver(model, solver_spec.petsc_options)
    series = io.SurfaceSeries(out / "solution.xdmf", model.mesh)
    series.write(model.displacement(), 0.0)
    rows = []
    clock = io.Progress()

    def progress(step: LoadStep):
        value = model.node_value(probe) if probe is not None else np.full(3, np.nan)
        rows.append([step.load_factor, step.iterations, *value])
        done = step.load_factor / targets[-1]
        say(f"  load factor {step.load_factor:8.4f}  Newton {step.iterations:2d}  {clock(done)}")

    history = solve_load_path(model, targets, solver=solver, initial_step=solver_spec.initial_step,
                              min_step=solver_spec.min_step, progress=progress,
                              on_target=lambda lam: series.write(model.displacement(), lam))
    series.close()
    io.write_csv(out / "history.csv", ["load_factor", "newton_iterations", "probe_ux_m", "probe_uy_m", "probe_uz_m"],
                 rows, comm)
    if output.render:
        surfaces = [io.gather_surface(model.mesh), io.gather_surface(model.mesh, model.displacement())]
        io.render_surfaces(out / "final.png", surfaces, title=scene_name(scene),
                           colors=["lightgray", "steelblue"], camera="iso")
    wall = time.perf_counter() - t0
    memory = io.peak_memory_mib(comm)
    say(f"done: {len(history)} load steps, {sum(h.iterations for h in history)} Newton iterations, {wall:.1f} s, "
        f"peak memory {memory['max_mib']:.0f} MiB (max over {comm.size} rank(s))")
    summary = {"scene": scene_name(scene), "kind": "static", "ranks": comm.size, "ndofs": model.ndofs,
               "load_steps": len(history), "newton_iterations": sum(h.iterations for h in history),
               "wall_s": wall, "peak_memory_mib": memory["max_mib"], "peak_memory_per_rank_mib": memory["per_rank_mib"]}
    if probe is not None:
        value = model.node_value(probe)
        summary["probe_displacement_m"] = list(value)
        summary.update({f"probe_u{c}_m": float(v) for c, v in zip("xyz", value)})
        say(f"probe {tuple(probe)}: displacement {value} m")
    io.write_json(out / "summary.json", summary, comm)
    say(f"wrote {out}/solution.xdmf, history.csv, summary.json" +
        (", final.png" if output.render else ""))
    return history


def scene_name(scene: Scene) -> str:
    """[scene] name, else the file's stem, else "scene"."""
    return section(SceneSection, scene.get("scene")).name or (scene.path.stem if scene.path is not None else "scene")


def output_dir(scene: Scene) -> Path:
    """[output] dir, else results/<scene name>."""
    return Path(section(OutputSection, scene.get("output")).dir or f"results/{scene_name(scene)}")


# ---------------------------------------------------------------------------------------- dynamic scenes
def build_obstacles(spec: list[dict]) -> list:
    """Plane / RoundedBox obstacles of [[dynamics.obstacles]] (validated by fabricfem.scenes.schema), SI units."""
    out = []
    for i, o in enumerate(spec):
        try:
            if o["type"] == "plane":
                out.append(Plane(o["point"], o["normal"]))
            elif o["type"] == "box":
                out.append(RoundedBox(o["lower"], o["upper"], float(o["radius"])))
            else:
                out.append(table_top(o["center"], float(o["half_x"]), float(o["half_y"]), float(o["height"]),
                                     float(o["fillet_radius"])))
        except ValueError as exc:
            raise SceneError(f"dynamics.obstacles[{i}]: {exc}") from None
    return out


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
    failure: str = ""           # why the run stopped before end_time (an interrupt), "" when it completed


def _load_function(ramp_time: float):
    """lambda(t) = min(t / ramp_time, 1) (1 at once when ramp_time = 0)."""
    if ramp_time > 0.0:
        return lambda t: min(t / ramp_time, 1.0)
    return 1.0


# [dynamics] integrator -> its class (build_integrator)
INTEGRATORS = {"explicit": CentralDifference, "newmark": NewmarkIntegrator,
               "generalized-alpha": GeneralizedAlphaIntegrator}


def build_integrator(spec: dict, model):
    """(integrator, n_steps, dt [s], dt_crit [s] or None) for a [dynamics] section; dt is end_time / n_steps.
    `model`: the ShellModel or a CompositeSystem of it (fabricfem.solvers.system, e.g. with obstacle contact)."""
    d = section(DynamicsSection, spec)
    kind = d.integrator
    end_time = float(d.end_time)
    rayleigh = tuple(float(c) for c in d.rayleigh)
    common = dict(load_factor=_load_function(float(d.ramp_time)), rayleigh=rayleigh, air_drag=float(d.air_drag))
    dt_crit = critical_time_step(base_model(model), rayleigh) if kind == "explicit" else None
    dt = float(d.dt_fraction) * dt_crit if d.dt == "auto" else float(d.dt)
    n_steps = max(1, math.ceil(end_time / dt * (1.0 - 1e-12)))
    dt = end_time / n_steps
    if kind == "explicit":
        force = bool(d.force)
        if dt > dt_crit and not force:
            raise SceneError(f"dynamics.dt: {dt:.6g} s exceeds the critical time step {dt_crit:.6g} s of this mesh "
                             f"(ratio {dt / dt_crit:.3g}, [Man2006, eqs. 2.86-2.87]); use a smaller dt or force = true")
        integrator = CentralDifference(model, dt, force=force, dt_crit=dt_crit, **common)
    elif kind == "newmark":
        integrator = NewmarkIntegrator(model, dt, beta=float(d.beta), gamma=float(d.gamma), lumped=bool(d.lumped),
                                       **common)
    else:
        integrator = GeneralizedAlphaIntegrator(model, dt, rho_inf=float(d.rho_inf), lumped=bool(d.lumped), **common)
    return integrator, n_steps, dt, dt_crit


class _StrainMeter:
    """Vertex Green strains (patch averages of fabricfem.dynamics.strain_limit) once per recorded step."""

    def __init__(self, projection, integrator):
        self.projection, self.integrator = projection, integrator
        self._step, self._summary = None, None

    def summary(self) -> dict[str, float]:
        if self._step != self.integrator.step_count:
            self._summary = self.projection.strain_summary()
            self._step = self.integrator.step_count
        return self._summary

    def max_strain(self) -> float:
        s = self.summary()
        return max(s["max_warp"], s["max_weft"])


def _max_displacement(model: ShellModel) -> float:
    """max over nodes of |u| [m], all ranks."""
    u = model.displacement().x.array.reshape(-1, 3)
    local = float(np.linalg.norm(u, axis=1).max(initial=0.0))
    return model.comm.allreduce(local, op=MPI.MAX)


def build_monitors(spec: list[dict], model: ShellModel, meter: _StrainMeter) -> dict:
    """{name: callable} of [[dynamics.monitors]] (point values on all ranks, global quantities)."""
    quantities = {"max_warp_strain": lambda: meter.summary()["max_warp"],
                  "max_weft_strain": lambda: meter.summary()["max_weft"],
                  "mean_warp_strain": lambda: meter.summary()["mean_warp"],
                  "mean_weft_strain": lambda: meter.summary()["mean_weft"],
                  "max_displacement": lambda: _max_displacement(model)}
    monitors = {}
    for i, table in enumerate(spec):
        m = section(MonitorSection, table)
        if m.quantity is not None:
            monitors[m.name] = quantities[m.quantity]
            continue
        try:
            monitors[m.name] = node_monitor(model, m.point, m.field,
                                            m.component if m.component is not None else 2 if m.field == "u" else 0)
        except ValueError as exc:
            raise SceneError(f"dynamics.monitors[{i}].point: {exc}") from None
    return monitors


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
    `resume` continues from the output folder's checkpoint; Ctrl-C (SIGINT, any rank) stops the run at the next
    record with valid outputs and a checkpoint there (`DynamicRun.failure` says so). `sha`: the scene's hash
    the checkpoint is checked against (default scene_sha256(scene))."""
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
    meter = _StrainMeter(projection, integrator)
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
            history = integrator.run(n_steps, monitors=monitors, xdmf=series, output_every=output_every,
                                     progress=_progress(comm, n_steps, say), history=history,
                                     after_record=checkpoint.after_record, should_stop=interrupted)
        if history.stopped and checkpoint.records != len(history.time) - 1:
            checkpoint.save(history)        # the interrupted run resumes from its last record
    finally:
        series.close()
    run_wall = time.perf_counter() - start
    header, rows = history.columns()
    header.append("newton_iterations")
    rows = [row + [its] for row, its in zip(rows, history.newton_iterations)]
    io.write_csv(out / f"{name}.csv", header, rows, comm)
    user = [m["name"] for m in d.monitors]
    panels = {m: {m: history.monitors[m]} for m in user}
    panels["energy [J]"] = {"kinetic": history.kinetic, "strain": history.strain, "total": list(history.total)}
    panels["max strain [-]"] = {"max vertex Green strain": history.monitors["max_strain"]}
    io.plot_time_series(out / f"{name}.png", history.time, panels, title=name, comm=comm)
    wall = time.perf_counter() - t0
    memory = io.peak_memory_mib(comm)
    iterations = [r.iterations for r in log]
    summary = {"scene": name, "kind": "dynamic", "integrator": d.integrator, "ranks": comm.size,
               "ndofs": model.ndofs, "steps": n_steps, "dt_s": dt, "dt_crit_s": dt_crit,
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
    io.write_json(outputs["summary"], summary, comm)
    say(f"done: {n_steps} steps in {run_wall:.1f} s (total {wall:.1f} s); final kinetic {summary['kinetic_J']:.4g} J, "
        f"strain {summary['strain_J']:.4g} J, external work {summary['external_work_J']:.4g} J, dissipated "
        f"{summary['dissipated_J']:.4g} J; max strain {summary['max_strain_final']:.4g}"
        + (f"; projection iterations {sum(iterations)} (max {max(iterations, default=0)} per step)" if limit else "")
        + f"; peak memory {memory['max_mib']:.0f} MiB (max over {comm.size} rank(s))")
    say(f"wrote {', '.join(str(p) for p in outputs.values())}")
    if history.stopped:
        say(f"STOPPED EARLY: {history.stopped}; continue with --resume")
    integrator.destroy()
    projection.destroy()
    return DynamicRun(history, n_steps, dt, dt_crit, wall, memory["max_mib"], summary, outputs, history.stopped)


class DynamicCheckpoint:
    """The checkpoints of a dynamic scene's run (fabricfem.io.Checkpoint files under <out>/checkpoint/).

    Every `every` records (default CHECKPOINT_EVERY) each rank saves the integrator's `state()` (d, v, a, t, step
    counts, work and dissipation, the step-halving state of Newmark; fabricfem.dynamics.newmark.TimeIntegrator),
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
        self.log[:] = state["projection_log"]
        for key, value in state["contact"].items():
            setattr(self.contact, key, copy.deepcopy(value))
        io.SurfaceSeries.restore(self.xdmf, self.files.folder, state["series"], self.comm)
        self.records = state["records"]
        return state["history"]


def _say_static_resume(scene: Scene, comm) -> None:
    if comm.rank == 0:
        print(f"{scene_name(scene)}: a static scene has no checkpoint; --resume solves it from the start", flush=True)


# scene kind -> runner(scene, out, comm, resume, sha)
RUNNERS = {
    "static": lambda scene, out, comm, resume, sha: (_say_static_resume(scene, comm) if resume else None,
                                                     run_static_scene(scene, comm))[1],
    "dynamic": lambda scene, out, comm, resume, sha: run_dynamic_scene(scene, comm, resume, sha),
    "wear": run_wear_scene}
