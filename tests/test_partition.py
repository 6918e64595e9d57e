"""The mesh partition of a parallel run: the same every time, and a tube split by angle.

fabricfem sets SCOTCH_PTHREAD_NUMBER = 1: PT-Scotch with threads split a mesh differently from run to run, so 2-rank
results could not be repeated bit for bit. A whole tube is not given to SCOTCH: its cells are split by their angle
about the tube's axis (fabricfem.meshes.sector_partition), which balances the sleeve's contact between the ranks."""
import hashlib

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.meshes.sector_partition import destinations, sector_owner
from fabricfem.meshes.tube import cylindrical_panel, tube


def _partition(mesh) -> tuple[int, str]:
    """This rank's owned cells and a digest of its owned node coordinates (rounded to 1e-12 m)."""
    nodes = mesh.geometry.x[:mesh.geometry.index_map().size_local]
    return mesh.topology.index_map(2).size_local, hashlib.sha1(np.round(nodes, 12).tobytes()).hexdigest()


@pytest.mark.mpi
def test_the_graph_partition_is_the_same_every_time():
    if MPI.COMM_WORLD.size < 2:
        pytest.skip("a partition needs 2 ranks")
    def panel():   # a panel is split by SCOTCH (graph), a whole tube is not
        return _partition(cylindrical_panel(0.5, 0.06, 1.5 * np.pi, 33, 57, order=2).mesh)
    first = panel()
    for _ in range(5):
        assert panel() == first


@pytest.mark.mpi
def test_a_tube_is_split_by_angle_into_equal_halves_with_ghosts():
    """On 2 ranks, the 44x57 tube: each rank owns the cells of one side of z = 0 (1254 of 2508: the mesh has 22
    cells around on each side), its owned nodes lie on that side (to the cut line's nodes at z = 0), and each rank
    ghosts the other's cells along the two cut lines (2 x 57 cells, shared-facet ghosting)."""
    comm = MPI.COMM_WORLD
    if comm.size != 2:
        pytest.skip("the halves need exactly 2 ranks")
    mesh = tube(0.5, 0.06, 44, 57, order=2).mesh
    cells = mesh.topology.index_map(2)
    assert cells.size_local == 44 * 57 // 2 and cells.num_ghosts == 2 * 57
    z = mesh.geometry.x[:mesh.geometry.index_map().size_local, 2]
    side = 1.0 if comm.rank == 1 else -1.0
    assert np.all(side * z >= -1e-12)


def test_sector_owners_and_destinations_on_a_ring_of_cells():
    """Independent of dolfinx: a ring of 8 quadrilaterals about +x (vertices 0-7 at x = 0, 8-15 at x = 1) on 2
    parts: the 4 cells of z < 0 go to part 0; the 4 cells at the two cut lines are also sent to the other part, the
    owner first."""
    angles = np.arange(8) * np.pi / 4 - np.pi + 0.1    # no centroid on a cut
    ring = np.column_stack([np.zeros(8), np.cos(angles), np.sin(angles)])
    x = np.vstack([ring, ring + [1.0, 0.0, 0.0]])
    vertices = np.array([[i, (i + 1) % 8, i + 8, (i + 1) % 8 + 8] for i in range(8)])
    owner = sector_owner(x[vertices].mean(axis=1), 2)
    np.testing.assert_array_equal(owner, [0, 0, 0, 0, 1, 1, 1, 1])
    data, offsets = destinations(vertices, owner)
    lists = [[int(r) for r in data[offsets[i]:offsets[i + 1]]] for i in range(8)]
    # the cuts: cells 3 | 4 (the edge of vertices 4, 12) and 7 | 0 (vertices 0, 8); each side ghosts the other's
    assert lists == [[0, 1], [0], [0], [0, 1], [1, 0], [1], [1], [1, 0]]
