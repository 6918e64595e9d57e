"""The yarns' lateral surfaces of a distributed dolfinx hexahedral mesh, gathered on every rank: the set-up of
yarn contact (which nodes and facets take part, with outward facet orientation and lumped areas) and the
gather of the surface displacements at each evaluation. Lengths in m.

The surfaces are small, so every rank holds all of them (allgather): each surface node is sent by the rank
owning its dof block, and all ranks order the nodes by their global dof block.
"""
from __future__ import annotations

from dataclasses import dataclass

import dolfinx.fem as fem
import numpy as np

__all__ = ["Surfaces", "gather_surfaces", "lumped_areas", "vertex_to_dof_block"]


def vertex_to_dof_block(V: fem.FunctionSpace) -> np.ndarray:
    """Local vertex -> local dof block of a P1 (vector) space; -1 for vertices without dofs."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0)
    nv = mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts
    per_cell = c2v.offsets[1] - c2v.offsets[0]
    dofs = V.dofmap.list.array.reshape(-1, per_cell)
    if dofs.shape[1] != per_cell:
        raise ValueError("u must be a first-order Lagrange vector Function (one dof block per vertex)")
    out = np.full(nv, -1, dtype=np.int64)
    out[c2v.array.reshape(-1, per_cell)] = dofs
    return out


@dataclass
class Surfaces:
    """The tagged surfaces, the same on every rank.

    Attributes:
        nodes: (n,) global dof blocks of all surface nodes, sorted
        X: (n, 3) their reference positions [m]
        quads: per facet tag the facets (m, 4) as indices into nodes, tensor vertex order oriented so that
            (v1 - v0) x (v2 - v0) points out of the cell, each facet once
        local_owned: local dof blocks of the surface nodes this rank owns (the ones it sends)
        recv_order: the order that sorts the gathered owned blocks of all ranks
    """

    nodes: np.ndarray
    X: np.ndarray
    quads: dict[int, np.ndarray]
    local_owned: np.ndarray
    recv_order: np.ndarray

    def gather(self, values: np.ndarray, comm) -> np.ndarray:
        """Per-node data (n, 3) of all surface nodes, in the order of `nodes`, from the owned rows of a local
        blocked array `values` (local blocks, 3) (e.g. u.x.array.reshape(-1, 3)); collective."""
        return np.concatenate(comm.allgather(values[self.local_owned]))[self.recv_order]


def _vertex_nodes(mesh, c2v, n_vertices: int) -> np.ndarray:
    """Local vertex -> geometry node (P1 geometry: same reference order as the topology)."""
    gdofs = mesh.geometry.dofmap.array.reshape(-1, c2v.offsets[1] - c2v.offsets[0])
    vertex_node = np.zeros(n_vertices, dtype=np.int64)
    vertex_node[c2v.array.reshape(-1, gdofs.shape[1])] = gdofs
    return vertex_node


def _check_tags(facet_tags, tags: list[int], comm) -> None:
    """ValueError if a tag marks no facet on any rank."""
    present = set(np.unique(np.concatenate(comm.allgather(facet_tags.values))).tolist())
    for t in tags:
        if t not in present:
            raise ValueError(f"pairs: facet tag {t} marks no facet of the mesh")


def _outward_vertices(mesh, facets: np.ndarray, vertex_node: np.ndarray) -> np.ndarray:
    """Local vertices (k, 4) of the local facets `facets`, reordered (v0, v2, v1, v3) where (v1 - v0) x (v2 - v0)
    points into the adjacent cell (its centre) so that it points out."""
    tdim = mesh.topology.dim
    f2v, f2c, c2v = (mesh.topology.connectivity(tdim - 1, 0), mesh.topology.connectivity(tdim - 1, tdim),
                     mesh.topology.connectivity(tdim, 0))
    if f2v.offsets[1] - f2v.offsets[0] != 4:
        raise ValueError("the contact surfaces must be quadrilateral facets (hexahedral mesh)")
    X_all = mesh.geometry.x
    verts = f2v.array.reshape(-1, 4)[facets]
    x = X_all[vertex_node[verts]]
    cells = f2c.array[f2c.offsets[facets]]
    centre = X_all[vertex_node[c2v.array.reshape(-1, c2v.offsets[1] - c2v.offsets[0])[cells]]].mean(axis=1)
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    inward = (normal * (x.mean(axis=1) - centre)).sum(1) < 0.0
    return np.where(inward[:, None], verts[:, [0, 2, 1, 3]], verts)


def gather_surfaces(V: fem.FunctionSpace, facet_tags, tags: list[int]) -> Surfaces:
    """The facets of `facet_tags` (MeshTags) with the given tags and their nodes, gathered on every rank of
    V's mesh (collective). V: the first-order Lagrange vector space of the displacement. ValueError if a tag
    marks no facet or the facets are not quadrilaterals."""
    mesh = V.mesh
    comm = mesh.comm
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, 0)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim, 0)
    imap = V.dofmap.index_map
    vertex_block = vertex_to_dof_block(V)
    block_global = np.asarray(imap.local_to_global(np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)),
                              dtype=np.int64)
    vertex_node = _vertex_nodes(mesh, mesh.topology.connectivity(tdim, 0), len(vertex_block))
    _check_tags(facet_tags, tags, comm)
    quads_by_tag, owned_blocks, owned_X = {}, [], []
    for t in tags:  # local quads as global dof blocks, gathered everywhere; the owned nodes with their positions
        verts = _outward_vertices(mesh, facet_tags.indices[facet_tags.values == t], vertex_node)
        quads_by_tag[t] = np.concatenate(comm.allgather(block_global[vertex_block[verts]])).reshape(-1, 4)
        local_blocks = vertex_block[np.unique(verts)]
        mine = local_blocks < imap.size_local
        owned_blocks.append(block_global[local_blocks[mine]])
        owned_X.append(mesh.geometry.x[vertex_node[np.unique(verts)[mine]]])
    owned_blocks, first = np.unique(np.concatenate(owned_blocks), return_index=True)
    owned_X = np.concatenate(owned_X)[first]
    all_blocks = comm.allgather(owned_blocks)
    recv_order = np.argsort(np.concatenate(all_blocks), kind="stable")
    nodes = np.concatenate(all_blocks)[recv_order]
    X = np.concatenate(comm.allgather(owned_X))[recv_order]
    for t in tags:  # indices into nodes; one facet once (a facet shared by ranks appears several times)
        q = np.searchsorted(nodes, quads_by_tag[t])
        _, keep = np.unique(np.sort(q, axis=1), axis=0, return_index=True)
        quads_by_tag[t] = q[np.sort(keep)]
    return Surfaces(nodes=nodes, X=X, quads=quads_by_tag,
                    local_owned=(owned_blocks - imap.local_range[0]).astype(np.int64), recv_order=recv_order)


def lumped_areas(X: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Lumped reference areas (n,) [m^2] of the nodes X (n, 3) [m]: a quarter of each adjacent quad's area
    (the sum of its two triangles (v0, v1, v3), (v0, v3, v2))."""
    x = X[quads]
    area = 0.5 * (np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 3] - x[:, 0]), axis=1)
                  + np.linalg.norm(np.cross(x[:, 3] - x[:, 0], x[:, 2] - x[:, 0]), axis=1))
    a = np.zeros(len(X))
    np.add.at(a, quads.ravel(), np.repeat(area / 4.0, 4))
    return a
