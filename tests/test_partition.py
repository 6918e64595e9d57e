"""The mesh partition of a parallel run is the same every time (fabricfem sets SCOTCH_PTHREAD_NUMBER = 1: PT-Scotch
with threads split the sleeve's tube differently from run to run, so 2-rank results could not be repeated bit for
bit)."""
import hashlib

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.meshes.tube import tube


def _partition() -> tuple[int, str]:
    """This rank's owned cells and a digest of its owned node coordinates (rounded to 1e-12 m)."""
    mesh = tube(0.5, 0.06, 44, 57, order=2).mesh
    nodes = mesh.geometry.x[:mesh.geometry.index_map().size_local]
    return mesh.topology.index_map(2).size_local, hashlib.sha1(np.round(nodes, 12).tobytes()).hexdigest()


@pytest.mark.mpi
def test_the_partition_is_the_same_every_time():
    if MPI.COMM_WORLD.size < 2:
        pytest.skip("a partition needs 2 ranks")
    first = _partition()
    for _ in range(5):
        assert _partition() == first
