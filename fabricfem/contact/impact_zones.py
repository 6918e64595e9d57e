"""The failsafe of cloth-cloth contact: continuous collision detection over the step and rigid impact zones,
compiled ([Bridson2002, sec. 7.3-7.4]).

The proximity impulses (fabricfem.contact.impulses) act on the pairs closer than d_c at x^{n+1}; a pair that
approaches by more than its gap within one step, or two layers that cross between two proximity searches, pass
through, and once crossed the penalty and the impulses hold them crossed. This module checks the step itself:
every node moves from x = x^{n+1} to x + dt u (u the corrected predictor, the velocities that set x^{n+2},
fabricfem.contact.impulses), and

* CCD ([Bridson2002, sec. 7.3]): a vertex-triangle pair (p; a, b, c) or an edge-edge pair (a, b; c, d) can only
  touch when its four points are coplanar. With every point moving linearly, x_k(t) = x_k + t dx_k (dx = dt u,
  t in [0, 1]), the coplanarity condition (x_ab(t) x x_ac(t)) . x_ap(t) = 0 (edges: (x_ab x x_cd) . x_ac = 0) is a
  cubic in t; its roots in [0, 1] (brackets between the roots of its derivative, then bisection to 1e-14) are
  tested in order, and the pair collides at the first root where its distance (the vertex to the triangle, the
  segments' closest points) is below eta (`TOLERANCE` d_c);
* rigid impact zones ([Bridson2002, sec. 7.4]): the nodes of all colliding pairs are merged into zones (a union-find
  over the nodes; a zone of the last iteration is kept and grows), and each zone's nodes take the rigid velocity
  that conserves the zone's linear and angular momentum: with weights m_k, centre x_c = sum m x / M, v_c =
  sum m u / M, L = sum m (x - x_c) x (u - v_c), I = sum m (|r|^2 1 - r r^T), omega = I^-1 L (I + 1e-14 tr I
  for a zone of (nearly) collinear nodes), u_k = v_c + omega x (x_k - x_c). The velocity field of a zone is affine,
  so its nodes cannot collide with each other during the step. Detection and zones alternate until a detection
  finds no collision or `iterations` is reached.

Held nodes (1 / m = 0: a prescribed displacement, or held on the body by the body contact this step) are of
infinite mass: in a zone that contains one, the rigid motion is that of the held nodes (the weights m_k of the free
nodes set to 0, the held nodes' lumped masses kept), the free nodes take it and the held ones keep their
velocities. The rotation is scaled by min(1, R_h^2 / R_z^2), R_h^2 = sum_held m r^2 / sum_held m and R_z^2 =
sum_zone m r^2 / sum_zone m (r from the held nodes' centre), so that omega x r is not extrapolated beyond the held
nodes' own extent on (mass-weighted) average: the zone's RMS rotational speed is then at most the held nodes'. A
single free node far out in a zone whose other free nodes sit near the held ones can still move faster than any held
node. A rotation fitted to two held nodes a few millimetres apart, extrapolated to free nodes 0.1 m away,
gave those nodes speeds far above any held node's (measured on the pants' sewing: a zone of 69 nodes with 2 held ones
at 0.03 m/s took the zones' largest speed from 0.66 to 10 m/s and the walk blew up;
docs/findings/2026-11-28-zone-release.md). A zone whose held nodes do not move rigidly (across the elbow's crease,
or on two segments) can still collide. So from round `RELEASE_ROUND` on, a zone with a collision left releases its
held nodes: they take its rigid motion too, with their lumped masses, as every node of a zone does in
[Bridson2002, sec. 7.4], and stay released for the rest of the step. Nodes with a prescribed component are not
released (the caller's `releasable`): the integrator imposes their motion whatever the zone says. A released node
may leave the skin by the zone's motion within the step; the body contact puts it back in the next one (the run's
penetration monitor sees it). Measured on a fast copy of the sleeve flexed to 130 degrees
(docs/findings/2026-11-28-zone-release.md): without the release, 129 of 195 steps with collisions ended unresolved
at the round limit.

Candidates: the pairs that can collide during the step are those closer than the step's largest relative motion
2 max_k |dx_k| (+ eta) at x. The caller (fabricfem.contact.self_contact) passes the Verlet candidates of the
proximity (all pairs within d_c at x) when that motion is below d_c, a fresh search within the motion otherwise.

Parallel: every rank holds the gathered x, u and the same candidates; detection is set-valued and the zones'
sums run over the global node numbers, so the ranks agree (to the round-off of the sums' order, which depends on
the partition's numbering). Units: metres, seconds, kilograms.
"""
from __future__ import annotations

import functools

import numpy as np

from fabricfem.contact import stitch_groups
from fabricfem.contact.proximity import CLOSEST_C
from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

TOLERANCE = 1e-3        # eta / d_c: the distance at a coplanar time below which a pair collides
DEFAULT_ITERATIONS = 20  # detection / zone rounds per step
RELEASE_ROUND = 10       # the round from which a zone still colliding moves its held nodes too (module docstring)
SUMS = 19                # per-zone sums of rigid_velocities

CDEF = """
int64_t detect(int64_t n_vt, const int64_t* vt_p, const int64_t* vt_t, const int64_t* tri, int64_t n_ee,
               const int64_t* ee_a, const int64_t* ee_b, const int64_t* edges, const double* x, const double* dx,
               double eta, uint8_t* hit, double* when);
int64_t merge_zones(int64_t N, int64_t n_hit, const int64_t* nodes, int64_t* parent);
void rigid_velocities(int64_t N, const int64_t* parent, const double* x, double* u, const double* mass,
                      const uint8_t* held, double* sums);
"""

SOURCE = "#pragma GCC diagnostic ignored \"-Wunused-function\"\n#include <math.h>\n" + f"#define SUMS {SUMS}\n" \
    + CLOSEST_C + r"""
static void cross3(const double* a, const double* b, double* c)
{
  c[0] = a[1] * b[2] - a[2] * b[1], c[1] = a[2] * b[0] - a[0] * b[2], c[2] = a[0] * b[1] - a[1] * b[0];
}

static double cubic(const double* k, double t) { return ((k[3] * t + k[2]) * t + k[1]) * t + k[0]; }

/* coefficients k[0..3] of f(t) = ((A + t dA) x (B + t dB)) . (C + t dC) */
static void coplanarity(const double* A, const double* dA, const double* B, const double* dB, const double* C,
                        const double* dC, double* k)
{
  double AB[3], dAB[3], AdB[3], dAdB[3], mix[3];
  cross3(A, B, AB), cross3(dA, B, dAB), cross3(A, dB, AdB), cross3(dA, dB, dAdB);
  for (int i = 0; i < 3; ++i)
    mix[i] = dAB[i] + AdB[i];
  k[0] = dot3(AB, C);
  k[1] = dot3(mix, C) + dot3(AB, dC);
  k[2] = dot3(dAdB, C) + dot3(mix, dC);
  k[3] = dot3(dAdB, dC);
}

/* the roots of the cubic in [0, 1], ascending (at most 3); brackets between the derivative's roots, bisection */
static int roots01(const double* k, double* root)
{
  double cut[4] = {0.0, 0.0, 0.0, 1.0};
  int n_cut = 1;
  const double a = 3.0 * k[3], b = 2.0 * k[2], c = k[1];
  double r[2];
  int n_r = 0;
  if (a != 0.0)
  {
    const double disc = b * b - 4.0 * a * c;
    if (disc >= 0.0)
    {
      const double q = -0.5 * (b + copysign(sqrt(disc), b));
      r[n_r++] = q / a;
      if (q != 0.0)
        r[n_r++] = c / q;
    }
  }
  else if (b != 0.0)
    r[n_r++] = -c / b;
  if (n_r == 2 && r[0] > r[1])
  {
    const double s = r[0];
    r[0] = r[1], r[1] = s;
  }
  for (int i = 0; i < n_r; ++i)
    if (r[i] > 0.0 && r[i] < 1.0)
      cut[n_cut++] = r[i];
  cut[n_cut] = 1.0;
  int n = 0;
  for (int i = 0; i < n_cut; ++i)
  {
    double lo = cut[i], hi = cut[i + 1], flo = cubic(k, lo), fhi = cubic(k, hi);
    if (flo == 0.0) { root[n++] = lo; continue; }
    if (i == n_cut - 1 && fhi == 0.0) { root[n++] = hi; continue; }
    if ((flo < 0.0) == (fhi < 0.0))
      continue;
    for (int it = 0; it < 200 && hi - lo > 1e-14; ++it)
    {
      const double mid = 0.5 * (lo + hi), fm = cubic(k, mid);
      if ((fm < 0.0) == (flo < 0.0))
        lo = mid, flo = fm;
      else
        hi = mid;
    }
    root[n++] = 0.5 * (lo + hi);
  }
  return n;
}

/* squared distance of the segments p1 q1, p2 q2 [Ericson2005, sec. 5.1.9] */
static double segment_distance2(const double* p1, const double* q1, const double* p2, const double* q2)
{
  double d1[3], d2[3], r[3];
  for (int i = 0; i < 3; ++i)
    d1[i] = q1[i] - p1[i], d2[i] = q2[i] - p2[i], r[i] = p1[i] - p2[i];
  const double a = dot3(d1, d1), e = dot3(d2, d2), f = dot3(d2, r), c = dot3(d1, r), b = dot3(d1, d2);
  double s = 0.0, t = 0.0;
  if (a > 0.0 && e > 0.0)
  {
    const double denom = a * e - b * b;
    s = denom > 0.0 ? fmin(fmax((b * f - c * e) / denom, 0.0), 1.0) : 0.0;
    t = (b * s + f) / e;
    if (t < 0.0)
      t = 0.0, s = fmin(fmax(-c / a, 0.0), 1.0);
    else if (t > 1.0)
      t = 1.0, s = fmin(fmax((b - c) / a, 0.0), 1.0);
  }
  double g2 = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    const double g = p1[i] + s * d1[i] - p2[i] - t * d2[i];
    g2 += g * g;
  }
  return g2;
}

/* the four nodes' positions at time t of the step */
static void at_time(const int64_t* node, const double* x, const double* dx, double t, double (*y)[3])
{
  for (int q = 0; q < 4; ++q)
    for (int i = 0; i < 3; ++i)
      y[q][i] = x[3 * node[q] + i] + t * dx[3 * node[q] + i];
}

/* the first time in [0, 1] at which the pair (vertex-triangle: p, a, b, c; edge-edge: a, b, c, d) is coplanar and
   closer than eta; -1 if none */
static double collision_time(const int64_t* node, int edge_pair, const double* x, const double* dx, double eta)
{
  double y[4][3], A[3], dA[3], B[3], dB[3], C[3], dC[3], k[4], root[3], w[3];
  const int64_t o = edge_pair ? node[0] : node[1];                 /* the origin a */
  const int64_t ia = edge_pair ? node[1] : node[2], ib = edge_pair ? node[3] : node[3];
  const int64_t ic = edge_pair ? node[2] : node[0];
  const int64_t jb = edge_pair ? node[2] : o;                      /* edges: B = d - c; triangle: B = c - a */
  for (int i = 0; i < 3; ++i)
  {
    A[i] = x[3 * ia + i] - x[3 * o + i], dA[i] = dx[3 * ia + i] - dx[3 * o + i];
    B[i] = x[3 * ib + i] - x[3 * jb + i], dB[i] = dx[3 * ib + i] - dx[3 * jb + i];
    C[i] = x[3 * ic + i] - x[3 * o + i], dC[i] = dx[3 * ic + i] - dx[3 * o + i];
  }
  coplanarity(A, dA, B, dB, C, dC, k);
  const int n = roots01(k, root);
  for (int r = 0; r < n; ++r)
  {
    at_time(node, x, dx, root[r], y);
    const double d2 = edge_pair ? segment_distance2(y[0], y[1], y[2], y[3]) : closest(y[0], y[1], y[2], y[3], w);
    if (d2 < eta * eta)
      return root[r];
  }
  return -1.0;
}

/* all candidates: hit[i] = 1 and when[i] the first collision time of the pair, vertex-triangle pairs first; returns
   the number of collisions */
int64_t detect(int64_t n_vt, const int64_t* vt_p, const int64_t* vt_t, const int64_t* tri, int64_t n_ee,
               const int64_t* ee_a, const int64_t* ee_b, const int64_t* edges, const double* x, const double* dx,
               double eta, uint8_t* hit, double* when)
{
  int64_t count = 0;
  for (int64_t i = 0; i < n_vt + n_ee; ++i)
  {
    int64_t node[4];
    if (i < n_vt)
      node[0] = vt_p[i], node[1] = tri[3 * vt_t[i]], node[2] = tri[3 * vt_t[i] + 1], node[3] = tri[3 * vt_t[i] + 2];
    else
    {
      const int64_t j = i - n_vt;
      node[0] = edges[2 * ee_a[j]], node[1] = edges[2 * ee_a[j] + 1];
      node[2] = edges[2 * ee_b[j]], node[3] = edges[2 * ee_b[j] + 1];
    }
    when[i] = collision_time(node, i >= n_vt, x, dx, eta);
    hit[i] = when[i] >= 0.0;
    count += hit[i];
  }
  return count;
}

static int64_t find(int64_t* parent, int64_t i)
{
  while (parent[i] != i)
  {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

/* the nodes (n_hit, 4) of the colliding pairs into the zones parent (N,): -1 outside any zone, else a union-find
   forest (the root of a zone is the smallest node number); returns the number of nodes in zones */
int64_t merge_zones(int64_t N, int64_t n_hit, const int64_t* nodes, int64_t* parent)
{
  for (int64_t i = 0; i < 4 * n_hit; ++i)
    if (parent[nodes[i]] < 0)
      parent[nodes[i]] = nodes[i];
  for (int64_t h = 0; h < n_hit; ++h)
    for (int q = 1; q < 4; ++q)
    {
      const int64_t a = find(parent, nodes[4 * h]), b = find(parent, nodes[4 * h + q]);
      if (a != b)
        parent[a < b ? b : a] = a < b ? a : b;
    }
  int64_t count = 0;
  for (int64_t i = 0; i < N; ++i)
    if (parent[i] >= 0)
      parent[i] = find(parent, i), ++count;
  return count;
}

/* u of the nodes in zones (parent[i] >= 0, flattened to the root) := the zone's rigid velocity (module docstring;
   a zone with held nodes: their rotation scaled by their extent over the zone's);
   sums (N, SUMS) scratch: held flag, M, M x_c, M v_c, L, I (6), then the whole zone's mass and second moment about
   the centre, per root */
void rigid_velocities(int64_t N, const int64_t* parent, const double* x, double* u, const double* mass,
                      const uint8_t* held, double* sums)
{
  for (int64_t i = 0; i < SUMS * N; ++i)
    sums[i] = 0.0;
  for (int64_t i = 0; i < N; ++i)
    if (parent[i] >= 0 && held[i])
      sums[SUMS * parent[i]] = 1.0;
  for (int64_t i = 0; i < N; ++i)
  {
    if (parent[i] < 0)
      continue;
    double* S = sums + SUMS * parent[i];
    const double m = (S[0] > 0.0 && !held[i]) ? 0.0 : mass[i];
    S[1] += m;
    for (int k = 0; k < 3; ++k)
      S[2 + k] += m * x[3 * i + k], S[5 + k] += m * u[3 * i + k];
  }
  for (int64_t i = 0; i < N; ++i)
  {
    if (parent[i] < 0)
      continue;
    double* S = sums + SUMS * parent[i];
    const double m = (S[0] > 0.0 && !held[i]) ? 0.0 : mass[i];
    double r[3], v[3], L[3];
    for (int k = 0; k < 3; ++k)
      r[k] = x[3 * i + k] - S[2 + k] / S[1], v[k] = u[3 * i + k] - S[5 + k] / S[1];
    cross3(r, v, L);
    const double rr = dot3(r, r);
    for (int k = 0; k < 3; ++k)
      S[8 + k] += m * L[k];
    S[11] += m * (rr - r[0] * r[0]), S[12] += m * (rr - r[1] * r[1]), S[13] += m * (rr - r[2] * r[2]);
    S[14] -= m * r[0] * r[1], S[15] -= m * r[0] * r[2], S[16] -= m * r[1] * r[2];
    S[17] += mass[i], S[18] += mass[i] * rr;
  }
  for (int64_t i = 0; i < N; ++i)       /* omega = I^-1 L at each root, into S[8..10] */
  {
    if (parent[i] != i)
      continue;
    double* S = sums + SUMS * i;
    const double trace = S[11] + S[12] + S[13];
    double eps = 0.0, a, b, c, d, e, f, c00, c01, c02, c11, c12, c22, det;
    for (int attempt = 0; attempt < 2; ++attempt)     /* exact, then regularised for a (nearly) collinear zone */
    {
      a = S[11] + eps, b = S[14], c = S[15], d = S[12] + eps, e = S[16], f = S[13] + eps;
      c00 = d * f - e * e, c01 = c * e - b * f, c02 = b * e - c * d;
      c11 = a * f - c * c, c12 = b * c - a * e, c22 = a * d - b * b;
      det = a * c00 + b * c01 + c * c02;
      if (det > 1e-9 * trace * trace * trace)
        break;
      eps = 1e-14 * trace;
    }
    const double L0 = S[8], L1 = S[9], L2 = S[10];
    double ok = det > 0.0 ? 1.0 / det : 0.0;
    if (S[0] > 0.0 && S[18] > 0.0)      /* held nodes: omega x r not extrapolated beyond their extent */
      ok *= fmin(1.0, (0.5 * trace / S[1]) / (S[18] / S[17]));
    S[8] = ok * (c00 * L0 + c01 * L1 + c02 * L2);
    S[9] = ok * (c01 * L0 + c11 * L1 + c12 * L2);
    S[10] = ok * (c02 * L0 + c12 * L1 + c22 * L2);
  }
  for (int64_t i = 0; i < N; ++i)
  {
    if (parent[i] < 0 || held[i])
      continue;
    const double* S = sums + SUMS * parent[i];
    double r[3], w[3];
    for (int k = 0; k < 3; ++k)
      r[k] = x[3 * i + k] - S[2 + k] / S[1];
    cross3(S + 8, r, w);
    for (int k = 0; k < 3; ++k)
      u[3 * i + k] = S[5 + k] / S[1] + w[k];
  }
}
"""


def _module(comm):
    """(lib, ffi) of the compiled detection and zones, built on first use (rank 0 of `comm` builds)."""
    return built_once("fabricfem_impact_zones", CDEF, SOURCE, comm, KERNEL_FLAGS)


def detect(vertex: np.ndarray, triangle: np.ndarray, triangles: np.ndarray, first: np.ndarray, second: np.ndarray,
           edges: np.ndarray, x: np.ndarray, dx: np.ndarray, eta: float, comm) -> tuple[np.ndarray, np.ndarray]:
    """CCD of the candidate pairs over the step x -> x + dx (module docstring).

    Args:
        vertex, triangle: (n,) the vertex-triangle candidates (node, row of `triangles` (T, 3)).
        first, second: (m,) the edge-edge candidates (rows of `edges` (E, 2)).
        x: (N, 3) positions at the step's start [m]; dx: (N, 3) the step's displacements [m]; eta: tolerance [m].

    Returns:
        (hit (n + m,) bool, when (n + m,) the first collision time as a fraction of the step, -1 without).
    """
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    c = functools.partial(np.ascontiguousarray, dtype=np.int64)
    n = len(vertex) + len(first)
    hit, when = np.zeros(n, dtype=np.uint8), np.zeros(n)
    lib.detect(len(vertex), p(c(vertex), "int64_t"), p(c(triangle), "int64_t"), p(c(triangles), "int64_t"),
               len(first), p(c(first), "int64_t"), p(c(second), "int64_t"), p(c(edges), "int64_t"),
               p(np.ascontiguousarray(x, dtype=float), "double"), p(np.ascontiguousarray(dx, dtype=float), "double"),
               float(eta), p(hit, "uint8_t"), p(when, "double"))
    return hit.astype(bool), when


def merge(nodes: np.ndarray, parent: np.ndarray, comm) -> int:
    """Merge the nodes (k, 4) of the colliding pairs into the zones `parent` (N,) int64 (-1: no zone; changed in
    place, flattened to each zone's smallest node); returns the number of nodes in zones."""
    lib, ffi = _module(comm)
    nodes = np.ascontiguousarray(nodes, dtype=np.int64)
    return int(lib.merge_zones(len(parent), len(nodes), pointer(ffi, nodes, "int64_t"),
                               pointer(ffi, parent, "int64_t")))


def rigid(parent: np.ndarray, x: np.ndarray, u: np.ndarray, mass: np.ndarray, held: np.ndarray, comm) -> None:
    """u (N, 3) [m/s] of the nodes in zones (`parent` from `merge`) := their zone's rigid velocity (module
    docstring), in place; mass (N,) finite lumped masses [kg], held (N,) bool (infinite mass)."""
    lib, ffi = _module(comm)
    sums = np.empty((len(parent), SUMS))
    lib.rigid_velocities(len(parent), pointer(ffi, parent, "int64_t"),
                         pointer(ffi, np.ascontiguousarray(x, dtype=float), "double"), pointer(ffi, u, "double"),
                         pointer(ffi, np.ascontiguousarray(mass, dtype=float), "double"),
                         pointer(ffi, np.ascontiguousarray(held, dtype=np.uint8), "uint8_t"),
                         pointer(ffi, sums, "double"))


def pair_nodes(vertex: np.ndarray, triangle: np.ndarray, triangles: np.ndarray, first: np.ndarray,
               second: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(n + m, 4) the nodes of the vertex-triangle pairs (p, a, b, c), then of the edge-edge pairs (a, b, c, d)."""
    return np.concatenate([np.column_stack([vertex, triangles[triangle]]),
                           np.column_stack([edges[first], edges[second]])]).astype(np.int64).reshape(-1, 4)


def resolve(candidates, x: np.ndarray, u: np.ndarray, dt: float, mass: np.ndarray, held: np.ndarray, eta: float,
            iterations: int, comm, release: int | None = None, releasable: np.ndarray | None = None,
            joined: np.ndarray | None = None) -> dict:
    """Detection and rigid zones until the step x -> x + dt u is collision-free or `iterations` rounds (module
    docstring); u (N, 3) [m/s] changed in place; from round `release` (0-based; None: RELEASE_ROUND) on, the held
    nodes of the zones with a collision left are released (module docstring), those of `releasable` (N,) bool only
    (None: all; a node whose motion is prescribed must not be).

    Args:
        candidates: callable(u) -> (vertex, triangle, triangles, first, second, edges): the candidate pairs for the
            velocities u (the caller widens them when the step's motion exceeds its proximity radius).
        x: (N, 3) positions [m]; dt [s]; mass (N,) lumped masses [kg], positive and finite (ValueError
            otherwise); held (N,) bool; eta [m].

    Returns:
        {"collisions": the first detection's collisions, "rounds": detections run, "zone_nodes": nodes in zones,
        "left": collisions of the last detection (0: the step is collision-free), "released": held nodes
        released}.
    """
    if not (np.isfinite(mass).all() and (mass > 0.0).all()):
        raise ValueError("impact zones: the lumped masses must be positive and finite (a zone of zero total mass "
                         "has no rigid velocity)")
    release = RELEASE_ROUND if release is None else release
    releasable = held if releasable is None else held & releasable
    parent = np.full(len(x), -1, dtype=np.int64)
    released = np.zeros(len(x), dtype=bool)
    report = {"collisions": 0, "rounds": 0, "zone_nodes": 0, "left": 0, "released": 0}
    for round_ in range(iterations + 1):
        vertex, triangle, triangles, first, second, edges = candidates(u)
        hit, _ = detect(vertex, triangle, triangles, first, second, edges, x, dt * u, eta, comm)
        count = int(hit.sum())
        report["rounds"], report["left"] = round_ + 1, count
        if round_ == 0:
            report["collisions"] = count
        if count == 0 or round_ == iterations:
            break
        nodes = pair_nodes(vertex, triangle, triangles, first, second, edges)[hit]
        report["zone_nodes"] = merge(nodes, parent, comm)
        if joined is not None and len(joined):
            stitch_groups.join_zones(joined, parent, lambda rows, zones: merge(rows, zones, comm))
            report["zone_nodes"] = int((parent >= 0).sum())
        if round_ >= release:              # the zones still colliding: their held nodes join the rigid motion
            released |= np.isin(parent, parent[nodes.ravel()]) & releasable
            report["released"] = int(released.sum())
        rigid(parent, x, u, mass, held & ~released, comm)
    return report
