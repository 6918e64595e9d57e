"""Membrane patch test [Peng2022, sec. 4.4]."""
from __future__ import annotations

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fabricfem.forms import shell as shell_forms
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import Timer, case, result

# Points in the reference triangle where the stress is sampled (centroid and near two vertices)
SAMPLE_POINTS = np.array([[1 / 3, 1 / 3], [0.05, 0.05], [0.9, 0.05], [0.05, 0.9]])


def stress_samples(model: ShellModel) -> np.ndarray:
    """First Piola-Kirchhoff stress P (3x3, Pa) at SAMPLE_POINTS of every owned cell, (n, 3, 3)."""
    P = shell_forms.nominal_stress(model.u, model.phi0, model.t1, model.t2, model.A, model.thickness)
    expr = fem.Expression(P, SAMPLE_POINTS)
    n_cells = model.mesh.topology.index_map(2).size_local
    return expr.eval(np.arange(n_cells, dtype=np.int32)).reshape(-1, 3, 3)


@case("membrane-patch", mpi=True)
def membrane_patch(n: int = 8, traction: float = 1.0) -> list:
    """1 m square fixed on its top edge, 1 N/m pulling on the bottom edge (membrane model, nu = 0,
    E t = 1000 N/m, in-plane): the nominal stress is P_yy = traction / t everywhere and the other
    components vanish, within 1e-6 relative (the exact solution is a homogeneous stretch, which the
    elements represent exactly)."""
    with Timer() as timer:
        fabric = Fabric.isotropic(1e6, 0.0, 1e-3)
        model = ShellModel(plate(1.0, 1.0, n, n, structured=False), fabric, model="membrane")
        model.constrain("top", u=(0.0, 0.0, 0.0))
        model.constrain(lambda x: np.full(x.shape[1], True), u=(None, None, 0.0))  # in-plane problem
        model.add_edge_traction("bottom", (0.0, -traction, 0.0))
        solve_load_path(model, 1.0, initial_step=1.0)
        P = stress_samples(model)
    expected = traction / fabric.thickness
    comm = model.comm
    dev_yy = comm.allreduce(float(np.abs(P[:, 1, 1] - expected).max(initial=0.0)), op=MPI.MAX)
    P_other = P.copy()
    P_other[:, 1, 1] = 0.0
    dev_other = comm.allreduce(float(np.abs(P_other).max(initial=0.0)), op=MPI.MAX)
    return [result("membrane-patch", "max |P_yy - T/t| / (T/t) over all cells", dev_yy / expected, 0.0, 1e-6,
                   model.ndofs, timer.elapsed, scale=1.0),
            result("membrane-patch", "max |other P components| / (T/t)", dev_other / expected, 0.0, 1e-6,
                   model.ndofs, timer.elapsed, scale=1.0)]
