"""Roll-up: a fabric strip rolled into a full circle by an end moment, against the exact circle.

    .venv/bin/python demos/demo_rollup.py [--out results/demos/rollup] [--quick]

Data flow: mesh (meshes.plate, quadrilaterals, warp along the strip) -> forms (Naghdi shell, orthotropic
St. Venant-Kirchhoff) -> solver (solvers.loadstep: Newton by PETSc SNES with the exact Jacobian, load steps of
the end moment M = m 2 pi B / L, a moment vector in the global frame) -> outputs (rollup.xdmf for ParaView,
rollup.csv with the tip against the exact circle of radius B / M, rollup.png).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path

LENGTH, WIDTH = 0.3, 0.03                                                        # m
FABRIC = Fabric(E1=5e6, E2=3e6, G12=0.2e6, nu12=0.1, thickness=5e-4, density=600.0, name="cotton-like")


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[list[float]]:
    """Run into `out`; returns the rows (m, tip x, tip z, exact x, exact z, error / L)."""
    model = ShellModel(plate(LENGTH, WIDTH, 20 if quick else 60, 3, cell="quadrilateral", comm=comm), FABRIC)  # mesh
    model.clamp("left")
    B = FABRIC.bending_matrix[0, 0] * WIDTH                       # bending stiffness of the strip [N m^2]
    model.add_edge_moment("right", (0.0, -2.0 * np.pi * B / LENGTH / WIDTH, 0.0))   # N m/m at load factor 1
    series = io.SurfaceSeries(out / "rollup.xdmf", model.mesh)
    tip0, rows, surfaces = np.array([LENGTH, 0.0, 0.0]), [], [io.gather_surface(model.mesh)]

    def at_target(m: float):                                     # outputs at each requested load factor
        tip = tip0 + model.node_value(tip0)
        radius = LENGTH / (2.0 * np.pi * m)                       # exact: a circular arc of radius B / M
        exact = np.array([radius * np.sin(LENGTH / radius), radius * (1.0 - np.cos(LENGTH / radius))])
        rows.append([m, tip[0], tip[2], *exact, float(np.hypot(*(tip[[0, 2]] - exact)) / LENGTH)])
        series.write(model.displacement(), m)
        surfaces.append(io.gather_surface(model.mesh, model.displacement()))

    solve_load_path(model, [0.25, 0.5, 0.75, 1.0], initial_step=0.05, on_target=at_target)   # solver
    series.close()
    io.write_csv(out / "rollup.csv", ["m", "tip_x_m", "tip_z_m", "exact_x_m", "exact_z_m", "error_over_L"], rows,
                 comm)
    if comm.rank == 0:
        io.render_surfaces(out / "rollup.png", surfaces, title="strip rolled up by an end moment", camera="iso")
        print(f"roll-up: tip error / L at m = 1: {rows[-1][-1]:.1e}; wrote {out}/rollup.xdmf, rollup.csv, rollup.png")
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/rollup"))
    parser.add_argument("--quick", action="store_true", help="a coarser strip")
    args = parser.parse_args()
    main(args.out, args.quick)
