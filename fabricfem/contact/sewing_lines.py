"""Which stitches of a placed garment must be sewn through another panel.

The sewing draws each pair of stitched nodes together along the straight line between them (fabricfem.contact.seams:
both move to the pair's centre). If that line crosses a third panel, no contact can close the seam without passing
cloth through cloth: with self-contact the seam stays open or closes through the panel, without it the cloth
crosses itself (docs/findings/2026-11-28-stitched-zones.md). The panels are triangulated on their geometry nodes
(a 9-node quadrilateral split into 8 triangles on its 3 x 3 nodes as the self-contact splits it,
fabricfem.contact.cloth_surface.SPLIT, a 4-node one into 2; the chord of a panel rolled onto a cylinder of radius r
departs from it by h^2 / (32 r) with h the cell size) and each stitch's line is tested against the triangles of
the panels other than the two it joins (libigl's `ray_mesh_intersect`, the library of the intersection count's
degenerate cases; hit parameters t in (1e-9, 1 - 1e-9) of the line from a to b, its ends left out).
Metres. Parallel: each rank tests its own cells, the answers are OR-ed.
"""
from __future__ import annotations

from collections.abc import Sequence

import igl
import numpy as np
from mpi4py import MPI

from fabricfem.contact.cloth_surface import SPLIT

END_MARGIN = 1e-9     # fraction of a stitch's line left out at each end (its own panels' edges lie there)


def panel_triangles(fabric) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) [m], triangles (T, 3), panel tag per triangle (T,)) of this rank's quadrilateral cells of a
    FabricMesh (module docstring)."""
    mesh = fabric.mesh
    nodes = mesh.geometry.dofmap.array.reshape(mesh.topology.index_map(2).size_local, -1)
    local = SPLIT if nodes.shape[1] == 9 else np.array([[0, 1, 3], [0, 3, 2]])
    tags = np.zeros(len(nodes), dtype=np.int64)
    owned = fabric.cell_tags.indices < len(nodes)
    tags[fabric.cell_tags.indices[owned]] = fabric.cell_tags.values[owned]
    triangles = nodes[:, local].reshape(-1, 3)
    return mesh.geometry.x, triangles, np.repeat(tags, len(local))


def crossing_stitches(points_a: np.ndarray, points_b: np.ndarray, own_tags: tuple[int, int], points: np.ndarray,
                      triangles: np.ndarray, triangle_tags: np.ndarray) -> np.ndarray:
    """(n,) bool: the stitched pairs (points_a[i], points_b[i]) [m] whose straight line meets a triangle of a panel
    whose tag is not in `own_tags` (module docstring)."""
    faces = np.ascontiguousarray(triangles[~np.isin(triangle_tags, own_tags)], dtype=np.int64)
    vertices = np.ascontiguousarray(points, dtype=float)
    crossed = np.zeros(len(points_a), dtype=bool)
    if not len(faces):
        return crossed
    for i, (start, end) in enumerate(zip(points_a, points_b)):      # a check at setup, a few hundred lines
        hits = igl.ray_mesh_intersect(np.ascontiguousarray(start, dtype=float),
                                      np.ascontiguousarray(end - start, dtype=float), vertices, faces) or []
        crossed[i] = any(END_MARGIN < hit[1] < 1.0 - END_MARGIN for hit in hits)
    return crossed


def sewn_through(fabric, seams: Sequence, comm: MPI.Comm) -> list[np.ndarray]:
    """Per seam (objects with points_a, points_b (n, 3) [m], tag_a, tag_b), the (n,) bool of its stitches whose
    sewing line crosses another panel of `fabric` on any rank; collective on `comm`, the same on every rank."""
    points, triangles, tags = panel_triangles(fabric)
    mine = [crossing_stitches(seam.points_a, seam.points_b, (seam.tag_a, seam.tag_b), points, triangles, tags)
            for seam in seams]
    local = np.concatenate(mine + [np.zeros(0, dtype=bool)]).astype(np.int32)
    total = np.zeros_like(local)
    comm.Allreduce(local, total, op=MPI.SUM)           # one collective for all seams
    return np.split(total > 0, np.cumsum([len(c) for c in mine])[:-1])
