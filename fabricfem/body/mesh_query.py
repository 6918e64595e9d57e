"""The closest points of a posed mesh skin in compiled code: one bounding-box tree, refitted where it blends.

`CompiledSkin` answers the queries of `fabricfem.body.mesh_skin.MeshSkin` (the Skin contract) for a closed,
outward triangulation rigged by linear blend skinning, in C (`fabricfem.body.skin_kernel`, built with cffi by
`fabricfem.forms.jit.built_once`):

* the segments' maps rest -> pose, A_k = R_k diag(1, g, g) (R_k^0)^T, b_k = c_k - A_k c_k^0, from the joints and
  markers (the frames of fabricfem.body.pose.segment_frame, [Man2006, sec. 5.1]; g the donning's transverse growth);
* the posed vertices, v = sum_k w_k (A_k v^0 + b_k) ([MagnenatThalmann1988]), A_k v^0 + b_k for a vertex of
  weight 1 on segment k, computed where a search needs them, once per pose (and for the whole surface by `pose`);
  with implicit skinning (fabricfem.body.mesh_skin) a vertex of more than one segment is then moved by the pose's
  shift (`Pose.shift`), and the mapped boxes below are grown by the pose's largest shift;
* an axis-aligned bounding-box tree over the triangles, built once on the rest pose (top-down, split at the middle
  of the triangles' centroids along the longest axis, leaves of at most LEAF_SIZE triangles, [Ericson2005,
  sec. 6.2]), never rebuilt nor refitted. A node whose triangles all follow one segment k rigidly keeps its rest
  box: while the maps are rotations it is searched with the point in that segment's rest frame, A_k^T (x - b_k)
  (distances are invariant under the rigid map). Any other node (one holding a triangle of the blended bands around
  the joints, or every node when the maps are not rotations: g != 1, the donning) is bounded at a pose by the union
  of its rest box mapped by each segment its vertices follow (half extents |A_k| h about A_k c + b_k: a posed vertex
  is a convex combination of points of those boxes), computed on its first visit at that pose and kept for the
  pose's other points (the cheap alternative to refitting the tree bottom-up, [Bergen1997]: looser, nothing done
  for the nodes no search reaches). Every box bounds its triangles for the pose, so a search is exact (no
  tolerance: a looser box only costs visits);
* the search: a point descends the tree nearest box first, starting from the distance to the triangle it found last
  (an upper bound, which prunes the tree for a point that moved little), pruning every box no nearer than the best
  triangle found; the closest point of a triangle by its Voronoi regions ([Ericson2005, sec. 5.1.5]) with its
  barycentric coordinates; the sign and normal of `fabricfem.body.mesh_distance.signed_closest` (the angle-weighted
  pseudonormal of the foot's feature, [Baerentzen2005], for the sign; the unit offset for the normal) and the
  segment weights interpolated at the foot (barycentric coordinates clipped to [0, 1] and renormalised);
* the active set of `MeshSkin.query`: a point last searched at x0 with gap g0 and skin travel s0 is searched again
  only where g0 - |x - x0| - (travel - s0) <= margin (margin < 0: every point is searched).

The results are those of libigl's AABB tree on the posed vertices (`PosedSurface.closest`, `signed_closest`) up
to round-off: the same triangle or one at the same distance (a foot on a shared edge or vertex), gaps and feet to
1e-12 m, normals and weights to 1e-9 (tests/test_mesh_skin.py). Units: metres.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.body.mesh_distance import Topology
from fabricfem.body.skin_kernel import CDEF, MAX_SEGMENTS, SOURCE
from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

RIGID_MAPS = 1e-9        # max |A^T A - I| below which the maps are taken for rotations (the rest-frame search)


class QueryState:
    """The active set's state of N points and the buffers of their answers (`CompiledSkin.query`): x0 (N, 3) [m],
    g0 (N,) [m], s0 (N,) [m] of the last search; gap (N,) [m], foot (N, 3) [m], normal (N, 3), weights (N, K),
    triangle (N,) (-1 before the first search), barycentric coordinates (N, 3) of the last query."""

    def __init__(self, ffi, n: int, k: int):
        self.x0, self.g0, self.s0 = np.zeros((n, 3)), np.full(n, -np.inf), np.zeros(n)
        self.gap, self.foot, self.normal = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3))
        self.weights, self.triangle, self.bary = np.zeros((n, k)), np.full(n, -1, dtype=np.int64), np.zeros((n, 3))
        self.pointers = tuple(ffi.from_buffer("double[]", a) for a in (self.x0, self.g0, self.s0, self.gap,
                                                                        self.foot, self.normal, self.weights)) + (
            ffi.from_buffer("int64_t[]", self.triangle), ffi.from_buffer("double[]", self.bary))


class Pose:
    """The skin at one time: the segments' maps A (K, 3, 3), b (K, 3) [m] (one buffer, `pointers` into it), whether
    they are rotations (`rigid`), the posed vertices (V, 3) [m] (None until `CompiledSkin.pose`) and the implicit
    skinning's shifts of the blended vertices (`shift` (S, 3) [m] in the order of `CompiledSkin`'s `shifted`, None
    for linear blend skinning; `shift_bound` [m] their largest length)."""

    def __init__(self, ffi, k: int):
        self.ffi = ffi
        self.maps = np.empty(12 * k)
        self.A, self.b = self.maps[:9 * k].reshape(k, 3, 3), self.maps[9 * k:].reshape(k, 3)
        pointer = ffi.from_buffer("double[]", self.maps)
        self.pointers = (pointer, pointer + 9 * k)
        self.vertices: np.ndarray | None = None
        self.rigid, self.epoch = True, 0
        self.shift: np.ndarray | None = None
        self.shift_bound, self.shift_pointer = 0.0, ffi.NULL

    def set_shift(self, shift: np.ndarray) -> None:
        """Add the shifts (S, 3) [m] of the blended vertices to this pose (before any vertex is posed)."""
        if self.vertices is not None:
            raise RuntimeError("set_shift: the pose's vertices were already computed")
        self.shift = np.ascontiguousarray(shift, dtype=float)
        self.shift_bound = float(np.sqrt((self.shift ** 2).sum(axis=1).max())) if len(self.shift) else 0.0
        self.shift_pointer = self.ffi.from_buffer("double[]", self.shift)


class CompiledSkin:
    """A rigged closed triangulation's compiled queries (module docstring): the tree built on the rest pose.

    Args:
        rest: (V, 3) rest vertices [m]; topology: their faces, edges and vertex rings; weights: (V, K) skinning
            weights (rows summing to 1).
        fraction: (K,) the segments' centre fractions; rest_centers (K, 3) [m], rest_rotations (K, 3, 3): their
            rest frames (`fabricfem.body.skinning.frames`).
        centers (K, 3) [m], radii (K,) [m]: the bounding spheres of each segment's weighted rest vertices (`travel`).
        shifted: (S,) indices of the vertices a `Pose.shift` moves (implicit skinning; empty: linear blend
            skinning); they are never searched as rigid parts.
    """

    def __init__(self, rest: np.ndarray, topology: Topology, weights: np.ndarray, fraction: np.ndarray,
                 rest_centers: np.ndarray, rest_rotations: np.ndarray, centers: np.ndarray, radii: np.ndarray,
                 shifted: np.ndarray = np.zeros(0, dtype=np.int64)):
        self.lib, self.ffi = built_once("fabricfem_skin_query", CDEF, SOURCE, MPI.COMM_SELF, KERNEL_FLAGS)
        weights = np.ascontiguousarray(weights, dtype=float)
        nv, k = weights.shape
        if k > MAX_SEGMENTS:
            raise ValueError(f"skin: at most {MAX_SEGMENTS} segments, the body has {k}")
        nf = len(topology.faces)
        rows, cols = np.nonzero(weights)
        single = (weights > 0.0).sum(axis=1) == 1
        single[shifted] = False                   # a shifted vertex does not follow its segment rigidly
        a = {"rest": rest, "faces": topology.faces, "weights": weights,
             "wstart": np.searchsorted(rows, np.arange(nv + 1)), "wseg": cols, "wval": weights[rows, cols],
             "vertex_segment": np.where(single, np.argmax(weights, axis=1), -1),
             "face_edges": topology.face_edges, "edge_faces": topology.edge_faces, "ring_start": topology.ring_start,
             "ring_face": topology.ring_face, "ring_corner": topology.ring_corner}
        nodes = max(2 * nf - 1, 1)
        a.update({name: np.zeros(nodes, dtype=np.int64) for name in ("left", "right", "first", "count",
                                                                      "node_segment", "mask", "stamp")})
        a.update({name: np.zeros((nodes, 3)) for name in ("rest_lo", "rest_hi", "lo", "hi")})
        slot = np.full(nv, -1, dtype=np.int64)
        slot[shifted] = np.arange(len(shifted))
        a.update(perm=np.zeros(max(nf, 1), dtype=np.int64), vstamp=np.zeros(nv, dtype=np.int64),
                 vposed=np.zeros((nv, 3)), shift_slot=slot)
        # kept alive: the struct points into them
        self.arrays = {name: np.ascontiguousarray(v, dtype=float if np.asarray(v).dtype.kind == "f" else np.int64)
                       for name, v in a.items()}
        self.mesh = self.ffi.new("skin_mesh *")
        self.mesh.nv, self.mesh.nf, self.mesh.k = nv, nf, k
        for name, array in self.arrays.items():
            setattr(self.mesh, name, self._p(array))
        self.mesh.shift, self.mesh.box_grow = self.ffi.NULL, 0.0
        self.nodes = int(self.lib.skin_build(self.mesh, self._p(np.zeros((nf, 3)))))
        self.segments = tuple(np.ascontiguousarray(v, dtype=float) for v in (fraction, rest_centers, rest_rotations,
                                                                              centers, radii))
        self._segment_pointers = tuple(self._p(v) for v in self.segments)
        self.epochs = 0          # poses made (each its own number for the nodes' box cache)

    def _p(self, array: np.ndarray):
        return pointer(self.ffi, array, "int64_t" if array.dtype == np.int64 else "double")

    def pose_at(self, points: np.ndarray, growth: float = 1.0) -> Pose:
        """The Pose (maps only) from the segments' joints and markers `points` (3K, 3) [m] (the proximal joints,
        the distal joints, the markers; module docstring) and the transverse `growth` g."""
        k = len(self.segments[0])
        pose = Pose(self.ffi, k)
        self.epochs += 1
        pose.epoch = self.epochs
        fraction, rest_c, rest_r = self._segment_pointers[:3]
        error = self.lib.skin_maps(k, self._p(points), fraction, rest_c, rest_r, float(growth), *pose.pointers)
        pose.rigid = bool(error < RIGID_MAPS)
        return pose

    def travel(self, pose: Pose, before: Pose) -> float:
        """max_k |A_k - A0_k|_F R_k + |(A_k - A0_k) c_k + b_k - b0_k| [m] with (A0, b0) the maps of `before`: a bound
        on any vertex's displacement between the poses (`CompiledSkin` args: the bounding spheres (c_k, R_k))."""
        return float(self.lib.skin_travel(len(pose.b), *pose.pointers, *before.pointers,
                                          *self._segment_pointers[3:]))

    def _bind(self, pose: Pose) -> None:
        """The pose's shifts and their bound in the compiled mesh (for `pose` and `query`)."""
        self.mesh.shift, self.mesh.box_grow = pose.shift_pointer, pose.shift_bound

    def pose(self, pose: Pose) -> np.ndarray:
        """The posed vertices (V, 3) [m] of `pose` (linear blend skinning plus the pose's shifts, written once)."""
        if pose.vertices is None:
            vertices = np.empty((self.mesh.nv, 3))
            self._bind(pose)
            self.lib.skin_pose(self.mesh, *pose.pointers, self._p(vertices))
            pose.vertices = vertices
        return pose.vertices

    def query(self, pose: Pose, x: np.ndarray, state: QueryState, travel: float = 0.0, margin: float = -1.0) -> int:
        """Search the points x (N, 3) [m] (C-contiguous) on the skin at `pose`, the answers in `state`; the active set
        by `travel` and `margin` [m] (< 0: every point). Returns the number of points searched; ValueError for a
        point that is not finite."""
        self._bind(pose)
        searched = int(self.lib.skin_query(self.mesh, *pose.pointers, int(pose.rigid), pose.epoch, len(x),
                                           self.ffi.from_buffer("double[]", x), float(travel), float(margin),
                                           *state.pointers))
        if searched < 0:
            raise ValueError(f"x must be finite, got {x[-1 - searched]}")
        return searched
