"""An independent check of a cloth state: the number of intersecting triangle pairs of its surface.

It does not use the contact code. The candidates are the pairs of triangles whose centroids lie closer than the
sum of their circumradii about the centroids (the only pairs whose bounding spheres, hence the triangles, can meet),
whose bounding boxes overlap and that share no node (neighbours in the triangulation touch along an edge or at a
node by construction and are not counted; so are two triangles with nodes that are one point of the cloth, the
stitched nodes of a seam, given as `same` labels); a uniform grid of cells of edge at least twice the largest radius
lists them (fabricfem.contact.intersections_kernel). Then, for each candidate, in the same compiled loop:

* the plane test of [Guigue2003] (its first test): a pair where all three nodes of one triangle lie strictly on
  one side of the other's plane cannot intersect (most candidates of a smooth surface end there);
* the interval test of [Moller1997] for the general case (each triangle crosses the other's plane with no node
  on it): the two triangles meet the line of the planes' intersection in two intervals, and intersect if and
  only if the intervals overlap;
* libigl's triangle-triangle test (`igl.tri_tri_intersection_test_3d`, Guigue and Devillers' orientation
  predicates [Guigue2003]) for the rest: a node on (or within DEGENERATE of) the other's plane, nearly parallel
  planes. Coplanar triangles that overlap count as intersecting.

The compiled loop rounds as the numpy expressions of these tests did (intersections_kernel's docstring), so the
pairs are those of the numpy version, bit for bit in every decision (but for a pair whose centroids lie within
round-off of 2 r_max, which cKDTree's broad phase could also accept by its cells' bounds).
Units: metres (the count has none).
"""
from __future__ import annotations

import igl
import numpy as np

from fabricfem.contact import intersections_kernel
from fabricfem.forms.jit import pointer

DEGENERATE = 1e-9     # a node's distance to the other's plane below DEGENERATE x the pair's size: libigl decides
_CAPACITY = {True: 1024, False: 1024}   # output rows of the last calls (narrow or not), grown on demand
_WORK: dict[int, np.ndarray] = {}       # the compiled pass's workspace, by triangle count (kept: no page faults)


def _checked(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """points (N, 3) float64 and triangles (T, 3) int64, C-contiguous, node indices in range, positions finite."""
    points = np.ascontiguousarray(points, dtype=float)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"points must be (N, 3) and triangles (T, 3), got {points.shape} and {triangles.shape}")
    if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(points)):
        raise ValueError("triangles index nodes outside points")
    if not np.isfinite(points).all():
        raise ValueError("points must be finite")
    return points, triangles


def _pass(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int], narrow: bool) -> tuple[np.ndarray,
                                                                                                  np.ndarray]:
    """The compiled pass (intersections_kernel): (n, 2) pairs (i < j) in lexicographic order and their flags (n,)
    (narrow: 1 intersecting, 2 degenerate; else the candidates, flags 0)."""
    k, parts = part
    if not (parts >= 1 and 0 <= k < parts):
        raise ValueError(f"part must be (k, parts) with 0 <= k < parts, got {part}")
    points, triangles = _checked(points, triangles)
    lib, ffi = intersections_kernel.module()
    if len(triangles) not in _WORK:
        _WORK.clear()
        _WORK[len(triangles)] = np.empty(lib.workspace(len(triangles)) // 8, np.int64)
    work = pointer(ffi, _WORK[len(triangles)], "int64_t")
    while True:
        capacity = _CAPACITY[narrow]
        pairs, flags = np.empty((capacity, 2), np.int64), np.empty(capacity, np.int64)
        n = lib.crossings(len(triangles), pointer(ffi, points, "double"), pointer(ffi, triangles, "int64_t"), k,
                          parts, DEGENERATE, int(narrow), work, capacity, pointer(ffi, pairs, "int64_t"),
                          pointer(ffi, flags, "int64_t"))
        if n <= capacity:
            break
        _CAPACITY[narrow] = int(1.25 * n) + 1
    order = np.lexsort((pairs[:n, 1], pairs[:n, 0]))
    return pairs[:n][order], flags[:n][order]


def candidate_pairs(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1)) -> np.ndarray:
    """(n, 2) triangle pairs (i < j), in lexicographic order, whose bounding spheres and boxes overlap and that
    share no node; `part` = (k, parts): only the pairs met by run k of the triangles in the order of the search grid
    (intersections_kernel: the pairs are met by the earlier of their two triangles in that order, so the parts
    together list every pair once)."""
    return _pass(points, triangles, part, narrow=False)[0]


def intersecting_pairs(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1),
                       same: np.ndarray | None = None) -> int:
    """Number of pairs of triangles (rows of `triangles` (T, 3), node indices into `points` (N, 3) [m]) that
    intersect and share no node (module docstring); `part` = (k, parts): the pairs of `candidate_pairs`' part k
    only (the counts of the parts sum to the whole count: each rank of a run counts one part, a run of 1 / parts
    of the triangles in grid order, so each does about 1 / parts of the pair work); `same` (N,): a label per
    node, equal for nodes that are one point of the cloth (`ClothSurface.stitched`); triangles that share a label
    are neighbours and are not counted (None: each node its own)."""
    return len(intersecting(points, triangles, part, same))


def intersecting(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1),
                 same: np.ndarray | None = None) -> np.ndarray:
    """The (n, 2) pairs (i < j), in lexicographic order, counted by `intersecting_pairs`."""
    pairs, flags = _pass(points, triangles, part, narrow=True)
    hits = flags == 1
    if (flags == 2).any():                          # degenerate pairs (rare): libigl decides
        points, triangles = _checked(points, triangles)
        for k in np.flatnonzero(flags == 2):
            p, q = points[triangles[pairs[k, 0]]], points[triangles[pairs[k, 1]]]
            hits[k] = bool(igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0])
    found = pairs[hits]
    if same is not None and len(found):
        labels = np.asarray(same)
        if labels.shape != (len(points),):
            raise ValueError(f"same must hold one label per point ({len(points)}), got shape {labels.shape}")
        first, second = labels[triangles[found[:, 0]]], labels[triangles[found[:, 1]]]
        found = found[~(first[:, :, None] == second[:, None, :]).any(axis=(1, 2))]
    return found
