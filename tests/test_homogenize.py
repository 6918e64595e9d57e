"""Periodic unit-cell homogenization (fabricfem.weave.homogenize) against closed forms and in parallel."""
import dolfinx.mesh as dmesh
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.verify import load_cases
from fabricfem.verify.homogenization import (
    LAMBDA,
    MU,
    PHI_GENERAL,
    box_cell,
    laminate_problem,
    neo_hookean,
    neo_hookean_S,
)
from fabricfem.weave.homogenize import PeriodicPair, UnitCellProblem, box_periodic_pairs, solve_unit_cell

CASES = load_cases()
# A finite, non-symmetric deformation of the laminate: the fluctuation is far from zero.
PHI_LAMINATE = np.array([[1.10, 0.20, 0.00],
                         [0.05, 0.95, 0.10],
                         [0.00, 0.00, 1.05]])


@pytest.mark.mpi
@pytest.mark.parametrize("name", ["homogenize-homogeneous", "homogenize-laminate"])
def test_case(name):
    results = CASES[name]()
    failed = [r for r in results if not r.passed]
    assert not failed, "\n".join(f"{r.quantity}: {r.value} vs {r.reference} (rel {r.rel_error:.2e})" for r in failed)


@pytest.mark.mpi
def test_parallel_matches_serial():
    """S and P of the laminate under a finite non-symmetric Phi on all ranks equal those computed on
    COMM_SELF in the same process within 1e-6 relative (only the summation order of the
    assembly and the LU pivoting differ, so agreement should be near round-off)."""
    parallel = laminate_problem(comm=MPI.COMM_WORLD).solve(PHI_LAMINATE, steps=2)
    serial = laminate_problem(comm=MPI.COMM_SELF).solve(PHI_LAMINATE, steps=2)
    for a, b in zip(parallel.steps, serial.steps):
        assert np.linalg.norm(a.S - b.S) <= 1e-6 * np.linalg.norm(b.S)
        assert np.linalg.norm(a.P - b.P) <= 1e-6 * np.linalg.norm(b.P)
    assert np.linalg.norm(serial.S) > 1e8  # a finite stress, not a trivial zero


def test_newton_quadratic_and_fluctuation_periodic():
    """Large-strain laminate: Newton converges in few iterations per step (exact Jacobian), and the
    solved u* is equal at every dof on a max face and its image on the min face (including
    edges and corners, where two or three translations apply)."""
    problem = laminate_problem()
    res = problem.solve(PHI_LAMINATE, steps=2)
    assert all(1 <= s.newton_iterations <= 6 for s in res.steps), [s.newton_iterations for s in res.steps]
    u = problem.u
    x = u.function_space.tabulate_dof_coordinates()
    values = u.x.array.reshape(-1, 3)
    size = np.array([2e-3, 1e-3, 1e-3])
    image = x - np.where(np.isclose(x, size, atol=1e-12), size, 0.0)  # move max faces onto min faces
    moved = np.any(image != x, axis=1)
    assert moved.sum() > 0
    lookup = {tuple(np.round(p / 1e-9).astype(int)): i for i, p in enumerate(x)}
    for i in np.flatnonzero(moved):
        j = lookup[tuple(np.round(image[i] / 1e-9).astype(int))]
        np.testing.assert_allclose(values[i], values[j], rtol=0, atol=1e-12 * np.abs(values).max())
    assert np.abs(values).max() > 1e-6 * size[0]  # the fluctuation is not trivially zero


def test_geometric_locators_equal_closed_form():
    """Pairs given by locators + translations: the homogeneous cell returns S(Phi) (1e-8 relative,
    round-off level because the exact fluctuation is zero)."""
    L = 1e-3
    mesh = box_cell((2, 2, 2), (L, L, L))
    pairs = [PeriodicPair(slave=lambda x, a=a: np.isclose(x[a], L, atol=1e-12), translation=L * np.eye(3)[a])
             for a in range(3)]
    res = solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), PHI_GENERAL, pairs, steps=1)
    S_ref = neo_hookean_S(PHI_GENERAL, MU, LAMBDA)
    assert np.linalg.norm(res.S - S_ref) <= 1e-8 * np.linalg.norm(S_ref)


def test_volume_fraction_with_void():
    """Eq. 4.64 with voids: only layer 1 (E1, thickness f1 Lx) is meshed, its x faces border the void
    (traction-free), periodic in y and z. With volume_fraction = f1 the stiffness along the layers
    is the Voigt average with E2 = 0, f1 E1 (1e-4: exact Q1 solution, O(strain) = 1e-6 nonlinearity)."""
    f1, E1, strain = 0.4, 10e9, 1e-6
    mesh = box_cell((2, 2, 2), (f1 * 2e-3, 1e-3, 1e-3))
    tags, pairs = box_periodic_pairs(mesh, axes=(1, 2))
    res = solve_unit_cell(mesh, neo_hookean(E1 / 2, 0.0), np.eye(3) + strain * np.diag([0, 1, 0]), pairs,
                          facet_tags=tags, volume_fraction=f1)
    assert res.volume_fraction == f1
    assert res.S[1, 1] / strain == pytest.approx(f1 * E1, rel=1e-4)


def test_default_volume_fraction_is_solid_over_bounding_box():
    """A 3 x 3 x 1 cell with its central column removed: phi = |Y_s| / |bounding box| = 8 / 9
    (eq. 4.65), from the geometry alone."""
    full = box_cell((3, 3, 1), (1e-3, 1e-3, 0.5e-3), comm=MPI.COMM_SELF)
    a, b, tol = 1e-3 / 3, 2e-3 / 3, 1e-12
    # locate_entities marks cells whose vertices all satisfy the marker: the central column
    column = dmesh.locate_entities(full, 3, lambda x: (x[0] > a - tol) & (x[0] < b + tol) &
                                   (x[1] > a - tol) & (x[1] < b + tol))
    assert len(column) == 1
    keep = np.setdiff1d(np.arange(full.topology.index_map(3).size_local, dtype=np.int32), column)
    mesh = dmesh.create_submesh(full, 3, keep)[0]
    tags, pairs = box_periodic_pairs(mesh, axes=(0, 1))
    problem = UnitCellProblem(mesh, neo_hookean(MU, LAMBDA), pairs, facet_tags=tags)
    assert problem.volume_fraction == pytest.approx(8.0 / 9.0, rel=1e-12)
    assert problem.cell_volume == pytest.approx(1e-3 * 1e-3 * 0.5e-3, rel=1e-12)
    res = problem.solve(np.diag([1.05, 1.0, 1.0]))
    assert np.all(np.isfinite(res.S)) and res.S[0, 0] > 0


@pytest.fixture(scope="module")
def small_cell():
    mesh = box_cell((1, 1, 1), (1e-3, 1e-3, 1e-3))
    tags, pairs = box_periodic_pairs(mesh)
    return mesh, tags, pairs


@pytest.mark.parametrize("phi", [0.0, -0.2, 1.5, float("nan")])
def test_bad_volume_fraction(small_cell, phi):
    mesh, tags, pairs = small_cell
    with pytest.raises(ValueError, match="volume_fraction"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.eye(3), pairs, facet_tags=tags, volume_fraction=phi)


@pytest.mark.parametrize("Phi", [np.diag([1.0, 1.0, -1.0]), np.zeros((3, 3)), np.eye(2),
                                 np.full((3, 3), np.nan)])
def test_bad_Phi(small_cell, Phi):
    mesh, tags, pairs = small_cell
    with pytest.raises(ValueError, match="Phi"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), Phi, pairs, facet_tags=tags)


def test_load_path_through_det_zero(small_cell):
    """A half-turn about z has det = 1 but the straight path 1 + t (Phi - 1) crosses det = 0."""
    mesh, tags, pairs = small_cell
    with pytest.raises(ValueError, match="Phi"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.diag([-1.0, -1.0, 1.0]), pairs, facet_tags=tags)


def test_missing_periodic_tag(small_cell):
    mesh, tags, _ = small_cell
    with pytest.raises(ValueError, match="periodic_pairs"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.eye(3), [PeriodicPair(slave=99, master=1)],
                        facet_tags=tags)
    with pytest.raises(ValueError, match="periodic_pairs"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.eye(3), [PeriodicPair(slave=2, master=77)],
                        facet_tags=tags)
    with pytest.raises(ValueError, match="periodic_pairs"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.eye(3), [], facet_tags=tags)


def test_bad_steps_and_psi(small_cell):
    mesh, tags, pairs = small_cell
    with pytest.raises(ValueError, match="steps"):
        solve_unit_cell(mesh, neo_hookean(MU, LAMBDA), np.eye(3), pairs, facet_tags=tags, steps=0)
    with pytest.raises(ValueError, match="cell_tags"):
        solve_unit_cell(mesh, {1: neo_hookean(MU, LAMBDA)}, np.eye(3), pairs, facet_tags=tags)
    ncells = mesh.topology.index_map(3).size_local
    cell_tags = dmesh.meshtags(mesh, 3, np.arange(ncells, dtype=np.int32), 1)
    with pytest.raises(ValueError, match="psi"):  # tag 2 is not in the mesh
        solve_unit_cell(mesh, {1: neo_hookean(MU, LAMBDA), 2: neo_hookean(MU, LAMBDA)}, np.eye(3), pairs,
                        facet_tags=tags, cell_tags=cell_tags)


def test_cells_without_energy():
    mesh = box_cell((2, 1, 1), (2e-3, 1e-3, 1e-3))
    tags, pairs = box_periodic_pairs(mesh)
    ncells = mesh.topology.index_map(3).size_local
    values = np.full(ncells, 2, dtype=np.int32)  # 2 cells: the first gets tag 1, the second tag 2
    values[:1] = 1
    cell_tags = dmesh.meshtags(mesh, 3, np.arange(ncells, dtype=np.int32), values)
    with pytest.raises(ValueError, match="psi"):  # the cells of tag 2 would have no energy
        solve_unit_cell(mesh, {1: neo_hookean(MU, LAMBDA)}, np.eye(3), pairs, facet_tags=tags, cell_tags=cell_tags)
