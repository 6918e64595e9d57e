import os

import pytest
from mpi4py import MPI

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")


def pytest_collection_modifyitems(config, items):
    """Under mpirun only the tests marked `mpi` make sense (the others are serial by design)."""
    if MPI.COMM_WORLD.size > 1:
        skip = pytest.mark.skip(reason="serial test (run without mpirun)")
        for item in items:
            if "mpi" not in item.keywords:
                item.add_marker(skip)
