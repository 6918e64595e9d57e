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
from fabricfem.scenes.build import build_model, output_dir, scene_name
from fabricfem.scenes.schema import Scene
from fabricfem.scenes.sections import (
    OutputSection,
    SolverSection,
    section,
)
from fabricfem.solvers.loadstep import LoadStep, solve_load_path
from fabricfem.solvers.newton import NewtonSolver


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


