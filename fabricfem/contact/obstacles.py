"""Fixed rigid obstacles for the shell contact layer: a half-space (`Plane`) and a box with rounded edges
(`RoundedBox`, with the table helpers `table_top` and `table_edge`). SI units (m).

They duck-type `fabricfem.body.Ellipsoid` as used by `fabricfem.contact.problem.ContactProblem` and
`fabricfem.contact.nodal.nearest_gap`:

    gap(x) -> (g, n)          signed distance g [m] (positive outside) and unit outward normal n at the foot
    to_local(x), to_global(y) the obstacle frame (the world frame: these obstacles do not move)
    surface_velocity(x, v_center, omega)   v = v_c + omega x (x - c), c the obstacle's reference point

all vectorised over (N, 3) point arrays.

`ObstacleSkin(obstacles)` is what the implicit contact (ContactProblem) asks of a set of fixed obstacles: the query of
the wearer's surface contract (fabricfem.body.skin) for their union, seen through the nearest obstacle.

`RoundedBox(lower, upper, radius)` is the set of points within `radius` of the axis-aligned box
[lower, upper] (bounds may be infinite). Its signed distance is exact:

    g(x) = |x - q(x)| - r          outside the inner box, q(x) = clip(x, lower, upper) (closest point)
    g(x) = -(r + min_i d_i(x))      inside it, d_i the distances to its finite faces

and continuously differentiable outside the inner box (every point the cloth can reach): on the faces
n = e_i, across the edges and corners n = (x - q) / |x - q| turns continuously over the fillet of radius r.
A sharp edge (r = 0) switches the supporting normal discontinuously when a node slides over it, which
stalls Newton's method (found with the particle model, fabricfem/particles/obstacles.py); r > 0 is required.

A table (`table_top`, `table_edge`) is such a box whose flat top z = height covers exactly the given
footprint; the fillet lies outside the footprint (the inner box is the footprint lowered by r), as in the
particle model's `TableTop`, so that both methods see the same table.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fabricfem.body.ellipsoid import nearest_gap
from fabricfem.body.skin import SkinQuery


def _points(x) -> np.ndarray:
    """(N, 3) array of finite points (a single (3,) point becomes (1, 3))."""
    arr = np.atleast_2d(np.asarray(x, dtype=float))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"x must have shape (3,) or (N, 3), got {np.shape(x)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("x must be finite (positions contain NaN/inf: the solve diverged)")
    return arr


def _vector3(name: str, value, allow_inf: bool = False) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    ok = v.shape == (3,) and not np.any(np.isnan(v)) and (allow_inf or np.all(np.isfinite(v)))
    if not ok:
        raise ValueError(f"{name} must be a {'(possibly infinite) ' if allow_inf else 'finite '}vector of shape "
                         f"(3,), got {value!r}")
    return v


class _FixedObstacle:
    """Frame and kinematics shared by the fixed obstacles (world frame, reference point `origin`)."""

    origin: np.ndarray

    def to_local(self, x) -> np.ndarray:
        """Obstacle-frame coordinates of x: the world frame (the obstacle is fixed), shape (N, 3)."""
        return _points(x).copy()

    def to_global(self, y) -> np.ndarray:
        """World coordinates of obstacle-frame points y (identity), shape (N, 3)."""
        return np.atleast_2d(np.asarray(y, dtype=float)).copy()

    def surface_velocity(self, x, v_center, omega) -> np.ndarray:
        """Velocity [m/s] of the material point at x of the obstacle moving rigidly with reference-point
        velocity v_center [m/s] and angular velocity omega [rad/s]: v = v_c + omega x (x - c)."""
        pts = _points(x)
        v_c = _vector3("v_center", v_center)
        w = _vector3("omega", omega)
        return v_c + np.cross(w, pts - self.origin)

    def distance(self, x) -> np.ndarray:
        """Signed distance [m] (positive outside), shape (N,)."""
        return self.gap(x)[0]

    def contains(self, x) -> np.ndarray:
        """True where the point is strictly inside the solid (g < 0)."""
        return self.gap(x)[0] < 0.0


@dataclass(frozen=True, eq=False)
class Plane(_FixedObstacle):
    """The rigid half-space {x : n . (x - x0) <= 0} with boundary plane through `point` x0 [m] and unit
    outward normal `normal` (normalised here)."""

    point: Sequence[float]
    normal: Sequence[float]

    def __post_init__(self):
        point = _vector3("point", self.point)
        normal = _vector3("normal", self.normal)
        length = float(np.linalg.norm(normal))
        if length == 0.0:
            raise ValueError("normal must be a non-zero vector")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", normal / length)

    @property
    def origin(self) -> np.ndarray:
        return self.point

    def gap(self, x) -> tuple[np.ndarray, np.ndarray]:
        """g = n . (x - x0) [m] (exact signed distance) and n, shapes (N,), (N, 3)."""
        pts = _points(x)
        return (pts - self.point) @ self.normal, np.tile(self.normal, (len(pts), 1))


@dataclass(frozen=True, eq=False)
class RoundedBox(_FixedObstacle):
    """Points within `radius` r [m] > 0 of the axis-aligned box [lower, upper] [m] (bounds may be -inf /
    +inf; each axis needs lower <= upper and at least one bound must be finite)."""

    lower: Sequence[float]
    upper: Sequence[float]
    radius: float

    def __post_init__(self):
        lower = _vector3("lower", self.lower, allow_inf=True)
        upper = _vector3("upper", self.upper, allow_inf=True)
        if np.any(lower > upper) or np.any(lower == np.inf) or np.any(upper == -np.inf):
            raise ValueError(f"lower must not exceed upper on any axis (and not be +inf), got {lower}, {upper}")
        if not (np.any(np.isfinite(lower)) or np.any(np.isfinite(upper))):
            raise ValueError("lower/upper: at least one bound must be finite (an unbounded box fills space)")
        if not (isinstance(self.radius, (int, float, np.floating)) and math.isfinite(self.radius)
                and self.radius > 0.0):
            raise ValueError(f"radius must be a positive finite length (a sharp edge stalls Newton), got "
                             f"{self.radius!r}")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)
        object.__setattr__(self, "radius", float(self.radius))

    @property
    def origin(self) -> np.ndarray:
        """A finite reference point: the box centre on finite axes, the finite bound on half-infinite ones,
        0 on fully infinite axes."""
        lo, hi = self.lower, self.upper
        both = np.isfinite(lo) & np.isfinite(hi)
        return np.where(both, 0.5 * (np.where(both, lo, 0) + np.where(both, hi, 0)),
                        np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), hi, 0.0)))

    def gap(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Exact signed distance g [m] (positive outside) and the unit outward normal (module docstring)."""
        pts = _points(x)
        q = np.clip(pts, self.lower, self.upper)   # closest point of the inner box
        d = pts - q
        dist = np.linalg.norm(d, axis=1)
        outside = dist > 0.0
        g = dist - self.radius
        n = np.zeros_like(pts)
        n[outside] = d[outside] / dist[outside, None]
        inside = ~outside
        if np.any(inside):
            # distances to the six faces (inf for infinite bounds); the nearest finite face gives g and n
            faces = np.concatenate([pts[inside] - self.lower, self.upper - pts[inside]], axis=1)
            nearest = np.argmin(faces, axis=1)
            rows = np.arange(len(nearest))
            g[inside] = -(self.radius + faces[rows, nearest])
            sign = np.where(nearest < 3, -1.0, 1.0)
            n_in = np.zeros((len(nearest), 3))
            n_in[rows, nearest % 3] = sign
            n[inside] = n_in
        return g, n


def table_top(center: Sequence[float], half_x: float, half_y: float, height: float,
              fillet_radius: float) -> RoundedBox:
    """A rectangular table: flat top z = height [m] over the footprint |x - cx| <= half_x, |y - cy| <= half_y
    (center = (cx, cy) [m]), infinitely deep, edges and corners rounded to fillet_radius [m] outside the
    footprint."""
    cx, cy = (float(c) for c in center)
    for name, v in (("half_x", half_x), ("half_y", half_y)):
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"{name} must be a positive finite length, got {v!r}")
    if not math.isfinite(height):
        raise ValueError(f"height must be finite, got {height!r}")
    r = float(fillet_radius)
    return RoundedBox((cx - half_x, cy - half_y, -np.inf), (cx + half_x, cy + half_y, height - r), r)


def table_edge(edge_x: float, height: float, fillet_radius: float) -> RoundedBox:
    """The table x <= edge_x [m] with flat top z = height [m] and its straight edge (along y) rounded to
    fillet_radius [m] beyond x = edge_x (the support of the overhanging beam)."""
    if not (math.isfinite(edge_x) and math.isfinite(height)):
        raise ValueError(f"edge_x and height must be finite, got {edge_x!r}, {height!r}")
    r = float(fillet_radius)
    return RoundedBox((-np.inf, -np.inf, -np.inf), (edge_x, np.inf, height - r), r)


class ObstacleSkin:
    """The skin (the `query` of the wearer's surface contract, fabricfem.body.skin) of fixed rigid obstacles (Plane,
    RoundedBox, posed Ellipsoids: anything with gap(x) -> (g, n)): their union, seen from each point x through the
    nearest obstacle k. gap = g_k(x) [m] (the obstacle's own `gap`: exact for planes and rounded boxes, the ray-cast
    estimate of Ellipsoid.gap), normal n_k, foot x - g n [m], weight 1 on obstacle k. No blend: where two obstacles
    are equally near the normal switches from one to the other, as it does on their union. The obstacles do not
    move: `query(x, t)` is the same at every time t [s]. `segment_names`: "obstacle0", "obstacle1", ... in order;
    `obstacles`: the frames of the friction's stick points."""

    def __init__(self, obstacles: Sequence):
        self.obstacles = list(obstacles)
        self.segment_names = tuple(f"obstacle{k}" for k in range(len(self.obstacles)))

    def query(self, x: np.ndarray, t: float = 0.0) -> SkinQuery:
        """The union seen from the points x (N, 3) [m] (at any time t [s])."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        g, n, nearest = nearest_gap(x, self.obstacles)
        weights = np.zeros((len(x), len(self.obstacles)))
        weights[np.arange(len(x)), nearest] = 1.0
        return SkinQuery(g, x - g[:, None] * n, n, weights)
