"""The explicit Lagrange-multiplier contact step compiled: one C loop over the nodes instead of numpy calls.

`ExplicitBodyContact.correct` ([Man2006, Box 5] steps i-j with Coulomb friction, fabricfem.contact.explicit) spends
its time in the overhead of a hundred numpy calls on small arrays. These two C functions do the same arithmetic
node by node, in the same order as the numpy functions they replace (compiled without contraction of
multiply-adds, `-ffp-contract=off`, so that the products and sums round as numpy's do):

* `project`: the trial positions x* = X + d + dt v~ + dt^2 a, the normalised radius q = f + 1 of each segment
  [Man2006, eq. 3.61]; a point within the blend of two segments (the lower bound (sqrt(q) - 1) r_min of its
  distance below the blend width w for two of them, `projection.crease_points`) inside the blended skin goes to its
  closest point on it (fabricfem.body.blend_kernel, with the skin's normal and segment weights there; one
  that `blend_lower_bound` puts outside is left where it is without an exact distance); the
  others, near one segment only, take the passes of `project_onto_skin` (ray cast along grad f / |grad f|, the
  move onto the surface, [Man2006, Box 5] step i).
* `friction`: for the nodes in contact, |lambda_N| = |m (x^c - x*)| / dt^2, the stick point's pull
  d_T = P (s - x^c) limited by mu |lambda_N| (eq. 3.52, P with the skin's normal), the stick points kept in the
  frame of the segment (of largest weight in a crease), a^{n+1} += a^c = (x^c + d_T - x*) / dt^2 ([Man2006, Box 5]
  step j), and the torques of the registered monitors, a . sum_i s_i (x_i - J) x (-f_i) with s_i the node's
  weight on the monitor's segments (fabricfem.contact.torque.local_torques).
* `contact_step`: both in one call, as ExplicitBodyContact.correct takes them on the blended skin, with the work
  arrays kept from step to step (`StepBuffers`) and the clearing of the nodes out of contact (zero force, no slip,
  no stick point) over the last step's nodes in contact only.

`project` goes over the nodes in chunks of 64: the trial points and every segment's q and distance bound by loops
over the chunk's nodes that the compiler vectorises (the same expressions, so the same bits: the divisions and
square roots round exactly in a vector as in a scalar, and `-fno-math-errno` only drops errno), then node by node
only the nodes inside a segment take the ray casts and only those in a crease that `blend_lower_bound` does not put
outside the blended skin's closest point: on the sleeve (60x78, 18720 nodes) at most 954 and 13 of them a step
(docs/findings/2026-11-28-contact-step.md).

Away from the creases the only difference from the numpy path is q, which numpy computes by one matrix product
(rounded differently by BLAS); q only preselects the points that get ray casts, and the ray cast decides
(INSIDE_TOLERANCE), so the two paths move the same nodes by the same amounts; in the creases the two closest-point
iterations agree to their tolerance (tests/test_contact_compiled.py).
"""
from __future__ import annotations

import numpy as np

from fabricfem.body.blend_kernel import BLEND_CDEF, BLEND_SOURCE
from fabricfem.forms.jit import ROUNDING_FLAGS, built_once, pointer

MAX_SEGMENTS = 64          # the body segments a point is checked against (a stack array in `project`)
MAX_MONITORS = 64          # the torque monitors summed in `friction` (a stack array)
# no contracted multiply-adds (ROUNDING_FLAGS); no errno from sqrt, so that `chunk_radii` vectorises (sqrt rounds the
# same either way: the same bits)
FLAGS = (*ROUNDING_FLAGS[:-1], "-fno-math-errno", ROUNDING_FLAGS[-1])

CDEF = """
int project(int M, const double* reference, const int64_t* rows, const double* d, const double* v, const double* a,
            double dt, int K, const double* center, const double* rotation, const double* radii, double tolerance,
            int passes, const double* widths, double* trial, double* position, int64_t* segment, uint8_t* moved,
            uint8_t* crease, double* normals, double* weights, int64_t* trapped);
void friction(int n, const int64_t* index, const int64_t* rows, const double* trial, double* position,
              const int64_t* segment, const double* mass, double dt, double mu, const double* center,
              const double* rotation, const double* radii, int64_t* stick_segment, double* stick_local,
              double* a, double* force, double* normal_force, uint8_t* slip, int K, int monitors,
              const uint8_t* on_segments, const double* joints, const double* axes, double* torques,
              const uint8_t* crease, const double* normals, const double* weights);
int contact_step(int M, const double* reference, const int64_t* rows, const double* d, const double* v, double* a,
                 double dt, int K, const double* center, const double* rotation, const double* radii,
                 double tolerance, int passes, const double* widths, double* trial, double* position,
                 int64_t* segment, uint8_t* moved, uint8_t* crease, double* normals, double* weights,
                 int64_t* trapped, int64_t* index, int64_t* last, int64_t* count, const double* mass, double mu,
                 int64_t* stick_segment, double* stick_local, double* force, double* normal_force, uint8_t* slip,
                 int monitors, const uint8_t* on_segments, const double* joints, const double* axes, double* torques);
""" + BLEND_CDEF

SOURCE = r"""
#include <math.h>
#include <stddef.h>
#include <stdint.h>
""" + BLEND_SOURCE + r"""

/* y = R^T (x - c) (the products and sums of numpy's matmul of a row by R: sequential over i) */
static void to_local(const double* x, const double* c, const double* R, double* y)
{
  const double p0 = x[0] - c[0], p1 = x[1] - c[1], p2 = x[2] - c[2];
  for (int j = 0; j < 3; ++j)
    y[j] = (p0 * R[j] + p1 * R[3 + j]) + p2 * R[6 + j];
}

/* x = R y (+ c) */
static void rotate(const double* y, const double* R, double* x)
{
  for (int i = 0; i < 3; ++i)
    x[i] = (R[3 * i] * y[0] + R[3 * i + 1] * y[1]) + R[3 * i + 2] * y[2];
}

static double norm3(const double* v) { return sqrt((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2]); }

/* q = sum (y_i / r_i)^2 = f + 1 [Man2006, eq. 3.61] */
static double normalised_radius(const double* x, const double* c, const double* R, const double* r)
{
  double y[3];
  to_local(x, c, R, y);
  const double a = y[0] / r[0], b = y[1] / r[1], e = y[2] / r[2];
  return (a * a + b * b) + e * e;
}

/* fabricfem.body.ellipsoid._ray_to_surface: signed length of y - s u to the surface, hit flag */
static double ray_to_surface(const double* y, const double* r, const double* u, const double* r2, double c, int* hit)
{
  const double u0 = u[0] / r[0], u1 = u[1] / r[1], u2 = u[2] / r[2];
  const double a = (u0 * u0 + u1 * u1) + u2 * u2;
  const double b = -2.0 * ((y[0] * u[0] / r2[0] + y[1] * u[1] / r2[1]) + y[2] * u[2] / r2[2]);
  const double disc = b * b - 4.0 * a * c;
  *hit = disc >= 0.0;
  const double sq = sqrt(*hit ? disc : 0.0);
  const double q = -0.5 * (b + copysign(sq, b));
  const double s1 = q / a;
  const double s2 = q != 0.0 ? c / q : s1;
  const double s = fabs(s1) < fabs(s2) ? s1 : s2;
  return *hit ? s : 0.0;
}

/* SegmentStack.ray_gap: signed gap [m] of local point y (one cast along grad f, towards the centre if it misses) */
static double ray_gap(const double* y, const double* r)
{
  const double r2[3] = {r[0] * r[0], r[1] * r[1], r[2] * r[2]};
  const double yr0 = y[0] / r[0], yr1 = y[1] / r[1], yr2 = y[2] / r[2];
  const double q = (yr0 * yr0 + yr1 * yr1) + yr2 * yr2;
  double u[3] = {y[0] / r2[0], y[1] / r2[1], y[2] / r2[2]};
  const double norm = norm3(u);
  if (norm == 0.0)
  {
    const int k = (r[1] < r[0]) ? ((r[2] < r[1]) ? 2 : 1) : ((r[2] < r[0]) ? 2 : 0);   /* np.argmin */
    u[0] = u[1] = u[2] = 0.0;
    u[k] = 1.0;
  }
  else
    for (int i = 0; i < 3; ++i)
      u[i] = u[i] / norm;
  int hit;
  double s = ray_to_surface(y, r, u, r2, q - 1.0, &hit);
  if (!hit)
  {
    const double ny = norm3(y);
    const double uc[3] = {y[0] / ny, y[1] / ny, y[2] / ny};
    s = ray_to_surface(y, r, uc, r2, q - 1.0, &hit);
  }
  return fabs(s) * (q >= 1.0 ? 1.0 : -1.0);
}

/* SegmentStack.normal: unit grad f at local y of the segment (R, r), global */
static void normal(const double* y, const double* R, const double* r, double* n)
{
  const double g[3] = {2.0 * y[0] / (r[0] * r[0]), 2.0 * y[1] / (r[1] * r[1]), 2.0 * y[2] / (r[2] * r[2])};
  rotate(g, R, n);
  const double l = norm3(n);
  for (int i = 0; i < 3; ++i)
    n[i] = n[i] / l;
}

static double smallest(const double* r) { return fmin(fmin(r[0], r[1]), r[2]); }

/* the passes of project_with_segment near one segment only: x moved along grad f of the deepest segment it is in
   (ray cast, [Man2006, Box 5] step i) until it is inside none; returns 1 if still inside after `passes` */
static int ray_passes(int64_t p, double* x, int* inside, int K, const double* center, const double* rotation,
                      const double* radii, double tolerance, int passes, int64_t* segment, uint8_t* moved)
{
  int any = 1;
  for (int pass = 0; any && pass < passes; ++pass)
  {
    int deepest = 0;
    double g = INFINITY, y_deepest[3] = {0.0, 0.0, 0.0};
    for (int k = 0; k < K; ++k)
    {
      if (!inside[k])
        continue;
      double y[3];
      to_local(x, center + 3 * k, rotation + 9 * k, y);
      const double gap = ray_gap(y, radii + 3 * k);
      if (gap < g)
      {
        g = gap;
        deepest = k;
        y_deepest[0] = y[0], y_deepest[1] = y[1], y_deepest[2] = y[2];
      }
    }
    if (pass == 0)
      segment[p] = deepest;
    if (!(g < -tolerance * smallest(radii + 3 * deepest)))
      return 0;
    double n[3];
    normal(y_deepest, rotation + 9 * deepest, radii + 3 * deepest, n);
    for (int i = 0; i < 3; ++i)
      x[i] = x[i] - g * n[i];
    segment[p] = deepest;
    moved[p] = 1;
    any = 0;
    for (int k = 0; k < K; ++k)
    {
      inside[k] = normalised_radius(x, center + 3 * k, rotation + 9 * k, radii + 3 * k) < 1.0;
      any |= inside[k];
    }
  }
  return any;
}

#define CHUNK 64   /* the nodes of one vectorised pass of `chunk_radii` */

/* q = sum (y_i / r_i)^2 [Man2006, eq. 3.61] of the n points (x0, x1, x2) for the segment (c, R, r), and the distance
   bounds (sqrt(q) - 1) r_min: the expressions of `normalised_radius` (the same roundings: the same bits) in a loop
   that the compiler vectorises (the segment's numbers in registers, the outputs not aliased) */
static void segment_radii(int n, const double* x0, const double* x1, const double* x2, const double* c,
                          const double* R, const double* r, double* restrict q, double* restrict bound)
{
  const double c0 = c[0], c1 = c[1], c2 = c[2], r0 = r[0], r1 = r[1], r2 = r[2], r_min = smallest(r);
  const double R0 = R[0], R1 = R[1], R2 = R[2], R3 = R[3], R4 = R[4], R5 = R[5], R6 = R[6], R7 = R[7], R8 = R[8];
  for (int j = 0; j < n; ++j)
  {
    const double p0 = x0[j] - c0, p1 = x1[j] - c1, p2 = x2[j] - c2;
    const double y0 = (p0 * R0 + p1 * R3) + p2 * R6;
    const double y1 = (p0 * R1 + p1 * R4) + p2 * R7;
    const double y2 = (p0 * R2 + p1 * R5) + p2 * R8;
    const double e0 = y0 / r0, e1 = y1 / r1, e2 = y2 / r2;
    const double qj = (e0 * e0 + e1 * e1) + e2 * e2;
    q[j] = qj;
    bound[j] = (sqrt(qj) - 1.0) * r_min;
  }
}

/* the trial points x* = X + d + dt v~ + dt^2 a of the nodes p0 .. p0 + n - 1 (into position, and into trial unless
   NULL) and, for every segment k, their normalised radius q[k][j] and distance bound (`segment_radii`) */
static void chunk_radii(int p0, int n, const double* reference, const int64_t* rows, const double* d, const double* v,
                        const double* a, double dt, int K, const double* center, const double* rotation,
                        const double* radii, double* trial, double* position, double q[][CHUNK], double bound[][CHUNK])
{
  const double dt2 = dt * dt;
  double x0[CHUNK], x1[CHUNK], x2[CHUNK];
  for (int j = 0; j < n; ++j)
  {
    const int64_t p = p0 + j;
    double x[3];
    for (int i = 0; i < 3; ++i)
    {
      const int64_t row = rows[3 * p + i];
      position[3 * p + i] = x[i] = ((reference[3 * p + i] + d[row]) + dt * v[row]) + dt2 * a[row];
    }
    if (trial)
      trial[3 * p] = x[0], trial[3 * p + 1] = x[1], trial[3 * p + 2] = x[2];
    x0[j] = x[0], x1[j] = x[1], x2[j] = x[2];
  }
  for (int k = 0; k < K; ++k)
    segment_radii(n, x0, x1, x2, center + 3 * k, rotation + 9 * k, radii + 3 * k, q[k], bound[k]);
}

/* the nearest segment (smallest q, `best`) of node p and its crease flag: a pair of segments whose distances may
   both be below their blend width (bounds of the distances: bound[k][j]); returns whether a segment has q < 1 */
static int classify(int j, int K, double q[][CHUNK], double bound[][CHUNK], const double* widths, int* best,
                    uint8_t* crease)
{
  int any = 0;
  double qmin = INFINITY;
  *best = 0;
  for (int k = 0; k < K; ++k)
  {
    any |= q[k][j] < 1.0;
    if (q[k][j] < qmin)
    {
      qmin = q[k][j];
      *best = k;
    }
  }
  *crease = 0;
  for (int a = 0; a < K && !*crease; ++a)
    for (int b = a + 1; b < K; ++b)
      if (bound[a][j] < widths[a * K + b] && bound[b][j] < widths[a * K + b])
      {
        *crease = 1;
        break;
      }
  return any;
}

/* the projection of project_with_segment for node p at x (its trial point x0, copied in position) inside a segment
   or in a crease that `blend_lower_bound` does not put outside (`classify`), from its normalised radii q (K): segment
   and moved flag, the blended skin's normal and weights in a crease; returns 1 if the point stays inside a segment
   after `passes` projections (trapped) */
static int project_point(int64_t p, double* x, const double* x0, const double* q, int K,
                         const double* center, const double* rotation, const double* radii, double tolerance,
                         int passes, const double* widths, int64_t* segment, uint8_t* moved, const uint8_t* crease,
                         double* normals, double* weights)
{
  double* W = weights + (size_t)K * p;
  if (crease[p])   /* within the blend of two segments: the blended skin's closest point (blend_kernel) */
  {
    double grad[3];
    if (blend_eval(x, K, center, rotation, radii, widths, grad, W) < 0.0)
    {
      blend_closest(x0, K, center, rotation, radii, widths, x, normals + 3 * p, W);
      moved[p] = 1;
    }
    int heaviest = 0;
    for (int k = 1; k < K; ++k)
      if (W[k] > W[heaviest])
        heaviest = k;
    segment[p] = heaviest;
    return 0;
  }
  int inside[BLEND_MAX_SEGMENTS];
  for (int k = 0; k < K; ++k)
    inside[k] = q[k] < 1.0;
  return ray_passes(p, x, inside, K, center, rotation, radii, tolerance, passes, segment, moved);
}

/* friction and the acceleration correction of the n nodes `index` in contact (ExplicitBodyContact.correct) */
void friction(int n, const int64_t* index, const int64_t* rows, const double* trial, double* position,
              const int64_t* segment, const double* mass, double dt, double mu, const double* center,
              const double* rotation, const double* radii, int64_t* stick_segment, double* stick_local,
              double* a, double* force, double* normal_force, uint8_t* slip, int K, int monitors,
              const uint8_t* on_segments, const double* joints, const double* axes, double* torques,
              const uint8_t* crease, const double* normals, const double* weights)
{
  const double dt2 = dt * dt;
  double moment[64][3];
  for (int m = 0; m < monitors; ++m)
    moment[m][0] = moment[m][1] = moment[m][2] = 0.0;
  for (int j = 0; j < n; ++j)
  {
    const int64_t p = index[j];
    const int64_t k = segment[p];
    const double* m = mass + 3 * p;
    const double* x0 = trial + 3 * p;
    double* x = position + 3 * p;
    const double* c = center + 3 * k;
    const double* R = rotation + 9 * k;
    double dn[3] = {m[0] * (x[0] - x0[0]), m[1] * (x[1] - x0[1]), m[2] * (x[2] - x0[2])};
    const double lambda = norm3(dn) / dt2;               /* |lambda_N| */
    normal_force[p] = lambda;
    slip[p] = 0;
    if (mu > 0.0)
    {
      const int known = stick_segment[p] == k;
      double stick[3];
      if (known)
      {
        rotate(stick_local + 3 * p, R, stick);
        for (int i = 0; i < 3; ++i)
          stick[i] = stick[i] + c[i];
      }
      else
        stick[0] = x[0], stick[1] = x[1], stick[2] = x[2];
      double y[3], nrm[3];
      if (crease[p])   /* the blended skin's normal at the foot */
        nrm[0] = normals[3 * p], nrm[1] = normals[3 * p + 1], nrm[2] = normals[3 * p + 2];
      else
      {
        to_local(x, c, R, y);
        normal(y, R, radii + 3 * k, nrm);
      }
      const double diff[3] = {stick[0] - x[0], stick[1] - x[1], stick[2] - x[2]};
      const double along = (diff[0] * nrm[0] + diff[1] * nrm[1]) + diff[2] * nrm[2];
      double dT[3] = {diff[0] - along * nrm[0], diff[1] - along * nrm[1], diff[2] - along * nrm[2]};
      const double mt[3] = {m[0] * dT[0], m[1] * dT[1], m[2] * dT[2]};
      const double ft = norm3(mt) / dt2;
      const double limit = mu * lambda;                 /* eq. 3.52: |t| <= mu lambda_N */
      const int slips = known && (ft > limit);
      const double scale = slips ? limit / (ft > 0.0 ? ft : 1.0) : 1.0;
      for (int i = 0; i < 3; ++i)
      {
        dT[i] = known ? dT[i] * scale : 0.0;
        x[i] = x[i] + dT[i];
      }
      slip[p] = slips;
      /* the stick point stays on the segment when sticking, moves with the node when slipping, and is created at
         the contact point for a node touching down */
      const double* kept = (slips || !known) ? x : stick;
      stick_segment[p] = k;
      to_local(kept, c, R, stick_local + 3 * p);
    }
    for (int i = 0; i < 3; ++i)
    {
      const double ac = (x[i] - x0[i]) / dt2;
      a[rows[3 * p + i]] += ac;
      force[3 * p + i] = m[i] * ac;
    }
    /* fabricfem.contact.torque.local_torques: (x - J) x (-f) summed over the nodes on each monitor's segments */
    for (int mon = 0; mon < monitors; ++mon)
    {
      double share = on_segments[mon * K + k];   /* the segment weights of the blended skin in a crease */
      if (crease[p])
      {
        share = 0.0;
        for (int j = 0; j < K; ++j)
          share += on_segments[mon * K + j] ? weights[(size_t)K * p + j] : 0.0;
      }
      if (share == 0.0)
        continue;
      const double* J = joints + 3 * mon;
      const double r[3] = {x[0] - J[0], x[1] - J[1], x[2] - J[2]};
      const double f[3] = {-share * force[3 * p], -share * force[3 * p + 1], -share * force[3 * p + 2]};
      moment[mon][0] += r[1] * f[2] - r[2] * f[1];
      moment[mon][1] += r[2] * f[0] - r[0] * f[2];
      moment[mon][2] += r[0] * f[1] - r[1] * f[0];
    }
  }
  for (int mon = 0; mon < monitors; ++mon)
    torques[mon] = (moment[mon][0] * axes[3 * mon] + moment[mon][1] * axes[3 * mon + 1])
                   + moment[mon][2] * axes[3 * mon + 2];
}

/* the trial points and projections of the M nodes (`project`); with `index` (the fused `contact_step`), the trial
   points only of the nodes that may move (the others' are their positions) and the list of the nodes moved (their
   number in n_index[0]) */
static int project_nodes(int M, const double* reference, const int64_t* rows, const double* d, const double* v,
                         const double* a, double dt, int K, const double* center, const double* rotation,
                         const double* radii, double tolerance, int passes, const double* widths, double* trial,
                         double* position, int64_t* segment, uint8_t* moved, uint8_t* crease, double* normals,
                         double* weights, int64_t* trapped, int64_t* index, int64_t* n_index)
{
  int n_trapped = 0;
  int64_t n_moved = 0;
  double qs[BLEND_MAX_SEGMENTS][CHUNK], bounds[BLEND_MAX_SEGMENTS][CHUNK];
  for (int p0 = 0; p0 < M; p0 += CHUNK)
  {
    const int n = M - p0 < CHUNK ? M - p0 : CHUNK;
    chunk_radii(p0, n, reference, rows, d, v, a, dt, K, center, rotation, radii, index ? NULL : trial, position, qs,
                bounds);
    for (int j = 0; j < n; ++j)
    {
      const int64_t p = p0 + j;
      int best;
      const int any = classify(j, K, qs, bounds, widths, &best, crease + p);
      segment[p] = best;
      moved[p] = 0;
      if (any || crease[p])   /* else outside every segment, away from the creases: stays where it is */
      {
        double q[BLEND_MAX_SEGMENTS], bound[BLEND_MAX_SEGMENTS];
        for (int k = 0; k < K; ++k)
          q[k] = qs[k][j], bound[k] = bounds[k][j];
        if (crease[p] && blend_lower_bound(K, bound, widths) > 0.0)   /* certainly outside the blended skin */
          for (int k = 0; k < K; ++k)
            weights[(size_t)K * p + k] = k == best ? 1.0 : 0.0;
        else
        {
          if (index)
            for (int i = 0; i < 3; ++i)
              trial[3 * p + i] = position[3 * p + i];
          if (project_point(p, position + 3 * p, trial + 3 * p, q, K, center, rotation, radii, tolerance, passes,
                            widths, segment, moved, crease, normals, weights))
            trapped[n_trapped++] = p;
        }
      }
      if (index && moved[p])
        index[n_moved++] = p;
    }
  }
  if (n_index)
    n_index[0] = n_moved;
  return n_trapped;
}

/* trial positions and the projection passes of project_with_segment; returns the number of trapped points */
int project(int M, const double* reference, const int64_t* rows, const double* d, const double* v, const double* a,
            double dt, int K, const double* center, const double* rotation, const double* radii, double tolerance,
            int passes, const double* widths, double* trial, double* position, int64_t* segment, uint8_t* moved,
            uint8_t* crease, double* normals, double* weights, int64_t* trapped)
{
  return project_nodes(M, reference, rows, d, v, a, dt, K, center, rotation, radii, tolerance, passes, widths, trial,
                       position, segment, moved, crease, normals, weights, trapped, NULL, NULL);
}

/* the whole Lagrange step of ExplicitBodyContact.correct in one call: `project` of the M nodes, then, if none is
   trapped, `friction` of the count[0] nodes moved (listed in index). The nodes not in contact get zero force, no
   slip and (mu > 0) no stick point: `last` lists the count[1] nodes in contact at the last step, the only ones that
   can have them (count[1] = -1: every node is cleared, as after a restart); the list of this step replaces it at
   the end. Returns the number of trapped points (listed in trapped; no friction then, and count[1] = -1) */
int contact_step(int M, const double* reference, const int64_t* rows, const double* d, const double* v, double* a,
                 double dt, int K, const double* center, const double* rotation, const double* radii,
                 double tolerance, int passes, const double* widths, double* trial, double* position,
                 int64_t* segment, uint8_t* moved, uint8_t* crease, double* normals, double* weights,
                 int64_t* trapped, int64_t* index, int64_t* last, int64_t* count, const double* mass, double mu,
                 int64_t* stick_segment, double* stick_local, double* force, double* normal_force, uint8_t* slip,
                 int monitors, const uint8_t* on_segments, const double* joints, const double* axes, double* torques)
{
  const int n_trapped = project_nodes(M, reference, rows, d, v, a, dt, K, center, rotation, radii, tolerance, passes,
                                      widths, trial, position, segment, moved, crease, normals, weights, trapped,
                                      index, count);
  if (n_trapped)
  {
    count[1] = -1;
    return n_trapped;
  }
  for (int64_t j = 0; j < (count[1] < 0 ? M : count[1]); ++j)
  {
    const int64_t p = count[1] < 0 ? j : last[j];
    if (moved[p])
      continue;
    force[3 * p] = force[3 * p + 1] = force[3 * p + 2] = normal_force[p] = 0.0;
    slip[p] = 0;
    if (mu > 0.0)
      stick_segment[p] = -1;
  }
  friction((int)count[0], index, rows, trial, position, segment, mass, dt, mu, center, rotation, radii,
           stick_segment, stick_local, a, force, normal_force, slip, K, monitors, on_segments, joints, axes, torques,
           crease, normals, weights);
  for (int64_t j = 0; j < count[0]; ++j)
    last[j] = index[j];
  count[1] = count[0];
  return 0;
}
"""

def module(comm):
    """The compiled module: (lib, ffi), built on first use by rank 0 of `comm` while the others wait
    (fabricfem.forms.jit.built_once)."""
    return built_once("fabricfem_contact", CDEF, SOURCE, comm, FLAGS)


def stacked(ellipsoids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (K, 3), rotations (K, 3, 3), radii (K, 3)) [m] of the posed segments, C-contiguous, for the loops;
    ValueError beyond MAX_SEGMENTS."""
    if len(ellipsoids) > MAX_SEGMENTS:
        raise ValueError(f"compiled contact: at most {MAX_SEGMENTS} body segments, got {len(ellipsoids)}")
    return (np.ascontiguousarray([e.center for e in ellipsoids], dtype=float),
            np.ascontiguousarray([e.rotation for e in ellipsoids], dtype=float),
            np.ascontiguousarray([e.radii for e in ellipsoids], dtype=float))


class StepBuffers:
    """What `contact_step` keeps from one explicit step to the next for M nodes against K segments: its work arrays
    (trial points [m], crease flags, the blended skin's normals and weights, the nodes in contact and their number,
    the trapped nodes; entries of nodes outside a crease or out of contact are stale, and only read where written
    the same step; the list of the nodes in contact is kept for the next step, whose clearing of the force, slip and
    stick point of the nodes out of contact goes over those only), and the cffi pointers of the arrays that live
    as long as the contact (`cached`)."""

    def __init__(self, ffi, M: int, K: int):
        self.ffi, self.M, self.K = ffi, M, K
        self.trial, self.normals, self.weights = np.zeros((M, 3)), np.zeros((M, 3)), np.zeros((M, K))
        self.crease = np.zeros(M, dtype=np.uint8)
        self.index, self.last, self.trapped = (np.zeros(M, dtype=np.int64) for _ in range(3))
        self.count = np.array([0, -1], dtype=np.int64)   # nodes in contact at this step, at the last (-1: none yet)
        self._pointers: dict[str, tuple[np.ndarray, object]] = {}

    def cached(self, name: str, array: np.ndarray, ctype: str):
        """The cffi pointer of `ctype` into `array` (a bool array as uint8_t), made again only when `name` is given
        another array object (ValueError unless C-contiguous)."""
        hit = self._pointers.get(name)
        if hit is None or hit[0] is not array:
            view = array.view(np.uint8) if array.dtype == bool else array
            hit = self._pointers[name] = (array, pointer(self.ffi, view, ctype))
        return hit[1]

    def work(self) -> tuple:
        """The pointers of the work arrays in `contact_step`'s order: trial, (position, segment, moved: the caller's),
        crease, normals, weights, trapped, index, last, count."""
        c = self.cached
        return (c("trial", self.trial, "double"), c("crease", self.crease, "uint8_t"),
                c("normals", self.normals, "double"), c("weights", self.weights, "double"),
                c("trapped", self.trapped, "int64_t"), c("index", self.index, "int64_t"),
                c("last", self.last, "int64_t"), c("count", self.count, "int64_t"))
