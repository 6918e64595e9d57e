"""The body's segments joined by a smooth blend: a skin without creases at the joints (the wearer's surface contract,
fabricfem.body.skin).

Where two ellipsoidal segments overlap (the elbow, the knees, the hips) their union has a sharp concave crease, into
which the fabric is pinched ever deeper as the mesh is refined. The blended body replaces the union by the zero set
of a smooth minimum of the segments' exact signed distances d_k(x) [m] (negative inside; the closest point on
an ellipsoid by Newton's method on the Lagrange multiplier, [Eberly2013], `Ellipsoid.closest_point`), whose
gradients are the unit outward normals at the closest points. Two segments a, b are joined with the quadratic
polynomial smooth minimum of width w_ab [m] ([Quilez2013]):

    smin(a, b) = min(a, b) - w h^2 / 4,   h = max(w - |a - b|, 0) / w,
    grad smin = (1 - h / 2) grad(min) + h / 2 grad(max)

and the skin is the zero set of phi = min(min_k d_k, min over the pairs with |d_a - d_b| < w_ab of smin_ab),
grad phi = sum_k W_k grad d_k with the weights W >= 0 (summing to 1) of the smallest term: the segment weights of the
contract. Segments that meet at a joint with their tips (they share a joint name and it lies in the outer part of
both: upper arm and forearm, thigh and shank; `pair_widths`) blend over the body's width w; segments that do not
(the two thighs, a hand and a thigh, the trunk and the pelvis at the trunk's centre) over SEPARATE_FRACTION w
only, so that a gap between them stays open down to SEPARATE_FRACTION w / 2 instead of being bridged by a web, while a node between two such segments that touch still has a skin with a normal to go to.
smin is C1 and equals min(a, b) wherever |a - b| >= w_ab: the skin is each segment's own ellipsoid away from the
joints, and in a crease the blend fills the corner, turning the normal over a band of width ~ w instead of at a
line (phi is C1 where one pair decides; where two pairs' blends meet, between two legs at the crotch, it keeps the
crease the two legs make). The quadratic blend turns the normal more evenly than the cubic one of the same rounding
(docs/findings/2026-11-27-blended-skin.md). Rounding bound: smin_ab >= min(d_a, d_b) - w_ab / 4, so where phi = 0
the skin lies outside the segments' union by at most w / 4 (measured in the verify case `skin-continuity`).

The gap of a point is its distance to the zero set, found by the orthogonal projection iteration ([Hartmann1999]):
Newton steps onto phi = 0 along grad phi alternated with the projection of x onto the tangent plane at the foot,
until x - p is parallel to grad phi(p) (`closest_points`). Units: metres throughout.

`blend` evaluates phi, grad phi and the weights; `closest_points` the contract's SkinQuery; `BlendedEllipsoids` is
the Skin of a Body (posed at any t), and its `widths` are the ones the explicit contact uses. The same arithmetic
is compiled for the explicit contact in fabricfem.body.blend_kernel (BLEND_SOURCE, part of
fabricfem.contact.compiled's loops).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from skimage.measure import marching_cubes

from fabricfem.body.blend_kernel import closest_points as compiled_closest_points
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.skin import SkinQuery

BLEND_WIDTH = 0.05            # m: the default width w of the smooth minimum (rounding <= w / 4 = 12.5 mm)
SEPARATE_FRACTION = 0.2       # the width of the blend of two segments that do not meet at their tips, over w
JOINT_TIP_Q = 0.5             # q of a shared joint in both segments from which they meet at their tips (pair_widths)
MIN_GRADIENT = 0.5            # |grad phi| below this (a web between two facing segments) is not divided by
CLOSEST_ITERATIONS = 200      # orthogonal projection iterations of `closest_points`
FULL_STEPS = 10               # undamped tangential steps before the iteration halves them (concave blends)
CLOSEST_TOLERANCE = 1e-9      # m: |phi| and the tangential residual at convergence
GRID_CHUNK = 1 << 20          # grid points per evaluation of the implicit function (`triangulate`)


def check_width(width: float) -> float:
    """The blend width [m] as a float; ValueError naming `blend_width` unless finite and > 0."""
    if not (isinstance(width, (int, float)) and math.isfinite(width) and width > 0.0):
        raise ValueError(f"blend_width must be a positive length [m], got {width!r}")
    return float(width)


def stacked(ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (K, 3), rotations (K, 3, 3), radii (K, 3)) [m] of the posed segments."""
    return (np.array([e.center for e in ellipsoids], dtype=float),
            np.array([e.rotation for e in ellipsoids], dtype=float),
            np.array([e.radii for e in ellipsoids], dtype=float))


def segment_distances(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """d_k(x) (K, N) [m], the exact signed distances of the points x (N, 3) to the segments
    (`Ellipsoid.closest_point`, [Eberly2013]), and their gradients grad d_k (K, N, 3): the unit outward normal at
    the closest point."""
    d = np.empty((len(centers), len(x)))
    grad = np.empty((len(centers), len(x), 3))
    for k, (c, R, r) in enumerate(zip(centers, rotations, radii)):   # the few segments, vectorised over points
        _, d[k], grad[k] = Ellipsoid(c, R, r).closest_point(x)
    return d, grad


def pair_widths(segments, width: float, positions: dict | None = None) -> np.ndarray:
    """(K, K) blend widths w_ab [m] of the segments (fabricfem.body.pose.Segment, in order): `width` for two
    segments that meet at a shared joint, SEPARATE_FRACTION `width` for the others, 0 on the diagonal. With the
    joint and marker `positions` of a pose ({name: (3,) [m]}), two segments sharing a joint meet there only when
    the joint lies in the outer part of both ellipsoids (q >= JOINT_TIP_Q, q = f + 1 [Man2006, eq. 3.61]: the
    elbow and the knees, where the tips overlap); a joint deep inside one of them (the waist at the trunk's centre,
    the ankle inside the foot) has no crease to fill, and a full blend there would only thicken the body (by up to
    w / 4 where the two surfaces run side by side)."""
    joints = [{s.proximal, s.distal} for s in segments]
    posed = [s.pose(positions) for s in segments] if positions is not None else None
    K = len(joints)
    out = np.full((K, K), SEPARATE_FRACTION * check_width(width))
    for a in range(K):
        for b in range(K):
            shared = joints[a] & joints[b]
            if shared and (posed is None or _meet_at_tips(posed[a], posed[b], positions[next(iter(shared))])):
                out[a, b] = width
    np.fill_diagonal(out, 0.0)
    return out


def _meet_at_tips(a: Ellipsoid, b: Ellipsoid, joint: np.ndarray) -> bool:
    """True when the joint [m] lies in the outer part of both ellipsoids (q >= JOINT_TIP_Q, or outside)."""
    point = np.asarray(joint, dtype=float).reshape(1, 3)
    return all(float(np.sum((e.to_local(point) / e.radii) ** 2)) >= JOINT_TIP_Q for e in (a, b))


def blend(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray, widths: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """phi (N,) [m], grad phi (N, 3) and the segment weights W (N, K) of the blended body at the points x (N, 3):
    the smallest of the segments' distances and of the smooth minima of the pairs within their widths `widths`
    (K, K) [m] (`pair_widths`; module docstring, [Quilez2013])."""
    d, grad_d = segment_distances(np.asarray(x, dtype=float).reshape(-1, 3), centers, rotations, radii)
    K, N = d.shape
    columns = np.arange(N)
    nearest = d.argmin(axis=0)
    phi = d[nearest, columns]
    weights = np.zeros((N, K))
    weights[columns, nearest] = 1.0
    for a in range(K):             # a loop over the few pairs of segments, vectorised over the points
        for b in range(a + 1, K):
            w = widths[a, b]
            near = np.flatnonzero(np.abs(d[a] - d[b]) < w) if w > 0.0 else np.zeros(0, dtype=np.int64)
            if len(near) == 0:
                continue
            h = (w - np.abs(d[a, near] - d[b, near])) / w
            value = np.minimum(d[a, near], d[b, near]) - w * h * h / 4.0
            lower = value < phi[near]
            rows, h = near[lower], h[lower]
            phi[rows] = value[lower]
            share_a = np.where(d[a, rows] <= d[b, rows], 1.0 - 0.5 * h, 0.5 * h)
            weights[rows] = 0.0
            weights[rows, a], weights[rows, b] = share_a, 1.0 - share_a
    grad = np.einsum("nk,kni->ni", weights, grad_d)
    return phi, grad, weights


def closest_points(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray, widths: np.ndarray,
                   strict: bool = True) -> SkinQuery:
    """The contract's SkinQuery of the points x (N, 3) against the blended body: the foot p on phi = 0 with
    x - p parallel to grad phi(p) ([Hartmann1999] orthogonal projection), gap = sign(phi(x)) |x - p| [m], the unit
    normal grad phi(p) / |grad phi(p)| and the weights at p. The iteration converges for points nearer to the skin
    than its radius of curvature on the concave side of a blend; where it does not, RuntimeError (`strict`) or the
    foot of the last iterate (not strict: the gap then bounds the distance from above)."""
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    phi_x, _, _ = blend(x, centers, rotations, radii, widths)
    p = x.copy()
    active = np.ones(len(x), dtype=bool)
    for iteration in range(CLOSEST_ITERATIONS):
        if not active.any():
            break
        step = 1.0 if iteration < FULL_STEPS else 0.5
        pa = _onto_surface(p[active], centers, rotations, radii, widths)
        _, g, _ = blend(pa, centers, rotations, radii, widths)
        n = g / np.linalg.norm(g, axis=1)[:, None]
        r = x[active] - pa
        tangential = r - (r * n).sum(axis=1)[:, None] * n
        p[active] = pa + step * tangential
        done = np.linalg.norm(tangential, axis=1) <= CLOSEST_TOLERANCE
        rows = np.flatnonzero(active)
        p[rows[done]] = pa[done]
        active[rows[done]] = False
    if active.any():
        if strict:
            raise RuntimeError(f"blended skin: the closest point of {int(active.sum())} points did not converge "
                               f"(farther from the skin than its curvature radius?)")
        p[active] = _onto_surface(p[active], centers, rotations, radii, widths)
    phi, g, w = blend(p, centers, rotations, radii, widths)
    n = g / np.linalg.norm(g, axis=1)[:, None]
    gap = np.linalg.norm(x - p, axis=1) * np.where(phi_x < 0.0, -1.0, 1.0)
    return SkinQuery(gap, p, n, w)


def _onto_surface(p: np.ndarray, centers, rotations, radii, widths: np.ndarray) -> np.ndarray:
    """Newton steps p <- p - phi grad phi / |grad phi|^2 until |phi| <= CLOSEST_TOLERANCE."""
    for _ in range(CLOSEST_ITERATIONS):
        phi, g, _ = blend(p, centers, rotations, radii, widths)
        if np.all(np.abs(phi) <= CLOSEST_TOLERANCE):
            return p
        p = p - (phi / np.maximum((g * g).sum(axis=1), MIN_GRADIENT ** 2))[:, None] * g
    return p


class BlendedEllipsoids:
    """The Skin (fabricfem.body.skin) of a `Body`: its segments' ellipsoids posed at t, joined by the smooth
    minimum of width `width` [m] at the joints (module docstring, `pair_widths`). `segment_names`: the body's
    segments in order. `strict`: a point whose closest point does not converge (deep inside a concave blend) raises
    RuntimeError in `query`; not strict, it gets the foot of the last iterate (`closest_points`), as the explicit
    contact's projection does: the Newton iterates of the implicit contact may pass there."""

    def __init__(self, body, width: float = BLEND_WIDTH, strict: bool = True):
        self.body = body
        self.width = check_width(width)
        self.strict = bool(strict)
        t0 = body.kinematics.time_range[0]
        self.widths = pair_widths(list(body.segments.values()), self.width, body.kinematics.positions(t0))
        self.segment_names = tuple(body.segments)

    @property
    def rounding_bound(self) -> float:
        """Largest distance [m] (d metric) of the blended skin outside the segments' union: w / 4."""
        return self.width / 4.0

    def posed(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The stacked posed segments at time t [s] (`stacked`)."""
        posed = self.body.pose(t)
        return stacked([posed[name] for name in self.segment_names])

    def implicit(self, x: np.ndarray, t: float) -> np.ndarray:
        """phi (N,) [m] at the points x (N, 3) at time t [s]: < 0 inside the body."""
        return blend(x, *self.posed(t), self.widths)[0]

    def query(self, x: np.ndarray, t: float) -> SkinQuery:
        """The contract's SkinQuery of the points x (N, 3) [m] at time t [s] (`closest_points`, compiled:
        fabricfem.body.blend_kernel)."""
        return compiled_closest_points(x, *self.posed(t), self.widths, strict=self.strict)

    def surface(self, t: float, spacing: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
        """Marching-cubes triangulation (scikit-image) of phi = 0 at time t [s] on a grid of `spacing` [m]:
        vertices (V, 3) [m], triangles (F, 3), outward oriented."""
        return triangulate(lambda points: self.implicit(points, t), self.bounds(t), spacing)

    def bounds(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Corners [m] of a box holding the posed body and its blend: the box of the posed segments' ellipsoids
        (each one's: centre -+ sqrt(sum_j R_ij^2 r_j^2) along axis i) grown by the blend's rounding bound w / 4."""
        centers, rotations, radii = self.posed(t)
        half = np.sqrt(np.einsum("kij,kj->ki", rotations ** 2, radii ** 2))
        grow = self.rounding_bound
        return (centers - half).min(axis=0) - grow, (centers + half).max(axis=0) + grow


def triangulate(implicit, bounds: tuple[np.ndarray, np.ndarray], spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangulation of {implicit(x) = 0} inside `bounds` (lower, upper corners [m]) by marching cubes
    (skimage.measure.marching_cubes) on a grid of `spacing` [m], outward oriented (the normals along grad phi);
    `implicit` is evaluated on GRID_CHUNK points at a time (its temporaries stay bounded)."""
    lower, upper = (np.asarray(b, dtype=float) for b in bounds)
    lower, upper = lower - 2.0 * spacing, upper + 2.0 * spacing
    axes = [np.arange(lo, hi + spacing, spacing) for lo, hi in zip(lower, upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = np.concatenate([np.asarray(implicit(grid[k:k + GRID_CHUNK]), dtype=float).reshape(-1)
                             for k in range(0, len(grid), GRID_CHUNK)]).reshape(tuple(len(a) for a in axes))
    vertices, faces, _, _ = marching_cubes(values, level=0.0, spacing=(spacing,) * 3, gradient_direction="descent")
    return vertices + lower, faces.astype(np.int64)
