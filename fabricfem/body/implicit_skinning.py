"""Implicit skinning of a mesh skin: the blended vertices kept on the level sets of the body's blended ellipsoids.

Linear blend skinning ([MagnenatThalmann1988], fabricfem.body.skinning) cannot follow the smooth minimum of rigidly
moving distance fields (fabricfem.body.blended): at a flexed elbow the linearly blended vertices fold into the crease
and bulge on the outer side by millimetres (docs/findings/2026-11-28-mesh-skin-normals.md). Implicit skinning
([Vaillant2013, sec. 4]) moves each vertex of more than one segment, after linear blend skinning, along grad phi of
the blended ellipsoids posed at the same time back onto the level phi_i^0 it had at rest (phi_i^0 ~ 0 for a
triangulation of the blended body itself, `fabricfem.body.mesh_skin.ellipsoid_skin`: the posed mesh is then the
blended body at every pose, to the triangulation's chords).

Tracking ([Vaillant2014]): restarted from the linearly blended positions at every pose, the projection folds the
compressed inner crease (measured on the 2 mm arm at 57 degrees: 236 of 114960 triangles turned over). So the
positions are tracked instead, on a grid of key times t_k = t_0 + k dt_key from the kinematics' first time: key
k starts from key k - 1's positions moved by the increment of linear blend skinning, is projected onto the levels
(Newton steps along grad phi, `fabricfem.body.blend_kernel.onto_levels`), relaxed once tangentially towards the mean
of its one-ring (x_i <- x_i + RELAX (I - n n^T)(mean_j x_j - x_i), n the unit grad phi) and projected again. Keys of
0.25 and 0.5 degrees of elbow flexion keep every triangle the right way up to 57 degrees; 1 degree per key turns
29 over (/tmp measurements, docs/findings/2026-11-28-implicit-skinning.md). Between two keys the shift (tracked
position minus linearly blended position) is interpolated linearly in time and added to the linearly blended
vertex, so a vertex is within the shift's second difference of its level; the keys depend only on the kinematics
and dt_key, not on which times are asked (a resumed run poses the skin as an uninterrupted one). Units: metres,
seconds.
"""
from __future__ import annotations

from typing import Callable

import igl
import numpy as np
import scipy.sparse as sp

from fabricfem.body.blend_kernel import onto_levels
from fabricfem.body.skinning import pose_vertices

RELAX = 0.5                   # the tangential relaxation's step towards the one-ring mean [Vaillant2014]
RELAX_PASSES = 1              # relaxations (each followed by a projection) per key
SKINNING_REACH = 0.1          # m: default reach of the moved vertices around a shared joint (mesh_skin.MeshSkin)
KEY_INTERVAL = 2e-3           # s: default dt_key (0.09 deg per key at the sleeve's 45 deg/s, 0.6 deg at a 300 deg/s knee)


def ring_matrix(faces: np.ndarray, rows: np.ndarray) -> sp.csr_matrix:
    """(len(rows), V) sparse matrix whose row r averages the one-ring neighbours of vertex rows[r] (libigl's
    vertex adjacency of the triangles `faces`)."""
    adjacency = sp.csr_matrix(igl.adjacency_matrix(np.asarray(faces, dtype=np.int64)), dtype=float)[rows]
    return sp.diags(1.0 / np.asarray(adjacency.sum(axis=1)).ravel()) @ adjacency


class ImplicitSkinning:
    """The tracked shifts of a mesh skin's blended vertices (module docstring).

    Args:
        rest: (V, 3) rest vertices [m]; faces: (F, 3) triangles; weights: (V, K) skinning weights.
        shifted: (S,) the vertices moved (of more than one segment); levels: (S,) their rest levels phi_i^0 [m].
        linear: t -> (A (K, 3, 3), b (K, 3) [m]): the segments' maps rest -> pose at time t [s]
            (fabricfem.body.mesh_skin.MeshSkin.maps without the shifts).
        field: t -> (centres (K, 3), rotations (K, 3, 3), radii (K, 3), widths (K, K)) of the blended
            ellipsoids at time t [s] (grown by the donning across their axes).
        t0: the first key time [s]; interval: dt_key [s].
    """

    def __init__(self, rest: np.ndarray, faces: np.ndarray, weights: np.ndarray, shifted: np.ndarray,
                 levels: np.ndarray, linear: Callable, field: Callable, t0: float, interval: float = KEY_INTERVAL):
        if not (np.isfinite(interval) and interval > 0.0):
            raise ValueError(f"skinning_interval must be a positive time [s], got {interval!r}")
        self.shifted, self.levels = np.asarray(shifted, dtype=np.int64), np.asarray(levels, dtype=float)
        ring = np.unique(np.concatenate([self.shifted, np.asarray(faces)[np.isin(faces, self.shifted).any(axis=1)]
                                         .ravel()]))
        self.ring = ring                                   # the shifted vertices and their neighbours
        self.inner = np.searchsorted(ring, self.shifted)   # the shifted ones among them
        self.mean = ring_matrix(faces, self.shifted)[:, ring]
        self.rest, self.weights = rest[ring], weights[ring]
        self.linear, self.field = linear, field
        self.t0, self.interval = float(t0), float(interval)
        self.keys = 0                                      # keys computed since the start
        self._key = -1
        self._tracked = self._lbs = None                   # (S, 3) at key self._key
        self._shifts: dict[int, np.ndarray] = {}

    def _advance(self) -> None:
        """Key self._key + 1 from key self._key (or key 0 from linear blend skinning)."""
        k = self._key + 1
        t = self.t0 + k * self.interval
        ring = pose_vertices(self.rest, self.weights, *self.linear(t))
        lbs = ring[self.inner]
        start = lbs if self._tracked is None else self._tracked + (lbs - self._lbs)
        centers, rotations, radii, widths = self.field(t)
        x, n = onto_levels(start, self.levels, centers, rotations, radii, widths)
        for _ in range(RELAX_PASSES):
            ring[self.inner] = x
            step = self.mean @ ring - x
            x = x + RELAX * (step - (step * n).sum(axis=1)[:, None] * n)
            x, n = onto_levels(x, self.levels, centers, rotations, radii, widths)
        self._key, self._tracked, self._lbs = k, x, lbs
        self._shifts = {key: s for key, s in self._shifts.items() if key >= k - 1}
        self._shifts[k] = x - lbs
        self.keys += 1

    def _shift_at_key(self, k: int) -> np.ndarray:
        if k < self._key - 1 or k not in self._shifts and k <= self._key:
            self._key, self._tracked, self._lbs, self._shifts = -1, None, None, {}   # back in time: from the start
        while self._key < k:
            self._advance()
        return self._shifts[k]

    def shift(self, t: float) -> np.ndarray:
        """(S, 3) shifts [m] of the shifted vertices at time t [s] (linear in time between the keys; before t0 the
        first key's)."""
        s = max((float(t) - self.t0) / self.interval, 0.0)
        k = int(np.floor(s))
        lam = s - k
        first = self._shift_at_key(k)
        if lam == 0.0:
            return first.copy()
        return (1.0 - lam) * first + lam * self._shift_at_key(k + 1)
