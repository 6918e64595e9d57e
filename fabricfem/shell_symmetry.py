"""Mirror-symmetry planes of a `fabricfem.shell.ShellModel` (`ShellSymmetry.symmetry`).

On the edge of the cut, u . n = 0 by a penalty energy and d . n = 0 exactly (an angle held at zero after the
director base is turned to the plane). The penalty stiffness depends on the mesh (smallest cell) and on the
thickness (membrane stiffness): it enters the energy as a dolfinx Constant, so that another mesh or fabric
compiles no new form. Units: SI (m, N, Pa).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.shell_loads import nonzero_vector


def normalize_rows(v: np.ndarray) -> np.ndarray:
    """The rows of `v` (n, 3) scaled to unit length."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)


class ShellSymmetry:
    """The symmetry method of ShellModel (mixed in: it reads the model's spaces, fields and stiffness, prescribes
    angles through `constrain` and adds its penalty to the model's `energy` and `_extra_energy`)."""

    def symmetry(self, where: str, normal: Sequence[float], penalty: float = 1e8):
        """Mirror symmetry about the plane through the edge `where` with normal n = `normal` (global
        frame, any direction): on the edge u . n = 0 and d . n = 0 (no displacement through the plane,
        no rotation of the director out of it).

        d . n = 0 is exact: the director base is turned (everywhere, before any solve, about the
        reference normal) so that a2 = -n on the edge, where d . n = sin th1, and th1 = 0 is prescribed
        there; re-basing keeps a2 (rebase_director with th1 = 0). A base already aligned (warp or weft
        normal to the plane, or a perpendicular plane set before) is kept and th1 or th2 is fixed.
        u . n = 0 is a penalty energy int_edge k_u / 2 (u . n)^2 dS, k_u = penalty max|A_ij| / h_min
        [N/m^2] (A the membrane stiffness [N/m], h_min the smallest cell [m]; a Constant of the form), met
        to O(1 / penalty) relative (symmetry-plane verify case).

        Raises:
            ValueError: naming `normal` if it is not a finite non-zero 3-vector, if the plane through the
                edge does not contain the edge, if the sheet's normal along the edge leaves the plane, or if
                the base cannot be turned to it (the sheet's normal is parallel to n somewhere, or an
                earlier symmetry plane is not perpendicular to this one); naming `penalty` if it is not a
                positive number.
        """
        if self._compiled:
            raise ValueError(f"symmetry: add it before the first solve (the forms of {where!r} are compiled)")
        n = nonzero_vector("normal", normal)
        n = n / np.linalg.norm(n)
        if not (np.isfinite(penalty) and penalty > 0):
            raise ValueError(f"penalty must be a positive number, got {penalty!r}")
        nodes = fem.locate_dofs_topological(self.V2, self.mesh.topology.dim - 1, self.fmesh.facets(where))
        self._check_plane(where, nodes, n)
        if self.model == "naghdi":
            self.constrain(where, theta=self._symmetry_angle(nodes, n))
        h_min = self.comm.allreduce(float(self.cell_size.x.array.min(initial=np.inf)), op=MPI.MIN)
        k_u = fem.Constant(self.mesh, PETSc.ScalarType(penalty * float(np.abs(self.A.value).max()) / h_min))
        n_c = fem.Constant(self.mesh, PETSc.ScalarType(n))
        penalty_energy = 0.5 * k_u * ufl.dot(self.u, n_c) ** 2 * self._ds(where)
        self._extra_energy.append(penalty_energy)
        self.energy = self.energy + penalty_energy
        return self

    def _check_plane(self, where: str, nodes: np.ndarray, n: np.ndarray) -> None:
        """ValueError naming `normal` unless the plane with unit normal n contains the edge `where` (its P2 `nodes`)
        and the sheet's normal along it lies in the plane."""
        offsets = self.V2.tabulate_dof_coordinates()[nodes] @ n
        lo = self.comm.allreduce(offsets.min(initial=np.inf), op=MPI.MIN)
        hi = self.comm.allreduce(offsets.max(initial=-np.inf), op=MPI.MAX)
        size = self.comm.allreduce(float(np.ptp(self.mesh.geometry.x, axis=0).max()), op=MPI.MAX)
        if hi - lo > 1e-8 * size:
            raise ValueError(f"normal: the plane with normal {tuple(n)} does not contain the edge {where!r} "
                             f"(it spans {hi - lo:.3e} m along the normal)")
        if self._edge_max(np.abs(self.n0.x.array.reshape(-1, 3)[nodes] @ n)) > 1e-6:
            raise ValueError(f"normal: the sheet's normal along {where!r} leaves the plane with normal "
                             f"{tuple(n)}; no mirror symmetry there")

    def _edge_max(self, values: np.ndarray) -> float:
        return self.comm.allreduce(float(values.max(initial=0.0)), op=MPI.MAX)

    def _symmetry_angle(self, nodes: np.ndarray, n: np.ndarray) -> tuple[float | None, float | None]:
        """The angle constraint (th1 = 0 or th2 = 0) that holds d . n = 0 on `nodes`, turning the director
        base about n0 so that a2 = -n there when neither a1 nor a2 is along n yet."""
        a1, a2 = (f.x.array.reshape(-1, 3) for f in (self.a1, self.a2))
        if self._edge_max(1.0 - np.abs(a2[nodes] @ n)) < 1e-10:
            return (0.0, None)
        if self._edge_max(1.0 - np.abs(a1[nodes] @ n)) < 1e-10:
            return (None, 0.0)
        if self._base_turned:
            raise ValueError(f"normal: {tuple(n)} is not perpendicular to an earlier symmetry plane (one "
                             "director base cannot be aligned with both)")
        n0 = self.n0.x.array.reshape(-1, 3)
        b1 = np.cross(n0, n)
        if self.comm.allreduce(float(np.linalg.norm(b1, axis=1).min(initial=1.0)), op=MPI.MIN) < 1e-6:
            raise ValueError(f"normal: the sheet's normal is parallel to {tuple(n)} somewhere; the director base "
                             "cannot be turned to the plane")
        b1 = normalize_rows(b1)
        self.a1.x.array[:] = b1.reshape(-1)
        self.a2.x.array[:] = np.cross(n0, b1).reshape(-1)
        self._base_turned = True
        return (0.0, None)
