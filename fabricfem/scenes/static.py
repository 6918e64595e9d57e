"""Static scenes: the shell a scene describes (mesh, fabric, supports, loads) solved by load stepping.

Outputs of a static scene: <dir>/solution.xdmf (ParaView), <dir>/history.csv (load factor, Newton iterations,
probe displacement [m]), <dir>/final.png (the deformed shell coloured by the displacement magnitude |u| [m] with its
colour bar, the undeformed shell translucent behind it) and <dir>/summary.json; progress on rank 0 with an estimated
time left.
"""
from __future__ import annotations

import time

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.scenes.build import build_fabric, build_mesh, output_dir, scene_name
from fabricfem.scenes.schema import ALL_NODES, Scene, SceneError
from fabricfem.scenes.sections import (
    ModelSection,
    OutputSection,
    SolverSection,
    section,
)
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import LoadStep, solve_load_path
from fabricfem.solvers.newton import NewtonSolver


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
    model = ShellModel(fmesh, fabric, model=kind, rebase=model_spec.rebase, psri_degrees=model_spec.psri_degrees)
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
    if output.render:   # the deformed shell coloured by |u| with its colour bar, the undeformed one translucent
        reference = io.gather_surface(model.mesh)
        deformed = io.gather_surface(model.mesh, model.displacement())
        if comm.rank == 0:
            io.render_field(out / "final.png", deformed, np.linalg.norm(deformed[0] - reference[0], axis=1),
                            f"{scene_name(scene)}: deformed, coloured by |u| (translucent: undeformed)",
                            bodies=[reference], camera="iso", scalar_bar_title="displacement |u| [m]")
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


