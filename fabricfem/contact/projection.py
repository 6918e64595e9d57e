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

from fabricfem.body.blend_kernel import closest_points as blend_closest_points
from fabricfem.body.blended import BLEND_WIDTH, blend, closest_points
from fabricfem.body.ellipsoid import Ellipsoid, _ray_to_surface
from fabricfem.contact import compiled
from fabricfem.contact.nodal import nearest_gap, positive_parameter
from fabricfem.forms.jit import pointer

MAX_PROJECTION_PASSES = 8
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
    """Move the points inside the body onto its skin: along grad f at the point ([Man2006, Box 5], the ray
    x + s grad f / |grad f| intersected with the surface) away from the joints, to the closest point of the blended
    skin in a crease (`project_onto_skin`). Returns (projected points (N, 3), moved mask (N,))."""
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


@dataclass
class SkinProjection:
    """Trial points projected onto the blended skin of posed segments (`project_onto_skin`): positions (N, 3) [m],
    moved (N,) bool, segment (N,) (the segment a point was projected out of; in a crease the one of largest
    weight; for points not moved the nearest by q, a diagnostic), crease (N,) bool (the points within the blend of
    two segments, projected onto the blended skin), and for the crease points the skin's unit normal (N, 3) at the
    foot and the segment weights (N, K) (fabricfem.body.skin)."""

    position: np.ndarray
    moved: np.ndarray
    segment: np.ndarray
    crease: np.ndarray
    normal: np.ndarray
    weights: np.ndarray


def resolve_widths(widths: np.ndarray | None, count: int) -> np.ndarray:
    """The (K, K) blend widths [m] of `count` segments: `widths`, or BLEND_WIDTH between every two of them (segments
    whose joints are not known: fabricfem.body.blended.pair_widths knows them from a body)."""
    if widths is not None:
        out = np.asarray(widths, dtype=float)
        if out.shape != (count, count):
            raise ValueError(f"widths: expected a ({count}, {count}) matrix of blend widths, got shape {out.shape}")
        return out
    out = np.full((count, count), BLEND_WIDTH)
    np.fill_diagonal(out, 0.0)
    return out


def crease_points(q: np.ndarray, scale: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """(N,) mask of the points whose distances to two segments a, b may both be below their blend width w_ab [m]
    (`widths` (K, K), fabricfem.body.blended.pair_widths): the lower bound (sqrt(q) - 1) r_min of the distance
    (sqrt(q) is 1 / r_min-Lipschitz) below w_ab for both; q (K, N)."""
    bound = (np.sqrt(q) - 1.0) * scale[:, None]
    out = np.zeros(q.shape[1], dtype=bool)
    for a in range(len(q)):          # the few pairs of segments, vectorised over the points
        for b in range(a + 1, len(q)):
            out |= (bound[a] < widths[a, b]) & (bound[b] < widths[a, b])
    return out


def project_onto_skin(x, ellipsoids: Sequence[Ellipsoid], widths: np.ndarray | None = None,
                      segments: SegmentStack | None = None) -> SkinProjection:
    """Move the points inside the blended skin of the segments (fabricfem.body.blended; blend widths `widths` (K, K)
    [m], `resolve_widths`) onto it.

    Away from the creases (a point near one segment only) the skin is that segment's ellipsoid and a point inside
    is projected along grad f at the point ([Man2006, Box 5]: a ray cast, `SegmentStack.ray_gap`; a point inside
    two segments is near both, so one pass suffices; the passes re-check up to MAX_PROJECTION_PASSES). A point
    within the blend of two segments (`crease_points`) inside the blended skin (phi < 0) is moved to its closest
    point on it ([Hartmann1999], `closest_points`), with the skin's normal and segment weights there.
    `segments`: the ellipsoids already stacked (`SegmentStack`), if the caller has them.
    """
    x = as_points("x", x)
    n = len(x)
    stack = SegmentStack(ellipsoids) if segments is None else segments
    K = len(ellipsoids)
    normal, weights = np.zeros((n, 3)), np.zeros((n, K))
    if n == 0 or not ellipsoids:
        return SkinProjection(x.copy(), np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int64),
                              np.zeros(n, dtype=bool), normal, weights)
    q = stack.normalised_radii(x)
    widths = resolve_widths(widths, K)
    crease = crease_points(q, stack.scale, widths)
    out, moved, segment = _project_single(x, stack, q, ~crease)
    index = np.flatnonzero(crease)
    if len(index):
        posed = (stack.center, stack.rotation, stack.radii)
        phi, _, weights[index] = blend(x[index], *posed, widths)
        inside = index[phi < 0.0]
        if len(inside):
            skin = closest_points(x[inside], *posed, widths, strict=False)
            out[inside], normal[inside], weights[inside] = skin.foot, skin.normal, skin.weights
            moved[inside] = True
        segment[index] = np.argmax(weights[index], axis=1)
    return SkinProjection(out, moved, segment, crease, normal, weights)


def skin_gap(x, ellipsoids: Sequence[Ellipsoid], widths: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed gap [m] of the points x (N, 3) to the blended skin of the segments (negative inside), the unit outward
    normal, the segment index (of largest weight in a crease) and the segment weights (N, K) (fabricfem.body.skin):
    the nearest segment's gap (`nodal.nearest_gap`) away from the creases, the blended skin's closest point within
    them (fabricfem.body.blend_kernel.closest_points, not strict)."""
    x = as_points("x", x)
    g, n, segment = nearest_gap(x, ellipsoids)
    weights = np.zeros((len(x), len(ellipsoids)))
    weights[np.arange(len(x)), segment] = 1.0
    if len(x) == 0 or len(ellipsoids) < 2:
        return g, n, segment, weights
    stack = SegmentStack(ellipsoids)
    widths = resolve_widths(widths, len(ellipsoids))
    crease = crease_points(stack.normalised_radii(x), stack.scale, widths)
    if crease.any():
        skin = blend_closest_points(x[crease], stack.center, stack.rotation, stack.radii, widths, strict=False)
        g[crease], n[crease], segment[crease], weights[crease] = skin.gap, skin.normal, skin.segment, skin.weights
    return g, n, segment, weights


def project_with_segment(x, ellipsoids: Sequence[Ellipsoid], segments: SegmentStack | None = None,
                         widths: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`project_onto_skin`'s (positions (N, 3), moved (N,), segment (N,))."""
    p = project_onto_skin(x, ellipsoids, widths, segments)
    return p.position, p.moved, p.segment


def _project_single(x: np.ndarray, stack: SegmentStack, q: np.ndarray, allowed: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ray-cast projection of `project_onto_skin` for the points `allowed` (near one segment only): positions,
    moved mask and segment index (N,). Vectorised: only the points with q < 1 for some segment get ray casts, and a
    later pass re-checks only the points the previous one moved."""
    out = x.copy()
    moved = np.zeros(len(x), dtype=bool)
    segment = q.argmin(axis=0)
    inside_q = (q < 1.0) & allowed[None, :]
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
        direction = stack.normal(local[pair[deepest[inside], columns[inside]]], deepest[inside])
        points[inside] = points[inside] - g[inside, None] * direction
        out[candidates] = points
        candidates = candidates[inside]
        segment[candidates] = deepest[inside]
        moved[candidates] = True
        inside_q = stack.normalised_radii(out[candidates]) < 1.0
        keep = inside_q.any(axis=0)
        candidates, inside_q = candidates[keep], inside_q[:, keep]
    if len(candidates):
        raise RuntimeError(f"contact: {len(candidates)} points near one segment only remain inside it after "
                           f"{MAX_PROJECTION_PASSES} projections")
    return out, moved, segment


def project_compiled(reference: np.ndarray, rows: np.ndarray, d: np.ndarray, v: np.ndarray, a: np.ndarray,
                     dt: float, segments: tuple[np.ndarray, np.ndarray, np.ndarray], widths: np.ndarray,
                     comm: MPI.Comm) -> tuple[np.ndarray, SkinProjection]:
    """`project_onto_skin` of the trial points x* = reference + d[rows] + dt v[rows] + dt^2 a[rows] by the
    compiled loop (fabricfem.contact.compiled.project; `segments`: its stacked centres, rotations and radii; the
    blend widths `widths` (K, K) [m], C-contiguous); `comm`: the ranks that build the loops on first use
    (compiled.module). Returns (trial points (M, 3), the SkinProjection of them)."""
    lib, ffi = compiled.module(comm)
    p = functools.partial(pointer, ffi)
    M, K = len(reference), len(segments[0])
    trial, position = np.empty((M, 3)), np.empty((M, 3))
    segment, trapped = np.empty(M, dtype=np.int64), np.empty(M, dtype=np.int64)
    moved, crease = np.empty(M, dtype=bool), np.empty(M, dtype=bool)
    normal, weights = np.zeros((M, 3)), np.zeros((M, K))
    n_trapped = lib.project(M, p(reference, "double"), p(rows, "int64_t"), p(d, "double"), p(v, "double"),
                            p(a, "double"), dt, K, *(p(array, "double") for array in segments),
                            INSIDE_TOLERANCE, MAX_PROJECTION_PASSES, p(widths, "double"), p(trial, "double"),
                            p(position, "double"), p(segment, "int64_t"), p(moved.view(np.uint8), "uint8_t"),
                            p(crease.view(np.uint8), "uint8_t"), p(normal, "double"), p(weights, "double"),
                            p(trapped, "int64_t"))
    if n_trapped:
        raise RuntimeError(f"contact: {n_trapped} points near one segment only remain inside it after "
                           f"{MAX_PROJECTION_PASSES} projections")
    return trial, SkinProjection(position, moved, segment, crease, normal, weights)


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
