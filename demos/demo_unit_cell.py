"""A woven unit cell and its fitted fabric law: the plain-weave quarter cell with transversely isotropic yarns
and yarn-yarn contact stretched along the warp [Man2006, ch. 4], beside the membrane law fitted to such cells.

    .venv/bin/python demos/demo_unit_cell.py [--out results/demos/unit_cell] [--quick]

Data flow: mesh (meshes.unit_cell: yarns of the balanced plain weave, periodic end faces) -> forms (Bonet-Burton
transversely isotropic yarn law [BonetBurton1998]) -> solver and contact (weave.unit_cell.ContactUnitCell:
periodic homogenization with dolfinx_mpc, augmented-Lagrangian yarn contact with Coulomb friction) -> outputs
(unit_cell.csv: the homogenized membrane resultant N11 = t S11 [N/m] against E11, beside the stored fitted law
`plain-weave-ti-contact` (fabricfem.fabrics), the convex energy W fitted to such cells, at the same strain).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.fabrics import load_fabric
from fabricfem.materials.fitted import membrane_state
from fabricfem.studies.unit_cell import RunKey, run_case

FITTED = "plain-weave-ti-contact"


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> list[list[float]]:
    """Run into `out`; returns rows (E11, E22, N11 of the cell, N11 of the fitted law) [-, -, N/m, N/m]."""
    fabric = load_fabric(FITTED)
    run = run_case(RunKey("ti", "uniaxial"), steps=2 if quick else 6, scale=0.1 if quick else 0.5, comm=comm)
    rows = []
    for r in run.rows:
        E = np.array([[r["E11"], r["E12"], 0.0], [r["E12"], r["E22"], 0.0], [0.0, 0.0, 0.0]])
        S = np.array([[r["S11"], r["S12"], 0.0], [r["S12"], r["S22"], 0.0], [0.0, 0.0, 0.0]])
        strain, resultant = membrane_state(E, S, fabric.thickness)
        rows.append([r["E11"], r["E22"], resultant[0], float(fabric.membrane_law.resultants(strain[None, :])[0, 0])])
    io.write_csv(out / "unit_cell.csv", ["E11", "E22", "N11_cell_N_per_m", "N11_fitted_law_N_per_m"], rows, comm)
    if comm.rank == 0:
        for e11, _, n_cell, n_law in rows:
            print(f"  E11 = {e11:.4f}: N11 cell {n_cell:9.2f} N/m, fitted law {n_law:9.2f} N/m")
        print(f"unit cell: {run.ndofs} dofs, {run.wall_s:.0f} s" + (f", stopped: {run.stopped}" if run.stopped else "")
              + f"; wrote {out}/unit_cell.csv")
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/unit_cell"))
    parser.add_argument("--quick", action="store_true", help="two small load steps")
    args = parser.parse_args()
    main(args.out, args.quick)
