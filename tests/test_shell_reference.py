"""The internal force with the reference geometry evaluated once at the quadrature points (fabricfem.shell_reference),
by the hand-written C kernel (fabricfem.forms.naghdi_kernel, ShellModel(internal_force="kernel"), the default) and by
FFCx's derivative of `naghdi_energy_on_reference` ("ffcx-quadrature"), against the shell's energy written on the P2
fields (fabricfem.forms.shell.naghdi_energy, differentiated by UFL: "ffcx").

They are the same function of the state written in different ways (the strains expanded in the material frame, the
director's gradient by the chain rule), so they must agree to round-off: the bound 1e-11 relative (in the
max-norm over all dofs) is about 1e4 x machine epsilon, the cancellation of O(1) reference terms in strains of
the displacements used here (0.1-1 % of the element size, rotations 0.05 rad).

Serial:  python -m pytest -q tests/test_shell_reference.py;  MPI: mpirun -n 2 python -m pytest -m mpi ...
"""
from __future__ import annotations

import numpy as np
import pytest
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.forms import naghdi_kernel
from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.materials.fitted import FittedMembraneLaw
from fabricfem.meshes import plate, tube
from fabricfem.shell import ShellModel
from fabricfem.shell_reference import PrepackedForms

COMM = MPI.COMM_WORLD
ROUND_OFF = 1e-11
LAWS = {"linear": None, "kawabata": KawabataBending((2e-5, 1e-6, 3e-8)),
        "square root": SquareRootBending(B0=1e-5, kappa0=20.0)}


def fabric(law=None) -> Fabric:
    """An orthotropic cotton-like sheet with the given bending law."""
    return Fabric(E1=5e6, E2=2e6, nu12=0.3, G12=3e5, thickness=5e-4, density=400.0, bending_law=law)


def perturbed_state(model: ShellModel, seed: int = 1) -> PETSc.Vec:
    """A smooth-ish random state: displacements ~ 1e-4 m, rotations ~ 0.05 rad (same on every rank count:
    values drawn from the dof coordinates)."""
    x = model.create_vector()
    u_space, u_dofs = model.W.sub(0).collapse()
    t_space, t_dofs = model.W.sub(1).collapse()
    coords_u = u_space.tabulate_dof_coordinates()
    coords_t = t_space.tabulate_dof_coordinates()
    rng = np.random.default_rng(seed)
    k = rng.normal(size=(3, 3)) * 20.0
    values = x.getArray()
    n_owned = x.getLocalSize()
    for dofs, coords, amplitude in ((u_dofs, coords_u, 1e-4), (t_dofs, coords_t, 0.05)):
        bs = len(dofs) // len(coords)
        phase = np.sin(coords @ k)                                 # (nodes, 3)
        block = amplitude * phase[:, :bs]
        dofs = np.asarray(dofs).reshape(-1, bs)
        mask = dofs[:, 0] < n_owned
        values[dofs[mask].ravel()] = block[mask].ravel()
    x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return x


KERNELS = ("kernel", "ffcx-quadrature")


def force_difference(fabric_mesh_factory, law=None, symmetric: bool = False, rebase: bool = False,
                     kernel: str = "kernel") -> float:
    """Max-norm relative difference of the internal forces at a perturbed state: the reference geometry at the
    quadrature points with the `kernel` (KERNELS) against `naghdi_energy` ("ffcx")."""
    forces = []
    for internal_force in (kernel, "ffcx"):
        model = ShellModel(fabric_mesh_factory(), fabric(law), internal_force=internal_force)
        assert model.hand_kernel is (internal_force == "kernel")
        if symmetric:
            model.symmetry("left", (1.0, 0.0, 0.0), penalty=1.0)   # a small penalty: its force does not dominate
        model.compile()
        b = model.create_vector()
        if rebase:   # evaluate (building the quadrature data), turn the director base by a first state, evaluate again
            first = perturbed_state(model, seed=2)
            model.internal_force(first, b)
            model.set_state(first)
            model.rebase_director()
        x = perturbed_state(model)
        model.internal_force(x, b)
        assert model.reference_at_quadrature is (internal_force != "ffcx")
        forces.append(b)
    diff = forces[0].copy()
    diff.axpy(-1.0, forces[1])
    return diff.norm(PETSc.NormType.NORM_INFINITY) / forces[1].norm(PETSc.NormType.NORM_INFINITY)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("law", list(LAWS))
def test_curved_quadrilaterals_agree(law, kernel):
    """A Q2 tube (curved: reference curvature 1 / R, a 9-node geometry) with each bending law."""
    error = force_difference(lambda: tube(0.1, 0.03, 8, 3, comm=COMM, order=2), LAWS[law], kernel=kernel)
    assert error < ROUND_OFF, error


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("law", ["linear", "square root"])
def test_triangles_with_bubble_agree(law, kernel):
    """P2 + bubble triangles on a tube (6 and 3 point rules; 7 displacement and 6 rotation nodes)."""
    error = force_difference(lambda: tube(0.1, 0.03, 8, 3, cell="triangle", comm=COMM, order=2), LAWS[law],
                             kernel=kernel)
    assert error < ROUND_OFF, error


@pytest.mark.parametrize("kernel", KERNELS)
def test_symmetry_penalty_is_carried_over(kernel):
    """The symmetry plane's penalty energy is part of the internal force."""
    error = force_difference(lambda: plate(0.1, 0.05, 4, 2, cell="quadrilateral", comm=COMM), symmetric=True,
                             kernel=kernel)
    assert error < ROUND_OFF, error


@pytest.mark.parametrize("kernel", KERNELS)
def test_quadrature_data_follow_a_rebased_director(kernel):
    """After rebase_director the quadrature data are re-evaluated (a stale base would differ at O(0.05))."""
    error = force_difference(lambda: tube(0.1, 0.03, 8, 3, comm=COMM, order=2), rebase=True, kernel=kernel)
    assert error < ROUND_OFF, error


@pytest.mark.mpi
@pytest.mark.parametrize("law", ["linear", "square root"])
@pytest.mark.parametrize("n_around", [7, 5])
def test_batched_cells_match_one_cell_calls(law, n_around):
    """The kernel's batched loop (naghdi_kernel.LANES cells a call, PrepackedForms) against dolfinx's assembly of
    the same kernel one cell a call, on 21 and 5 cells (a short last batch; under MPI each rank's share, ghosts
    summed): the lanes compute each cell as the one-cell call does and add in the same order (1e-14 relative);
    and against FFCx's derivative of `naghdi_energy` (ROUND_OFF)."""
    assert (3 * n_around) % naghdi_kernel.LANES
    mesh = lambda: tube(0.1, 0.03, n_around, 3, comm=COMM, order=2)       # noqa: E731
    model = ShellModel(mesh(), fabric(LAWS[law]))
    model.compile()
    assert_as_dolfinx_assembles(model, perturbed_state(model))
    assert force_difference(mesh, LAWS[law]) < ROUND_OFF


def assert_as_dolfinx_assembles(model, x) -> None:
    """The model's internal force at x equals dolfinx's own assembly of its forms (one cell a call) to 1e-14 of
    its largest entry (max norm)."""
    b, plain = model.create_vector(), model.create_vector()
    model.internal_force(x, b)
    with plain.localForm() as local:
        local.set(0.0)
    for form in model.internal_force_forms.forms:
        fem_petsc.assemble_vector(plain, form)
    plain.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    plain.axpy(-1.0, b)
    assert plain.norm(PETSc.NormType.NORM_INFINITY) <= 1e-14 * b.norm(PETSc.NormType.NORM_INFINITY)


def test_kernel_layouts_share_their_offsets():
    """The hand kernel reads the reduced rule's quantities at the full rule's offsets and |J|, alpha as the last two
    values of both layouts."""
    full = naghdi_kernel._offsets(naghdi_kernel.KERNEL_FULL)
    reduced = naghdi_kernel._offsets(naghdi_kernel.KERNEL_REDUCED)
    assert all(reduced[name] == full[name] for name, _ in naghdi_kernel.KERNEL_REDUCED[:-2])
    for layout in (naghdi_kernel.KERNEL_FULL, naghdi_kernel.KERNEL_REDUCED):
        assert [name for name, _ in layout[-2:]] == ["detJ", "alpha"]


def test_fitted_membrane_law_keeps_the_ffcx_kernel():
    """The hand-written kernel has the quadratic membrane energy only: a fitted membrane law keeps FFCx's form."""
    law = FittedMembraneLaw(exponents=((2, 0, 0), (0, 2, 0), (0, 0, 2)), coefficients=(1e3, 1e3, 1e2))
    model = ShellModel(tube(0.1, 0.03, 8, 3, comm=COMM, order=2),
                       Fabric(1e6, 1e6, 1e5, 0.3, 1e-3, density=400.0, membrane_law=law))
    assert model.reference_at_quadrature and not model.hand_kernel


def test_force_is_the_gradient_of_the_energy():
    """Independent of the other implementation: the internal force is the derivative of the shell's energy
    (central differences of the assembled energy along a direction, relative error of O(h^2) ~ 1e-7)."""
    model = ShellModel(tube(0.1, 0.03, 8, 3, comm=COMM, order=2), fabric(LAWS["kawabata"]))
    model.compile()
    x = perturbed_state(model)
    direction = perturbed_state(model, seed=5)
    b = model.create_vector()
    model.internal_force(x, b)
    energy = fem.form(model.energy)

    def energy_at(step: float) -> float:
        y = x.copy()
        y.axpy(step, direction)
        model.set_state(y)
        return COMM.allreduce(fem.assemble_scalar(energy), op=MPI.SUM)

    h = 1e-3
    derivative = (energy_at(h) - energy_at(-h)) / (2 * h)
    assert abs(derivative - b.dot(direction)) < 1e-6 * abs(b.dot(direction))


@pytest.mark.mpi
@pytest.mark.parametrize("kernel", KERNELS)
def test_two_ranks_agree(kernel):
    """The same comparison on the distributed mesh (ghost cells get their quadrature data too)."""
    assert force_difference(lambda: tube(0.1, 0.03, 8, 3, comm=COMM, order=2), LAWS["kawabata"],
                            kernel=kernel) < ROUND_OFF


@pytest.mark.mpi
def test_prepacked_coefficients_follow_the_state():
    """PrepackedForms: the internal force at a sequence of states (the state block refreshed, the rest packed once)
    equals dolfinx's assembly that packs everything, on cell and exterior-facet integrals (symmetry penalty), to
    the last bit of the summation (1e-14 relative)."""
    model = ShellModel(plate(0.1, 0.05, 4, 2, cell="quadrilateral", comm=COMM), fabric())
    model.symmetry("left", (1.0, 0.0, 0.0), penalty=1.0)
    model.compile()
    for seed in (1, 2, 3):
        assert_as_dolfinx_assembles(model, perturbed_state(model, seed))
        assert model.internal_force_forms.prepacked


def test_prepacked_coefficients_of_a_blocked_state():
    """The same on the membrane model, whose state is a blocked vector space (dofmap block size 3)."""
    model = ShellModel(tube(0.1, 0.03, 8, 3, comm=COMM, order=2), fabric(), model="membrane")
    model.compile()
    form = fem.form(model.residual_form)
    prepacked = PrepackedForms([form], model.w)
    assert prepacked.prepacked and model.w.function_space.dofmap.bs == 3
    b, plain = model.create_vector(), model.create_vector()
    for seed in (1, 2):
        model.w.x.array[:] = 1e-4 * np.sin(np.arange(model.w.x.array.size) * (0.3 + seed))
        for vec in (b, plain):
            with vec.localForm() as local:
                local.set(0.0)
        prepacked.assemble(b)
        fem_petsc.assemble_vector(plain, form)
        plain.axpy(-1.0, b)
        assert plain.norm(PETSc.NormType.NORM_INFINITY) <= 1e-14 * b.norm(PETSc.NormType.NORM_INFINITY)
