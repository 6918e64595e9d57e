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
from fabricfem.forms import shell as shell_forms
from fabricfem.forms.jit import KERNEL_JIT
from fabricfem.materials import Fabric, SquareRootBending
from fabricfem.shell_loads import ShellLoads
from fabricfem.shell_reference import PrepackedForms, ReferenceAtQuadrature, naghdi_kernel_form
from fabricfem.shell_symmetry import ShellSymmetry, normalize_rows

Locator = str | Callable[[np.ndarray], np.ndarray]

MODELS = ("naghdi", "membrane")
# how R_int (`ShellModel.internal_force`) is computed: the hand-written C kernel, FFCx's kernel with the reference
# geometry at the quadrature points, FFCx's kernel of the energy on the P2 fields (ShellModel.use_internal_force)
INTERNAL_FORCES = ("kernel", "ffcx-quadrature", "ffcx")


def equispaced_coordinates(mesh) -> None:
    """Give the mesh's coordinate element the equispaced points FFCx gives it when it first compiles a form on the mesh
    (ffcx.analysis replaces an element without a variant): the element is part of every form's signature, the JIT
    cache key, so set now, the forms of a model have the same signatures whether FFCx compiled on the mesh before or
    found everything in its cache (another mesh or thickness then compiles nothing). The points are those of
    dolfinx.io.gmshio's meshes; for the degrees 1 and 2 of the coordinate maps they are the points of any variant."""
    domain = mesh.ufl_domain()
    element = domain.ufl_coordinate_element()
    if element.variant() is None:
        scalar = ufl.FiniteElement(element.family(), element.cell(), element.degree(), element.quadrature_scheme(),
                                   variant="equispaced")
        domain._ufl_coordinate_element = ufl.VectorElement(scalar)   # as ffcx.analysis does, before any form


class ShellModel(ShellLoads, ShellSymmetry):
    """Geometrically nonlinear fabric sheet on a `fabricfem.meshes.FabricMesh`.

    Loads: fabricfem.shell_loads.ShellLoads (add_gravity, add_pressure, ...); symmetry planes:
    fabricfem.shell_symmetry.ShellSymmetry.

    Args:
        fabric_mesh: the surface mesh with tags and warp/normal fields.
        fabric: material (Fabric).
        model: "naghdi" (membrane + bending + transverse shear, rotations) or "membrane".
        degree: polynomial degree of the fields (2; the displacement of the Naghdi
            shell on triangles is enriched with a cubic bubble).
        psri_degrees: (full, reduced) quadrature degrees of the PSRI split (equal degrees: full integration, no
            split); its weight alpha = min(1, t_eq^2 / h^2) follows the bending and membrane stiffnesses
            (`psri_thickness`, fabricfem.forms.shell.equivalent_thickness).
        bending_eps: regularisation [1/m] of |K| for the square-root bending law
            (default 1e-3 kappa0).
        rebase: after each converged load step, rotate the director base onto the current
            director and zero the angles, so that only increments are parametrised (no
            singularity at |theta1| = pi/2 however far the sheet turns). Off while a non-zero
            rotation is prescribed.
        internal_force: how the internal force of the explicit and dynamic integrators is computed, one of
            INTERNAL_FORCES (`use_internal_force`); "kernel" (the default) where it applies.
    """

    def __init__(self, fabric_mesh, fabric: Fabric, model: str = "naghdi", degree: int = 2,
                 psri_degrees: tuple[int, int] = (4, 2), bending_eps: float | None = None,
                 rebase: bool = True, internal_force: str = "kernel"):
        if model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {model!r}")
        if not isinstance(fabric, Fabric):
            raise ValueError(f"fabric must be a fabricfem.materials.Fabric, got {type(fabric).__name__}")
        self.fmesh = fabric_mesh
        self.mesh = fabric_mesh.mesh
        equispaced_coordinates(self.mesh)
        self.comm = self.mesh.comm
        self.fabric = fabric
        self.model = model
        self._state_space(degree)
        self._reference_fields(degree)
        self._stiffness_constants()
        self.cell_size = self._cell_size()
        self._shell_energy(psri_degrees, bending_eps)
        self.dx = ufl.Measure("dx", domain=self.mesh)
        self.ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=fabric_mesh.facet_tags)
        self._external: list = []
        self._director_loads: list = []   # external work that depends on the current director (moments)
        self._point_loads: list[tuple[np.ndarray, np.ndarray]] = []
        self._point_moments: list[tuple[np.ndarray, np.ndarray]] = []   # (point [m], moment [N m])
        self.bcs: list = []
        self._scaled_bcs: list[tuple[fem.Function, np.ndarray]] = []
        self._extra_energy: list = []   # energies added after the shell's own (symmetry penalties)
        self._compiled = False
        self.use_internal_force(internal_force)
        self.rebase = rebase and model == "naghdi"
        self._rotation_prescribed = False
        self._base_turned = False   # the director base was turned to a symmetry plane (symmetry)
        self._collapsed: dict = {}  # (field, component) -> collapsed subspace and map, for probes

    # ------------------------------------------------------------------ set-up
    def _state_space(self, degree: int) -> None:
        """The state space W ((u, theta) for the Naghdi shell, u for the membrane), its Function, test and trial."""
        cell = self.mesh.ufl_cell()
        P = ufl.FiniteElement("Lagrange", cell, degree)
        if self.model == "naghdi":
            P_u = P + ufl.FiniteElement("Bubble", cell, 3) if cell.cellname() == "triangle" else P
            element = ufl.MixedElement([ufl.VectorElement(P_u, dim=3), ufl.VectorElement(P, dim=2)])
        else:
            element = ufl.VectorElement(P, dim=3)
        self.W = fem.FunctionSpace(self.mesh, element)
        self.w = fem.Function(self.W, name="state")
        self.w_test = ufl.TestFunction(self.W)
        self.w_trial = ufl.TrialFunction(self.W)
        if self.model == "naghdi":
            self.u, self.theta = ufl.split(self.w)
            self.v, self.eta = ufl.split(self.w_test)
        else:
            self.u, self.theta = self.w, None
            self.v, self.eta = self.w_test, None

    def _reference_fields(self, degree: int) -> None:
        """Reference geometry and frames as P2 vector fields on the surface; the director base (a3, a1, a2),
        re-based between load steps (rebase_director)."""
        self.V2 = fem.VectorFunctionSpace(self.mesh, ("Lagrange", degree), dim=3)
        x = self.V2.tabulate_dof_coordinates().T
        warp, normal = self.fmesh.directions_at(self.V2)   # per panel where the mesh has panel_directions
        n0 = normalize_rows(normal.T)
        warp = warp.T
        t1 = normalize_rows(warp - np.sum(warp * n0, axis=1, keepdims=True) * n0)
        t2 = np.cross(n0, t1)
        self.phi0 = self._vector_field(x.T, "reference_position")
        self.n0 = self._vector_field(n0, "reference_normal")
        self.t1 = self._vector_field(t1, "warp")
        self.t2 = self._vector_field(t2, "weft")
        self.a3 = self._vector_field(n0, "director_base")
        self.a1 = self._vector_field(t1, "director_base_1")
        self.a2 = self._vector_field(t2, "director_base_2")

    def _stiffness_constants(self) -> None:
        """A = t Q [N/m], D [N m], k_s G13 t [N/m], t [m], the PSRI weight's thickness t_eq [m] (t itself
        unless the bending rigidity is given apart from t: fabricfem.forms.shell.equivalent_thickness), the load
        factor and the fitted membrane law's parameters as Constants: another material or thickness compiles no
        new form."""
        fabric, mesh = self.fabric, self.mesh
        t = fabric.thickness
        self.A = fem.Constant(mesh, PETSc.ScalarType(t * fabric.plane_stress_matrix))
        self.D = fem.Constant(mesh, PETSc.ScalarType(fabric.bending_matrix))
        t_eq = t if fabric.bending_rigidity is None else shell_forms.equivalent_thickness(
            t * fabric.plane_stress_matrix, fabric.bending_matrix)
        self.psri_thickness = fem.Constant(mesh, PETSc.ScalarType(t_eq))
        self.shear_stiffness = fem.Constant(
            mesh, PETSc.ScalarType(fabric.shear_correction * fabric.transverse_shear_modulus * t))
        self.thickness = fem.Constant(mesh, PETSc.ScalarType(t))
        self.load_factor = fem.Constant(mesh, PETSc.ScalarType(0.0))
        self.membrane_density = None
        if fabric.membrane_law is not None:
            # fitted membrane energy W(E11, E22, 2 E12) [J/m^2] (fabricfem.materials.fitted) instead of 1/2 eps.A eps
            # (any law with .parameters and .ufl_energy(eps, parameters): polynomial or convex-ridge)
            self.membrane_coefficients = fem.Constant(
                mesh, PETSc.ScalarType(np.asarray(fabric.membrane_law.parameters, dtype=float)))
            self.membrane_density = functools.partial(fabric.membrane_law.ufl_energy,
                                                      parameters=self.membrane_coefficients)

    def _shell_energy(self, psri_degrees: tuple[int, int], bending_eps: float | None) -> None:
        """The strain energy [J] (UFL form) of the model; for the Naghdi shell also the director d and
        `energy_options`, the keyword arguments of fabricfem.forms.shell.naghdi_energy."""
        if self.model != "naghdi":
            self.energy = shell_forms.membrane_energy(self.u, self.phi0, self.t1, self.t2, self.A,
                                                      membrane_density=self.membrane_density)
            return
        law = self.fabric.bending_law
        eps = bending_eps
        if isinstance(law, SquareRootBending) and eps is None:
            eps = 1e-3 * law.kappa0
        self.bending_eps = eps
        self.energy_options = dict(law=law, law_eps=eps, degrees=psri_degrees, cell_size=self.cell_size,
                                   membrane_density=self.membrane_density)
        self.energy = shell_forms.naghdi_energy(
            self.u, self.theta, self.phi0, self.n0, (self.a3, self.a1, self.a2), (self.t1, self.t2),
            self.A, self.D, self.shear_stiffness, self.psri_thickness, **self.energy_options)
        self.d = shell_forms.director(self.theta, self.a3, self.a1, self.a2)

    def use_internal_force(self, internal_force: str) -> None:
        """Compute R_int (`internal_force`, the force of the explicit and dynamic integrators) from now on by

        * "kernel": the hand-written C kernel (fabricfem.forms.naghdi_kernel) with the reference geometry evaluated
          once at the quadrature points (fabricfem.shell_reference); where it does not apply (the membrane model,
          a fitted membrane law) as "ffcx-quadrature";
        * "ffcx-quadrature": FFCx's kernel of fabricfem.forms.shell.naghdi_energy_on_reference (the reference
          geometry at the quadrature points); the membrane model as "ffcx";
        * "ffcx": FFCx's derivative of the energy on the P2 fields (the reference geometry recomputed at every
          evaluation).

        The three give the same force up to round-off. The compiled force in use, if any, is dropped.
        Sets `hand_kernel` and `reference_at_quadrature` (what applies). Raises ValueError naming `internal_force`
        for any other value."""
        if internal_force not in INTERNAL_FORCES:
            raise ValueError(f"internal_force must be one of {INTERNAL_FORCES}, got {internal_force!r}")
        self.reference_at_quadrature = internal_force != "ffcx" and self.model == "naghdi"
        # the hand-written kernel covers the quadratic membrane energy (not a fitted membrane law)
        self.hand_kernel = (self.reference_at_quadrature and internal_force == "kernel"
                            and self.fabric.membrane_law is None)
        self.quadrature_reference: ReferenceAtQuadrature | None = None   # of the internal force, built on first use
        self._R_internal: PrepackedForms | None = None                    # the internal force, compiled on first use

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

    def clamp(self, where: Locator):
        """All displacements and rotations zero."""
        return self.constrain(where, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0) if self.model == "naghdi" else None)

    @property
    def has_prescribed_values(self) -> bool:
        """Whether a constraint prescribes a non-zero displacement or rotation (scaled by the load factor)."""
        return bool(self._scaled_bcs)

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
        d = normalize_rows(new[0])
        b1 = normalize_rows(new[1] - np.sum(new[1] * d, axis=1, keepdims=True) * d)
        b2 = np.cross(d, b1)
        for field_, values in ((self.a3, d), (self.a1, b1), (self.a2, b2)):
            field_.x.array[:] = values.reshape(-1)
        if self.quadrature_reference is not None:
            self.quadrature_reference.update()
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
    def internal_force_forms(self) -> PrepackedForms:
        """The compiled forms of R_int (`internal_force`), compiled on first use by the implementation chosen
        (`use_internal_force`). With the reference geometry at the quadrature points (`reference_at_quadrature`,
        `quadrature_reference`) the coefficients are packed once; the force is the hand-written kernel
        (`hand_kernel`) or FFCx's derivative of `naghdi_energy_on_reference`, otherwise FFCx's derivative of
        `energy`: the same force up to round-off."""
        self.compile()
        if self._R_internal is not None:
            return self._R_internal
        energies, forms = [], []
        if self.hand_kernel:
            self.quadrature_reference = reference = ReferenceAtQuadrature(self, self.energy_options["degrees"],
                                                                          for_kernel=True)
            forms = [naghdi_kernel_form(self, reference, self._kernel_jit["cffi_extra_compile_args"])]
            energies = [sum(self._extra_energy[1:], self._extra_energy[0])] if self._extra_energy else []
        elif self.reference_at_quadrature:
            self.quadrature_reference = reference = ReferenceAtQuadrature(self, self.energy_options["degrees"])
            full, reduced = shell_forms.naghdi_energy_on_reference(
                self.u, self.theta, reference.full, reference.reduced, self.A, self.D,
                self.shear_stiffness, self.psri_thickness, **self.energy_options)
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
            self.internal_force_forms.assemble(b)
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
        """Displacement as a collapsed vector Function (for output; a new Function, its space made once)."""
        if self.model == "naghdi":
            if getattr(self, "_displacement_map", None) is None:
                space, dofs = self.W.sub(0).collapse()
                self._displacement_map = (space, np.asarray(dofs, dtype=np.int64))   # dofs: into w.x.array
            space, dofs = self._displacement_map
            u = fem.Function(space)
            u.x.array[:] = self.w.x.array[dofs]
            return u
        return self.w
