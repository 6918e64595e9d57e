"""Dead loads of a `fabricfem.shell.ShellModel`: gravity, body force, edge tractions, pressure, moments, point loads.

`ShellLoads` is mixed into ShellModel: it collects the external virtual work at load factor 1 (F_ref, assembled by
ShellModel.compile) and the configuration-dependent work of the moments. Every number that enters a form is a
dolfinx Constant, so that another mesh, thickness or load value compiles no new form. Units: SI (m, N, Pa, kg, s).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from fabricfem.forms import loads as load_forms


def nonzero_vector(name: str, value: Sequence[float]) -> np.ndarray:
    """`value` as a finite non-zero 3-vector, else ValueError naming `name`."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise ValueError(f"{name} must be a finite non-zero 3-vector (global x, y, z), got {value!r}")
    return v


class ShellLoads:
    """The load methods of ShellModel (mixed in: they read the model's mesh, test functions, measures and director
    and append to its lists of external work `_external`, `_director_loads`, `_point_loads`, `_point_moments`)."""

    def _constant(self, value) -> fem.Constant:
        """A Constant on the model's mesh holding `value` (a number or an array)."""
        return fem.Constant(self.mesh, PETSc.ScalarType(value))

    def _ds(self, tag: str):
        return self.ds(self.fmesh.tag(tag))

    def add_gravity(self, g: Sequence[float] = (0.0, 0.0, -9.81)):
        """Weight of the sheet, areal density rho t [kg/m^2] times g [m/s^2]."""
        if self.fabric.areal_density <= 0:
            raise ValueError("gravity needs a positive fabric density (Fabric.density, kg/m^3)")
        self._external.append(load_forms.body_force(self.v, self._constant(self.fabric.areal_density),
                                                    self._constant(g), self.dx))

    def add_body_force(self, force_per_area: Sequence[float]):
        """Dead force per unit reference area [N/m^2]."""
        self._external.append(ufl.dot(self._constant(force_per_area), self.v) * self.dx)

    def add_edge_traction(self, tag: str, traction: Sequence[float]):
        """Dead force per unit reference edge length [N/m] on the edge named `tag`."""
        self._external.append(load_forms.edge_traction(self.v, self._constant(traction), self._ds(tag)))

    def add_pressure(self, pressure: float):
        """Dead pressure [Pa] along the reference normal."""
        self._external.append(load_forms.surface_pressure(self.v, self._constant(pressure), self.n0, self.dx))

    def add_edge_moment(self, tag: str, moment: Sequence[float]):
        """Dead moment per unit reference edge length [N m/m] on the edge `tag`: a vector (mx, my, mz) in
        the global frame (right-handed about its axis, fixed in space while the sheet turns).

        Its virtual work is int m . (d x delta d) dS [Man2006, eqs. 2.47-2.51] (forms.loads.moment_work):
        the work of a moment about any axis and through finite rotations; the component of m along the
        current director d does no work (a director has no drilling rotation).
        """
        if self.model != "naghdi":
            raise ValueError("edge moments need the 'naghdi' model (the membrane has no rotations)")
        m = self._constant(nonzero_vector("moment", moment))
        delta_d = ufl.derivative(self.d, self.w, self.w_test)
        self._director_loads.append(load_forms.moment_work(m, self.d, delta_d, self._ds(tag)))

    def add_point_moment(self, point: Sequence[float], moment: Sequence[float]):
        """Dead moment [N m] at the mesh node at `point`: a vector (mx, my, mz) in the global frame, fixed in
        space. Its virtual work is m . (d x delta d) at the node (as add_edge_moment's per unit length; the
        component along the director does no work), with the consistent tangent (`_point_moment_terms`)."""
        if self.model != "naghdi":
            raise ValueError("point moments need the 'naghdi' model (the membrane has no rotations)")
        self._point_moments.append((np.asarray(point, dtype=float), nonzero_vector("moment", moment)))
        self._compiled = False

    def _point_moment_terms(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per point moment on its owning rank: (theta dofs (2,), -lambda g (2,), -lambda dg/dtheta (2, 2)) with
        the generalized forces g_i = m . (d x d_i) of the director d = c1 c2 a3 + c1 s2 a1 - s1 a2 at the node
        (d_i = dd/dtheta_i) and their derivatives m . (d_j x d_i + d x d_ij); rows of held angles left out."""
        out = []
        lam = float(self.load_factor.value)
        for dofs, node, m in self._moment_nodes:
            n0, t1, t2 = (f.x.array.reshape(-1, 3)[node] for f in (self.a3, self.a1, self.a2))
            th1, th2 = self.w.x.array[dofs]
            c1, s1, c2, s2 = np.cos(th1), np.sin(th1), np.cos(th2), np.sin(th2)
            d = c1 * c2 * n0 + c1 * s2 * t1 - s1 * t2
            dd = [-s1 * c2 * n0 - s1 * s2 * t1 - c1 * t2, -c1 * s2 * n0 + c1 * c2 * t1]
            ddd = [[-c1 * c2 * n0 - c1 * s2 * t1 + s1 * t2, s1 * s2 * n0 - s1 * c2 * t1],
                   [s1 * s2 * n0 - s1 * c2 * t1, -c1 * c2 * n0 - c1 * s2 * t1]]
            g = np.array([m @ np.cross(d, dd[i]) for i in range(2)])
            k = np.array([[m @ (np.cross(dd[j], dd[i]) + np.cross(d, ddd[i][j])) for j in range(2)] for i in range(2)])
            free = ~np.isin(dofs, self._bc_dofs)
            out.append((dofs[free], -lam * g[free], -lam * k[np.ix_(free, free)]))
        return out

    def add_point_load(self, point: Sequence[float], force: Sequence[float]):
        """Force [N] on the mesh node nearest to `point` (which must be a node, within 1e-8 m)."""
        self._point_loads.append((np.asarray(point, dtype=float), np.asarray(force, dtype=float)))
