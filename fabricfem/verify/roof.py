"""Scordelis-Lo roof: membrane locking of the curved shell and the PSRI quadrature (case `scordelis-lo`).

The roof (Scordelis & Lo 1964; MacNeal & Harder 1985, the standard shell obstacle course): a cylindrical
panel of radius R = 25, length L = 50, opening angle 2 x 40 degrees, thickness t = 0.25, E = 4.32e8, nu = 0,
under its own weight q = 90 per unit area (-z), on rigid diaphragms at both curved ends (u_y = u_z = 0 there,
u_x and the rotations free), the straight edges free. Reference: the vertical displacement at the midpoint
of a free edge, 0.3024 (the converged value for shear-deformable shell models quoted by MacNeal & Harder and
used by Zienkiewicz, Taylor & Too 1971 to show that full integration locks and reduced integration does not).
Units are consistent, not SI (the benchmark's own numbers).

Why it is here: the sleeve is a curved shell whose torque depends on the quadrature
(SleeveConfig.quadrature): the fully integrated Q2 tube converges to the PSRI one from above on the thesis's
meshes, and with full quadrature the flexed sleeve turns membrane-dominated (docs/figures/sleeve/
fit_sensitivity.md). This case checks, against an independent reference, that the default PSRI split
(4, 2) of forms/shell.py is free of membrane locking on a curved shell and that full quadrature (4, 4) is not.

Linear reference, nonlinear model: the load is q x 1e-3 and the displacement is scaled back by 1e3, so that
the deflection (3e-4 against R = 25) is in the linear range (the geometric nonlinearity changes it by
O(w / R) ~ 1e-5 relative).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.materials import Fabric
from fabricfem.meshes import cylindrical_panel
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import CaseResult, Timer, case, result

RADIUS, LENGTH, HALF_ANGLE, THICKNESS = 25.0, 50.0, np.deg2rad(40.0), 0.25
E, NU, WEIGHT = 4.32e8, 0.0, 90.0          # weight per unit area
REFERENCE = 0.3024                         # |u_z| at the midpoint of a free edge (MacNeal & Harder)
LOAD_SCALE = 1e-3                          # linear range


def roof_deflection(n: int, psri_degrees: tuple[int, int] = (4, 2), comm=MPI.COMM_WORLD) -> tuple[float, int]:
    """Downward displacement at the midpoint of a free edge of the whole roof on n x n Q2 cells, and the
    number of dofs."""
    fmesh = cylindrical_panel(LENGTH, RADIUS, 2.0 * HALF_ANGLE, n, n, comm=comm, order=2)
    model = ShellModel(fmesh, Fabric.isotropic(E, NU, THICKNESS), psri_degrees=psri_degrees)
    for end in ("end0", "end1"):                                  # rigid diaphragms
        model.constrain(end, u=(None, 0.0, 0.0))
    model.constrain(lambda x: np.isclose(x[0], 0.5 * LENGTH), u=(0.0, None, None))   # axial rigid mode (symmetry)
    model.add_body_force((0.0, 0.0, -WEIGHT * LOAD_SCALE))
    solve_load_path(model, 1.0, initial_step=1.0)
    edge_midpoint = (0.5 * LENGTH, RADIUS * np.sin(HALF_ANGLE), RADIUS * np.cos(HALF_ANGLE))
    return float(-model.node_value(edge_midpoint)[2] / LOAD_SCALE), model.ndofs


@case("scordelis-lo", mpi=True)
def scordelis_lo() -> list[CaseResult]:
    """Midside deflection of the free edge against 0.3024 on n x n Q2 cells of the whole roof.

    PSRI (4, 2) within 1% on 8 x 8 and 16 x 16 (the reference is quoted to 4 digits; shear-deformable models
    differ from it by a few 1e-3). Locking: on 8 x 8, full quadrature (4, 4) must be more than ten times as far
    from the reference as PSRI (an order of magnitude is what separates a locking element from a discretisation
    error; measured in the quantity), and on 16 x 16 it must have approached the reference (error below its 8 x 8
    error: locking fades with refinement, it does not converge elsewhere)."""
    name = "scordelis-lo"
    out, runs = [], {}
    with Timer() as timer:
        for n in (8, 16):
            for degrees in ((4, 2), (4, 4)):
                runs[n, degrees] = roof_deflection(n, degrees)
    wall = timer.elapsed
    for n in (8, 16):
        w, ndofs = runs[n, (4, 2)]
        out.append(result(name, f"w at the free-edge midpoint, PSRI (4, 2), {n} x {n} Q2", w, REFERENCE, 0.01,
                          ndofs, wall))
    error = {key: abs(w / REFERENCE - 1.0) for key, (w, _) in runs.items()}
    ndofs = runs[8, (4, 2)][1]
    ratio = error[8, (4, 4)] / error[8, (4, 2)]
    out.append(CaseResult(name, f"locking on 8 x 8: error full (4, 4) {error[8, (4, 4)]:.3g} / error PSRI "
                          f"{error[8, (4, 2)]:.3g} > 10", ratio, 10.0, float("nan"), float("nan"), bool(ratio > 10.0),
                          ndofs, wall))
    out.append(CaseResult(name, f"full (4, 4) approaches the reference: error 16 x 16 {error[16, (4, 4)]:.3g} < "
                          f"8 x 8 {error[8, (4, 4)]:.3g}", error[16, (4, 4)], error[8, (4, 4)], float("nan"),
                          float("nan"), bool(error[16, (4, 4)] < error[8, (4, 4)]), runs[16, (4, 4)][1], wall))
    return out
