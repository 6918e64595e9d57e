"""`fabricfem run SCENE`: build the model a scene describes, solve it, write the outputs.

Static scenes (load stepping to the solver targets) are run here; progress is shown on rank 0
and the run ends with a summary. Outputs: <dir>/solution.xdmf (ParaView), <dir>/history.csv
(load factor, Newton iterations, probe displacement) and <dir>/final.png.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.meshes import plate, tube
from fabricfem.scene import Scene, SceneError
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import LoadStep, solve_load_path
from fabricfem.solvers.newton import NewtonSolver


def build_fabric(spec: dict) -> Fabric:
    law = None
    kind = spec.get("bending_law")
    if kind == "kawabata":
        if "kawabata_coefficients" not in spec:
            raise SceneError("fabric: bending_law = 'kawabata' needs kawabata_coefficients")
        law = KawabataBending(tuple(float(a) for a in spec["kawabata_coefficients"]))
    elif kind == "square_root":
        if "B0" not in spec or "kappa0" not in spec:
            raise SceneError("fabric: bending_law = 'square_root' needs B0 and kappa0")
        law = SquareRootBending(float(spec["B0"]), float(spec["kappa0"]))
    elif kind is not None:
        raise SceneError(f"fabric.bending_law: unknown law {kind!r}; allowed: 'kawabata', 'square_root'")
    rigidity = spec.get("bending_rigidity")
    try:
        return Fabric(E1=float(spec["E1"]), E2=float(spec["E2"]), G12=float(spec["G12"]), nu12=float(spec["nu12"]),
                      thickness=float(spec["thickness"]), density=float(spec.get("density", 0.0)),
                      G13=spec.get("G13"), bending_rigidity=tuple(rigidity) if rigidity else None,
                      bending_law=law, name=spec.get("name", "fabric"))
    except ValueError as exc:
        raise SceneError(f"fabric: {exc}") from None


def build_mesh(spec: dict, comm):
    kind = spec["type"]
    if kind == "plate":
        return plate(spec["lx"], spec["ly"], spec["nx"], spec["ny"], cell=spec.get("cell", "quadrilateral"),
                     structured=spec.get("structured", True), comm=comm)
    return tube(spec["length"], spec["radius"], spec["n_around"], spec["n_along"],
                cell=spec.get("cell", "quadrilateral"), order=spec.get("order", 1), comm=comm)


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


def build_model(scene: Scene, comm=MPI.COMM_WORLD) -> ShellModel:
    fabric = build_fabric(scene["fabric"])
    model_spec = scene.get("model", {})
    kind = model_spec.get("kind", "naghdi")
    fmesh = build_mesh(scene["mesh"], comm)
    model = ShellModel(fmesh, fabric, model=kind, rebase=model_spec.get("rebase", True))
    for i, support in enumerate(scene.get("support", [])):
        if support["edge"] not in fmesh.tags:
            raise SceneError(f"support[{i}].edge: unknown edge {support['edge']!r}; available: {sorted(fmesh.tags)}")
        model.constrain(support["edge"], u=_components(support.get("u"), 3, f"support[{i}].u"),
                        theta=_components(support.get("theta"), 2, f"support[{i}].theta"))
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


def run_scene(scene: Scene, comm=MPI.COMM_WORLD):
    """Run a scene: sleeve scenes (with [body]/[motion]/[contact]) go to fabricfem.sleeve, others are
    static load-stepping scenes (returns the list of LoadStep)."""
    if "body" in scene.data:
        from fabricfem.sleeve import run_sleeve_scene
        return run_sleeve_scene(scene, comm)
    return run_static_scene(scene, comm)


def run_static_scene(scene: Scene, comm=MPI.COMM_WORLD) -> list[LoadStep]:
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    out = Path(scene.get("output", {}).get("dir", f"results/{scene.get('scene', {}).get('name', 'scene')}"))
    probe = scene.get("output", {}).get("probe")
    solver_spec = scene["solver"]
    targets = list(np.atleast_1d(solver_spec["targets"]).astype(float))
    t0 = time.perf_counter()
    model = build_model(scene, comm)
    say(f"{model.model} shell, {model.ndofs} dofs, {model.comm.size} rank(s); solving to load factor {targets[-1]:g}")
    solver = NewtonSolver(model, solver_spec.get("petsc_options"))
    series = io.SurfaceSeries(out / "solution.xdmf", model.mesh)
    series.write(model.displacement(), 0.0)
    rows = []

    def progress(step: LoadStep):
        value = model.node_value(probe) if probe is not None else np.full(3, np.nan)
        rows.append([step.load_factor, step.iterations, *value])
        elapsed = time.perf_counter() - t0
        done = step.load_factor / targets[-1]
        eta = elapsed * (1 - done) / max(done, 1e-12)
        say(f"  load factor {step.load_factor:8.4f}  Newton {step.iterations:2d}  [{done:5.1%}, "
            f"{elapsed:6.1f} s, about {eta:5.1f} s left]")

    history = solve_load_path(model, targets, solver=solver, initial_step=solver_spec.get("initial_step"),
                              min_step=solver_spec.get("min_step", 1e-6), progress=progress,
                              on_target=lambda lam: series.write(model.displacement(), lam))
    series.close()
    io.write_csv(out / "history.csv", ["load_factor", "newton_iterations", "probe_ux_m", "probe_uy_m", "probe_uz_m"],
                 rows, comm)
    if scene.get("output", {}).get("render", True):
        surfaces = [io.gather_surface(model.mesh), io.gather_surface(model.mesh, model.displacement())]
        io.render_surfaces(out / "final.png", surfaces, title=scene.get("scene", {}).get("name", ""),
                           colors=["lightgray", "steelblue"], camera="iso")
    wall = time.perf_counter() - t0
    say(f"done: {len(history)} load steps, {sum(h.iterations for h in history)} Newton iterations, {wall:.1f} s")
    if probe is not None:
        say(f"probe {tuple(probe)}: displacement {model.node_value(probe)} m")
    say(f"wrote {out}/solution.xdmf, history.csv" + (", final.png" if scene.get("output", {}).get("render", True)
                                                    else ""))
    return history
