"""Signed distance, closest point and normal of points to a closed, outward-oriented triangulation.

The closest point C of a point x and its triangle I come from libigl's AABB tree (`igl.AABB.squared_distance`,
C++), built once per posed surface and kept for every later query of the same pose. The sign is that of
(x - C) . n with n the angle-weighted pseudonormal of the feature C lies on ([Baerentzen2005]): the face normal
inside a triangle, the sum of the two face normals on an edge, the angle-weighted sum of the face normals at a
vertex; it is correct for any x of a closed, consistently oriented, non-self-intersecting surface. This is the sign
of `igl.signed_distance(..., SIGNED_DISTANCE_TYPE_PSEUDONORMAL)` (tested against it); the pseudonormals are computed
here with numpy from a topology built once, so that a posed surface costs one tree build and one pass over its
faces, and a repeated query of the same pose only the tree search (the figures are in
docs/findings/2026-11-27-mesh-skin.md). The contact's queries of a rigged skin take the same closest points, sign
and normal in compiled code (`fabricfem.body.mesh_query`); `PosedSurface` is their reference.

The returned normal is the unit gradient of the signed distance, sign (x - C) / |x - C|, continuous in x off the
medial axis; where |x - C| is below `FOOT_NORMAL_DISTANCE` (x on the surface) it is the feature's pseudonormal.
Units: metres.
"""
from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

FEATURE_TOLERANCE = 1e-7        # barycentric coordinates below this put the foot on an edge or a vertex
FOOT_NORMAL_DISTANCE = 1e-7     # m: nearer than this the normal is the feature's pseudonormal


@dataclass(frozen=True, eq=False)
class Topology:
    """The edges and vertex rings of a closed triangulation, built once for all its poses: `faces` (F, 3),
    `face_edges` (F, 3) the index of the edge opposite each corner, `n_edges` their number, `edge_faces` (E, 2) the
    two faces of each edge, and the faces around each vertex as a CSR table: those of vertex v are
    `ring_face[ring_start[v]:ring_start[v + 1]]`, v being their corner `ring_corner[...]`."""

    faces: np.ndarray
    face_edges: np.ndarray
    n_edges: int
    edge_faces: np.ndarray
    ring_start: np.ndarray
    ring_face: np.ndarray
    ring_corner: np.ndarray

    @classmethod
    def of(cls, faces: np.ndarray) -> Topology:
        f = np.ascontiguousarray(faces, dtype=np.int64)
        opposite = np.stack([f[:, [1, 2]], f[:, [2, 0]], f[:, [0, 1]]], axis=1).reshape(-1, 2)   # (3F, 2)
        _, inverse = np.unique(np.sort(opposite, axis=1), axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        n_edges = int(inverse.max()) + 1
        count = np.bincount(inverse, minlength=n_edges)
        edge_faces = np.zeros((n_edges, 2), dtype=np.int64)
        order = np.argsort(inverse, kind="stable")
        if np.all(count == 2):                # a closed manifold: two faces per edge
            edge_faces = (order // 3).reshape(-1, 2)
        else:                                 # an open or non-manifold surface: the first face twice where alone
            first = np.concatenate([[0], np.cumsum(count)[:-1]])
            edge_faces[:, 0] = order[first] // 3
            edge_faces[:, 1] = order[first + (count > 1)] // 3
        corners = f.reshape(-1)
        ring = np.argsort(corners, kind="stable")
        start = np.concatenate([[0], np.cumsum(np.bincount(corners))]).astype(np.int64)
        return cls(f, inverse.reshape(-1, 3), n_edges, edge_faces, start, ring // 3, ring % 3)


def face_normals_areas(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward face normals (F, 3) and areas (F,) [m^2] of a triangulation (right-handed corners)."""
    p = vertices[faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    double = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(double, 1e-300)[:, None], 0.5 * double


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


class PosedSurface:
    """A triangulation in one pose with its AABB tree and pseudonormals (module docstring).

    Args:
        vertices: (V, 3) [m].
        topology: the faces and edges (`Topology.of(faces)`), shared by every pose of the same mesh.
        tree: (igl.AABB, the vertices it was built on) of an earlier pose to reuse instead of a new build. The
            tree's boxes then lag the triangles by at most delta = max |vertices - built vertices| [m], and a
            search may return a triangle up to 2 delta farther than the closest (the distance and foot are exact
            for the triangle returned: libigl evaluates the triangles on the vertices passed to the search).
    """

    def __init__(self, vertices: np.ndarray, topology: Topology, tree: tuple[igl.AABB, np.ndarray] | None = None):
        self.vertices = np.ascontiguousarray(vertices, dtype=float)
        self.topology = topology
        faces = topology.faces
        if tree is None:
            self.tree = igl.AABB()
            self.tree.init(self.vertices, faces)
            self.built_on = self.vertices
        else:
            self.tree, self.built_on = tree

    def closest(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(gap (N,) [m] negative inside, triangle (N,) int, barycentric coordinates (N, 3) of the foot,
        foot (N, 3) [m], unit outward normal (N, 3)) of the points x (N, 3) [m]."""
        x = np.ascontiguousarray(x, dtype=float)
        sqrd, tri, foot = self.tree.squared_distance(self.vertices, self.topology.faces, x)
        return signed_closest(self.vertices, self.topology, x, sqrd, tri, foot)


def _face_normals(vertices: np.ndarray, faces: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Unit outward normals (N, 3) of the faces `which` (N,)."""
    p = vertices[faces[which]]
    return _unit(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))


def pseudonormals(vertices: np.ndarray, topology: Topology, tri: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(N, 3) angle-weighted pseudonormals ([Baerentzen2005]) of the features the feet lie on (triangle `tri`,
    barycentric coordinates `bary`; a coordinate below FEATURE_TOLERANCE puts the foot on an edge, two on a vertex),
    computed for those features only from the posed `vertices` (V, 3) [m]."""
    faces = topology.faces
    small = bary < FEATURE_TOLERANCE
    count = small.sum(axis=1)
    pseudo = _face_normals(vertices, faces, tri)
    on_edge = np.flatnonzero(count == 1)
    if len(on_edge):
        pair = topology.edge_faces[topology.face_edges[tri[on_edge], np.argmax(small[on_edge], 1)]]
        pseudo[on_edge] = _unit(_face_normals(vertices, faces, pair[:, 0]) + _face_normals(vertices, faces, pair[:, 1]))
    on_vertex = np.flatnonzero(count >= 2)
    if len(on_vertex):
        v = faces[tri[on_vertex], np.argmax(bary[on_vertex], 1)]
        first, sizes = topology.ring_start[v], topology.ring_start[v + 1] - topology.ring_start[v]
        owner = np.repeat(np.arange(len(v)), sizes)
        slot = np.repeat(first - np.concatenate([[0], np.cumsum(sizes)[:-1]]), sizes) + np.arange(sizes.sum())
        ring, corner = topology.ring_face[slot], topology.ring_corner[slot]
        p = vertices[faces[ring]]
        rows = np.arange(len(ring))
        u = p[rows, (corner + 1) % 3] - p[rows, corner]
        w = p[rows, (corner + 2) % 3] - p[rows, corner]
        cross = np.cross(u, w)
        angle = np.arctan2(np.linalg.norm(cross, axis=1), np.einsum("ij,ij->i", u, w))
        weighted = angle[:, None] * _unit(cross)
        pseudo[on_vertex] = _unit(np.column_stack([np.bincount(owner, weights=weighted[:, i], minlength=len(v))
                                                   for i in range(3)]))
    return pseudo


def signed_closest(vertices: np.ndarray, topology: Topology, x: np.ndarray, sqrd: np.ndarray, tri: np.ndarray,
                   foot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(gap (N,) [m], triangle, barycentric coordinates (N, 3), foot (N, 3) [m], unit normal (N, 3)) of the points x
    (N, 3) [m] from their closest points (squared distance [m^2], triangle, foot) on the posed `vertices`: the sign
    and the normal of the module docstring."""
    corner = vertices[topology.faces[tri]]
    bary = igl.barycentric_coordinates(foot, np.ascontiguousarray(corner[:, 0]), np.ascontiguousarray(corner[:, 1]),
                                       np.ascontiguousarray(corner[:, 2])).reshape(-1, 3)
    pseudo = pseudonormals(vertices, topology, tri, bary)
    offset = x - foot
    sign = np.where(np.einsum("ij,ij->i", offset, pseudo) >= 0.0, 1.0, -1.0)
    distance = np.sqrt(np.maximum(sqrd, 0.0))
    far = distance > FOOT_NORMAL_DISTANCE
    normal = np.where(far[:, None], sign[:, None] * offset / np.where(far, distance, 1.0)[:, None], pseudo)
    return sign * distance, tri, bary, foot, normal
