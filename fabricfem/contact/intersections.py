"""An independent check of a cloth state: the number of intersecting triangle pairs of its surface.

It does not use the contact code: ipctk's broad phase (`ipctk.HashGrid`, [Li2020]) lists the pairs of triangles
whose bounding boxes overlap, and libigl's triangle-triangle test (`igl.tri_tri_intersection_test_3d`, Guigue and
Devillers' test [Guigue2003]) decides each pair, after a numpy rejection of the pairs where one triangle lies
strictly on one side of the other's plane (the first test of [Guigue2003], vectorised: most candidates of a smooth
surface end there). Pairs that share a node (neighbours in the triangulation, which
touch along an edge or at a node by construction) are not counted. Coplanar triangles that overlap count as
intersecting. Units: metres (the count has none).
"""
from __future__ import annotations

import igl
import ipctk
import numpy as np


def candidate_pairs(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n, 2) triangle pairs (i < j) whose bounding boxes overlap and that share no node (ipctk.HashGrid)."""
    x = np.asfortranarray(points, dtype=float)
    faces = np.asfortranarray(triangles, dtype=np.int32)
    grid = ipctk.HashGrid()
    grid.build(x, np.asfortranarray(ipctk.edges(faces)), faces, 0.0)
    pairs = np.array([(c.face0_id, c.face1_id) for c in grid.detect_face_face_candidates()],
                     dtype=np.int64).reshape(-1, 2)
    pairs = np.sort(pairs, axis=1)
    a, b = triangles[pairs[:, 0]], triangles[pairs[:, 1]]
    shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
    return np.unique(pairs[~shared], axis=0)


def intersecting_pairs(points: np.ndarray, triangles: np.ndarray) -> int:
    """Number of pairs of triangles (rows of `triangles` (T, 3), node indices into `points` (N, 3) [m]) that
    intersect and share no node (module docstring)."""
    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"points must be (N, 3) and triangles (T, 3), got {points.shape} and {triangles.shape}")
    count = 0
    for i, j in _straddling(points, triangles, candidate_pairs(points, triangles)):
        p, q = points[triangles[i]], points[triangles[j]]
        hit, *_ = igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])
        count += bool(hit)
    return count


def _straddling(points: np.ndarray, triangles: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """The candidate pairs (n, 2) not separated by a plane of one of the two triangles (the others cannot
    intersect: all three nodes of one triangle strictly on one side of the other's plane)."""
    a, b = points[triangles[pairs[:, 0]]], points[triangles[pairs[:, 1]]]
    keep = np.ones(len(pairs), dtype=bool)
    for u, w in ((a, b), (b, a)):
        normal = np.cross(u[:, 1] - u[:, 0], u[:, 2] - u[:, 0])
        side = np.einsum("ij,ikj->ik", normal, w - u[:, :1])
        keep &= ~((side > 0.0).all(axis=1) | (side < 0.0).all(axis=1))
    return pairs[keep]
