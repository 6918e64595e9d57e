"""The default demo: a cotton-like strip rolled up into a full circle by an end moment.

Writes results/demo/rollup.xdmf (ParaView), rollup.csv (tip position against the exact circle)
and rollup.png (the strip at m = 0, 0.25, 0.5, 0.75, 1).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import Timer, references

LENGTH, WIDTH = 0.30, 0.03  # m
FABRIC = Fabric(E1=5e6, E2=3e6, G12=0.2e6, nu12=0.0, thickness=5e-4, density=600.0, name="cotton-like")


def rollup_demo(out: str = "results/demo", comm=MPI.COMM_WORLD) -> list[list[float]]:
    out = Path(out)
    say = (lambda *a: print(*a, flush=True)) if comm.rank == 0 else (lambda *a: None)
    with Timer() as timer:
        model = ShellModel(plate(LENGTH, WIDTH, 60, 3, cell="quadrilateral", comm=comm), FABRIC)
        model.clamp("left")
        B1 = FABRIC.bending_matrix[0, 0] * WIDTH  # bending stiffness of the strip [N m^2]
        M = 2.0 * np.pi * B1 / LENGTH
        model.add_edge_moment("right", (0.0, -M / WIDTH, 0.0))
        say(f"roll-up demo: {model.ndofs} dofs, end moment up to {M:.3e} N m")
        series = io.SurfaceSeries(out / "rollup.xdmf", model.mesh)
        series.write(model.displacement(), 0.0)
        surfaces = [io.gather_surface(model.mesh)]
        tip0 = np.array([LENGTH, 0.0, 0.0])
        rows = []

        def at_target(m):
            tip = tip0 + model.node_value(tip0)
            exact = references.rollup_tip(LENGTH, m * 2.0 * np.pi / LENGTH)
            err = np.hypot(tip[0] - exact[0], tip[2] - exact[1]) / LENGTH
            rows.append([m, tip[0], tip[2], exact[0], exact[1], err])
            series.write(model.displacement(), m)
            surfaces.append(io.gather_surface(model.mesh, model.displacement()))
            say(f"  m = {m:4.2f}: tip ({tip[0]:+.5f}, {tip[2]:+.5f}) m, exact ({exact[0]:+.5f}, {exact[1]:+.5f}) m, "
                f"error {err:.1e} L  [{timer.elapsed:.1f} s]")

        solve_load_path(model, [0.25, 0.5, 0.75, 1.0], initial_step=0.05, on_target=at_target)
        series.close()
    io.write_csv(out / "rollup.csv", ["m", "tip_x_m", "tip_z_m", "exact_x_m", "exact_z_m", "error_over_L"], rows, comm)
    if comm.rank == 0:
        io.render_surfaces(out / "rollup.png", surfaces, title="fabric strip rolled up by an end moment, m = 0 ... 1",
                           colors=["lightgray", "khaki", "orange", "tomato", "firebrick"], camera="iso")
    say(f"done in {timer.elapsed:.1f} s: wrote {out}/rollup.xdmf, rollup.csv, rollup.png")
    return rows
