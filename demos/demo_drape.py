"""Drape: a strip of fabric on a table, hanging over its edge under its own weight [Eischen2000, sec. 4.3].

    .venv/bin/python demos/demo_drape.py [--out results/demos/drape] [--quick]

Data flow: mesh (meshes.plate, the strip from x = -(L - a) to the overhang a) -> forms (Naghdi shell, isotropic)
-> contact (contact.ContactProblem: penalty contact with the table, a rounded box, as a ResidualTerm of the
shell: problem.system) -> solver (load steps on the weight, Newton) -> outputs (drape.xdmf, drape.png and the
lift-off point, tip deflection and the contact force against the weight, which global equilibrium fixes).
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

LENGTH, OVERHANG, WIDTH = 0.06, 0.03, 0.0025          # m: strip length, overhang past the table edge, width
FABRIC = Fabric.isotropic(E=8.4e6, nu=0.0, thickness=4e-4)   # Pa, -, m (an EI of about 1e-6 N m^2 per metre)
WEIGHT = 2.5                                           # N/m^2 of body force per unit area x thickness


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> dict:
    """Run into `out`; returns the tip deflection [m] and the total contact force / weight (rank 0 and others)."""
    n = 12 if quick else 24
    fmesh = plate(LENGTH, WIDTH, n, 1, cell="quadrilateral", origin=(-(LENGTH - OVERHANG), -0.5 * WIDTH, 0.0),
                  comm=comm)                                                             # mesh
    model = ShellModel(fmesh, FABRIC)                                                    # forms
    model.constrain(lambda x: np.full(x.shape[1], True), u=(None, 0.0, None))            # a plane problem
    model.constrain("left", u=(0.0, None, None))                                         # no sliding off
    q = WEIGHT / FABRIC.thickness
    model.add_body_force((0.0, 0.0, -q))                                                 # N/m^3
    table = table_edge(0.0, 0.0, LENGTH / n / 10.0)                                      # the edge at x = 0
    problem = ContactProblem(model, [table])                                             # contact term
    solve_load_path(problem.system, [0.5, 1.0], initial_step=0.25)                       # solver
    tip = model.node_value((OVERHANG, 0.0, 0.0))
    contact = problem.total_force()[2]
    weight = WEIGHT * LENGTH * WIDTH
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
