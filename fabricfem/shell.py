"""A fabric sheet as a finite-element model: spaces, fields, loads and constraints.

`ShellModel` assembles the pieces of `fabricfem.forms` into the discrete residual

    R(w; lambda) = dPi_int/dw - lambda F_ref,

where w = (u, theta) (Naghdi shell) or w = u (membrane), F_ref collects all dead
loads (gravity, edge tractions, pressure, edge moments, point loads) at load factor 1
and prescribed non-zero displacements/rotations are also scaled by lambda.
Units: SI (m, N, Pa, kg, s, rad).
"""
from __future__ import annotations

import functools
from typing import Callable, Sequence

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.cpp import mesh as cpp_mesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem import probe
from fabricfem.forms import loads as load_forms
from fabricfem.forms import shell as shell_forms
from fabricfem.forms.jit import KERNEL_JIT
from fabricfem.materials import Fabric, SquareRootBending
from fabricfem.shell_reference import (
    HAND_KERNEL,
    REFERENCE_AT_QUADRATURE,
    PrepackedForms,
    ReferenceAtQuadrature,
    naghdi_kernel_form,
)

Locator = str | Callable[[np.ndarray], np.ndarray]

MODELS = ("naghdi", "membrane")


def _normalize_rows(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _nonzero_vector(name: str, value: Sequence[float]) -> np.ndarray:
    """`value` as a finite non-zero 3-vector, else ValueError naming `name`."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise ValueError(f"{name} must be a finite non-zero 3-vector (global x, y, z), got {value!r}")
    return v


class ShellModel:
    """Geometrically nonlinear fabric sheet on a `fabricfem.meshes.FabricMesh`.

    Args:
        fabric_mesh: the surface mesh with tags and warp/normal fields.
        fabric: material (Fabric).
        model: "naghdi" (membrane + bending + transverse shear, rotations) or "membrane".
        degree: polynomial degree of the fields (2; the displacement of the Naghdi
            shell on triangles is enriched with a cubic bubble).
        psri_degrees: (full, reduced) quadrature degrees of the PSRI split.
        bending_eps: regularisation [1/m] of |K| for the square-root bending law
            (default 1e-3 kappa0).
        rebase: after each converged load step, rotate the director base onto the current
            director and zero the angles, so that only increments are parametrised (no
            singularity at |theta1| = pi/2 however far the sheet turns). Off while a non-zero
            rotation is prescribed.
    """

    def __init__(self, fabric_mesh, fabric: Fabric, model: str = "naghdi", degree: int = 2,
                 psri_degrees: tuple[int, int] = (4, 2), bending_eps: float | None = None,
                 rebase: bool = True):
        if model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {model!r}")
        if not isinstance(fabric, Fabric):
            raise ValueError(f"fabric must be a fabricfem.materials.Fabric, got {type(fabric).__name__}")
        self.fmesh = fabric_mesh
        self.mesh = fabric_mesh.mesh
        self.comm = self.mesh.comm
        self.fabric = fabric
        self.model = model
        mesh = self.mesh
        cell = mesh.ufl_cell()
        family = "Lagrange"
        P = ufl.FiniteElement(family, cell, degree)
        if model == "naghdi":
            if cell.cellname() == "triangle":
                P_u = P + ufl.FiniteElement("Bubble", cell, 3)
            else:
                P_u = P
            element = ufl.MixedElement([ufl.VectorElement(P_u, dim=3), ufl.VectorElement(P, dim=2)])
        else:
            element = ufl.VectorElement(P, dim=3)
        self.W = fem.FunctionSpace(mesh, element)
        self.w = fem.Function(self.W, name="state")
        self.w_test = ufl.TestFunction(self.W)
        self.w_trial = ufl.TrialFunction(self.W)
        if model == "naghdi":
            self.u, self.theta = ufl.split(self.w)
            self.v, self.eta = ufl.split(self.w_test)
        else:
            self.u, self.theta = self.w, None
            self.v, self.eta = self.w_test, None

        # Reference geometry and frames as P2 vector fields on the surface
        self.V2 = fem.VectorFunctionSpace(mesh, (family, degree), dim=3)
        x = self.V2.tabulate_dof_coordinates().T
        warp, normal = fabric_mesh.directions_at(self.V2)   # per panel where the mesh has panel_directions
        n0 = _normalize_rows(normal.T)
        warp = warp.T
        t1 = _normalize_rows(warp - np.sum(warp * n0, axis=1, keepdims=True) * n0)
        t2 = np.cross(n0, t1)
        self.phi0 = self._vector_field(x.T, "reference_position")
        self.n0 = self._vector_field(n0, "reference_normal")
        self.t1 = self._vector_field(t1, "warp")
        self.t2 = self._vector_field(t2, "weft")
        # Director base, re-based between load steps (rebase_director)
        self.a3 = self._vector_field(n0, "director_base")
        self.a1 = self._vector_field(t1, "director_base_1")
        self.a2 = self._vector_field(t2, "director_base_2")

        # Stiffness constants (Constants: changing a material does not recompile forms)
        t = fabric.thickness
        self.A = fem.Constant(mesh, PETSc.ScalarType(t * fabric.plane_stress_matrix))
        self.D = fem.Constant(mesh, PETSc.ScalarType(fabric.bending_matrix))
        self.shear_stiffness = fem.Constant(
            mesh, PETSc.ScalarType(fabric.shear_correction * fabric.transverse_shear_modulus * t))
        self.thickness = fem.Constant(mesh, PETSc.ScalarType(t))
        self.load_factor = fem.Constant(mesh, PETSc.ScalarType(0.0))
        membrane_density = None
        if fabric.membrane_law is not None:
            # fitted membrane energy W(E11, E22, 2 E12) [J/m^2] (fabricfem.materials.fitted) instead of 1/2 eps.A eps
            # (any law with .parameters and .ufl_energy(eps, parameters): polynomial or convex-ridge)
            self.membrane_coefficients = fem.Constant(
                mesh, PETSc.ScalarType(np.asarray(fabric.membrane_law.parameters, dtype=float)))
            membrane_density = functools.partial(fabric.membrane_law.ufl_energy,
                                                 parameters=self.membrane_coefficients)

        self.cell_size = self._cell_size()
        if model == "naghdi":
            law = fabric.bending_law
            eps = bending_eps
            if isinstance(law, SquareRootBending) and eps is None:
                eps = 1e-3 * law.kappa0
            self.bending_eps = eps
            self._energy_args = dict(law=law, law_eps=eps, degrees=psri_degrees, cell_size=self.cell_size,
                                     membrane_density=membrane_density)
            self.energy = shell_forms.naghdi_energy(
                self.u, self.theta, self.phi0, self.n0, (self.a3, self.a1, self.a2), (self.t1, self.t2),
                self.A, self.D, self.shear_stiffness, self.thickness, **self._energy_args)
            self.d = shell_forms.director(self.theta, self.a3, self.a1, self.a2)
        else:
            self.energy = shell_forms.membrane_energy(self.u, self.phi0, self.t1, self.t2, self.A,
                                                      membrane_density=membrane_density)

        self.dx = ufl.Measure("dx", domain=mesh)
        self.ds = ufl.Measure("ds", domain=mesh, subdomain_data=fabric_mesh.facet_tags)
        self._external: list = []
        self._director_loads: list = []   # external work that depends on the current director (moments)
        self._point_loads: list[tuple[np.ndarray, np.ndarray]] = []
        self._point_moments: list[tuple[np.ndarray, np.ndarray]] = []   # (point [m], moment [N m])
        self.bcs: list = []
        self._scaled_bcs: list[tuple[fem.Function, np.ndarray]] = []
        self._extra_energy: list = []   # energies added after the shell's own (symmetry penalties)
        self._compiled = False
        self._reference = None          # ReferenceAtQuadrature of the internal force (built on first use)
        self._R_internal = None         # PrepackedForms of the internal force (`_internal_form`)
        self.reference_at_quadrature = REFERENCE_AT_QUADRATURE["enabled"] and model == "naghdi"
        # the hand-written kernel covers the quadratic membrane energy (not a fitted membrane law)
        self.hand_kernel = (self.reference_at_quadrature and HAND_KERNEL["enabled"]
                            and fabric.membrane_law is None)
        self.rebase = rebase and model == "naghdi"
        self._rotation_prescribed = False
        self._base_turned = False   # the director base was turned to a symmetry plane (symmetry)
        self._collapsed: dict = {}  # (field, component) -> collapsed subspace and map, for probes

    # ------------------------------------------------------------------ fields
    def _cell_size(self) -> fem.Function:
        """Largest vertex distance of each cell [m] (ufl.CellDiameter's definition) as a DG0 field,
        so that the PSRI weight also works on second-order (curved) meshes."""
        DG0 = fem.FunctionSpace(self.mesh, ("DG", 0))
        tdim = self.mesh.topology.dim
        im = self.mesh.topology.index_map(tdim)
        cells = np.arange(im.size_local + im.num_ghosts, dtype=np.int32)
        h = fem.Function(DG0, name="cell_size")
        h.x.array[:] = cpp_mesh.h(getattr(self.mesh, "_mesh", self.mesh), tdim, cells)
        return h

    def _vector_field(self, values: np.ndarray, name: str) -> fem.Function:
        f = fem.Function(self.V2, name=name)
        f.x.array[:] = np.ascontiguousarray(values).reshape(-1)
        return f

    @property
    def ndofs(self) -> int:
        im = self.W.dofmap.index_map
        return im.size_global * self.W.dofmap.index_map_bs

    # ------------------------------------------------------------------ loads
    def _ds(self, tag: str):
        return self.ds(self.fmesh.tag(tag))

    def add_gravity(self, g: Sequence[float] = (0.0, 0.0, -9.81)):
        """Weight of the sheet, areal density rho t [kg/m^2] times g [m/s^2]."""
        if self.fabric.areal_density <= 0:
            raise ValueError("gravity needs a positive fabric density (Fabric.density, kg/m^3)")
        gv = fem.Constant(self.mesh, PETSc.ScalarType(g))
        self._external.append(load_forms.body_force(self.v, self.fabric.areal_density, gv, self.dx))

    def add_body_force(self, force_per_area: Sequence[float]):
        """Dead force per unit reference area [N/m^2]."""
        f = fem.Constant(self.mesh, PETSc.ScalarType(force_per_area))
        self._external.append(ufl.dot(f, self.v) * self.dx)

    def add_edge_traction(self, tag: str, traction: Sequence[float]):
        """Dead force per unit reference edge length [N/m] on the edge named `tag`."""
        T = fem.Constant(self.mesh, PETSc.ScalarType(traction))
        self._external.append(load_forms.edge_traction(self.v, T, self._ds(tag)))

    def add_pressure(self, pressure: float):
        """Dead pressure [Pa] along the reference normal."""
        q = fem.Constant(self.mesh, PETSc.ScalarType(pressure))
        self._external.append(load_forms.surface_pressure(self.v, q, self.n0, self.dx))

    def add_edge_moment(self, tag: str, moment: Sequence[float]):
        """Dead moment per unit reference edge length [N m/m] on the edge `tag`: a vector (mx, my, mz) in
        the global frame (right-handed about its axis, fixed in space while the sheet turns).

        Its virtual work is int m . (d x delta d) dS [Man2006, eqs. 2.47-2.51] (forms.loads.moment_work):
        the work of a moment about any axis and through finite rotations; the component of m along the
        current director d does no work (a director has no drilling rotation).
        """
        if self.model != "naghdi":
            raise ValueError("edge moments need the 'naghdi' model (the membrane has no rotations)")
        m = fem.Constant(self.mesh, PETSc.ScalarType(_nonzero_vector("moment", moment)))
        delta_d = ufl.derivative(self.d, self.w, self.w_test)
        self._director_loads.append(load_forms.moment_work(m, self.d, delta_d, self._ds(tag)))

    def add_point_moment(self, point: Sequence[float], moment: Sequence[float]):
        """Dead moment [N m] at the mesh node at `point`: a vector (mx, my, mz) in the global frame, fixed in
        space. Its virtual work is m . (d x delta d) at the node (as add_edge_moment's per unit length; the
        component along the director does no work), with the consistent tangent (`_point_moment_terms`)."""
        if self.model != "naghdi":
            raise ValueError("point moments need the 'naghdi' model (the membrane has no rotations)")
        self._point_moments.append((np.asarray(point, dtype=float), _nonzero_vector("moment", moment)))
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

    # ------------------------------------------------------------ constraints
    def _subspace(self, field: str, component: int):
        if self.model == "naghdi":
            return self.W.sub(0 if field == "u" else 1).sub(component)
        return self.W.sub(component)

    def _locate(self, where: Locator, space_pair) -> np.ndarray:
        if callable(where):
            return fem.locate_dofs_geometrical(space_pair, where)
        facets = self.fmesh.facets(where)
        fdim = self.mesh.topology.dim - 1
        return fem.locate_dofs_topological(space_pair, fdim, facets)

    def constrain(self, where: Locator, u: Sequence[float | None] | None = None,
                  theta: Sequence[float | None] | None = None):
        """Prescribe displacement components u [m] and rotations theta [rad] on an edge tag or a
        geometric locator. None leaves a component free; non-zero values are scaled by the load factor."""
        if not callable(where):
            self.fmesh.tag(where)  # ValueError naming an unknown tag
        if theta is not None and self.model != "naghdi":
            raise ValueError("theta constraints need the 'naghdi' model")
        for field, values, n in (("u", u, 3), ("theta", theta, 2)):
            if values is None:
                continue
            if len(values) != n:
                raise ValueError(f"{field} must have {n} components (None for free), got {values!r}")
            for i, val in enumerate(values):
                if val is None:
                    continue
                sub = self._subspace(field, i)
                V, _ = sub.collapse()
                dofs = self._locate(where, (sub, V))
                g = fem.Function(V)
                if val != 0.0:
                    self._rotation_prescribed |= field == "theta"
                    self._scaled_bcs.append((g, np.full(g.x.array.shape, float(val))))
                self.bcs.append(fem.dirichletbc(g, dofs, sub))
        return self

    def symmetry(self, where: str, normal: Sequence[float], penalty: float = 1e8):
        """Mirror symmetry about the plane through the edge `where` with normal n = `normal` (global
        frame, any direction): on the edge u . n = 0 and d . n = 0 (no displacement through the plane,
        no rotation of the director out of it).

        d . n = 0 is exact: the director base is turned (everywhere, before any solve, about the
        reference normal) so that a2 = -n on the edge, where d . n = sin th1, and th1 = 0 is prescribed
        there; re-basing keeps a2 (rebase_director with th1 = 0). A base already aligned (warp or weft
        normal to the plane, or a perpendicular plane set before) is kept and th1 or th2 is fixed.
        u . n = 0 is a penalty energy int_edge k_u / 2 (u . n)^2 dS, k_u = penalty max|A_ij| / h_min
        [N/m^2] (A the membrane stiffness [N/m], h_min the smallest cell [m]), met to O(1 / penalty)
        relative (symmetry-plane verify case).

        Raises:
            ValueError: naming `normal` if it is not a finite non-zero 3-vector, if the plane through the
                edge does not contain the edge, if the sheet's normal along the edge leaves the plane, or if
                the base cannot be turned to it (the sheet's normal is parallel to n somewhere, or an
                earlier symmetry plane is not perpendicular to this one).
        """
        if self._compiled:
            raise ValueError(f"symmetry: add it before the first solve (the forms of {where!r} are compiled)")
        n = _nonzero_vector("normal", normal)
        n = n / np.linalg.norm(n)
        if not (np.isfinite(penalty) and penalty > 0):
            raise ValueError(f"penalty must be a positive number, got {penalty!r}")
        nodes = fem.locate_dofs_topological(self.V2, self.mesh.topology.dim - 1, self.fmesh.facets(where))
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
        if self.model == "naghdi":
            self.constrain(where, theta=self._symmetry_angle(nodes, n))
        h_min = self.comm.allreduce(float(self.cell_size.x.array.min(initial=np.inf)), op=MPI.MIN)
        k_u = penalty * float(np.abs(self.A.value).max()) / h_min
        n_c = fem.Constant(self.mesh, PETSc.ScalarType(n))
        penalty_energy = 0.5 * k_u * ufl.dot(self.u, n_c) ** 2 * self._ds(where)
        self._extra_energy.append(penalty_energy)
        self.energy = self.energy + penalty_energy
        return self

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
        b1 = _normalize_rows(b1)
        self.a1.x.array[:] = b1.reshape(-1)
        self.a2.x.array[:] = np.cross(n0, b1).reshape(-1)
        self._base_turned = True
        return (0.0, None)

    def clamp(self, where: Locator):
        """All displacements and rotations zero."""
        return self.constrain(where, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0) if self.model == "naghdi" else None)

    def set_load_factor(self, lam: float):
        self.load_factor.value = lam
        for g, values in self._scaled_bcs:
            g.x.array[:] = lam * values

    # -------------------------------------------------------- director base
    def after_converged_step(self):
        """Hook called by the solvers after each converged step."""
        if self.rebase and not self._rotation_prescribed:
            self.rebase_director()

    def rebase_director(self):
        """Rotate the director base (a3, a1, a2) by the current angles and set the angles to zero.

        With R = R_a2(th2) R_a1(th1): a3' = d, a1' = cos th2 a1 - sin th2 a3,
        a2' = sin th1 sin th2 a1 + cos th1 a2 + sin th1 cos th2 a3; re-orthonormalised at the nodes.
        The displacement and the director at the nodes are unchanged; between the nodes the
        interpolated base differs at O(h^2), so the discrete equilibrium shifts slightly (measured in
        tests/test_shell_physics.py: load paths with and without re-basing differ by 5e-5 L on 10
        elements and 3.5e-6 L on 20).
        """
        if not hasattr(self, "_rebase_expressions"):
            th1, th2 = self.theta[0], self.theta[1]
            c1, s1, c2, s2 = ufl.cos(th1), ufl.sin(th1), ufl.cos(th2), ufl.sin(th2)
            a3, a1, a2 = self.a3, self.a1, self.a2
            points = self.V2.element.interpolation_points()
            self._rebase_expressions = [
                fem.Expression(shell_forms.director(self.theta, a3, a1, a2), points),
                fem.Expression(c2 * a1 - s2 * a3, points),
                fem.Expression(s1 * s2 * a1 + c1 * a2 + s1 * c2 * a3, points)]
            self._theta_dofs = self.W.sub(1).collapse()[1]
        new = []
        for expr in self._rebase_expressions:
            f = fem.Function(self.V2)
            f.interpolate(expr)
            new.append(f.x.array.reshape(-1, 3).copy())
        d = _normalize_rows(new[0])
        b1 = _normalize_rows(new[1] - np.sum(new[1] * d, axis=1, keepdims=True) * d)
        b2 = np.cross(d, b1)
        for field_, values in ((self.a3, d), (self.a1, b1), (self.a2, b2)):
            field_.x.array[:] = values.reshape(-1)
        if self._reference is not None:
            self._reference.update()
        if self._R_internal is not None:
            self._R_internal.repack()
        self.w.x.array[self._theta_dofs] = 0.0

    def director_field(self) -> fem.Function:
        """Current director d as a P2 vector Function (for output)."""
        if self.model != "naghdi":
            raise ValueError("the membrane model has no director")
        f = fem.Function(self.V2, name="director")
        f.interpolate(fem.Expression(shell_forms.director(self.theta, self.a3, self.a1, self.a2),
                                     self.V2.element.interpolation_points()))
        return f

    # --------------------------------------------------------------- assembly
    def compile(self):
        """JIT-compile the residual and Jacobian forms and assemble F_ref."""
        if self._compiled:
            return
        internal = ufl.derivative(self.energy, self.w, self.w_test)
        self.residual_form = internal
        if self._director_loads:   # moments: configuration-dependent load, in R and (linearised) in J
            self.residual_form = internal - self.load_factor * sum(self._director_loads[1:], self._director_loads[0])
        self.jacobian_form = ufl.derivative(self.residual_form, self.w, self.w_trial)
        self._R = fem.form(self.residual_form, jit_params=KERNEL_JIT)
        self._kernel_jit = {key: list(value) for key, value in KERNEL_JIT.items()}   # the flags in effect now
        self._J_form = None       # compiled on first use (`_J`): explicit runs never need the tangent
        self.F_ref = fem_petsc.create_vector(self._R)
        with self.F_ref.localForm() as f:
            f.set(0.0)
        if self._external:
            fem_petsc.assemble_vector(self.F_ref, fem.form(sum(self._external[1:], self._external[0])))
        self.F_ref.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        for point, force in self._point_loads:
            for i in range(3):
                dof = self.owned_node_dof(point, "u", i)
                if dof is not None:
                    self.F_ref.setValueLocal(dof, force[i], addv=PETSc.InsertMode.ADD_VALUES)
        self.F_ref.assemble()
        fem_petsc.set_bc(self.F_ref, self.bcs, scale=0.0)
        self._bc_dofs = np.unique(np.concatenate([bc.dof_indices()[0] for bc in self.bcs])) if self.bcs else \
            np.zeros(0, dtype=np.int32)
        self._moment_nodes = []     # (theta dofs in W, node of V2, moment) on the owning rank
        for point, moment in self._point_moments:
            dofs = [self.owned_node_dof(point, "theta", i) for i in range(2)]
            node = probe.owned_node(self.V2, point)
            if dofs[0] is not None and node is not None:
                self._moment_nodes.append((np.array(dofs, dtype=np.int32), node, moment))
        self._compiled = True

    def set_state(self, x: PETSc.Vec):
        """Copy a solver vector into the Function the forms read (never alias the two: see docs)."""
        x.copy(self.w.vector)
        self.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    @property
    def _J(self):
        """The compiled tangent form (dolfinx's default compiler flags: its kernel is the slowest to compile and
        assembled once per Newton iteration, not once per explicit step)."""
        self.compile()
        if self._J_form is None:
            self._J_form = fem.form(self.jacobian_form)
        return self._J_form

    @property
    def _internal_form(self) -> PrepackedForms:
        """The compiled internal force R_int of the explicit and dynamic integrators, compiled on first use. For the
        Naghdi shell (`reference_at_quadrature`) the reference geometry is evaluated once at the quadrature points
        and the coefficients are packed once (fabricfem.shell_reference); the force is the hand-written kernel
        (`hand_kernel`, fabricfem.forms.naghdi_kernel) or FFCx's derivative of `naghdi_energy_on_reference`: the
        same force as `naghdi_energy`'s up to round-off."""
        self.compile()
        if self._R_internal is not None:
            return self._R_internal
        energies, forms = [], []
        if self.hand_kernel:
            self._reference = ReferenceAtQuadrature(self, self._energy_args["degrees"], for_kernel=True)
            forms = [naghdi_kernel_form(self, self._reference, self._kernel_jit["cffi_extra_compile_args"])]
            energies = [sum(self._extra_energy[1:], self._extra_energy[0])] if self._extra_energy else []
        elif self.reference_at_quadrature:
            self._reference = ReferenceAtQuadrature(self, self._energy_args["degrees"])
            full, reduced = shell_forms.naghdi_energy_on_reference(
                self.u, self.theta, self._reference.full, self._reference.reduced, self.A, self.D,
                self.shear_stiffness, self.thickness, **self._energy_args)
            energies = [sum(self._extra_energy, full), reduced]
        elif self._director_loads:      # the residual holds the moments' work: the internal force on its own
            energies = [self.energy]
        forms += [fem.form(ufl.derivative(e, self.w, self.w_test), jit_params=self._kernel_jit) for e in energies]
        self._R_internal = PrepackedForms(forms or [self._R], self.w, prepack=self.reference_at_quadrature)
        return self._R_internal

    def _assemble_internal(self, x: PETSc.Vec, b: PETSc.Vec, lift: bool):
        """b = R(x) (with the moments' work when lift, i.e. for the residual; R_int alone otherwise)."""
        self.set_state(x)
        with b.localForm() as bl:
            bl.set(0.0)
        if lift:
            fem_petsc.assemble_vector(b, self._R)
            fem_petsc.apply_lifting(b, [self._J], [self.bcs], x0=[x], scale=-1.0)
        else:
            self._internal_form.assemble(b)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)

    def residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """b = R_int(x) - lambda F_ref with Dirichlet rows set to x - lambda g."""
        self._assemble_internal(x, b, lift=True)
        b.axpy(-float(self.load_factor.value), self.F_ref)
        for dofs, force, _ in self._point_moment_terms():
            b.getArray()[dofs] += force         # owned rows of the node's owning rank
        fem_petsc.set_bc(b, self.bcs, x, -1.0)

    def internal_force(self, x: PETSc.Vec, b: PETSc.Vec):
        """b = R_int(x) (no load, no boundary rows modified)."""
        self._assemble_internal(x, b, lift=False)

    def jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        self.set_state(x)
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self._J, bcs=self.bcs)
        A.assemble()
        if self._point_moments:
            for dofs, _, tangent in self._point_moment_terms():
                A.setValuesLocal(dofs, dofs, tangent, addv=PETSc.InsertMode.ADD_VALUES)
            A.assemble()

    def create_matrix(self) -> PETSc.Mat:
        self.compile()
        return fem_petsc.create_matrix(self._J)

    def create_vector(self) -> PETSc.Vec:
        self.compile()
        return fem_petsc.create_vector(self._R)

    # ----------------------------------------------------------------- probes
    def owned_node_dof(self, point: Sequence[float], field: str, component: int,
                       side: str | None = None) -> int | None:
        """Local index (in W) of `field` component at the node at `point` on its owning rank, else None;
        `side`: an edge tag, to pick among coincident nodes the one on that edge."""
        key = (field, component)
        if key not in self._collapsed:
            self._collapsed[key] = self._subspace(field, component).collapse()
        V, to_parent = self._collapsed[key]
        candidates = None
        if side is not None:
            candidates = fem.locate_dofs_topological(V, self.mesh.topology.dim - 1, self.fmesh.facets(side))
        node = probe.owned_node(V, point, candidates)
        return None if node is None else int(to_parent[node])

    def node_value(self, point: Sequence[float], field: str = "u", side: str | None = None) -> np.ndarray:
        """Displacement [m] (field "u") or rotation angles [rad] ("theta") at a mesh node, on all ranks.

        Where nodes coincide (the two sides of a slit or a seam) `side` names the edge tag whose node is
        read; without it such a point is refused (ValueError naming `side`)."""
        n = 3 if field == "u" else 2
        out = np.zeros(n)
        for i in range(n):
            dof = self.owned_node_dof(point, field, i, side)
            if dof is not None:
                out[i] = self.w.x.array[dof]
        return self.comm.allreduce(out, op=MPI.SUM)

    def reaction(self, where: Locator, field: str = "u", component: int = 0) -> float:
        """Sum over the dofs of `field` component on an edge tag or locator of the internal force
        R_int (the support reaction, N, or moment reaction, N m), same on all ranks."""
        self.compile()
        b = self.create_vector()
        self.internal_force(self.w.vector, b)
        sub = self._subspace(field, component)
        V, _ = sub.collapse()
        dofs = self._locate(where, (sub, V))[0]
        n_owned = self.W.dofmap.index_map.size_local * self.W.dofmap.index_map_bs
        owned = dofs[dofs < n_owned]
        local = float(b.array[owned].sum()) if len(owned) else 0.0
        b.destroy()
        return self.comm.allreduce(local, op=MPI.SUM)

    def director_at(self, point: Sequence[float]) -> np.ndarray:
        """Unit director at a mesh node, on all ranks."""
        return probe.node_value(self.director_field(), point)

    def displacement(self) -> fem.Function:
        """Displacement as a collapsed vector Function (for output)."""
        if self.model == "naghdi":
            return self.w.sub(0).collapse()
        return self.w
