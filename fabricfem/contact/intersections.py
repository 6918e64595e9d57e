"""An independent check of a cloth state: the number of intersecting triangle pairs of its surface.

It does not use the contact code. scipy's k-d tree lists the pairs of triangles whose centroids lie closer than
the sum of their circumradii (the only pairs whose bounding spheres, hence the triangles, can meet), a numpy test
keeps those whose bounding boxes overlap and that share no node (neighbours in the triangulation touch along an
edge or at a node by construction and are not counted). Then, for each pair, vectorised over the pairs:

* the plane test of [Guigue2003] (its first test): a pair where all three nodes of one triangle lie strictly on
  one side of the other's plane cannot intersect (most candidates of a smooth surface end there);
* the interval test of [Moller1997] for the general case (each triangle crosses the other's plane with no node
  on it): the two triangles meet the line of the planes' intersection in two intervals, and intersect if and
  only if the intervals overlap;
* libigl's triangle-triangle test (`igl.tri_tri_intersection_test_3d`, Guigue and Devillers' orientation
  predicates [Guigue2003]) for the rest: a node on (or within DEGENERATE of) the other's plane, nearly parallel
  planes. Coplanar triangles that overlap count as intersecting.

Units: metres (the count has none).
"""
from __future__ import annotations

import igl
import numpy as np
from scipy.spatial import cKDTree

DEGENERATE = 1e-9     # a node's distance to the other's plane below DEGENERATE x the pair's size: libigl decides


def _slab(centroid: np.ndarray, reach: float, part: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Part k of `parts`: the triangles whose centroids lie within `reach` [m] of slab k (the centroids sorted
    along the axis of largest extent and cut into `parts` runs of equal count), and which of all triangles slab k
    owns (T,) bool."""
    k, parts = part
    axis = int(np.argmax(np.ptp(centroid, axis=0))) if len(centroid) else 0
    order = np.argsort(centroid[:, axis], kind="stable")
    owned = np.zeros(len(centroid), dtype=bool)
    owned[order[k * len(order) // parts:(k + 1) * len(order) // parts]] = True
    if not owned.any():
        return np.zeros(0, dtype=np.int64), owned
    lo, hi = centroid[owned, axis].min(), centroid[owned, axis].max()
    return np.flatnonzero((centroid[:, axis] >= lo - reach) & (centroid[:, axis] <= hi + reach)), owned


def candidate_pairs(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1)) -> np.ndarray:
    """(n, 2) triangle pairs (i < j) whose bounding boxes overlap and that share no node; `part` = (k, parts): only
    the pairs whose first triangle i lies in slab k of `_slab` (the parts together list every pair once: a pair
    within reach lies within slab k and its margin, and is kept by the slab of its first triangle)."""
    corners = points[triangles]                                   # (T, 3, 3)
    centroid = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centroid[:, None], axis=2).max(axis=1)
    reach = 2.0 * float(radius.max(initial=0.0))
    if part[1] == 1:
        pairs = cKDTree(centroid).query_pairs(reach, output_type="ndarray")
    else:
        local, owned = _slab(centroid, reach, part)
        pairs = local[cKDTree(centroid[local]).query_pairs(reach, output_type="ndarray")].reshape(-1, 2)
        pairs = np.sort(pairs, axis=1)
        pairs = pairs[owned[pairs[:, 0]]]
    pairs = pairs[np.linalg.norm(centroid[pairs[:, 0]] - centroid[pairs[:, 1]], axis=1)
                  <= radius[pairs[:, 0]] + radius[pairs[:, 1]]]
    low, high = corners.min(axis=1), corners.max(axis=1)
    overlap = ((low[pairs[:, 0]] <= high[pairs[:, 1]]) & (low[pairs[:, 1]] <= high[pairs[:, 0]])).all(axis=1)
    pairs = pairs[overlap]                  # query_pairs: each pair once, i < j
    a, b = triangles[pairs[:, 0]], triangles[pairs[:, 1]]
    shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
    return pairs[~shared].astype(np.int64).reshape(-1, 2)


def intersecting_pairs(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1)) -> int:
    """Number of pairs of triangles (rows of `triangles` (T, 3), node indices into `points` (N, 3) [m]) that
    intersect and share no node (module docstring); `part` = (k, parts): the pairs of `candidate_pairs`' part k
    only (the counts of the parts sum to the whole count: each rank of a run counts one part, a slab of the
    surface with its margin, so each does about 1 / parts of the work)."""
    return len(intersecting(points, triangles, part))


def intersecting(points: np.ndarray, triangles: np.ndarray, part: tuple[int, int] = (0, 1)) -> np.ndarray:
    """The (n, 2) pairs (i < j) counted by `intersecting_pairs`."""
    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"points must be (N, 3) and triangles (T, 3), got {points.shape} and {triangles.shape}")
    pairs = candidate_pairs(points, triangles, part)
    a, b = points[triangles[pairs[:, 0]]], points[triangles[pairs[:, 1]]]
    side_b, normal_a = _sides(a, b)          # nodes of b against the plane of a
    side_a, normal_b = _sides(b, a)
    keep = _straddles(side_b) & _straddles(side_a)
    pairs = pairs[keep]
    a, b, side_a, side_b, normal_a, normal_b = (v[keep] for v in (a, b, side_a, side_b, normal_a, normal_b))
    size = np.maximum(np.ptp(a, axis=1).max(axis=1), np.ptp(b, axis=1).max(axis=1))
    general = ((np.abs(side_a).min(axis=1) > DEGENERATE * size * np.linalg.norm(normal_b, axis=1))
               & (np.abs(side_b).min(axis=1) > DEGENERATE * size * np.linalg.norm(normal_a, axis=1)))
    direction = np.cross(normal_a[general], normal_b[general])
    general[general] = np.linalg.norm(direction, axis=1) > DEGENERATE * (np.linalg.norm(normal_a[general], axis=1)
                                                                        * np.linalg.norm(normal_b[general], axis=1))
    direction = np.cross(normal_a[general], normal_b[general])
    low_a, high_a = _interval(a[general], side_a[general], direction)
    low_b, high_b = _interval(b[general], side_b[general], direction)
    hits = np.zeros(len(pairs), dtype=bool)
    hits[general] = np.maximum(low_a, low_b) <= np.minimum(high_a, high_b)
    for k in np.flatnonzero(~general):
        p, q = a[k], b[k]
        hits[k] = bool(igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0])
    return pairs[hits]


def _sides(u: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances (n, 3), times |normal|, of the nodes of the triangles w (n, 3, 3) to the planes of the
    triangles u, and those planes' normals (n, 3) (unnormalised, (u1 - u0) x (u2 - u0))."""
    normal = np.cross(u[:, 1] - u[:, 0], u[:, 2] - u[:, 0])
    return np.einsum("ij,ikj->ik", normal, w - u[:, :1]), normal


def _straddles(side: np.ndarray) -> np.ndarray:
    """Not all three nodes strictly on one side of the plane [Guigue2003]."""
    return ~((side > 0.0).all(axis=1) | (side < 0.0).all(axis=1))


def _interval(corners: np.ndarray, side: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The interval (low, high) of the line of the two planes (direction (n, 3)) inside each triangle (corners
    (n, 3, 3)) that crosses the other plane with no node on it (`side` (n, 3): signed distances, none zero)
    [Moller1997, eq. 4]: the node alone on its side, v, and the two others, w: t = p_v + (p_w - p_v) s_v / (s_v - s_w),
    p the nodes' projections on the line."""
    projection = np.einsum("ikj,ij->ik", corners, direction)
    positive = side > 0.0
    lone = np.where(positive.sum(axis=1) == 1, np.argmax(positive, axis=1), np.argmin(positive, axis=1))
    rows = np.arange(len(side))
    others = (lone[:, None] + np.array([1, 2])) % 3
    p_v, s_v = projection[rows, lone][:, None], side[rows, lone][:, None]
    p_w, s_w = projection[rows[:, None], others], side[rows[:, None], others]
    t = p_v + (p_w - p_v) * s_v / (s_v - s_w)
    return t.min(axis=1), t.max(axis=1)
