"""Reference material direction fields (unit vectors) on simple surfaces.

Each factory returns a function ``x (3, N) -> v (3, N)`` (coordinates in
metres, result dimensionless and of unit length), the layout used by
``dolfinx.fem.Function.interpolate``.  Fully vectorised with numpy.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np


def constant(direction: Sequence[float]) -> Callable[[np.ndarray], np.ndarray]:
    """The same unit vector (normalised ``direction``) at every point."""
    v = np.asarray(direction, dtype=np.float64).reshape(3, 1)
    norm = np.linalg.norm(v)
    if not norm > 0.0:
        raise ValueError(f"direction: must be a non-zero 3-vector, got {direction!r}")
    v = v / norm

    def field(x: np.ndarray) -> np.ndarray:
        return np.repeat(v, np.shape(x)[1], axis=1)

    return field


def radial_from_x_axis() -> Callable[[np.ndarray], np.ndarray]:
    """Outward unit radial direction ``(0, y, z) / sqrt(y^2 + z^2)`` about the x axis.

    Undefined on the axis itself (points there get a zero vector).
    """

    def field(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        r = np.hypot(x[1], x[2])
        out = np.zeros((3, x.shape[1]))
        np.divide(x[1], r, out=out[1], where=r > 0.0)
        np.divide(x[2], r, out=out[2], where=r > 0.0)
        return out

    return field


def radial_from_origin() -> Callable[[np.ndarray], np.ndarray]:
    """Outward unit radial direction ``x / |x|`` (a sphere about the origin); zero at the origin."""

    def field(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        r = np.linalg.norm(x, axis=0)
        return np.divide(x, r, out=np.zeros_like(x), where=r > 0.0)

    return field
