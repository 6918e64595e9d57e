"""The blended skin (fabricfem.body.blended) in C, for the explicit contact's compiled step
(fabricfem.contact.compiled):
the same formulas node by node.

* `ellipsoid_distance`: the exact signed distance and outward normal of a point to one ellipsoid (the monotone
  Newton iteration on the Lagrange multiplier of `fabricfem.body.ellipsoid._closest_sorted`, [Eberly2013]). A point
  on a symmetry plane of the sorted axes (y_min = 0 exactly) is moved off it by 1e-15 of the smallest radius, so
  that the general root applies (the numpy code splits cases instead; the difference is of that size).
* `blend_eval`: phi, grad phi and the segment weights: the smallest of the segments' distances and of the pairs'
  quadratic smooth minima within their widths ([Quilez2013], `fabricfem.body.blended.blend`). A segment whose
  distance is certainly at least the widest blend above the nearest one's (the lower bound (sqrt(q) - 1) r_min of
  its distance, q = f + 1 [Man2006, eq. 3.61]) is left out: it cannot enter phi there.
* `blend_lower_bound`: a lower bound of phi from the segments' lower bounds (the same expression of them, phi
  being non-decreasing in each distance): a point it puts outside needs no exact distance at all.
* `blend_closest`: the foot of a point on phi = 0 by the orthogonal projection iteration ([Hartmann1999],
  `fabricfem.body.blended.closest_points`), with the gap, the normal and the weights at the foot.
* `blend_query`: `blend_closest` over N points (the tests compare it with the numpy functions); from Python,
  `closest_points` (the contract's SkinQuery, as fabricfem.body.blended.closest_points computes it in numpy).
* `blend_values`: phi over N points; from Python, `implicit_values` (whose sign is the gap's: the points that
  can penetrate, found without a closest-point iteration).
* `blend_levels`: points moved onto given level sets of phi by the Newton steps of `blend_onto`; from Python,
  `onto_levels` (the implicit skinning of a mesh skin, fabricfem.body.implicit_skinning); `blend_weights`: the
  segment weights at points (`segment_weights`, the contract's weights of an implicitly skinned mesh).
"""
from __future__ import annotations

import functools

import numpy as np
from mpi4py import MPI

from fabricfem.body.skin import SkinQuery
from fabricfem.forms.jit import ROUNDING_FLAGS, built_once, pointer

BLEND_CDEF = """
void blend_query(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                 const double* widths, double* gap, double* foot, double* normal, double* weights,
                 uint8_t* converged);
"""

BLEND_SOURCE = r"""
#define BLEND_ITERATIONS 200
#define BLEND_FULL_STEPS 10
#define BLEND_TOLERANCE 1e-9
#define BLEND_MAX_SEGMENTS 64
#define BLEND_MIN_GRADIENT 0.5

/* exact signed distance of x to the ellipsoid (c, R, r) and the unit outward normal n at the closest point */
static double ellipsoid_distance(const double* x, const double* c, const double* R, const double* r, double* n)
{
  double y[3];
  const double p0 = x[0] - c[0], p1 = x[1] - c[1], p2 = x[2] - c[2];
  for (int j = 0; j < 3; ++j)
    y[j] = (p0 * R[j] + p1 * R[3 + j]) + p2 * R[6 + j];
  int o[3] = {0, 1, 2};                      /* axes by decreasing radius (stable) */
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2 - i; ++j)
      if (r[o[j]] < r[o[j + 1]])
      {
        const int t = o[j];
        o[j] = o[j + 1];
        o[j + 1] = t;
      }
  double rs[3], ys[3], a[3], ry[3];
  for (int i = 0; i < 3; ++i)
  {
    rs[i] = r[o[i]];
    ys[i] = fabs(y[o[i]]);
  }
  if (ys[2] == 0.0)
    ys[2] = 1e-15 * rs[2];
  for (int i = 0; i < 3; ++i)
  {
    a[i] = rs[i] * rs[i] - rs[2] * rs[2];
    ry[i] = rs[i] * ys[i];
  }
  double s = -INFINITY, tied = 0.0, upper = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    s = fmax(s, ry[i] - a[i]);
    if (a[i] == 0.0)
      tied += ry[i] * ry[i];
    upper += ry[i] * ry[i];
  }
  s = fmax(s, sqrt(tied));
  upper = sqrt(upper);
  for (int it = 0; it < 100; ++it)
  {
    double g = -1.0, dg = 0.0;
    for (int i = 0; i < 3; ++i)
    {
      const double ratio = ry[i] / (a[i] + s);
      g += ratio * ratio;
      dg -= 2.0 * ratio * ratio / (a[i] + s);
    }
    const double next = fmin(fmax(s - g / dg, s), upper);
    const int done = fabs(next - s) <= 4.0 * 2.220446049250313e-16 * next;
    s = next;
    if (done)
      break;
  }
  double z[3], zl[3], d2 = 0.0, q = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    const double zi = rs[i] * rs[i] * ys[i] / (a[i] + s);
    z[o[i]] = y[o[i]] < 0.0 ? -zi : zi;
  }
  for (int i = 0; i < 3; ++i)
  {
    d2 += (y[i] - z[i]) * (y[i] - z[i]);
    q += (y[i] / r[i]) * (y[i] / r[i]);
    zl[i] = z[i] / (r[i] * r[i]);
  }
  const double l = sqrt(zl[0] * zl[0] + zl[1] * zl[1] + zl[2] * zl[2]);
  for (int i = 0; i < 3; ++i)
    n[i] = ((R[3 * i] * zl[0] + R[3 * i + 1] * zl[1]) + R[3 * i + 2] * zl[2]) / l;
  return q >= 1.0 ? sqrt(d2) : -sqrt(d2);
}

/* phi, grad phi and the weights W (K) of the blended body at x (fabricfem.body.blended.blend; widths: (K, K)) */
static double blend_eval(const double* x, int K, const double* center, const double* rotation, const double* radii,
                         const double* widths, double* grad, double* W)
{
  double bound[BLEND_MAX_SEGMENTS], d[BLEND_MAX_SEGMENTS], n[BLEND_MAX_SEGMENTS][3];
  double widest = 0.0, lowest = INFINITY;
  d[0] = INFINITY;
  for (int k = 0; k < K * K; ++k)
    widest = fmax(widest, widths[k]);
  for (int k = 0; k < K; ++k)
  {
    const double* c = center + 3 * k;
    const double* R = rotation + 9 * k;
    const double* r = radii + 3 * k;
    double y[3];
    const double p0 = x[0] - c[0], p1 = x[1] - c[1], p2 = x[2] - c[2];
    for (int j = 0; j < 3; ++j)
      y[j] = (p0 * R[j] + p1 * R[3 + j]) + p2 * R[6 + j];
    const double q = (y[0] / r[0]) * (y[0] / r[0]) + (y[1] / r[1]) * (y[1] / r[1]) + (y[2] / r[2]) * (y[2] / r[2]);
    bound[k] = (sqrt(q) - 1.0) * fmin(fmin(r[0], r[1]), r[2]);   /* <= the distance: sqrt(q) is 1/r_min-Lipschitz */
    lowest = fmin(lowest, bound[k]);
    W[k] = 0.0;
  }
  /* the exact distances of the segments that can matter: a segment whose distance is at least the nearest one's
     + the widest blend cannot enter phi (each term is >= min(d_a, d_b) - w / 4 and equals min where
     |d_a - d_b| >= w) */
  double smallest = INFINITY;
  for (int k = 0; k < K; ++k)
    if (bound[k] == lowest)
    {
      d[k] = ellipsoid_distance(x, center + 3 * k, rotation + 9 * k, radii + 3 * k, n[k]);
      smallest = fmin(smallest, d[k]);
    }
  for (int k = 0; k < K; ++k)
    if (bound[k] != lowest)
    {
      if (bound[k] >= smallest + widest)
        d[k] = INFINITY;
      else
      {
        d[k] = ellipsoid_distance(x, center + 3 * k, rotation + 9 * k, radii + 3 * k, n[k]);
        smallest = fmin(smallest, d[k]);
      }
    }
  int nearest = 0;
  for (int k = 1; k < K; ++k)
    if (d[k] < d[nearest])
      nearest = k;
  double phi = d[nearest];
  W[nearest] = 1.0;
  int best_a = -1, best_b = -1;
  double best_share = 1.0;
  for (int a = 0; a < K; ++a)
    for (int b = a + 1; b < K; ++b)
    {
      const double w = widths[a * K + b];
      if (!(w > 0.0) || d[a] == INFINITY || d[b] == INFINITY || !(fabs(d[a] - d[b]) < w))
        continue;
      const double h = (w - fabs(d[a] - d[b])) / w;
      const double value = fmin(d[a], d[b]) - w * h * h / 4.0;
      if (value < phi)
      {
        phi = value;
        best_a = a, best_b = b;
        best_share = d[a] <= d[b] ? 1.0 - 0.5 * h : 0.5 * h;
      }
    }
  if (best_a >= 0)
  {
    W[nearest] = 0.0;
    W[best_a] = best_share;
    W[best_b] = 1.0 - best_share;
  }
  grad[0] = grad[1] = grad[2] = 0.0;
  for (int k = 0; k < K; ++k)
    if (W[k] > 0.0)
      for (int i = 0; i < 3; ++i)
        grad[i] += W[k] * n[k][i];
  return phi;
}

/* a lower bound of phi from the segments' lower bounds b_k <= d_k (valid outside every segment, all b_k > 0;
   -INFINITY otherwise): phi is the smallest of the d_k and of the pairs' smooth minima, each non-decreasing in
   its arguments, so phi >= the same expression of the b_k */
static double blend_lower_bound(int K, const double* bound, const double* widths)
{
  double lower = INFINITY;
  for (int k = 0; k < K; ++k)
  {
    if (!(bound[k] > 0.0))
      return -INFINITY;
    lower = fmin(lower, bound[k]);
  }
  for (int a = 0; a < K; ++a)
    for (int b = a + 1; b < K; ++b)
    {
      const double w = widths[a * K + b];
      if (w > 0.0 && fabs(bound[a] - bound[b]) < w)
      {
        const double h = (w - fabs(bound[a] - bound[b])) / w;
        lower = fmin(lower, fmin(bound[a], bound[b]) - w * h * h / 4.0);
      }
    }
  return lower;
}

/* Newton steps onto phi = level; returns phi - level at the end and grad phi, W there */
static double blend_onto_level(double* p, double level, int K, const double* center, const double* rotation,
                               const double* radii, const double* widths, double* grad, double* W)
{
  double phi = blend_eval(p, K, center, rotation, radii, widths, grad, W) - level;
  for (int it = 0; it < BLEND_ITERATIONS && fabs(phi) > BLEND_TOLERANCE; ++it)
  {
    const double g2 = fmax(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2],
                           BLEND_MIN_GRADIENT * BLEND_MIN_GRADIENT);
    for (int i = 0; i < 3; ++i)
      p[i] -= phi / g2 * grad[i];
    phi = blend_eval(p, K, center, rotation, radii, widths, grad, W) - level;
  }
  return phi;
}

/* Newton steps onto phi = 0 */
static double blend_onto(double* p, int K, const double* center, const double* rotation, const double* radii,
                         const double* widths, double* grad, double* W)
{
  return blend_onto_level(p, 0.0, K, center, rotation, radii, widths, grad, W);
}

/* the foot p of x on phi = 0, the unit normal and the weights there; returns 1 if converged */
static int blend_closest(const double* x, int K, const double* center, const double* rotation, const double* radii,
                         const double* widths, double* p, double* normal, double* W)
{
  double grad[3];
  p[0] = x[0], p[1] = x[1], p[2] = x[2];
  int converged = 0;
  for (int it = 0; it < BLEND_ITERATIONS; ++it)
  {
    blend_onto(p, K, center, rotation, radii, widths, grad, W);
    const double l = sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]);
    const double nn[3] = {grad[0] / l, grad[1] / l, grad[2] / l};
    const double r[3] = {x[0] - p[0], x[1] - p[1], x[2] - p[2]};
    const double along = r[0] * nn[0] + r[1] * nn[1] + r[2] * nn[2];
    const double t[3] = {r[0] - along * nn[0], r[1] - along * nn[1], r[2] - along * nn[2]};
    if (sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]) <= BLEND_TOLERANCE)
    {
      converged = 1;
      break;
    }
    const double step = it < BLEND_FULL_STEPS ? 1.0 : 0.5;
    for (int i = 0; i < 3; ++i)
      p[i] += step * t[i];
  }
  if (!converged)
    blend_onto(p, K, center, rotation, radii, widths, grad, W);
  else
    blend_eval(p, K, center, rotation, radii, widths, grad, W);
  const double l = sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]);
  for (int i = 0; i < 3; ++i)
    normal[i] = grad[i] / l;
  return converged;
}

void blend_query(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                 const double* widths, double* gap, double* foot, double* normal, double* weights,
                 uint8_t* converged)
{
  double grad[3];
  for (int p = 0; p < N; ++p)
  {
    const double phi = blend_eval(x + 3 * p, K, center, rotation, radii, widths, grad, weights + (size_t)K * p);
    converged[p] = blend_closest(x + 3 * p, K, center, rotation, radii, widths, foot + 3 * p, normal + 3 * p,
                                 weights + (size_t)K * p);
    double d2 = 0.0;
    for (int i = 0; i < 3; ++i)
      d2 += (x[3 * p + i] - foot[3 * p + i]) * (x[3 * p + i] - foot[3 * p + i]);
    gap[p] = phi < 0.0 ? -sqrt(d2) : sqrt(d2);
  }
}
"""

# phi alone (`implicit_values`)
VALUES_CDEF = """
void blend_values(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                  const double* widths, double* phi);
int blend_levels(int N, double* x, const double* levels, int K, const double* center, const double* rotation,
                 const double* radii, const double* widths, double* normal);
void blend_weights(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                   const double* widths, double* weights);
"""

VALUES_SOURCE = r"""
void blend_values(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                  const double* widths, double* phi)
{
  double grad[3], W[BLEND_MAX_SEGMENTS];
  for (int p = 0; p < N; ++p)
    phi[p] = blend_eval(x + 3 * p, K, center, rotation, radii, widths, grad, W);
}

/* the segment weights W (N, K) of the blended body at the points x (N, 3) */
void blend_weights(int N, const double* x, int K, const double* center, const double* rotation, const double* radii,
                   const double* widths, double* weights)
{
  double grad[3];
  for (int p = 0; p < N; ++p)
    blend_eval(x + 3 * p, K, center, rotation, radii, widths, grad, weights + (size_t)K * p);
}

/* every point x (N, 3) moved in place onto phi = levels[p] by Newton steps along grad phi, the unit grad phi there
   in normal (N, 3); returns the number that did not converge */
int blend_levels(int N, double* x, const double* levels, int K, const double* center, const double* rotation,
                 const double* radii, const double* widths, double* normal)
{
  double grad[3], W[BLEND_MAX_SEGMENTS];
  int failed = 0;
  for (int p = 0; p < N; ++p)
  {
    failed += fabs(blend_onto_level(x + 3 * p, levels[p], K, center, rotation, radii, widths, grad, W))
              > BLEND_TOLERANCE;
    const double l = sqrt(grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]);
    for (int i = 0; i < 3; ++i)
      normal[3 * p + i] = grad[i] / l;
  }
  return failed;
}
"""


def _library(values: bool = False):
    """The compiled blend loops, `blend_query` or (`values`) `blend_values` in a module of its own, so that the
    query's machine code stays the same (each built once per process on its own, MPI.COMM_SELF)."""
    name, cdef, extra = ("fabricfem_blend_values", VALUES_CDEF, VALUES_SOURCE) if values else \
        ("fabricfem_blend", BLEND_CDEF, "")
    return built_once(name, cdef, "#include <math.h>\n#include <stdint.h>\n" + BLEND_SOURCE + extra, MPI.COMM_SELF,
                      ROUNDING_FLAGS)


def _body_pointers(ffi, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray, widths: np.ndarray) -> tuple:
    """(K, the four arrays' double pointers) of the posed segments for the compiled calls (each pointer keeps its
    C-contiguous copy alive)."""
    return len(radii), tuple(pointer(ffi, np.ascontiguousarray(a, dtype=float), "double")
                             for a in (centers, rotations, radii, widths))


def implicit_values(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray,
                    widths: np.ndarray) -> np.ndarray:
    """phi (N,) [m] of the blended body at the points x (N, 3) [m] by `blend_values` (fabricfem.body.blended.blend's
    phi): negative inside the skin, with the sign of the gap."""
    lib, ffi = _library(values=True)
    x = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(-1, 3))
    phi = np.empty(len(x))
    k, body = _body_pointers(ffi, centers, rotations, radii, widths)
    lib.blend_values(len(x), pointer(ffi, x, "double"), k, *body, pointer(ffi, phi, "double"))
    return phi


def segment_weights(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray,
                    widths: np.ndarray) -> np.ndarray:
    """The segment weights W (N, K) of the blended body at the points x (N, 3) [m] (`blend_weights`, the weights of
    fabricfem.body.blended.blend)."""
    lib, ffi = _library(values=True)
    x = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(-1, 3))
    k, body = _body_pointers(ffi, centers, rotations, radii, widths)
    weights = np.empty((len(x), k))
    lib.blend_weights(len(x), pointer(ffi, x, "double"), k, *body, pointer(ffi, weights, "double"))
    return weights


def onto_levels(x: np.ndarray, levels: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray,
                widths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points x (N, 3) [m] moved onto the level sets phi = levels (N,) [m] of the blended body by Newton steps
    along grad phi (`blend_levels`, the `blend_onto` iteration, tolerance 1e-9 m), and the unit grad phi (N, 3)
    there: the implicit skinning's projection ([Vaillant2013], fabricfem.body.implicit_skinning). RuntimeError if a
    point does not converge."""
    lib, ffi = _library(values=True)
    out = np.array(np.asarray(x, dtype=float).reshape(-1, 3), order="C")
    normal = np.empty_like(out)
    levels = np.ascontiguousarray(levels, dtype=float)
    if levels.shape != (len(out),):
        raise ValueError(f"levels: expected shape ({len(out)},), got {levels.shape}")
    k, body = _body_pointers(ffi, centers, rotations, radii, widths)
    failed = lib.blend_levels(len(out), pointer(ffi, out, "double"), pointer(ffi, levels, "double"), k, *body,
                              pointer(ffi, normal, "double"))
    if failed:
        raise RuntimeError(f"implicit skinning: {failed} vertices did not reach their level set")
    return out, normal


def closest_points(x: np.ndarray, centers: np.ndarray, rotations: np.ndarray, radii: np.ndarray, widths: np.ndarray,
                   strict: bool = True) -> SkinQuery:
    """fabricfem.body.blended.closest_points of the points x (N, 3) [m] by `blend_query` (the same iteration, its
    tolerance 1e-9 m; built once per process on its own, MPI.COMM_SELF). A point whose iteration does not converge
    raises RuntimeError (`strict`) or keeps the foot of its last iterate."""
    lib, ffi = _library()
    x = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(-1, 3))
    n = len(x)
    k, body = _body_pointers(ffi, centers, rotations, radii, widths)
    gap, foot, normal, weights = np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, k))
    converged = np.empty(n, dtype=np.uint8)
    p = functools.partial(pointer, ffi)
    lib.blend_query(n, p(x, "double"), k, *body, p(gap, "double"), p(foot, "double"), p(normal, "double"),
                    p(weights, "double"), p(converged, "uint8_t"))
    if strict and not converged.all():
        raise RuntimeError(f"blended skin: the closest point of {int(n - converged.sum())} points did not converge "
                           f"(farther from the skin than its curvature radius?)")
    return SkinQuery(gap, foot, normal, weights)
