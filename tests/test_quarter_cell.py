"""Anti-symmetric periodicity of the quarter unit cell ([Man2006, sec. 4.3.3], Fig. 19 option B):
PeriodicPair with a point map (x, y, z) -> (x - Lx, y, -z) and component signs (1, 1, -1)."""
import dolfinx.mesh as dmesh
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.verify.homogenization import LAMBDA, MU, neo_hookean, neo_hookean_S
from fabricfem.weave.homogenize import PeriodicPair, UnitCellProblem

SIZE = np.array([2e-3, 1e-3, 1e-3])  # Lx, Ly, Lz [m]; z in [-Lz/2, Lz/2] so that z -> -z maps the cell onto itself
TOL = 1e-9 * SIZE.max()  # geometric tolerance [m] for face membership


def mirror_x(x: np.ndarray) -> np.ndarray:
    """End face x = Lx onto the start face x = 0 with z -> -z (as UnitCellMesh.periodic_relation, quarter)."""
    out = np.array(x, dtype=np.float64, copy=True)
    out[0] -= SIZE[0]
    out[2] = -out[2]
    return out


def quarter_problem(comm=MPI.COMM_WORLD, n=(4, 2, 2)) -> UnitCellProblem:
    """Neo-Hookean box, anti-symmetric in x, plainly periodic in y and z (no free face)."""
    mesh = dmesh.create_box(comm, [np.array([0.0, 0.0, -SIZE[2] / 2]), np.array([SIZE[0], SIZE[1], SIZE[2] / 2])],
                            list(n), dmesh.CellType.hexahedron)
    pairs = [PeriodicPair(slave=lambda x: np.abs(x[0] - SIZE[0]) <= TOL, relation=mirror_x,
                          component_scale=(1.0, 1.0, -1.0)),
             PeriodicPair(slave=lambda x: np.abs(x[1] - SIZE[1]) <= TOL, translation=(0.0, SIZE[1], 0.0)),
             PeriodicPair(slave=lambda x: np.abs(x[2] - SIZE[2] / 2) <= TOL, translation=(0.0, 0.0, SIZE[2]))]
    return UnitCellProblem(mesh, neo_hookean(MU, LAMBDA), pairs)


@pytest.mark.mpi
def test_in_plane_stretch_returns_own_stress():
    """Phi = diag(1.01, 1, 1) has no z coupling, so u* = 0 satisfies the mirrored periodicity and
    equilibrium of a homogeneous cell: S must equal the closed-form Neo-Hookean S(Phi) (an
    independent formula) to round-off. Tolerance 1e-8 relative to |S|: Newton stops at
    |R| <= 1e-10 of the force scale, the rest is summation round-off."""
    Phi = np.diag([1.01, 1.0, 1.0])
    result = quarter_problem().solve(Phi)
    reference = neo_hookean_S(Phi, MU, LAMBDA)
    assert np.linalg.norm(result.S - reference) <= 1e-8 * np.linalg.norm(reference)
    assert np.abs(result.fluctuation.x.array).max() <= 1e-8 * SIZE.max()


def test_shear_fluctuation_flips_uz():
    """Phi13 shear couples x and z: the boundary term (s - 1) P e_x of the mirrored faces no longer
    vanishes (P_zx != 0), so a fluctuation appears; it must obey u*_x,y(end) = u*_x,y(start) and
    u*_z(end) = -u*_z(start) at points matched by (x, y, z) -> (x - Lx, y, -z), edges and corners
    included. Tolerance 1e-10 of max |u*|: the constraint is imposed exactly by elimination,
    only the back-substitution round-off remains."""
    Phi = np.eye(3)
    Phi[0, 2] = 0.1
    problem = quarter_problem(comm=MPI.COMM_SELF)
    problem.solve(Phi)
    u = problem.u
    x = u.function_space.tabulate_dof_coordinates()
    values = u.x.array.reshape(-1, 3)[: len(x)]
    scale = np.abs(values).max()
    assert scale > 1e-6 * SIZE.max()  # a real fluctuation, not zero
    key = lambda p: tuple(np.round(p / 1e-9).astype(int))
    lookup = {key(p): i for i, p in enumerate(x)}
    end = np.flatnonzero(np.abs(x[:, 0] - SIZE[0]) <= TOL)
    assert len(end) > 0
    for i in end:
        j = lookup[key(mirror_x(x[i][:, None])[:, 0])]
        np.testing.assert_allclose(values[i], values[j] * np.array([1.0, 1.0, -1.0]), rtol=0, atol=1e-10 * scale)
    # the z flip is active: u*_z is not plainly periodic in x
    mismatch = max(abs(values[i, 2] - values[lookup[key(x[i] - [SIZE[0], 0, 0])], 2]) for i in end)
    assert mismatch > 1e-3 * scale


def test_bad_pair_input():
    mesh = dmesh.create_box(MPI.COMM_SELF, [np.zeros(3), SIZE], [1, 1, 1], dmesh.CellType.hexahedron)
    psi = neo_hookean(MU, LAMBDA)
    with pytest.raises(ValueError, match="component_scale"):
        UnitCellProblem(mesh, psi, [PeriodicPair(slave=lambda x: x[0] > 1, relation=mirror_x,
                                                 component_scale=(1.0, 0.0, 1.0))])
    with pytest.raises(ValueError, match="relation or a translation"):
        UnitCellProblem(mesh, psi, [PeriodicPair(slave=lambda x: x[0] > 1, relation=mirror_x,
                                                 translation=(1.0, 0.0, 0.0))])
