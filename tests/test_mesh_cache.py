"""The mesh cache (fabricfem.meshes.mesh_cache): a tube meshed again comes from the kept arrays without gmsh and
is the same dolfinx mesh (coordinates, cells and edge tags identical, not close), on one rank and on the ranks of
COMM_WORLD; a changed argument meshes again; an unreadable file is meshed again and replaced."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.meshes import gmsh_io, mesh_cache
from fabricfem.meshes.tube import tube


def _state(fmesh) -> tuple:
    """This rank's geometry (sorted), its cells' node positions (sorted) and the number of its edges tagged end0 and
    end1, of a FabricMesh (comparable across builds on the same ranks)."""
    mesh = fmesh.mesh
    x = mesh.geometry.x
    order = np.lexsort(np.round(x / 1e-12).T)
    cells = mesh.geometry.dofmap.array
    tags = {name: len(fmesh.facet_tags.find(fmesh.tags[name])) for name in ("end0", "end1")}
    return x[order], np.sort(np.round(x[cells].reshape(-1, 3) / 1e-12), axis=0), tags


def _without_gmsh(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("gmsh was called although the mesh is kept")
    monkeypatch.setattr(gmsh_io, "gmsh_model", refuse)


@pytest.mark.parametrize("comm", [MPI.COMM_SELF, pytest.param(MPI.COMM_WORLD, marks=pytest.mark.mpi)])
def test_a_kept_tube_is_the_same_mesh_without_gmsh(tmp_path, monkeypatch, comm):
    folder = comm.bcast(str(tmp_path), root=0)
    monkeypatch.setenv("XDG_CACHE_HOME", folder)
    monkeypatch.setenv("FABRICFEM_MESH_CACHE", "1")
    built = _state(tube(0.3, 0.05, 12, 8, "quadrilateral", comm, 2))
    assert len(list(mesh_cache.folder().glob("*.npz"))) == 1
    with monkeypatch.context() as patch:
        _without_gmsh(patch)
        kept = _state(tube(0.3, 0.05, 12, 8, "quadrilateral", comm, 2))
    for a, b in zip(built[:2], kept[:2]):
        np.testing.assert_array_equal(a, b)
    assert built[2] == kept[2]
    tube(0.3, 0.05, 12, 9, "quadrilateral", comm, 2)                  # another argument: meshed and kept
    comm.barrier()
    assert len(list(mesh_cache.folder().glob("*.npz"))) == 2
    monkeypatch.setenv("FABRICFEM_MESH_CACHE", "0")                    # switched off: gmsh again, nothing kept
    tube(0.3, 0.05, 12, 10, "quadrilateral", comm, 2)
    comm.barrier()
    assert len(list(mesh_cache.folder().glob("*.npz"))) == 2


def test_an_unreadable_file_is_meshed_again(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("FABRICFEM_MESH_CACHE", "1")
    tube(0.3, 0.05, 12, 8, "quadrilateral", MPI.COMM_SELF, 2)
    (kept,) = mesh_cache.folder().glob("*.npz")
    whole = kept.read_bytes()
    for damaged in (b"not a mesh", whole[: len(whole) // 2]):              # not a zip file; a truncated one
        kept.write_bytes(damaged)
        assert mesh_cache.load(kept) is None
    tube(0.3, 0.05, 12, 8, "quadrilateral", MPI.COMM_SELF, 2)
    assert mesh_cache.load(kept) is not None
