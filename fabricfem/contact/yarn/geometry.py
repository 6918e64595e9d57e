"""Geometry of yarn contact ([Man2006, sec. 3.2]): closest points on the triangulated master facets, fixed-plane
projections, nodal and interpolated normals, the facet patches of the consistent tangent and the contact search.

Pure numpy, vectorized over points; lengths in m. A master facet is a quadrilateral of the hex mesh in
dolfinx' tensor-product vertex order (v0, v1, v2, v3) = (0,0), (1,0), (0,1), (1,1), split into the two
triangles (v0, v1, v3) and (v0, v3, v2).
"""
from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["candidate_pairs", "closest_point_on_triangles", "facet_patches", "foot_and_normal", "interpolated_normal",
           "nodal_normals", "project", "project_onto_quads", "project_onto_triangle_planes", "triangle_of"]

# the two triangles of a tensor-ordered quad (v0, v1, v2, v3) = (0,0), (1,0), (0,1), (1,1)
_QUAD_TRIANGLES = np.array([[0, 1, 3], [0, 3, 2]])


def _barycentric(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unclamped barycentric coordinates (v, w) of b and c of the projection of x (n, 3) onto the planes of the
    triangles (a, b, c) (n, 3 each) [m]; the weight of a is 1 - v - w. Raises ValueError on a zero-area triangle."""
    ab, ac, ax = b - a, c - a, x - a
    d00, d01, d11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    d20, d21 = (ax * ab).sum(1), (ax * ac).sum(1)
    den = d00 * d11 - d01 * d01
    if np.any(den <= 0.0):
        raise ValueError("master surface: degenerate (zero-area) triangle")
    return (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den


def closest_point_on_triangles(x: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points on triangles (a, b, c) to points x, all (n, 3) [m], vectorized.

    Returns (point (n, 3), barycentric weights (n, 3) of (a, b, c), distance (n,)). Exact: the
    projection onto the plane if it falls inside, otherwise the closest of the three edge points."""
    v, w = _barycentric(x, a, b, c)
    bary = np.column_stack([1.0 - v - w, v, w])
    inside = np.all(bary >= 0.0, axis=1)
    best_bary = np.where(inside[:, None], bary, 0.0)
    best_dist = np.where(inside, np.linalg.norm(x - (bary[:, :1] * a + v[:, None] * b + w[:, None] * c), axis=1),
                         np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):  # three edges, vectorized over points
        p, q = (a, b, c)[i], (a, b, c)[j]
        e = q - p
        t = np.clip(((x - p) * e).sum(1) / (e * e).sum(1), 0.0, 1.0)
        dist = np.linalg.norm(x - (p + t[:, None] * e), axis=1)
        better = dist < best_dist
        edge_bary = np.zeros_like(bary)
        edge_bary[:, i], edge_bary[:, j] = 1.0 - t, t
        best_bary = np.where(better[:, None], edge_bary, best_bary)
        best_dist = np.where(better, dist, best_dist)
    point = best_bary[:, :1] * a + best_bary[:, 1:2] * b + best_bary[:, 2:] * c
    return point, best_bary, best_dist


def project_onto_quads(x: np.ndarray, quads_x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of x (n, 3) on quadrilateral facets quads_x (n, 4, 3) (tensor vertex order, both
    as two triangles), pairwise. Returns (point (n, 3), weights (n, 4) of the quad's vertices,
    outward unit normal (n, 3) (of the chosen triangle, (v1 - v0) x (v2 - v0) orientation, or along
    x - point when the foot point lies on an edge or vertex), distance (n,))."""
    best = None
    for tri in _QUAD_TRIANGLES:
        a, b, c = (quads_x[:, k] for k in tri)
        point, bary, dist = closest_point_on_triangles(x, a, b, c)
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        weights = np.zeros((len(x), 4))
        np.put_along_axis(weights, np.broadcast_to(tri, (len(x), 3)), bary, axis=1)
        if best is None:
            best = [point, weights, normal, dist]
        else:
            better = dist < best[3]
            best = [np.where(better[:, None], point, best[0]), np.where(better[:, None], weights, best[1]),
                    np.where(better[:, None], normal, best[2]), np.where(better, dist, best[3])]
    point, weights, normal, dist = best
    # foot point on an edge or a vertex: the normal is the direction of the distance vector (signed by
    # the facet normal), which keeps the gap continuous when the closest facet changes
    on_edge = np.count_nonzero(weights > 0.0, axis=1) < 3
    diff = x - point
    sign = np.where((diff * normal).sum(1) < 0.0, -1.0, 1.0)
    use = on_edge & (dist > 0.0)
    safe = np.where(use, dist, 1.0)
    normal = np.where(use[:, None], sign[:, None] * diff / safe[:, None], normal)
    return point, weights, normal, dist


def project_onto_triangle_planes(x: np.ndarray, quads_x: np.ndarray, tri: np.ndarray
                                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthogonal projection of x (n, 3) onto the plane of triangle `tri` (n,) (0: (v0, v1, v3), 1: (v0, v3,
    v2)) of the quads quads_x (n, 4, 3), pairwise, with the barycentric weights NOT clamped (the triangle's
    linear shape functions extrapolated beyond its edges): a smooth function of x and the vertices, the
    projection of a fixed facet in the active-set strategy. Returns (point (n, 3), weights (n, 4) of the
    quad's vertices, distance (n,))."""
    idx = _QUAD_TRIANGLES[np.asarray(tri, dtype=np.int64)]                                  # (n, 3)
    rows = np.arange(len(x))[:, None]
    a, b, c = (quads_x[rows[:, 0], idx[:, k]] for k in range(3))
    v, w = _barycentric(x, a, b, c)
    weights = np.zeros((len(x), 4))
    np.put_along_axis(weights, idx, np.column_stack([1.0 - v - w, v, w]), axis=1)
    point = (weights[:, :, None] * quads_x).sum(1)
    return point, weights, np.linalg.norm(x - point, axis=1)


def triangle_of(weights: np.ndarray) -> np.ndarray:
    """The triangle (0: (v0, v1, v3), 1: (v0, v3, v2)) of a quad holding a foot point with quad vertex
    weights (n, 4) from project_onto_quads (v2 has no weight on triangle 0)."""
    return np.where(weights[:, 2] == 0.0, 0, 1)


def project(xs: np.ndarray, quad_x: np.ndarray, tri: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(foot point (n, 3) [m], weights (n, 4)) of xs (n, 3) on the quads quad_x (n, 4, 3): the closest point
    where tri < 0 (or tri None), else the projection onto the plane of the fixed triangle tri
    (project_onto_triangle_planes)."""
    point, w, _, _ = project_onto_quads(xs, quad_x)
    if tri is None or not np.any(tri >= 0):
        return point, w
    fixed = tri >= 0
    p2, w2, _ = project_onto_triangle_planes(xs, quad_x, np.where(fixed, tri, 0))
    return np.where(fixed[:, None], p2, point), np.where(fixed[:, None], w2, w)


def nodal_normals(x: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Unit outward normals at the nodes x (n, 3) of the quads (m, 4): area-weighted average of the
    adjacent facet normals (the quad's diagonals' cross product is twice its area vector)."""
    qx = x[quads]
    facet = np.cross(qx[:, 3] - qx[:, 0], qx[:, 2] - qx[:, 1])
    out = np.zeros_like(x)
    np.add.at(out, quads.ravel(), np.repeat(facet, 4, axis=0))
    norm = np.linalg.norm(out, axis=1)
    return out / np.where(norm > 0.0, norm, 1.0)[:, None]


def interpolated_normal(x: np.ndarray, quads: np.ndarray, facet: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Unit normal n = sum_i N_i n_i / |.| (k, 3) at foot points with quad vertex weights N_i (k, 4) on the
    facets `facet` (k,) of `quads` (m, 4), n_i the nodal normals of the nodes x (n, 3) (nodal_normals)."""
    nodal = nodal_normals(x, quads)
    nrm = (weights[:, :, None] * nodal[quads[facet]]).sum(1)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    return nrm


def foot_and_normal(xs: np.ndarray, xp: np.ndarray, ql: np.ndarray, pql: np.ndarray, pmask: np.ndarray,
                    member: np.ndarray, tri: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot point (m, 3) [m], its quad vertex weights (m, 4) and the interpolated unit nodal normal (m, 3) of
    slaves xs (m, 3) on their master facet, from the facet's patch (facet_patches) with vertex positions
    xp (m, 16, 3): the same quantities as interpolated_normal, as a function of the 16 patch vertices only
    (the stencil of the consistent tangent). ql, pql, pmask, member: the patch arrays of each slave's facet."""
    m = len(xs)
    quad_x = xp[np.arange(m)[:, None], ql]                                    # (m, 4, 3)
    point, w = project(xs, quad_x, tri)
    pq_x = xp[np.arange(m)[:, None, None], pql]                               # (m, 9, 4, 3)
    facet = np.cross(pq_x[:, :, 3] - pq_x[:, :, 0], pq_x[:, :, 2] - pq_x[:, :, 1]) * pmask[:, :, None]
    nodal = np.einsum("mij,mjc->mic", member, facet)
    nodal /= np.linalg.norm(nodal, axis=2)[:, :, None]
    n = (w[:, :, None] * nodal).sum(1)
    n /= np.linalg.norm(n, axis=1)[:, None]
    return point, w, n


def facet_patches(quads: np.ndarray) -> dict[str, np.ndarray]:
    """Per master facet of `quads` (m, 4) the facets sharing one of its vertices (the ones its nodal normals
    are averaged from, at most 9 on the lateral surface of a swept O-grid) and their vertices (at most 16):
    local indices for the finite-difference tangent (set-up only). Keys: pq (m, 9) patch facets, pmask (m, 9)
    1 for a used slot, pn (m, 16) patch vertices (-1 unused), pql (m, 9, 4) and ql (m, 4) the patch facets'
    and the facet's vertices as indices into pn, member (m, 4, 9) 1 where facet vertex i lies on patch facet j."""
    nq = len(quads)
    adjacent: dict[int, list[int]] = {}
    for q, row in enumerate(quads.tolist()):
        for v in row:
            adjacent.setdefault(v, []).append(q)
    pq = np.zeros((nq, 9), dtype=np.int64)
    pmask = np.zeros((nq, 9))
    pn = np.zeros((nq, 16), dtype=np.int64)
    pql = np.zeros((nq, 9, 4), dtype=np.int64)
    ql = np.zeros((nq, 4), dtype=np.int64)
    member = np.zeros((nq, 4, 9))
    for q, row in enumerate(quads.tolist()):
        patch = sorted({a for v in row for a in adjacent[v]})
        nodes = sorted({v for a in patch for v in quads[a].tolist()})
        if len(patch) > 9 or len(nodes) > 16:
            raise ValueError("contact surface: a facet vertex has more than 4 facets (not a structured "
                             "quadrilateral surface); the consistent tangent needs at most 9 neighbours")
        local = {v: i for i, v in enumerate(nodes)}
        pq[q, :len(patch)] = patch
        pmask[q, :len(patch)] = 1.0
        pn[q, :len(nodes)] = nodes
        pn[q, len(nodes):] = -1
        pql[q, :len(patch)] = [[local[v] for v in quads[a].tolist()] for a in patch]
        ql[q] = [local[v] for v in row]
        for i, v in enumerate(row):
            member[q, i, :len(patch)] = [float(v in quads[a].tolist()) for a in patch]
    return dict(pq=pq, pmask=pmask, pn=pn, pql=pql, ql=ql, member=member)


def candidate_pairs(x: np.ndarray, slave: np.ndarray, pair_of_slave: np.ndarray, master_quads: list[np.ndarray],
                    margin: float) -> list[np.ndarray]:
    """Global search ([Man2006, sec. 3.4]): per contact pair k the candidate (slave index, facet index) rows
    (c, 2) whose slave node x[slave] lies within the facet's circumradius + margin [m] of its centroid
    (scipy cKDTree). x: (n, 3) [m] positions of all surface nodes; pair_of_slave: the pair of each slave;
    master_quads: per pair the master facets (m_k, 4) as indices into x."""
    out = []
    for k, quads in enumerate(master_quads):
        qx = x[quads]
        centroid = qx.mean(axis=1)
        radius = np.linalg.norm(qx - centroid[:, None], axis=2).max(axis=1)
        slaves = np.flatnonzero(pair_of_slave == k)
        hits = cKDTree(x[slave[slaves]]).query_ball_point(centroid, radius + margin)
        counts = np.fromiter(map(len, hits), dtype=np.int64, count=len(hits))
        found = np.fromiter(itertools.chain.from_iterable(hits), dtype=np.int64, count=int(counts.sum()))
        out.append(np.column_stack([slaves[found], np.repeat(np.arange(len(quads)), counts)]))
    return out
