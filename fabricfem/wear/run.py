"""Run a sleeve configuration by its route (explicit, implicit, quasistatic) and the sleeve scene's outputs."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np
from dolfinx import fem as dfem
from dolfinx import io as dio
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.wear.outputs import body_surface, plot_torque, posed_bodies, render_pressure
from fabricfem.wear.sleeve import (SleeveConfig, SleeveHistory, SleeveStep, build_explicit, build_sleeve,
                                   config_from_scene, format_breakdown, run_explicit, run_quasistatic)
from fabricfem.wear.sleeve_implicit import build_implicit, run_implicit


def run_sleeve(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD,
               on_step: Callable[[SleeveStep], None] | None = None, stop_on_failure: bool = True) -> SleeveHistory:
    """Build and flex one sleeve configuration (config.solver: explicit, implicit or quasistatic); returns its
    torque history."""
    t0 = time.perf_counter()
    if config.solver == "implicit":
        problem = build_implicit(config, comm)
        history = run_implicit(problem, on_step=on_step, stop_on_failure=stop_on_failure)
        problem.solver.destroy()
    elif config.solver == "explicit":
        problem = build_explicit(config, comm)
        history = run_explicit(problem, on_step=on_step, stop_on_failure=stop_on_failure)
        problem.integrator.destroy()
    else:
        problem = build_sleeve(config, comm)
        history = run_quasistatic(problem, on_step=on_step, stop_on_failure=stop_on_failure)
        problem.solver.destroy()
    history.wall = time.perf_counter() - t0
    return history


def run_sleeve_scene(scene, comm: MPI.Comm = MPI.COMM_WORLD) -> SleeveHistory:
    """`fabricfem run` for sleeve scenes: flex the arm and write, under output.dir,
    cloth.xdmf (sleeve displacement and contact pressure per angle), body_NNNN.vtp + body.pvd (arm surfaces
    per angle), torque.csv (resisting elbow torque vs angle), torque.png and pressure_<angle>.png renders."""
    say = (lambda msg: print(msg, flush=True)) if comm.rank == 0 else (lambda msg: None)
    config = config_from_scene(scene)
    output = scene.get("output", {})
    out = Path(output.get("dir", f"results/{config.name}"))
    render = output.get("render", True)
    render_angles = [float(a) for a in output.get("render_angles", [config.final_angle / 3,
                                                                    2 * config.final_angle / 3,
                                                                    config.final_angle])]
    samples = int(output.get("body_samples", 24))
    t0 = time.perf_counter()
    explicit = config.solver == "explicit"
    problem = build_explicit(config, comm) if explicit else build_sleeve(config, comm)
    route = (f"explicit central differences, dt = {problem.dt:.3g} s (estimated critical step {problem.dt_estimate:.3g} s "
             f"with rotary-inertia scale {config.rotary_inertia_scale:g}, {problem.dt_estimate_unscaled:.3g} s without), "
             f"mass damping {config.damping:g} 1/s, records every {config.output_angle_step:g} deg"
             + (f", dynamic similarity: flexion at {config.flexion_speed:.4g} deg/s (c / c_ref = "
                f"{config.similarity_factor:.4g})" if config.dynamic_similarity else "")
             if explicit else f"{config.angle_steps} quasi-static steps")
    say(f"sleeve: {config.n_around} x {config.n_along} Q2 tube, {problem.model.ndofs} dofs, {comm.size} rank(s); "
        f"mu = {config.friction}, {config.method} contact, gravity {'on' if config.gravity else 'off'}; "
        f"flexion to {config.final_angle} deg by {route}")
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    V2 = problem.model.V2
    u_out = dfem.Function(V2, name="displacement")
    P = dfem.FunctionSpace(problem.model.mesh, ("Lagrange", 2))
    p_out = dfem.Function(P, name="contact_pressure")
    xdmf = dio.XDMFFile(comm, str(out / "cloth.xdmf"), "w")
    xdmf.write_mesh(problem.model.mesh)
    frames: list[tuple[float, str]] = []
    pending = sorted(render_angles)

    def on_step(step: SleeveStep):
        u_out.interpolate(problem.model.displacement())
        p_out.interpolate(problem.contact.pressure_field())   # explicit: time-averaged over the record
        xdmf.write_function(u_out, step.angle)
        xdmf.write_function(p_out, step.angle)
        if comm.rank == 0:
            import pyvista as pv      # optional heavy package: only when body frames are written
            bp, bc = body_surface(posed_bodies(problem, step.angle), samples)
            name = f"body_{len(frames):04d}.vtp"
            pv.PolyData(bp, np.hstack([np.full((len(bc), 1), 3), bc]).ravel()).save(str(out / name))
            frames.append((step.angle, name))
        while render and pending and step.angle >= pending[0] - 1e-9:
            angle = pending.pop(0)
            render_pressure(out / f"pressure_{angle:04.1f}deg.png", problem,
                             f"{config.name}: elbow {step.angle:.1f} deg, contact pressure [Pa]", step.angle)
        done = step.angle / config.final_angle
        elapsed = time.perf_counter() - t0
        eta = elapsed * (1 - done) / max(done, 1e-12) if done > 0 else float("nan")
        work = (f"steps {step.time_steps:5d}  KE/SE {step.kinetic_energy / step.strain_energy if step.strain_energy else 0:.1e}"
                if explicit else f"Newton {step.newton_iterations:3d}")
        say(f"  angle {step.angle:6.2f} deg  torque {step.torque:+.4e} N m  {work}  "
            f"penetration {step.max_penetration:.1e} m  [{done:5.1%}, {elapsed:6.1f} s, about {eta:6.1f} s left]")

    runner = run_explicit if explicit else run_quasistatic
    history = runner(problem, on_step=on_step, stop_on_failure=False)
    xdmf.close()
    history.wall = time.perf_counter() - t0
    fio.write_csv(out / "torque.csv", SleeveHistory.HEADER, history.rows(), comm)
    if comm.rank == 0:
        with open(out / "body.pvd", "w") as f:
            f.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n<Collection>\n')
            for angle, name in frames:
                f.write(f'  <DataSet timestep="{angle}" file="{name}"/>\n')
            f.write("</Collection>\n</VTKFile>\n")
    plot_torque(out / "torque.png", {f"mu = {config.friction}": (history.angles, history.torques)},
                f"{config.name}: elbow resisting torque")
    if explicit:
        problem.integrator.destroy()
    else:
        problem.solver.destroy()
    last = history.steps[-1]
    work = (f"{sum(s.time_steps for s in history.steps)} explicit steps, largest KE/SE {history.kinetic_ratio():.2e}"
            if explicit else f"{sum(s.newton_iterations for s in history.steps)} Newton iterations")
    say(f"done: {len(history.steps) - 1} records to {last.angle:.2f} deg, {work}, {history.wall:.1f} s; "
        f"torque at {last.angle:.2f} deg: {last.torque:.4e} N m; largest penetration "
        f"{max(s.max_penetration for s in history.steps):.2e} m; start clearance {history.initial_gap * 1e3:.2f} mm")
    if explicit and "ms_per_step" in history.timings:
        say(f"time per part: {format_breakdown(history.timings)}")
    if history.failure:
        say(f"STOPPED EARLY: {history.failure}")
    say(f"wrote {out}/cloth.xdmf, body.pvd (+ body_*.vtp), torque.csv, torque.png"
        + (", pressure_*.png" if render else ""))
    return history
