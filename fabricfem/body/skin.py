"""The wearer's surface contract: what the contact and the monitors may ask of a body's skin.

A skin is the outer surface of a `Body` (fabricfem.body.pose) at any time t [s] of its kinematics. For points x
(N, 3) [m] it answers with a `SkinQuery`:

* `gap` (N,) [m]: the signed distance to the skin, negative inside the body;
* `foot` (N, 3) [m]: the closest point of the skin;
* `normal` (N, 3): the unit outward normal of the skin at the foot (continuous across joints: no crease);
* `weights` (N, K): the share of each of the body's K segments (in `Body.segments` order) in the skin at the foot,
  non-negative, rows summing to 1. A contact force f at a point is carried by segment k as w_k f, so that a joint
  torque sums w_k (x - J) x (-f) over the segments on its side (fabricfem.contact.torque).

The skin moves with the segments: the velocity of its material point at the foot is sum_k w_k (v_k + omega_k x
(p - c_k)) (`skin_velocity`), and friction's stick points are kept in the frame of the segment of largest weight.

Implementations: `fabricfem.body.blended.BlendedEllipsoids` (the segments' ellipsoids joined by a smooth blend in
the creases, the default of every body) and the skins read from a triangulated surface mesh and rigged to the
segments (fabricfem.body.mesh_skin).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True, eq=False)
class SkinQuery:
    """The skin seen from N points (module docstring): gap (N,) [m], foot (N, 3) [m], normal (N, 3),
    weights (N, K)."""

    gap: np.ndarray
    foot: np.ndarray
    normal: np.ndarray
    weights: np.ndarray

    @property
    def segment(self) -> np.ndarray:
        """(N,) index of the segment of largest weight (ties: the first)."""
        return np.argmax(self.weights, axis=1).astype(np.int64) if self.weights.size else np.zeros(
            len(self.gap), dtype=np.int64)

    def __len__(self) -> int:
        return len(self.gap)


@runtime_checkable
class Skin(Protocol):
    """A body's surface over time (module docstring). `segment_names`: the K segments of the weights' columns."""

    segment_names: tuple[str, ...]

    def query(self, x: np.ndarray, t: float) -> SkinQuery:
        """The skin at time t [s] seen from the points x (N, 3) [m]."""
        ...

    def surface(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The posed skin as a triangulation: vertices (V, 3) [m] and triangles (F, 3) int, outward oriented."""
        ...


def skin_velocity(body, query: SkinQuery, t: float) -> np.ndarray:
    """(N, 3) velocity [m/s] of the skin's material points at the feet of `query` at time t [s]:
    sum_k w_k (v_k + omega_k x (p - c_k)) with each segment's rigid velocity (`Body.velocities`)."""
    posed = body.pose(t)
    velocities = body.velocities(t)
    out = np.zeros_like(query.foot)
    for k, name in enumerate(body.segments):
        w = query.weights[:, k]
        on = w > 0.0
        if on.any():
            v_c, omega = velocities[name]
            out[on] += w[on, None] * (v_c + np.cross(omega, query.foot[on] - posed[name].center))
    return out
