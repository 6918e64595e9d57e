import os
from pathlib import Path

import pytest
from mpi4py import MPI

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
os.environ.setdefault("FABRICFEM_MESH_CACHE", "0")     # the tests mesh with gmsh (tests/test_mesh_cache.py turns it on)


SLOW_TESTS = {line.split("#")[0].strip() for line in (Path(__file__).parent / "tiers.txt").read_text().splitlines()
              if line.split("#")[0].strip()}


def pytest_collection_modifyitems(config, items):
    """Tests listed in tests/tiers.txt (a test file, file::test or file::test[param]) are marked `slow`: `make test-fast` leaves
    them out. Under mpirun only the tests marked `mpi` make sense (the others are serial by design)."""
    for item in items:
        file, test = item.nodeid.split("::")[0].split("/")[-1], item.nodeid.split("::", 1)[-1]
        if {file, f"{file}::{test}", f"{file}::{test.split('[')[0]}"} & SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
    if MPI.COMM_WORLD.size > 1:
        skip = pytest.mark.skip(reason="serial test (run without mpirun)")
        for item in items:
            if "mpi" not in item.keywords:
                item.add_marker(skip)


@pytest.fixture
def no_meshing(monkeypatch):
    """Any attempt to mesh fails the test (the refusal must come before meshing): the scene builders' meshes, the
    sleeve's tube and the wear garments (tube and pattern)."""
    from fabricfem.scenes import build as scene_build

    def trap(*args, **kwargs):
        raise AssertionError("meshed before refusing the scene")
    monkeypatch.setattr(scene_build, "build_mesh", trap)
    monkeypatch.setattr("fabricfem.wear.sleeve.tube", trap)
    monkeypatch.setattr("fabricfem.scenes.wear.tube", trap)
    monkeypatch.setattr("fabricfem.scenes.wear.mesh_pattern", trap)
