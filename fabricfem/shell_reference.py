"""The shell's reference geometry at the quadrature points, for the internal force of explicit steps.

`naghdi_energy` (fabricfem.forms.shell) recomputes the reference geometry (F0 = grad phi0, the material frame by
Gram-Schmidt, the director base and its gradients, the reference curvature) from seven P2 fields at every
quadrature point of every evaluation. In a dynamic run those are fixed (the director base is not re-based), so
`ReferenceAtQuadrature` evaluates them once into Quadrature-element Functions at the points of the full and the
reduced PSRI rules (the same points FFCx integrates with) and `naghdi_energy_on_reference` reads them from there.
The two energies are the same function of the state up to round-off (tests/test_shell_reference.py). Which of
them (or the hand-written kernel) a model's internal force uses is its choice (ShellModel.use_internal_force).
"""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp as _cpp
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from dolfinx.fem.assemble import pack_coefficients
from ffcx.element_interface import create_quadrature

from fabricfem.forms import naghdi_kernel
from fabricfem.forms import shell as shell_forms


class ReferenceAtQuadrature:
    """Packed reference quantities of a Naghdi ShellModel at the points of its PSRI rules: `full` (with the bending
    quantities) and `reduced` are vector Quadrature Functions; `update()` re-evaluates them after the director base
    changed (ShellModel.rebase_director). `for_kernel`: the layout of the hand-written kernel
    (fabricfem.forms.naghdi_kernel.KERNEL_FULL / KERNEL_REDUCED) instead of fabricfem.forms.shell.reference_layout."""

    def __init__(self, model, degrees: tuple[int, int], for_kernel: bool = False):
        mesh = model.mesh
        cell = mesh.ufl_cell()
        base, frame = (model.a3, model.a1, model.a2), (model.t1, model.t2)
        tdim = mesh.topology.dim
        index_map = mesh.topology.index_map(tdim)
        self._cells = np.arange(index_map.size_local + index_map.num_ghosts, dtype=np.int32)
        self._parts = []
        for degree, bending in zip(degrees, (True, False)):
            if for_kernel:
                quantities = naghdi_kernel.kernel_reference_quantities(model.phi0, model.n0, base, frame,
                                                                       model.psri_thickness, model.cell_size, bending)
            else:
                quantities = shell_forms.reference_quantities(model.phi0, model.n0, base, frame, bending)
            size = quantities.ufl_shape[0]
            element = ufl.VectorElement("Quadrature", cell, degree, dim=size, quad_scheme="default")
            space = fem.FunctionSpace(mesh, element)
            points, _ = create_quadrature(cell.cellname(), degree, "default")
            function = fem.Function(space, name=f"reference_degree_{degree}")
            self._parts.append((fem.Expression(quantities, points), function, size))
        self.full, self.reduced = self._parts[0][1], self._parts[1][1]
        self.update()

    def update(self) -> None:
        """Evaluate the reference quantities at the quadrature points of every local cell (owned and ghost)."""
        for expression, function, size in self._parts:
            values = expression.eval(self._cells)                    # (cells, points x size), point-major
            blocks = function.function_space.dofmap.list.array.reshape(len(self._cells), -1)
            function.x.array.reshape(-1, size)[blocks.ravel()] = values.reshape(-1, size)


def naghdi_kernel_form(model, reference: ReferenceAtQuadrature, flags: tuple[str, ...]):
    """dolfinx Form (cpp) of the Naghdi shell's internal force by the hand-written kernel
    (fabricfem.forms.naghdi_kernel) on the state space of `model`, with `reference` in the kernel's layout;
    compiled with the C flags `flags`. The model's A, D, shear stiffness Constants are read at every assembly."""
    source, parameters = naghdi_source(model)
    law_constant = fem.Constant(model.mesh, np.asarray(parameters, dtype=float))
    addresses = naghdi_kernel.compile_kernel(source, model.comm, tuple(flags))
    return cell_kernel_form(model, reference, addresses, [model.A, model.D, model.shear_stiffness, law_constant])


def naghdi_source(model) -> tuple[str, np.ndarray]:
    """(C source of the hand-written kernel for `model`'s elements, PSRI degrees and bending law, the law's
    parameters) (fabricfem.forms.naghdi_kernel.kernel_source)."""
    args = model.energy_options
    law, parameters = naghdi_kernel.law_parameters(args["law"], args["law_eps"])
    u_element = model.W.ufl_element().sub_elements()[0].sub_elements()[0]
    theta_element = model.W.ufl_element().sub_elements()[1].sub_elements()[0]
    source = naghdi_kernel.kernel_source(u_element, theta_element, model.mesh.ufl_cell().cellname(),
                                         args["degrees"], law, len(parameters))
    return source, parameters


def cell_kernel_form(model, reference: ReferenceAtQuadrature, addresses: tuple[int, int], constants: list):
    """dolfinx Form (cpp) of a compiled cell kernel on the state space of `model`, with the coefficients (state,
    reference.full, reference.reduced) and `constants` packed in that order; it holds the C++ Constants and Functions
    (shared pointers). `addresses` (naghdi_kernel.compile_kernel's): the one-cell kernel (dolfinx's) and the batched
    assembly (naghdi_kernel.assemble_cells) that PrepackedForms and the compiled loop call instead."""
    address, cells_address = addresses
    form = KernelForm([model.W._cpp_object], {fem.IntegralType.cell: ([(-1, address)], None)},
                      [model.w._cpp_object, reference.full._cpp_object, reference.reduced._cpp_object],
                      [c._cpp_object for c in constants], False, model.mesh._mesh)
    form.kernel_address, form.cells_address = address, cells_address
    return form


class KernelForm(_cpp.fem.Form_float64):
    """dolfinx's Form (cpp) of a hand-written cell kernel, with the addresses (ints) of the kernel (`kernel_address`)
    and of its batched assembly over cells (`cells_address`, fabricfem.forms.naghdi_kernel.assemble_cells)."""


class PrepackedForms:
    """Linear forms assembled many times with only the `state` Function changing (the internal force of an explicit
    run): their coefficients are packed once (dolfinx packs every coefficient at every assembly otherwise) and
    before each assembly only the state's block is refreshed, by one vectorised gather over the cells. A hand-written
    kernel's form (KernelForm) is then assembled by the kernel's own batched loop over its cells, in dolfinx's order,
    which reads the state from the state's array (owned and ghost entries) itself.

    With `prepack` False (the per-evaluation baseline), forms on interior facets, or a state whose element needs dof
    transformations, every coefficient is packed at every assembly as dolfinx does (`prepacked` is False)."""

    def __init__(self, forms: list, state: fem.Function, prepack: bool = True):
        self.forms, self.state = forms, state
        element = state.function_space.element
        types = {t for form in forms for t in form.integral_types}
        self.prepacked = (prepack and not element.needs_dof_transformations
                          and fem.IntegralType.interior_facet not in types)
        self.coefficients = [None] * len(forms)
        self._batched: dict[int, tuple[np.ndarray, np.ndarray]] = {}     # form index -> (batched reference, cell dofs)
        if self.prepacked:
            self.repack()

    def repack(self) -> None:
        """Pack every coefficient again (after a fixed coefficient changed, e.g. ReferenceAtQuadrature.update)."""
        if not self.prepacked:
            return
        dofmap = self.state.function_space.dofmap
        blocks = dofmap.list.array.reshape(-1, dofmap.dof_layout.num_dofs)           # per cell, node-major
        cell_dofs = (blocks[:, :, None] * dofmap.bs + np.arange(dofmap.bs)).reshape(len(blocks), -1)
        self._blocks, self._batched = [], {}
        for k, form in enumerate(self.forms):
            packed = pack_coefficients(form)
            sizes = [c.function_space.element.space_dimension for c in form.coefficients]
            position = next(i for i, c in enumerate(form.coefficients)
                            if np.shares_memory(c.x.array, self.state.x.array))
            start = int(np.sum(sizes[:position]))
            if isinstance(form, KernelForm):       # the state (first) read from its vector by the kernel's loop
                cells = np.asarray(form.domains(fem.IntegralType.cell, -1))
                reference = naghdi_kernel.batched_reference(packed[(fem.IntegralType.cell, -1)], sizes[position])
                self._batched[k] = (reference, np.ascontiguousarray(cell_dofs[cells], dtype=np.int32))
                continue
            for (integral_type, subdomain), array in packed.items():
                entities = np.asarray(form.domains(integral_type, subdomain))
                cells = entities if integral_type == fem.IntegralType.cell else entities.reshape(-1, 2)[:, 0]
                self._blocks.append((array, slice(start, start + sizes[position]), cell_dofs[cells]))
            self.coefficients[k] = packed

    def assemble(self, b) -> None:
        """Add the forms' vectors to the PETSc vector `b` (not zeroed, ghosts not accumulated) at the current state."""
        if self.prepacked:
            values = self.state.x.array
            for array, columns, dofs in self._blocks:
                array[:, columns] = values[dofs]
        for k, (form, coefficients) in enumerate(zip(self.forms, self.coefficients)):
            if k in self._batched:
                reference, dofs = self._batched[k]
                constants = np.ascontiguousarray(_cpp.fem.pack_constants(form), dtype=np.float64)
                with b.localForm() as local:
                    naghdi_kernel.assemble_cells(form.cells_address, local.array, self.state.x.array, reference,
                                                 constants, dofs)
            else:
                fem_petsc.assemble_vector(b, form, coeffs=coefficients)
