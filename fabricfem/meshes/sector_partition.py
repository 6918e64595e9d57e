"""A tube's cells split among the ranks by their angle about the tube's axis (sectors) instead of by graph cuts.

SCOTCH cuts a tube across (the shortest cut: one ring of edges), so each rank holds one end. On a garment whose
contact sits nearer one end (the sleeve's elbow), one rank then does most of the contact work and the other waits
(docs/findings/2026-11-28-sector-partition.md). A scene that is mirror-symmetric about a plane through the tube's
axis (the sleeve: flexion about +z, gravity along -y, the plane z = 0) splits evenly in both internal-force and
contact work when each rank takes one side of that plane.

The mesh must go all the way round the axis (a panel would leave sectors, and so ranks, empty) and lie in 3D.
`sector_partitioner(x)` returns a cell partitioner for dolfinx.mesh.create_mesh (the callable
(comm, n_parts, tdim, cells, ghost_mode) -> AdjacencyList_int32 of destination ranks, the owner first, then the
ranks that hold the cell as a ghost): cell c goes to sector floor((theta_c + pi) / (2 pi / n_parts)), where
theta_c = atan2(z, y) of the mean of its vertices (x: the input node coordinates, [m]; the tube's axis is +x
through the origin), so with two ranks the cells of z < 0 are rank 0's and those of z >= 0 rank 1's. With shared-
facet ghosting each cell is also sent, as a ghost, to the ranks owning a cell that shares one of its edges.
"""
from __future__ import annotations

from typing import Callable

import dolfinx.cpp
import numpy as np
from dolfinx.mesh import GhostMode

# the local vertex pairs of the edges of dolfinx's reference cells (basix numbering)
CELL_EDGES = {3: ((1, 2), (0, 2), (0, 1)), 4: ((0, 1), (0, 2), (1, 3), (2, 3))}


def by_sectors(ranks: int, n_around: int) -> bool:
    """Whether a tube of `n_around` cells around is split by angle on `ranks` ranks: while each rank gets at least
    2 cells around (else the graph partitioner)."""
    return ranks <= n_around // 2


def sector_owner(centroids: np.ndarray, n_parts: int) -> np.ndarray:
    """The sector index (0 .. n_parts - 1) of each centroid (n, 3) [m] by its angle atan2(z, y) about +x."""
    theta = np.arctan2(centroids[:, 2], centroids[:, 1])
    return np.minimum((theta + np.pi) // (2.0 * np.pi / n_parts), n_parts - 1).astype(np.int32)


def destinations(vertices: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(data, offsets) of the cells' destination ranks: for each cell of corner `vertices` (n, 3 or 4), its
    `owner` first, then the other ranks that own a cell sharing an edge with it (its shared-facet ghosts)."""
    edges = CELL_EDGES[vertices.shape[1]]
    pairs = np.concatenate([np.sort(vertices[:, list(e)], axis=1) for e in edges])
    cell_of = np.tile(np.arange(len(vertices)), len(edges))
    _, edge, counts = np.unique(pairs, axis=0, return_inverse=True, return_counts=True)
    edge = edge.reshape(-1)
    shared = counts[edge] == 2
    order = np.argsort(edge[shared], kind="stable")
    two = cell_of[shared][order].reshape(-1, 2)            # the two cells of each interior edge
    two = two[owner[two[:, 0]] != owner[two[:, 1]]]         # the edges of the cut
    ghost = np.unique(np.concatenate([np.column_stack([two[:, 0], owner[two[:, 1]]]),
                                      np.column_stack([two[:, 1], owner[two[:, 0]]])]), axis=0).reshape(-1, 2)
    cell = np.concatenate([np.arange(len(owner)), ghost[:, 0]])
    rank = np.concatenate([owner, ghost[:, 1]])
    first = np.concatenate([np.zeros(len(owner)), np.ones(len(ghost))])    # the owner before the ghosts
    order = np.lexsort((rank, first, cell))
    offsets = np.concatenate(([0], np.cumsum(np.bincount(cell, minlength=len(owner)))))
    return rank[order].astype(np.int32), offsets.astype(np.int32)


def sector_partitioner(x: np.ndarray) -> Callable:
    """A dolfinx cell partitioner splitting a tube about +x into equal angular sectors (module docstring); `x` is
    this rank's input node coordinates (n, 3) [m], indexed by the cells' vertex numbers."""
    points = np.asarray(x, dtype=float)

    def partition(comm, n_parts: int, tdim: int, cells, ghost_mode) -> dolfinx.cpp.graph.AdjacencyList_int32:
        offsets = np.asarray(cells.offsets)
        if len(offsets) <= 1:
            return dolfinx.cpp.graph.AdjacencyList_int32(np.zeros(0, np.int32), np.zeros(1, np.int32))
        vertices = np.asarray(cells.array).reshape(len(offsets) - 1, -1)
        owner = sector_owner(points[vertices].mean(axis=1), n_parts)
        if ghost_mode == GhostMode.none or n_parts == 1:
            return dolfinx.cpp.graph.AdjacencyList_int32(owner.copy(), np.arange(len(owner) + 1, dtype=np.int32))
        return dolfinx.cpp.graph.AdjacencyList_int32(*destinations(vertices, owner))

    return partition
