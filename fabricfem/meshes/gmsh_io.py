"""Convert a gmsh model, built on one MPI rank, to a distributed dolfinx mesh.

dolfinx 0.5.2 ships ``dolfinx.io.gmshio`` only as an unimported,
partly broken submodule, so this is our own converter.  It

1. reads, on ``rank`` only, the cells of the highest dimension that has
   elements (restricted to physical groups of that dimension if there are
   any) and the elements of the physical groups one dimension lower (facets);
2. keeps only the nodes the cells use, renumbered 0..n-1 (gmsh node tags need
   not be contiguous);
3. permutes gmsh node order to dolfinx order (``dolfinx.cpp.io.perm_gmsh``);
4. calls ``dolfinx.mesh.create_mesh`` with the data on ``rank`` and empty
   arrays elsewhere (dolfinx partitions and distributes the cells);
5. sends cell and facet tags to the ranks that hold those entities with
   ``dolfinx.cpp.io.distribute_entity_data`` (entities given by their input
   node indices) and builds ``MeshTags`` with ``meshtags_from_entities``.

Supported cells: first- and second-order triangles (gmsh types 2, 9) and
quadrilaterals (3, 10; the 9-node quadrilateral), with first- or
second-order edges (1, 8) as facets.  Coordinates are passed through
unchanged (metres in this package).

The material-frame container :class:`FabricMesh` is re-exported here:
warp is the first material direction E1, weft E2 = normal x warp.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import dolfinx.cpp
import dolfinx.mesh
import numpy as np
import ufl
from dolfinx.mesh import GhostMode, Mesh, MeshTagsMetaClass
from mpi4py import MPI

from . import directions, mesh_cache
from ._gmsh_session import gmsh_model
from .fabric_mesh import DirectionField, FabricMesh
from .sector_partition import sector_partitioner

__all__ = ["FabricMesh", "gmsh_to_dolfinx", "mesh_from_gmsh", "model_to_mesh"]

# gmsh element type -> (dolfinx/ufl cell name, degree)
_CELLS: dict[int, tuple[str, int]] = {
    2: ("triangle", 1), 9: ("triangle", 2),
    3: ("quadrilateral", 1), 10: ("quadrilateral", 2),
}
# gmsh element type of facets -> (cell name, degree)
_FACETS: dict[int, tuple[str, int]] = {1: ("interval", 1), 8: ("interval", 2)}


def _elements(model: Any, dim: int, entity: int = -1) -> tuple[np.ndarray, np.ndarray, int]:
    """Element tags, node tags (n_elements, n_nodes) and the gmsh type of the
    elements of dimension ``dim`` on ``entity`` (all entities if -1)."""
    types, tags, nodes = model.mesh.getElements(dim, entity)
    if len(types) == 0:
        return np.empty(0, np.int64), np.empty((0, 0), np.int64), -1
    if len(types) > 1:
        names = [model.mesh.getElementProperties(t)[0] for t in types]
        raise ValueError(f"model: mixed element types {names} in dimension {dim}; "
                         "dolfinx 0.5 needs a single cell type")
    n_nodes = model.mesh.getElementProperties(types[0])[3]
    return (np.asarray(tags[0], np.int64),
            np.asarray(nodes[0], np.int64).reshape(-1, n_nodes), int(types[0]))


def _group_elements(model: Any, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, dict[str, int]]:
    """Elements of all physical groups of dimension ``dim``.

    Returns element tags, node tags, group ids, gmsh type (-1 if none) and
    name -> id.  An element in several groups keeps its first group.
    """
    etags, nodes, values, types, names = [], [], [], set(), {}
    for _, group in model.getPhysicalGroups(dim):
        names[model.getPhysicalName(dim, group) or str(group)] = int(group)
        for entity in model.getEntitiesForPhysicalGroup(dim, group):
            t, n, etype = _elements(model, dim, int(entity))
            if etype < 0:
                continue
            etags.append(t)
            nodes.append(n)
            values.append(np.full(len(t), group, dtype=np.int32))
            types.add(etype)
    if not etags:
        return np.empty(0, np.int64), np.empty((0, 0), np.int64), np.empty(0, np.int32), -1, names
    if len(types) > 1:
        raise ValueError(f"model: physical groups of dimension {dim} mix element types {sorted(types)}")
    etags_all = np.concatenate(etags)
    _, first = np.unique(etags_all, return_index=True)
    first.sort()
    return (etags_all[first], np.concatenate(nodes)[first], np.concatenate(values)[first],
            types.pop(), names)


def _extract(model: Any, gdim: int) -> dict[str, Any]:
    """Read cells, facets, tags and coordinates from the current gmsh model."""
    tdim = max((d for d in (3, 2, 1) if len(model.mesh.getElements(d)[0]) > 0), default=-1)
    if tdim < 1:
        raise ValueError("model: the gmsh model has no mesh (call model.mesh.generate first)")
    _, cells, cell_values, cell_type, _ = _group_elements(model, tdim)
    has_cell_tags = cell_type >= 0
    if not has_cell_tags:
        _, cells, cell_type = _elements(model, tdim)
    if cell_type not in _CELLS:
        name = model.mesh.getElementProperties(cell_type)[0]
        raise ValueError(f"model: unsupported cell type {name!r} (gmsh type {cell_type}); "
                         f"supported gmsh types {sorted(_CELLS)}")
    _, facets, facet_values, facet_type, names = _group_elements(model, tdim - 1)
    if facet_type >= 0 and _FACETS.get(facet_type, (None, -1))[1] != _CELLS[cell_type][1]:
        raise ValueError(f"model: facet type (gmsh {facet_type}) does not match cell type (gmsh {cell_type})")

    # Keep only nodes used by cells, numbered 0..n-1 in order of gmsh tag
    used = np.unique(cells)
    node_tags, coords, _ = model.mesh.getNodes()
    node_tags = np.asarray(node_tags, np.int64)
    order = np.argsort(node_tags)
    pos = order[np.searchsorted(node_tags, used, sorter=order)]
    x = np.asarray(coords, np.float64).reshape(-1, 3)[pos]
    cells = np.searchsorted(used, cells)
    if facet_type >= 0:
        idx = np.minimum(np.searchsorted(used, facets), len(used) - 1)
        if not np.array_equal(used[idx], facets):
            raise ValueError("model: some tagged facets have nodes that belong to no cell")
        facets = idx
    return {"tdim": tdim, "cell_type": cell_type, "cells": cells, "cell_values": cell_values,
            "has_cell_tags": has_cell_tags, "facet_type": facet_type, "facets": facets,
            "facet_values": facet_values, "names": names, "x": x[:, :gdim]}


def _ufl_domain(cell_name: str, degree: int, gdim: int) -> ufl.Mesh:
    cell = ufl.Cell(cell_name, geometric_dimension=gdim)
    return ufl.Mesh(ufl.VectorElement("Lagrange", cell, degree))


def entity_tags(mesh: Mesh, dim: int, entities: np.ndarray, values: np.ndarray) -> MeshTagsMetaClass:
    """MeshTags from entities given by input node indices (any rank may pass none)."""
    local, local_values = dolfinx.cpp.io.distribute_entity_data(
        mesh._mesh, dim, np.ascontiguousarray(entities, dtype=np.int64),
        np.ascontiguousarray(values, dtype=np.int32))
    mesh.topology.create_connectivity(dim, 0)
    mesh.topology.create_connectivity(dim, mesh.topology.dim)
    adj = dolfinx.cpp.graph.AdjacencyList_int32(np.ascontiguousarray(local, dtype=np.int32))
    return dolfinx.mesh.meshtags_from_entities(mesh, dim, adj, local_values.astype(np.int32))


def _partitioner(partition: str, x: np.ndarray, gdim: int):
    """The cell partitioner named `partition` ("graph" or "sectors"; `x`: this rank's input nodes [m]); checked on
    every rank, before create_mesh, so that a refusal cannot leave the other ranks waiting in it."""
    if partition == "sectors":
        if gdim != 3:
            raise ValueError(f"partition: 'sectors' splits a tube about +x in 3D, got gdim = {gdim}")
        return sector_partitioner(x)
    if partition != "graph":
        raise ValueError(f"partition: must be 'graph' or 'sectors', got {partition!r}")
    return dolfinx.mesh.create_cell_partitioner()


def model_to_mesh(model: Any, comm: MPI.Comm, rank: int = 0, gdim: int = 3,
                  ghost_mode: GhostMode = GhostMode.shared_facet, partition: str = "graph",
                  save_to: Path | None = None,
                  ) -> tuple[Mesh, MeshTagsMetaClass | None, MeshTagsMetaClass, dict[str, int]]:
    """Convert the current gmsh model (meshed on ``rank`` only) to a dolfinx mesh.

    Collective on ``comm``: every rank must call it; only ``rank`` reads
    ``model`` (pass ``None`` or anything elsewhere).

    Args:
        model: ``gmsh.model`` with a generated mesh, on ``rank``.
        comm: Communicator of the new mesh.
        rank: The rank that holds the gmsh model.
        gdim: Geometric dimension of the mesh (3 for surfaces in space).
        ghost_mode: dolfinx ghost mode (default as in dolfinx 0.5,
            ``shared_facet``).
        partition: ``"graph"`` (dolfinx's graph partitioner, SCOTCH) or
            ``"sectors"`` (a tube about +x split by angle,
            fabricfem.meshes.sector_partition).
        save_to: a cache file (fabricfem.meshes.mesh_cache) that keeps the extracted arrays.

    Returns:
        ``(mesh, cell_tags, facet_tags, names)``: cell tags from physical
        groups of the cell dimension (None if there are none), facet tags
        from physical groups one dimension lower (possibly empty), and
        physical name -> id of the facet groups (unnamed groups are keyed by
        their id as a string).

    Raises:
        ValueError: on every rank, if the model cannot be converted.
    """
    if not isinstance(gdim, (int, np.integer)) or not 1 <= gdim <= 3:
        raise ValueError(f"gdim: must be 1, 2 or 3, got {gdim!r}")
    data: dict[str, Any] | Exception | None = None
    if comm.rank == rank:
        try:
            data = _extract(model, gdim)
            if data["tdim"] > gdim:
                raise ValueError(f"gdim: {gdim} is less than the cell dimension {data['tdim']}")
        except Exception as error:  # re-raised on every rank below
            data = error
        if save_to is not None and isinstance(data, dict):
            mesh_cache.save(save_to, data)          # never raises
    return _distribute(data, comm, rank, gdim, ghost_mode, partition)


def _distribute(data: dict[str, Any] | Exception | None, comm: MPI.Comm, rank: int, gdim: int,
                ghost_mode: GhostMode, partition: str
                ) -> tuple[Mesh, MeshTagsMetaClass | None, MeshTagsMetaClass, dict[str, int]]:
    """The dolfinx mesh and tags of the extracted `data` on `rank` (or its error, raised on every rank)."""
    if comm.rank == rank:
        try:
            header: dict[str, Any] | Exception = data if isinstance(data, Exception) else {
                **{k: data[k] for k in ("tdim", "cell_type", "facet_type", "has_cell_tags", "names")},
                "nodes": (data["cells"].shape[1], data["facets"].shape[1])}
        except Exception as error:  # re-raised on every rank below
            header = error
        header = comm.bcast(header, root=rank)
    else:
        header = comm.bcast(None, root=rank)
    if isinstance(header, Exception):
        raise header if isinstance(header, ValueError) else ValueError(f"model: {header}")
    if comm.rank != rank:
        n_cell_nodes, n_facet_nodes = header["nodes"]
        data = {"cells": np.empty((0, n_cell_nodes), np.int64), "cell_values": np.empty(0, np.int32),
                "facets": np.empty((0, n_facet_nodes), np.int64), "facet_values": np.empty(0, np.int32),
                "x": np.empty((0, gdim), np.float64)}

    cell_name, degree = _CELLS[header["cell_type"]]
    cell_type = dolfinx.mesh.to_type(cell_name)
    cells = data["cells"][:, dolfinx.cpp.io.perm_gmsh(cell_type, data["cells"].shape[1])]
    mesh = dolfinx.mesh.create_mesh(
        comm, cells, np.ascontiguousarray(data["x"]), _ufl_domain(cell_name, degree, gdim),
        ghost_mode=ghost_mode, partitioner=_partitioner(partition, data["x"], gdim))
    tdim = mesh.topology.dim

    cell_tags = None
    if header["has_cell_tags"]:
        cell_tags = entity_tags(mesh, tdim, cells, data["cell_values"])
        cell_tags.name = "cell_tags"

    mesh.topology.create_entities(tdim - 1)
    if header["facet_type"] >= 0:
        facet_cell = dolfinx.cpp.mesh.cell_entity_type(cell_type, tdim - 1, 0)
        facets = data["facets"][:, dolfinx.cpp.io.perm_gmsh(facet_cell, data["facets"].shape[1])]
        facet_tags = entity_tags(mesh, tdim - 1, facets, data["facet_values"])
    else:
        facet_tags = dolfinx.mesh.meshtags(mesh, tdim - 1, np.empty(0, np.int32), np.empty(0, np.int32))
    facet_tags.name = "facet_tags"
    return mesh, cell_tags, facet_tags, dict(header["names"])


def gmsh_to_dolfinx(build: Callable[[Any], None], comm: MPI.Comm, rank: int = 0, gdim: int = 3,
                    name: str = "fabricfem", options: Mapping[str, float] | None = None,
                    ghost_mode: GhostMode = GhostMode.shared_facet, partition: str = "graph",
                    cache_key: str | None = None,
                    ) -> tuple[Mesh, MeshTagsMetaClass | None, MeshTagsMetaClass, dict[str, int]]:
    """Run ``build(gmsh.model)`` in a fresh gmsh model on ``rank`` and convert it (``partition``: as in
    :func:`model_to_mesh`).

    ``build`` must create the geometry, physical groups and mesh.  gmsh is
    initialised/cleaned up around it (see ``_gmsh_session.gmsh_model``) with
    the numeric gmsh ``options`` set meanwhile.  An error in ``build`` is
    raised on every rank (no deadlock).  Returns what :func:`model_to_mesh`
    returns.  With ``cache_key`` (a string naming the code and arguments of
    ``build``; fabricfem.meshes.mesh_cache) a mesh kept from an earlier run
    is used instead of gmsh, and a new one is kept.
    """
    source = Path(__file__).read_text() if cache_key and mesh_cache.enabled() else ""   # this module's code is
    path = (mesh_cache.path_for(f"{name}|{dict(options or {})}|{gdim}|{source}|{cache_key}")   # part of the key
            if source else None)
    if path is not None:
        kept = mesh_cache.load(path) if comm.rank == rank else None
        if comm.bcast(kept is not None, root=rank):
            return _distribute(kept, comm, rank, gdim, ghost_mode, partition)
    with gmsh_model(comm, rank, name, options) as model:
        error = None
        if model is not None:
            try:
                build(model)
            except Exception as exc:  # re-raised on every rank below
                error = exc
        error = comm.bcast(error, root=rank)
        if error is not None:
            raise error
        return model_to_mesh(model, comm, rank, gdim=gdim, ghost_mode=ghost_mode, partition=partition,
                             save_to=path)


def mesh_from_gmsh(build: Callable[[Any], None], warp: Sequence[float] | DirectionField,
                   normal: Sequence[float] | DirectionField, comm: MPI.Comm = MPI.COMM_WORLD, name: str = "fabricfem",
                   options: Mapping[str, float] | None = None,
                   ghost_mode: GhostMode = GhostMode.shared_facet, partition: str = "graph",
                   cache_key: str | None = None) -> FabricMesh:
    """Any surface built in gmsh as a distributed, tagged :class:`FabricMesh` (metres).

    ``build(model)`` runs on rank 0 in a fresh ``gmsh.model`` (``options``: numeric gmsh options meanwhile)
    and must create the geometry, the physical groups and the mesh (``model.mesh.generate(2)``, optionally
    ``model.mesh.setOrder(2)``): triangles or quadrilaterals, one type. Named physical curves become the
    edge tags (``FabricMesh.tag(name)``; unnamed ones are keyed by their id as a string).

    Args:
        build: geometry, physical groups and mesh of the surface in the given gmsh model.
        warp: unit warp direction tangent to the surface: a constant 3-vector or a field
            ``x (3, N) -> (3, N)`` (fabricfem.meshes.directions).
        normal: unit reference normal, oriented like the cells (a 3-vector or a field as ``warp``).
        comm: communicator of the mesh; gmsh runs on its rank 0 only.
        partition: how the cells are split among the ranks: "graph" (SCOTCH) or "sectors" (a tube about +x,
            by angle: fabricfem.meshes.sector_partition).
        cache_key: a string naming the code and arguments of ``build``: the mesh is kept on disk and reused
            without gmsh (fabricfem.meshes.mesh_cache); None: always meshed.

    Raises:
        ValueError: on every rank, if ``build`` fails or the model cannot be converted (naming the cause), or
            if ``warp``/``normal`` is a zero vector.
    """
    fields = [directions.constant(v) if not callable(v) else v for v in (warp, normal)]
    mesh, cell_tags, facet_tags, names = gmsh_to_dolfinx(build, comm, 0, gdim=3, name=name, options=options,
                                                         ghost_mode=ghost_mode, partition=partition,
                                                         cache_key=cache_key)
    return FabricMesh(mesh=mesh, facet_tags=facet_tags, tags=names, warp=fields[0], normal=fields[1],
                      cell_tags=cell_tags)
