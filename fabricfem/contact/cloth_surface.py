"""The cloth's current surface triangulation, the same on every rank.

A shell's quadrilateral Q2 cell has nine displacement nodes on a 3 x 3 grid; split through its nodes, it is four
sub-quadrilaterals of two triangles each, eight triangles per cell. The triangles are numbered by the global
index of the scalar displacement space's nodes (dolfinx's index map), gathered once onto every rank; every step
each rank sends the current positions (and velocities) of its owned nodes to all others (`MPI.Allgatherv`), so
that every rank holds the whole surface and a search on it finds the pairs across rank boundaries as on one rank.
Units: metres, seconds.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse
from mpi4py import MPI
from scipy.sparse.csgraph import connected_components

from fabricfem.contact import nodal

# basix's Q2 quadrilateral: vertices (0, 0), (1, 0), (0, 1), (1, 1), the midpoints of the edges (v0 v1), (v0 v2),
# (v1 v3), (v2 v3), the centre; GRID[j][i] is the local node at (i / 2, j / 2) of the reference square
GRID = np.array([[0, 4, 1], [5, 8, 6], [2, 7, 3]])


def split_cell(grid: np.ndarray) -> np.ndarray:
    """(8, 3) local node indices of the eight triangles of a cell whose 3 x 3 nodes are `grid` (grid[j][i] the node
    at (i / 2, j / 2) of the reference square), counter-clockwise in it, so that their normals follow the cell's."""
    return np.array([(grid[j, i], grid[j, i + 1], grid[j + 1, i + 1]) for j in range(2) for i in range(2)]
                    + [(grid[j, i], grid[j + 1, i + 1], grid[j + 1, i]) for j in range(2) for i in range(2)])


SPLIT = split_cell(GRID)


class ClothSurface:
    """The shell's nodes and Q2 cells as one global triangulation on every rank (module docstring).

    Attributes:
        nodes: fabricfem.contact.nodal.ContactNodes of the owned nodes of this rank.
        owned: (n,) global indices of this rank's owned nodes (the order of `nodes`).
        count: N, the number of nodes of the whole cloth.
        triangles: (T, 3) global node indices of the triangles (8 per cell, in cell order); cell_nodes: (C, 9)
            global node indices of every cell; triangle_index: (T,) 0 ... T - 1
            (each triangle its own row of `triangles`: with `triangles` as the proximity's `cell_nodes`, a vertex is
            left out only against the triangles it is a node of, fabricfem.contact.self_contact).
        reference: (N, 3) reference positions [m]; area: (N,) lumped reference areas [m^2]; held: (N,) True for
            a node with a prescribed displacement component (all ranks).
    """

    def __init__(self, model):
        self.comm = model.comm
        self.nodes = nodal.contact_nodes(model)
        scalar = self.nodes.scalar_space
        index_map = scalar.dofmap.index_map
        local_to_global = np.asarray(index_map.local_to_global(
            np.arange(index_map.size_local + index_map.num_ghosts, dtype=np.int32)), dtype=np.int64)
        self.owned = local_to_global[self.nodes.node_index]
        n_cells = model.mesh.topology.index_map(2).size_local
        cells = local_to_global[np.asarray(scalar.dofmap.list.array).reshape(-1, 9)[:n_cells]]
        self.cell_nodes = np.concatenate(self.comm.allgather(cells)).astype(np.int64)
        self.count = int(index_map.size_global)
        self.triangles = self.cell_nodes[:, SPLIT].reshape(-1, 3)
        self.triangle_index = np.arange(len(self.triangles), dtype=np.int64)
        self._counts = np.array(self.comm.allgather(len(self.owned)), dtype=np.int64)
        self._order = self._gather_ints(self.owned)
        self.reference = self.gather(self.nodes.reference)
        self.area = self.gather(self.nodes.area[:, None])[:, 0]
        self.held = self.gather(self.nodes.constrained.any(axis=1).astype(float)[:, None])[:, 0] > 0.0

    def _gather_ints(self, values: np.ndarray) -> np.ndarray:
        out = np.empty(int(self._counts.sum()), dtype=np.int64)
        self.comm.Allgatherv(np.ascontiguousarray(values, dtype=np.int64), [out, self._counts, MPI.INT64_T])
        return out

    def gather(self, owned_values: np.ndarray) -> np.ndarray:
        """(N, k) array of all nodes (global order) from this rank's (n, k) values of its owned nodes (all ranks
        call this)."""
        owned_values = np.ascontiguousarray(owned_values, dtype=float)
        k = owned_values.shape[1]
        received = np.empty((int(self._counts.sum()), k))
        self.comm.Allgatherv(owned_values, [received, self._counts * k, MPI.DOUBLE])
        out = np.empty((self.count, k))
        out[self._order] = received
        return out

    def positions(self, d: np.ndarray) -> np.ndarray:
        """(N, 3) current positions X + u [m] of all nodes from the local array `d` of the model's space W."""
        return self.gather(self.nodes.reference + d[self.nodes.dofs])

    def owned_rows(self, values: np.ndarray) -> np.ndarray:
        """The (n, k) rows of an (N, k) all-node array that belong to this rank's owned nodes."""
        return values[self.owned]

    def stitched(self, joined: np.ndarray | None = None) -> np.ndarray:
        """(N,) label of each node, equal for the nodes that the node pairs `joined` ((k, 2) global indices, a
        garment's seams) make one point of the cloth; each other node its own label."""
        pairs = np.asarray(joined, dtype=np.int64).reshape(-1, 2) if joined is not None else None
        return joined_labels(pairs, self.count)

    def parts(self, joined: np.ndarray | None = None) -> np.ndarray:
        """(N,) label of the connected part of each node: nodes of a cell are connected, and so are the node pairs
        `joined` ((k, 2) global indices, e.g. a garment's seams)."""
        cells = np.c_[np.repeat(self.cell_nodes[:, 0], self.cell_nodes.shape[1]), self.cell_nodes.ravel()]
        pairs = [cells] if joined is None else [cells, np.asarray(joined, dtype=np.int64).reshape(-1, 2)]
        return joined_labels(np.concatenate(pairs), self.count)


def joined_labels(pairs: np.ndarray | None, count: int) -> np.ndarray:
    """(count,) label of each of `count` nodes: the connected components of the graph of the node pairs `pairs`
    ((k, 2) indices; None: none), so that nodes joined through any chain of pairs share a label."""
    pairs = np.zeros((0, 2), dtype=np.int64) if pairs is None else np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)[1]
