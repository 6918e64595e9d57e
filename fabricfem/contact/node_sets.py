"""Sets of garment nodes named by (panel, position) that constraints act on across the ranks: the stitched nodes of
the seams, the nodes of a gripped edge or of a belt (fabricfem.contact.seams, fabricfem.contact.handles).

A point of a panel is the owned displacement node of a cell tagged with the panel within MATCH_TOLERANCE of it
(the panels of a pattern are disjoint meshes, so coincident nodes of two panels are told apart by their tag).
Every rank finds the points it owns; their global indices are summed over the ranks, so every rank knows the
whole set. `gather` sums per-member values filled by their owners (one MPI Allreduce of a small array), so a
constraint's result does not depend on the partition.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from fabricfem.contact.nodal import contact_nodes

MATCH_TOLERANCE = 1e-9     # m: a point is a mesh node of its panel within this distance


def _panel_nodes(model, nodes, tag: int) -> tuple[np.ndarray, np.ndarray]:
    """Owned contact-node indices of the cells tagged `tag` and their reference positions."""
    cell_tags = model.fmesh.cell_tags
    if cell_tags is None:
        raise ValueError("mesh: node sets need the panels' cell tags (a garment mesh from fabricfem.meshes.pattern)")
    cells = cell_tags.indices[cell_tags.values == tag]
    dofmap = nodes.scalar_space.dofmap
    scalar = np.unique(dofmap.list.array.reshape(-1, dofmap.dof_layout.num_dofs)[cells].ravel())
    owned_node = np.full(dofmap.index_map.size_local + dofmap.index_map.num_ghosts, -1, dtype=np.int64)
    owned_node[nodes.node_index] = np.arange(len(nodes.node_index))
    node = owned_node[scalar]
    node = node[node >= 0]
    return node, nodes.reference[node]


class PanelNodeSet:
    """The nodes of `chunks` = [(panel cell tag, points (n, 3) [m]), ...] (module docstring).

    Attributes:
        point_member: (sum n,) member index of every given point, in the order given.
        members: sorted global node ids (the set, without repetitions).
        rows: (k, 3) local rows in model.W of the members this rank owns; `owned_member` their member indices.
        reference: (k, 3) their reference positions [m]; `held`: (k,) whether a displacement component is held.
    """

    def __init__(self, model, chunks: Sequence[tuple[int, np.ndarray]], what: Sequence[str]):
        self.comm = model.comm
        nodes = contact_nodes(model)
        imap = nodes.scalar_space.dofmap.index_map
        ids = []
        for tag, points in chunks:
            points = np.asarray(points, dtype=float).reshape(-1, 3)
            node, X = _panel_nodes(model, nodes, tag)
            found = np.full(len(points), -1, dtype=np.int64)
            if len(node):
                distance, nearest = cKDTree(X).query(points)
                hit = distance < MATCH_TOLERANCE
                found[hit] = imap.local_to_global(nodes.node_index[node[nearest[hit]]].astype(np.int32))
            ids.append(found)
        local = np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)
        global_ids = np.empty_like(local)
        self.comm.Allreduce(local, global_ids, op=MPI.MAX)
        offsets = np.cumsum([0] + [len(i) for i in ids])
        for k in range(len(ids)):
            missing = int(np.sum(global_ids[offsets[k]:offsets[k + 1]] < 0))
            if missing:
                raise ValueError(f"{what[k]}: {missing} points are not nodes of their panel (tolerance "
                                 f"{MATCH_TOLERANCE} m)")
        self.members, self.point_member = np.unique(global_ids, return_inverse=True)
        owned_global = imap.local_to_global(nodes.node_index.astype(np.int32))
        n = len(self.members)
        position = np.minimum(np.searchsorted(self.members, owned_global), max(n - 1, 0))
        owned = self.members[position] == owned_global if n else np.zeros(len(owned_global), dtype=bool)
        self._owned_node = np.flatnonzero(owned)
        self.owned_member = position[self._owned_node]
        self.rows = nodes.dofs[self._owned_node]
        self.reference = nodes.reference[self._owned_node]
        self.held = nodes.constrained[self._owned_node].any(axis=1)

    def gather(self, values: np.ndarray) -> np.ndarray:
        """(members, ...) array of per-member `values` (given for the owned members), summed over the ranks."""
        full = np.zeros((len(self.members),) + values.shape[1:])
        full[self.owned_member] = values
        total = np.empty_like(full)
        self.comm.Allreduce(full, total, op=MPI.SUM)
        return total

    def positions(self, d: np.ndarray) -> np.ndarray:
        """(members, 3) current positions [m] at displacements `d` (local array of W), all ranks."""
        return self.gather(self.reference + d[self.rows])
