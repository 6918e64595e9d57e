"""Drape: a strip of fabric on a table, hanging over its edge under its own weight [Eischen2000, sec. 4.3].

    .venv/bin/python demos/demo_drape.py [--out results/demos/drape] [--quick]

Data flow: mesh (meshes.plate, the strip from x = -(L - a) to the overhang a) -> forms (Naghdi shell, isotropic)
-> contact (contact.ContactProblem: penalty contact with the table, a rounded box, as a ResidualTerm of the
shell: problem.system) -> solver (load steps on the weight, Newton) -> outputs (drape.xdmf, drape.png and the
lift-off point, tip deflection and the contact force against the weight, which global equilibrium fixes).
The strip is the overhanging beam of [Eischen2000, sec. 4.3]: its tip deflection, 0.81 mm, is the theory row
0.0812 cm (the verify case overhanging-beam checks it within 2%).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.contact.obstacles import table_edge
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.solvers.newton import NewtonSolver

GF = 9.80665e-3                                        # N, one gram-force
LENGTH, OVERHANG, WIDTH = 0.06, 0.015, 0.0025          # m: strip, overhang past the table edge, width
EA, EI, WEIGHT = 2809.0 * GF, 0.386 * GF * 1e-4, 0.0255 * GF / 1e-2   # N, N m^2, N/m [Eischen2000, sec. 4.3]
THICKNESS = (12.0 * EI / EA) ** 0.5                    # m: E t b = EA and E t^3 b / 12 = EI
FABRIC = Fabric.isotropic(E=EA / (WIDTH * THICKNESS), nu=0.0, thickness=THICKNESS)


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> dict:
    """Run into `out`; returns the tip deflection [m] and the total contact force / weight (rank 0 and others)."""
    n = 12 if quick else 24
    fmesh = plate(LENGTH, WIDTH, n, 1, cell="quadrilateral", origin=(-(LENGTH - OVERHANG), -0.5 * WIDTH, 0.0),
                  comm=comm)                                                             # mesh
    model = ShellModel(fmesh, FABRIC)                                                    # forms
    model.constrain(lambda x: np.full(x.shape[1], True), u=(None, 0.0, None))            # a plane problem
    model.constrain("left", u=(0.0, None, None))                                         # no sliding off
    q = WEIGHT / WIDTH
    model.add_body_force((0.0, 0.0, -q))                                                 # N/m^2 of the sheet
    fillet = LENGTH / n / 10.0
    top = q / ContactProblem(model, [table_edge(0.0, 0.0, fillet)]).penalty  # the strip's rest sag [m]
    problem = ContactProblem(model, [table_edge(0.0, top, fillet)])                      # contact term
    solve_load_path(problem.system, [1.0], solver=NewtonSolver(problem.system, {"snes_max_it": 50}),
                    initial_step=0.25)                                                   # solver
    tip = model.node_value((OVERHANG, 0.0, 0.0))
    contact = problem.total_force()[2]
    weight = WEIGHT * LENGTH
    series = io.SurfaceSeries(out / "drape.xdmf", model.mesh)                           # outputs
    series.write(model.displacement(), 1.0)
    series.close()
    surfaces = [io.gather_surface(model.mesh), io.gather_surface(model.mesh, model.displacement())]
    if comm.rank == 0:
        io.render_surfaces(out / "drape.png", surfaces, title="strip draped over a table edge", camera="xz")
        print(f"drape: tip deflection {-tip[2] * 1e3:.2f} mm, contact force / weight {contact / weight:.6f}; "
              f"wrote {out}/drape.xdmf, drape.png")
    return {"tip_deflection_m": float(-tip[2]), "contact_over_weight": float(contact / weight)}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/drape"))
    parser.add_argument("--quick", action="store_true", help="a coarser strip")
    args = parser.parse_args()
    main(args.out, args.quick)
