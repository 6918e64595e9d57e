"""A body's motion placed in a garment, and whether the garment meets the body (the scene key motion.place).

Garment: its reference bounding box B = [lower, upper] [m], the axis-aligned box of its reference points (a
tube's circles, a pattern's placed panel outlines), centre c_g = (lower + upper) / 2.

Body: the posed segments (ellipsoids, centres x^c_i, radii r_i) of its first pose; centre of volume

    c_b = sum_i V_i x^c_i / sum_i V_i,     V_i = r1_i r2_i r3_i   (the ellipsoid volume / (4 pi / 3)).

Placement: the whole motion is translated by one constant vector

    d = P (c_g - c_b),   P = diag(1, 1, 0) for a body that stands on the floor (z up: the heights stay, so the
                         feet keep the floor the file recorded), P = I for a body that does not (an arm, a limb).

Reach: the distance between the body's first pose and B, bounded from below by

    D = min_i max_{n in N} ( min_{v in B} n.v - h_i(n) ),   h_i(n) = n.x^c_i + |diag(r_i) R_i^T n|,

h_i the support function of ellipsoid i and N a set of unit directions (golden-angle spiral): each direction
separates the two convex sets by at most their distance, so D never exceeds the true distance (0 when a segment
reaches into B). The garment meets the body's first pose only if D = 0.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid

DIRECTIONS = 2000   # unit directions of the distance bound: spacing ~0.08 rad, deficit O(size x angle^2) ~ 2 mm for 1 m


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit vectors (golden-angle spiral)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    rho = np.sqrt(1.0 - z * z)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def centre_of_volume(posed: Mapping[str, Ellipsoid]) -> np.ndarray:
    """c_b [m]: the centres of the posed segments weighted by their volumes (module docstring)."""
    volumes = np.array([np.prod(e.radii) for e in posed.values()])
    return volumes @ np.array([e.center for e in posed.values()]) / volumes.sum()


def placement_offset(posed: Mapping[str, Ellipsoid], lower, upper, keep_height: bool) -> np.ndarray:
    """d [m]: the translation that takes the centre of volume of `posed` to the centre of the box [lower, upper]
    [m], without its z component when `keep_height` (module docstring)."""
    d = 0.5 * (np.asarray(lower, dtype=float) + np.asarray(upper, dtype=float)) - centre_of_volume(posed)
    if keep_height:
        d[2] = 0.0
    return d


def box_distance(posed: Mapping[str, Ellipsoid], lower, upper, directions: int = DIRECTIONS) -> float:
    """D [m]: a lower bound of the distance between the posed segments and the box [lower, upper] [m], 0 when a
    segment reaches into it (module docstring)."""
    n = fibonacci_sphere(directions)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    box_side = n @ (0.5 * (lo + hi)) - np.abs(n) @ (0.5 * (hi - lo))     # min over the box of n.v
    gaps = [np.max(box_side - n @ e.center - np.linalg.norm((n @ e.rotation) * e.radii, axis=1))
            for e in posed.values()]
    return max(0.0, float(min(gaps)))


class Translated:
    """A kinematics source (fabricfem.body.motion.KinematicsSource) moved by a constant vector `offset` [m]: the
    same names and time range, every position + offset."""

    def __init__(self, source, offset):
        self.source = source
        self.offset = np.asarray(offset, dtype=float)
        if self.offset.shape != (3,) or not np.all(np.isfinite(self.offset)):
            raise ValueError(f"offset must be a finite (3,) vector [m], got {offset!r}")
        self.names = tuple(source.names)
        self.time_range = source.time_range

    def positions(self, t: float) -> dict[str, np.ndarray]:
        return {name: p + self.offset for name, p in self.source.positions(t).items()}
