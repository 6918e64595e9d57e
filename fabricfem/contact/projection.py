"""Projection of trial points onto moving ellipsoid segments and the forward-increment Lagrange step of [Man2006,
Box 5] on numpy arrays: the geometry the explicit body contact (fabricfem.contact.explicit) uses.

    d^c = proj(x*) - x*,   a^c = d^c / dt^2,   lambda = -M a^c                             ([Man2006, Box 5], step i)
    a^{n+1} = a* + a^c,    v^{n+1} = v* + dt/2 a^c                                          ([Man2006, Box 5], step j)

Positions [m], velocities [m/s], accelerations [m/s^2], lumped masses [kg], shape (N,) or (N, 3).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid, _ray_to_surface
from fabricfem.contact import compiled
from fabricfem.contact.nodal import (
    positive_parameter,
)

MAX_PROJECTION_PASSES = 8
MAX_CREASE_ITERATIONS = 20   # bisector pushes out of overlapping segments after the passes (project_with_segment)
INSIDE_TOLERANCE = 1e-12   # relative to the smallest radius: rounding of a projected point is not "inside"
PARKED_AT = np.array([1e4, 1e4, 1e4])   # m: where an inactive segment waits (fabricfem.wear donning), far from any garment


def as_points(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (the explicit step diverged?)")
    return arr


def as_masses(masses, n: int) -> np.ndarray:
    m = np.asarray(masses, dtype=float)
    if m.shape == (n,):
        m = np.repeat(m[:, None], 3, axis=1)
    if m.shape != (n, 3) or not np.all(np.isfinite(m)) or np.any(m <= 0.0):
        raise ValueError(f"masses must be positive with shape ({n},) or ({n}, 3), got shape {m.shape}")
    return m


def project_along_gradient(x, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """Move the points inside any ellipsoid onto its surface along grad f at the point ([Man2006, Box 5]).

    The ray x + s grad f / |grad f| is intersected with the surface (`Ellipsoid.gap` with one cast);
    a point inside two overlapping segments is projected out of the deeper one first and re-checked
    (at most MAX_PROJECTION_PASSES passes). Returns (projected points (N, 3), moved mask (N,)).
    """
    out, moved, _ = project_with_segment(x, ellipsoids)
    return out, moved


def normalised_radius(x: np.ndarray, e: Ellipsoid) -> np.ndarray:
    """q(x) = sum_i y_i^2 / r_i^2 = f(x) + 1 [Man2006, eq. 3.61], y = R^T (x - c): q < 1 strictly inside."""
    y = (x - e.center) @ e.rotation
    return np.sum((y / e.radii) ** 2, axis=1)


def normalised_radii(x: np.ndarray, ellipsoids: Sequence[Ellipsoid]) -> np.ndarray:
    """(K, N) q of every point against every segment with one matrix product: q_k = |x A_k - c_k A_k|^2 with
    A_k = R_k diag(1 / r_k) (q = f + 1 [Man2006, eq. 3.61], q < 1 strictly inside). Equal to
    sum_i y_i^2 / r_i^2 with y = R^T (x - c) up to rounding (~1e-16), which only matters for points within
    rounding of the surface; those are not "inside" for the projection's tolerance (INSIDE_TOLERANCE), so the
    prefilter q < 1 selects the same points that the ray casts would move."""
    return SegmentStack(ellipsoids).normalised_radii(x)


def ray_gap(x: np.ndarray, e: Ellipsoid) -> np.ndarray:
    """Signed gap [m] of `Ellipsoid.gap(x, ray_casts=1)` (`SegmentStack.ray_gap`) without the input checks and the
    foot-point normal, which the projection does not use."""
    one = SegmentStack([e])
    k = np.zeros(len(x), dtype=np.int64)
    return one.ray_gap(one.to_local(x, k), k)


class SegmentStack:
    """The K posed segments stacked, so that the functions of (point, segment) pairs run as one vectorised
    evaluation instead of a loop over the segments: centres c (K, 3) [m], rotations R (K, 3, 3), radii r and
    r^2 (K, 3) [m, m^2], the smallest radius of each segment [m] and the matrices of `normalised_radii`.

    Each pair function has the arithmetic of the `Ellipsoid` method it replaces (the same products, quotients
    and sums of three in the same order), so the two agree to the last bit; `k` is the (P,) segment index of
    each of the P points."""

    def __init__(self, ellipsoids: Sequence[Ellipsoid]):
        self.count = len(ellipsoids)
        self.center = np.array([e.center for e in ellipsoids])
        self.rotation = np.array([e.rotation for e in ellipsoids])
        self.radii = np.array([e.radii for e in ellipsoids])
        self.radii2 = self.radii ** 2
        self.scale = self.radii.min(axis=1)
        self._A = np.concatenate(self.rotation / self.radii[:, None, :], axis=1)                    # (3, 3K)
        self._b = (np.matmul(self.center[:, None, :], self.rotation)[:, 0] / self.radii).reshape(-1)  # (3K,)

    def normalised_radii(self, x: np.ndarray) -> np.ndarray:
        """(K, N) q of the points x (N, 3) against every segment (`normalised_radii`)."""
        y = x @ self._A - self._b
        return (y * y).reshape(len(x), self.count, 3).sum(axis=2).T

    def to_local(self, x: np.ndarray, k: np.ndarray) -> np.ndarray:
        """y = R_k^T (x - c_k) [m] (`Ellipsoid.to_local`), (P, 3)."""
        return np.matmul((x - self.center[k])[:, None, :], self.rotation[k])[:, 0]

    def to_global(self, y: np.ndarray, k: np.ndarray) -> np.ndarray:
        """x = c_k + R_k y [m] (`Ellipsoid.to_global`), (P, 3)."""
        return self._rotate(y, k) + self.center[k]

    def _rotate(self, v: np.ndarray, k: np.ndarray) -> np.ndarray:
        """R_k v of local vectors v (P, 3) (the products of v @ R_k^T)."""
        return np.matmul(self.rotation[k], v[:, :, None])[:, :, 0]

    def normal(self, y: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Unit outward normal grad f / |grad f| (`Ellipsoid.normal`) at the points of local coordinates y."""
        return row_unit(self._rotate(2.0 * y / self.radii2[k], k))

    def ray_gap(self, y: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Signed gap [m] of the points of local coordinates y: `Ellipsoid.gap(x, ray_casts=1)` (one cast along
        grad f at the point, the ray towards the centre where it misses) without the foot-point normal."""
        r, r2 = self.radii[k], self.radii2[k]
        yr = y / r
        q = (yr * yr).sum(axis=1)
        grad = y / r2
        norm = row_length(grad)
        at_center = norm == 0.0
        if at_center.any():
            shortest = np.eye(3)[np.argmin(r, axis=1)]
            u = np.where(at_center[:, None], shortest, grad / np.where(at_center, 1.0, norm)[:, None])
        else:
            u = grad / norm[:, None]
        s, hit = _ray_to_surface(y, r, u, r2, q - 1.0)
        if not hit.all():
            u_center = row_unit(np.where(hit[:, None], u, y))
            s = np.where(hit, s, _ray_to_surface(y, r, u_center, r2, q - 1.0)[0])
        return np.abs(s) * np.where(q >= 1.0, 1.0, -1.0)

    def gaps_inside(self, points: np.ndarray, inside_q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray-cast gaps (K, n) [m] of `points` (n, 3) against the segments each is inside of (inside_q, (K, n)
        bool), +inf against the others (the gap is >= 0 there, no ray cast needed); with the local coordinates
        (P, 3) of the P inside pairs and the (K, n) index of each pair among them (-1: no pair)."""
        k, j = np.nonzero(inside_q)
        y = self.to_local(points[j], k)
        gaps = np.full(inside_q.shape, np.inf)
        gaps[k, j] = self.ray_gap(y, k)
        pair = np.full(inside_q.shape, -1)
        pair[k, j] = np.arange(len(k))
        return gaps, y, pair


def row_length(v: np.ndarray) -> np.ndarray:
    """|v| of the rows of v (N, 3) (the sum of squares of np.linalg.norm, without its dispatch)."""
    return np.sqrt((v * v).sum(axis=1))


def row_unit(v: np.ndarray) -> np.ndarray:
    """v / |v| row by row (`fabricfem.body.ellipsoid._unit_rows`)."""
    return v / row_length(v)[:, None]


def project_with_segment(x, ellipsoids: Sequence[Ellipsoid], strict: bool = True,
                         segments: SegmentStack | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`project_along_gradient` that also returns the segment index (N,) each point was last projected
    out of (for points inside no segment: the segment of smallest normalised radius q, a diagnostic).
    `segments`: the ellipsoids already stacked (`SegmentStack`), if the caller has them.

    Vectorised search: q = f + 1 (eq. 3.61) of every point and segment first (one matrix product); only the
    points with q < 1 for some segment (the candidates) get the ray casts of `Ellipsoid.gap`, one evaluation
    over all (point, segment) pairs with q < 1, and a later pass re-checks only the points moved by the
    previous one (the others have not moved). The gap of a point with q >= 1 is >= 0 (`Ellipsoid.gap`), so
    casting rays only from the points inside a segment, against that segment, gives the same projections as
    casting them from every point against every segment.
    """
    x = as_points("x", x)
    out = x.copy()
    n = len(x)
    moved = np.zeros(n, dtype=bool)
    if n == 0 or not ellipsoids:
        return out, moved, np.zeros(n, dtype=np.int64)
    stack = SegmentStack(ellipsoids) if segments is None else segments
    q = stack.normalised_radii(x)
    segment = q.argmin(axis=0)
    inside_q = q < 1.0
    candidates = np.flatnonzero(inside_q.any(axis=0))
    inside_q = inside_q[:, candidates]        # (K, candidates): inside segment k by q
    for k_pass in range(MAX_PROJECTION_PASSES):
        if len(candidates) == 0:
            return out, moved, segment
        points = out[candidates]
        gaps, local, pair = stack.gaps_inside(points, inside_q)
        deepest = gaps.argmin(axis=0)
        if k_pass == 0:
            segment[candidates] = deepest
        columns = np.arange(len(points))
        g = gaps[deepest, columns]
        inside = g < -INSIDE_TOLERANCE * stack.scale[deepest]
        if not inside.any():
            return out, moved, segment
        # grad f / |grad f| at the trial point, against the deepest segment
        direction = stack.normal(local[pair[deepest[inside], columns[inside]]], deepest[inside])
        points[inside] = points[inside] - g[inside, None] * direction
        out[candidates] = points
        candidates = candidates[inside]
        segment[candidates] = deepest[inside]
        moved[candidates] = True
        # the next pass re-checks the moved points (the others have not moved)
        inside_q = stack.normalised_radii(out[candidates]) < 1.0
        keep = inside_q.any(axis=0)
        candidates, inside_q = candidates[keep], inside_q[:, keep]
    return _push_out_of_creases(out, moved, segment, candidates, inside_q, stack, strict)


def _push_out_of_creases(out: np.ndarray, moved: np.ndarray, segment: np.ndarray, candidates: np.ndarray,
                         inside_q: np.ndarray, stack: SegmentStack, strict: bool
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crease fallback of `project_with_segment` for the points `candidates` still inside after its passes
    (inside_q: (K, candidates) q < 1). A point in the lens where two segments overlap (the inner side of a flexed
    elbow) is sent back and forth by the one-segment projections; push it out of all the segments it is inside
    of at once, along the bisector d of their outward normals (in the cone of the normals, where a contact
    force between the cloth and two rigid bodies lies), by the largest |g_k| / (d . n_k)."""
    for _ in range(MAX_CREASE_ITERATIONS):
        if len(candidates) == 0:
            return out, moved, segment
        points = out[candidates]
        gaps, local, pair = stack.gaps_inside(points, inside_q)
        gaps = np.minimum(gaps, 0.0)   # 0 where not inside
        k, j = np.nonzero(inside_q)
        normals = np.zeros((stack.count,) + points.shape)
        normals[k, j] = stack.normal(local[pair[k, j]], k)
        direction = np.zeros_like(points)
        for normal in normals:  # loop over the few segments, vectorised over the points
            direction += normal
        direction /= np.maximum(row_length(direction)[:, None], 1e-300)
        cosine = np.einsum("kni,ni->kn", normals, direction)
        reach = np.where(inside_q & (gaps < 0.0), -gaps / np.maximum(cosine, 1e-3), 0.0)
        out[candidates] = points + reach.max(axis=0)[:, None] * direction
        segment[candidates] = np.argmin(gaps, axis=0)
        inside_q = stack.normalised_radii(out[candidates]) < 1.0
        # rounding of a point projected onto a surface is not "inside" (as in the passes above)
        gap_left = stack.gaps_inside(out[candidates], inside_q)[0].min(axis=0)
        keep = gap_left < -INSIDE_TOLERANCE * stack.scale.min()
        candidates, inside_q = candidates[keep], inside_q[:, keep]
    if len(candidates) == 0 or not strict:
        return out, moved, segment      # not strict: the trapped points stay where the last push put them
    raise ValueError("ellipsoids: points remain inside after repeated projections (overlapping segments "
                     "trap them); refine the time step")


def project_compiled(reference: np.ndarray, rows: np.ndarray, d: np.ndarray, v: np.ndarray, a: np.ndarray,
                     dt: float, segments: tuple[np.ndarray, np.ndarray, np.ndarray], ellipsoids: Sequence[Ellipsoid],
                     strict: bool, comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`project_with_segment` of the trial points x* = reference + d[rows] + dt v[rows] + dt^2 a[rows] by the
    compiled loop (fabricfem.contact.compiled.project; `segments`: its stacked centres, rotations and radii), with
    `_push_out_of_creases` for the points still inside after the passes; `comm`: the ranks that build the loops on
    first use (compiled.module). Returns (trial points (M, 3), projected points (M, 3), segment (M,), moved (M,)
    bool)."""
    lib, ffi = compiled.module(comm)
    p = functools.partial(compiled.pointer, ffi)
    M = len(reference)
    trial, position = np.empty((M, 3)), np.empty((M, 3))
    segment, trapped = np.empty(M, dtype=np.int64), np.empty(M, dtype=np.int64)
    moved = np.empty(M, dtype=bool)
    n_trapped = lib.project(M, p(reference, "double"), p(rows, "int64_t"), p(d, "double"), p(v, "double"),
                            p(a, "double"), dt, len(segments[0]), *(p(array, "double") for array in segments),
                            INSIDE_TOLERANCE, MAX_PROJECTION_PASSES, p(trial, "double"), p(position, "double"),
                            p(segment, "int64_t"), p(moved.view(np.uint8), "uint8_t"), p(trapped, "int64_t"))
    if n_trapped:
        stack = SegmentStack(ellipsoids)
        stuck = trapped[:n_trapped].copy()
        _push_out_of_creases(position, moved, segment, stuck, stack.normalised_radii(position[stuck]) < 1.0, stack,
                             strict)
    return trial, position, segment, moved


@dataclass
class ExplicitContact:
    """Correction of one explicit step ([Man2006, Box 5], step i).

    Attributes:
        position: (N, 3) corrected positions proj(x*) [m].
        correction: (N, 3) d^c [m].
        acceleration: (N, 3) a^c [m/s^2].
        force: (N, 3) contact force on the nodes f_c = M a^c [N].
        multiplier: (N, 3) lambda = -M a^c [N] (thesis sign).
        active: (N,) nodes that were projected.
    """

    position: np.ndarray
    correction: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray
    multiplier: np.ndarray
    active: np.ndarray


def forward_increment_correction(x_trial, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> ExplicitContact:
    """[Man2006, Box 5] step i: project penetrating trial positions and return the multipliers."""
    dt = positive_parameter("dt", dt)
    x_trial = as_points("x_trial", x_trial)
    m = as_masses(masses, len(x_trial))
    projected, active = project_along_gradient(x_trial, ellipsoids)
    d_c = projected - x_trial
    a_c = d_c / dt ** 2
    force = m * a_c
    return ExplicitContact(projected, d_c, a_c, force, -force, active)


def box5_step(x, v, a, masses, dt: float, acceleration: Callable[[np.ndarray, float], np.ndarray],
              t: float, ellipsoids_at: Callable[[float], Sequence[Ellipsoid]]):
    """One step n -> n+1 of [Man2006, Box 5] for point masses (positions x = X + d).

    Args:
        x, v, a: (N, 3) state at t^n; x must be admissible.
        masses: lumped masses [kg], (N,) or (N, 3).
        dt: time step [s].
        acceleration: a*(x, t) = M^-1 (f_ext(t) - f_int(x)) [m/s^2] without contact.
        t: time t^n [s].
        ellipsoids_at: body segments posed at a given time.

    Returns:
        (x^{n+1}, v^{n+1}, a^{n+1}, ExplicitContact of the step).
    """
    dt = positive_parameter("dt", dt)
    x, v, a = as_points("x", x), as_points("v", v), as_points("a", a)
    v_star = v + 0.5 * dt * a                               # [Man2006, Box 5] f
    x_next = x + dt * v + 0.5 * dt ** 2 * a                 # [Man2006, Box 5] f
    a_star = np.asarray(acceleration(x_next, t + dt), dtype=float)   # [Man2006, Box 5] g
    v_star = v_star + 0.5 * dt * a_star                     # [Man2006, Box 5] h
    x_trial = x_next + dt * v_star + 0.5 * dt ** 2 * a_star  # [Man2006, Box 5] i: trial for n+2
    contact = forward_increment_correction(x_trial, masses, dt, ellipsoids_at(t + 2.0 * dt))
    a_next = a_star + contact.acceleration                  # [Man2006, Box 5] j
    v_next = v_star + 0.5 * dt * contact.acceleration
    return x_next, v_next, a_next, contact


def initial_state(x, v, a_free, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """(v^0, a^0) of [Man2006, Box 5] step 1 for nodes that may start in contact: the first predictor
    x + dt v + dt^2/2 a is corrected as in step j (a^0 = a* + a^c, v^0 = v + dt/2 a^c), so that it lands
    on the surface instead of inside."""
    a_free = as_points("a_free", a_free)
    v = as_points("v", v)
    trial = as_points("x", x) + dt * v + 0.5 * dt ** 2 * a_free
    a_c = forward_increment_correction(trial, masses, dt, ellipsoids).acceleration
    return v + 0.5 * dt * a_c, a_free + a_c


# ------------------------------------------------------------------------------------------------------------
# Explicit contact of a shell (CentralDifference) with moving rigid ellipsoids
# ------------------------------------------------------------------------------------------------------------
