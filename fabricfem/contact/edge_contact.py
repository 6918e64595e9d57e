"""Edge-edge proximity of a cloth's surface triangulation and its penalty-friction response, compiled: the part of
cloth-cloth contact (fabricfem.contact.self_contact) that holds two edges crossing each other with no vertex of
either layer within the contact distance of the other's triangles ([Bridson2002, sec. 6]: "vertex-triangle and
edge-edge proximity").

Geometry: the edges are the unique sides of the surface triangles (`surface_edges`). For two edges (a0, a1) and
(b0, b1) that share no node, the closest points x_a = (1 - s) x_a0 + s x_a1 and x_b = (1 - t) x_b0 + t x_b1 of the
two segments ([Ericson2005, sec. 5.1.9]: s, t clamped to [0, 1] in turn) give delta = |x_a - x_b| [m]. A pair
takes contact when delta < d_c and both closest points lie inside their edges (tol < s, t < 1 - tol, tol the
feature tolerance) and the edges are not parallel (sin^2 of their angle > 1e-12): a closest point at an end node is
a vertex near the other layer, which the vertex-triangle pairs already hold ([Bridson2002, sec. 6]; counting it here
too would double its spring).

Broad phase (`compiled_pairs`): a spatial hash in C [Teschner2003], as fabricfem.contact.proximity's: every edge's
box inflated by r goes into the cells of a uniform grid (cell size: the largest inflated extent) it touches; each
edge visits the cells of its own box and tests the edges of higher index there whose boxes overlap (box gap < r on
every axis, necessary for delta < r). `narrow` recomputes the distances of a kept candidate list (the Verlet list of
fabricfem.contact.cloth_kernel [Verlet1967]: the distance of two segments changes by at most the largest
displacement of their four nodes times 2, so the candidates within d_c + s of the last search hold every pair now
within d_c while no node moved more than s / 2).

Response (`respond`, one C loop over the pairs; `respond_numpy` its numpy twin), the law of the vertex-triangle
pairs ([Bridson2002, sec. 7.1-7.2]) with the four nodes' barycentric weights w = (1 - s, s, -(1 - t), -t):

    n = (x_a - x_b) / delta (or e_a x e_b / |e_a x e_b| where delta < 1e-9 d_c),    v_rel = sum_k w_k v_k
    1 / m_eff = sum_k w_k^2 / m_k,    1 / A_eff = sum_k w_k^2 / A_k,    share = eta / max_k n_k
    eta = min(1, min(s, 1 - s, t, 1 - t) / tau)
    f_e = k_N share A_eff (d_c - delta),   f_N = f_e + clip(-c v_N, -f_e, f_e),   c = 2 zeta sqrt(k_N share A_eff m_eff)
    f_T = -min(mu f_N, m_eff |v_T| / dt) v_T / |v_T|,   v_T = v_rel - v_N n,   f = f_N n + f_T on node k: w_k f

A_k are the nodes' lumped reference areas [m^2] (1 / A = 0 and 1 / m = 0 for a held node), n_k the number of
edge-edge pairs acting on node k in the step. A_eff is the pair's reduced area, the analogue of its reduced mass, so
that one pair's spring k_N share A_eff on m_eff ~ rho t A_eff has the frequency sqrt(share k_N / (rho t)), at most
half the vertex-triangle pairs' bound sqrt(4 k_N / (rho t)) (SelfContact.penalty_frequency); and since
w_k^2 A_eff <= A_k, the share bounds what all edge-edge pairs on node k add to its stiffness by k_N A_k, one
vertex-triangle spring. Sharing per edge instead (n_a, n_b) left a node in the pairs of its 6-8 edges with up to
that many springs: two pressed concentric tubes (fabricfem.verify.layers) then chattered at the step's Nyquist
frequency (the monitor's mean pressure 67 instead of 100 Pa; 99.0 Pa shared per node). Three departures from the
vertex-triangle law, all found on layers pressed together (fabricfem.verify.self_contact, fabricfem.verify.layers):

* the damper is bounded by the spring's force ([Hunt1975]: a contact damping that vanishes with the penetration):
  at the first touch the edge pairs' dampers added to the vertex-triangle pairs' reversed the landing velocity
  within a step and the sheets bounced apart (the press never settled);
* eta tapers the spring over the last tau = TAPER of either edge's length, so that the force is continuous where a
  pair ends because its closest point reaches an edge's end (the vertex-triangle pairs of that end node take over
  there): at full force to the end, the pairs of a sheet sliding over another switched on and off, the sheets
  chattered and the friction fell 2.3 % short of mu N (-0.25 % with the taper).

* the per-node share above.

Momentum is conserved (sum_k w_k = 0). Units: metres, seconds, kilograms, newtons.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from fabricfem.contact.proximity import CLOSEST_C
from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

PARALLEL = 1e-12          # sin^2 of the angle of two edges below which they count as parallel (no edge-edge pair)
TAPER = 0.1               # tau: the spring fades linearly over the last tau of an edge's length at either end

CDEF = """
int64_t edge_edge_pairs(int64_t N, const double* x, int64_t E, const int64_t* edges, double radius, int interior,
                        double tolerance, int64_t capacity, int64_t* first, int64_t* second, double* distance,
                        double* s, double* t);
int64_t narrow_edges(const double* x, int64_t M, const int64_t* cand_a, const int64_t* cand_b, const int64_t* edges,
                     double radius, double tolerance, int64_t* first, int64_t* second, double* distance, double* s,
                     double* t);
void respond_edges(int64_t n, const int64_t* first, const int64_t* second, const double* distance, const double* s,
                   const double* t, const double* share, const int64_t* edges, const double* x, const double* v,
                   const double* inverse_mass, const double* inverse_area, double penalty, double contact_distance,
                   double zeta, double mu, double dt, double* normal_force, double* friction_force);
"""

SOURCE = "#pragma GCC diagnostic ignored \"-Wunused-function\"\n" + CLOSEST_C + r"""
static inline double clamp01(double u) { return u < 0.0 ? 0.0 : (u > 1.0 ? 1.0 : u); }

/* closest points of the segments p1 q1 and p2 q2 [Ericson2005, sec. 5.1.9]: parameters s, t, sin^2 of their angle;
   returns the squared distance (INFINITY for a segment of zero length) */
static double segments(const double* p1, const double* q1, const double* p2, const double* q2, double* s, double* t,
                       double* sine2)
{
  double d1[3], d2[3], r[3];
  for (int i = 0; i < 3; ++i)
    d1[i] = q1[i] - p1[i], d2[i] = q2[i] - p2[i], r[i] = p1[i] - p2[i];
  const double a = dot3(d1, d1), e = dot3(d2, d2), f = dot3(d2, r), c = dot3(d1, r), b = dot3(d1, d2);
  if (!(a > 0.0) || !(e > 0.0))
    return INFINITY;
  const double denom = a * e - b * b;
  *sine2 = denom / (a * e);
  double ss = denom > 0.0 ? clamp01((b * f - c * e) / denom) : 0.0;
  double tt = (b * ss + f) / e;
  if (tt < 0.0)
    tt = 0.0, ss = clamp01(-c / a);
  else if (tt > 1.0)
    tt = 1.0, ss = clamp01((b - c) / a);
  double d2s = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    const double g = p1[i] + ss * d1[i] - p2[i] - tt * d2[i];
    d2s += g * g;
  }
  *s = ss, *t = tt;
  return d2s;
}

/* 1 if the edges a and b share no node and are closer than sqrt(r2); with `interior`, also their closest points
   inside both edges (tolerance) and the edges not parallel (sin^2 > PARALLEL) */
static int64_t test_pair(const double* x, const int64_t* edges, int64_t a, int64_t b, double r2, int interior,
                         double tolerance, double* s, double* t, double* d2s)
{
  const int64_t* ea = edges + 2 * a;
  const int64_t* eb = edges + 2 * b;
  if (ea[0] == eb[0] || ea[0] == eb[1] || ea[1] == eb[0] || ea[1] == eb[1])
    return 0;
  double sine2 = 0.0;
  *d2s = segments(x + 3 * ea[0], x + 3 * ea[1], x + 3 * eb[0], x + 3 * eb[1], s, t, &sine2);
  if (!(*d2s < r2))
    return 0;
  if (interior && !(sine2 > PARALLEL_SINE2 && *s > tolerance && *s < 1.0 - tolerance && *t > tolerance
                    && *t < 1.0 - tolerance))
    return 0;
  return 1;
}

/* the edge pairs a < b of test_pair by the hash (module docstring); returns their number (the first `capacity`
   written) */
int64_t edge_edge_pairs(int64_t N, const double* x, int64_t E, const int64_t* edges, double radius, int interior,
                        double tolerance, int64_t capacity, int64_t* first, int64_t* second, double* distance,
                        double* s, double* t)
{
  if (E == 0 || N == 0)
    return 0;
  double* box = malloc(sizeof(double) * 6 * E);
  double cell = 0.0;
  for (int64_t e = 0; e < E; ++e)
    for (int i = 0; i < 3; ++i)
    {
      const double u = x[3 * edges[2 * e] + i], w = x[3 * edges[2 * e + 1] + i];
      box[6 * e + i] = fmin(u, w), box[6 * e + 3 + i] = fmax(u, w);
      cell = fmax(cell, box[6 * e + 3 + i] - box[6 * e + i] + 2.0 * radius);
    }
  uint64_t size = 1;
  while (size < (uint64_t)(4 * E))
    size <<= 1;
  const uint64_t mask = size - 1;
  int64_t* start = calloc(size + 1, sizeof(int64_t));
  int64_t* fill = malloc(sizeof(int64_t) * size);
  int64_t* seen = malloc(sizeof(int64_t) * E);
  int64_t* entries = NULL;
  for (int pass = 0; pass < 2; ++pass)     /* pass 0 counts the entries per bucket, pass 1 files them */
  {
    if (pass)
    {
      entries = malloc(sizeof(int64_t) * (start[size] > 0 ? start[size] : 1));
      for (uint64_t b = 0; b < size; ++b)
        fill[b] = start[b];
    }
    for (int64_t e = 0; e < E; ++e)
    {
      const double* bx = box + 6 * e;
      for (int64_t i = (int64_t)floor((bx[0] - radius) / cell); i <= (int64_t)floor((bx[3] + radius) / cell); ++i)
        for (int64_t j = (int64_t)floor((bx[1] - radius) / cell); j <= (int64_t)floor((bx[4] + radius) / cell); ++j)
          for (int64_t k = (int64_t)floor((bx[2] - radius) / cell); k <= (int64_t)floor((bx[5] + radius) / cell); ++k)
          {
            const uint64_t b = bucket(i, j, k, mask);
            if (pass)
              entries[fill[b]++] = e;
            else
              start[b + 1]++;
          }
    }
    if (!pass)
      for (uint64_t b = 0; b < size; ++b)
        start[b + 1] += start[b];
  }
  for (int64_t e = 0; e < E; ++e)
    seen[e] = -1;
  int64_t n = 0;
  const double r2 = radius * radius;
  for (int64_t a = 0; a < E; ++a)
  {
    const double* ba = box + 6 * a;
    for (int64_t i = (int64_t)floor(ba[0] / cell); i <= (int64_t)floor(ba[3] / cell); ++i)
      for (int64_t j = (int64_t)floor(ba[1] / cell); j <= (int64_t)floor(ba[4] / cell); ++j)
        for (int64_t k = (int64_t)floor(ba[2] / cell); k <= (int64_t)floor(ba[5] / cell); ++k)
        {
          const uint64_t b = bucket(i, j, k, mask);
          for (int64_t q = start[b]; q < start[b + 1]; ++q)
          {
            const int64_t f = entries[q];
            if (f <= a || seen[f] == a)
              continue;
            seen[f] = a;
            const double* bf = box + 6 * f;
            int apart = 0;
            for (int c = 0; c < 3; ++c)
              apart |= ba[c] - bf[3 + c] >= radius || bf[c] - ba[3 + c] >= radius;
            double ss = 0.0, tt = 0.0, d2s = 0.0;
            if (apart || !test_pair(x, edges, a, f, r2, interior, tolerance, &ss, &tt, &d2s))
              continue;
            if (n < capacity)
              first[n] = a, second[n] = f, distance[n] = sqrt(d2s), s[n] = ss, t[n] = tt;
            ++n;
          }
        }
  }
  free(entries);
  free(fill);
  free(start);
  free(seen);
  free(box);
  return n;
}

/* the candidates whose closest points lie inside both edges closer than radius at x, in their order */
int64_t narrow_edges(const double* x, int64_t M, const int64_t* cand_a, const int64_t* cand_b, const int64_t* edges,
                     double radius, double tolerance, int64_t* first, int64_t* second, double* distance, double* s,
                     double* t)
{
  const double r2 = radius * radius;
  int64_t n = 0;
  for (int64_t m = 0; m < M; ++m)
  {
    double ss = 0.0, tt = 0.0, d2s = 0.0;
    if (!test_pair(x, edges, cand_a[m], cand_b[m], r2, 1, tolerance, &ss, &tt, &d2s))
      continue;
    first[n] = cand_a[m], second[n] = cand_b[m], distance[n] = sqrt(d2s), s[n] = ss, t[n] = tt;
    ++n;
  }
  return n;
}

void respond_edges(int64_t n, const int64_t* first, const int64_t* second, const double* distance, const double* s,
                   const double* t, const double* share, const int64_t* edges, const double* x, const double* v,
                   const double* inverse_mass, const double* inverse_area, double penalty, double contact_distance,
                   double zeta, double mu, double dt, double* normal_force, double* friction_force)
{
  for (int64_t i = 0; i < n; ++i)
  {
    const int64_t node[4] = {edges[2 * first[i]], edges[2 * first[i] + 1], edges[2 * second[i]],
                             edges[2 * second[i] + 1]};
    const double w[4] = {1.0 - s[i], s[i], -(1.0 - t[i]), -t[i]};
    double offset[3] = {0.0, 0.0, 0.0}, vr[3] = {0.0, 0.0, 0.0}, normal[3];
    double im = 0.0, ia = 0.0;
    for (int q = 0; q < 4; ++q)
    {
      for (int k = 0; k < 3; ++k)
        offset[k] += w[q] * x[3 * node[q] + k], vr[k] += w[q] * v[3 * node[q] + k];
      im += w[q] * w[q] * inverse_mass[node[q]], ia += w[q] * w[q] * inverse_area[node[q]];
    }
    double e1[3], e2[3];
    for (int k = 0; k < 3; ++k)
      e1[k] = x[3 * node[1] + k] - x[3 * node[0] + k], e2[k] = x[3 * node[3] + k] - x[3 * node[2] + k];
    contact_normal(e1, e2, offset, distance[i], 1e-9 * contact_distance, normal);
    if (!(im > 0.0) || !(ia > 0.0))      /* all four nodes held */
      continue;
    const double m_eff = 1.0 / im;
    const double spring = penalty * share[i] / ia;
    const double vn = dot3(vr, normal);
    const double elastic = spring * (contact_distance - distance[i]);
    const double fn = elastic + fmax(-elastic, fmin(-2.0 * zeta * sqrt(spring * m_eff) * vn, elastic));
    double ff[3];
    coulomb_friction(vr, vn, normal, mu, fn, m_eff, dt, ff);
    for (int q = 0; q < 4; ++q)
      for (int k = 0; k < 3; ++k)
      {
        normal_force[3 * node[q] + k] += w[q] * fn * normal[k];
        friction_force[3 * node[q] + k] += w[q] * ff[k];
      }
  }
}
"""


def _module(comm):
    """(lib, ffi) of the compiled loops, built on first use (rank 0 of `comm` builds, the others wait)."""
    source = SOURCE.replace("PARALLEL_SINE2", repr(PARALLEL))
    return built_once("fabricfem_edge_contact", CDEF, source, comm, KERNEL_FLAGS)


@dataclass
class EdgePairs:
    """Edge-edge pairs closer than the search radius.

    Attributes:
        first, second: (n,) int64 edge indices a < b (rows of the edge array).
        distance: (n,) delta = |x_a - x_b| [m].
        s, t: (n,) the closest points' parameters along the first and the second edge.
    """

    first: np.ndarray
    second: np.ndarray
    distance: np.ndarray
    s: np.ndarray
    t: np.ndarray

    def __len__(self) -> int:
        return len(self.first)

    def sorted(self) -> "EdgePairs":
        """The pairs ordered by (first, second)."""
        return self.subset(np.lexsort((self.second, self.first)))

    def subset(self, keep: np.ndarray) -> "EdgePairs":
        return EdgePairs(self.first[keep], self.second[keep], self.distance[keep], self.s[keep], self.t[keep])

    def keys(self, count: int) -> np.ndarray:
        """(n,) int64 first * count + second (count: the number of edges)."""
        return self.first * count + self.second


def no_edge_pairs() -> EdgePairs:
    """The empty pair list."""
    return EdgePairs(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros(0), np.zeros(0))


def surface_edges(triangles: np.ndarray) -> np.ndarray:
    """(E, 2) int64 C-contiguous: the unique sides (i < j) of the triangles (T, 3), sorted."""
    sides = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.ascontiguousarray(np.unique(sides, axis=0), dtype=np.int64)


def compiled_pairs(x: np.ndarray, edges: np.ndarray, radius: float, tolerance: float, comm,
                   interior: bool = True) -> EdgePairs:
    """All edge pairs (a < b, no shared node) closer than `radius` [m] at the positions x (N, 3) [m] by the compiled
    hash (module docstring); with `interior`, only those whose closest points lie inside both edges (`tolerance`
    on s, t) and that are not parallel."""
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    x = np.ascontiguousarray(x, dtype=float)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    capacity = max(64, 4 * len(edges))
    while True:
        out = (np.empty(capacity, np.int64), np.empty(capacity, np.int64), np.empty(capacity), np.empty(capacity),
               np.empty(capacity))
        n = lib.edge_edge_pairs(len(x), p(x, "double"), len(edges), p(edges, "int64_t"), float(radius),
                                int(interior), float(tolerance), capacity, p(out[0], "int64_t"), p(out[1], "int64_t"),
                                *(p(a, "double") for a in out[2:]))
        if n <= capacity:
            return EdgePairs(*(a[:n] for a in out))
        capacity = int(n)


def narrow(x: np.ndarray, candidates: EdgePairs, edges: np.ndarray, radius: float, tolerance: float,
           comm) -> EdgePairs:
    """The candidates that take contact at the positions x (N, 3) [m] (closer than `radius` [m], closest points
    inside both edges, not parallel), in the candidates' order. x and `edges` C-contiguous."""
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    M = len(candidates)
    out = (np.empty(M, np.int64), np.empty(M, np.int64), np.empty(M), np.empty(M), np.empty(M))
    n = lib.narrow_edges(p(x, "double"), M, p(candidates.first, "int64_t"), p(candidates.second, "int64_t"),
                         p(edges, "int64_t"), float(radius), float(tolerance), p(out[0], "int64_t"),
                         p(out[1], "int64_t"), *(p(a, "double") for a in out[2:]))
    return EdgePairs(*(a[:n] for a in out))


def shares(pairs: EdgePairs, edges: np.ndarray, count: int) -> np.ndarray:
    """(n,) eta / max_k n_k: n_k the number of the pairs acting on node k of the pair (`count` nodes, `edges` (E, 2)
    their node indices), eta the taper at the edges' ends (module docstring)."""
    nodes = np.concatenate([edges[pairs.first], edges[pairs.second]], axis=1)
    per_node = np.bincount(nodes.ravel(), minlength=count)
    end = np.minimum(np.minimum(pairs.s, 1.0 - pairs.s), np.minimum(pairs.t, 1.0 - pairs.t))
    return np.minimum(1.0, end / TAPER) / per_node[nodes].max(axis=1, initial=1)


def respond(pairs: EdgePairs, share: np.ndarray, edges: np.ndarray, x: np.ndarray, v: np.ndarray,
            inverse_mass: np.ndarray, inverse_area: np.ndarray, law: tuple[float, float, float, float, float],
            normal_force: np.ndarray, friction_force: np.ndarray, comm) -> None:
    """Add the pairs' forces [N] to normal_force and friction_force (N, 3) (module docstring). share (n,) from
    `shares`; x, v (N, 3) [m], [m/s]; inverse_mass (N,) [1/kg], inverse_area (N,) [1/m^2] (0 for a held node);
    law = (k_N [Pa/m], d_c [m], zeta, mu, dt [s]). Every array C-contiguous of its dtype."""
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    c = np.ascontiguousarray
    lib.respond_edges(len(pairs), p(c(pairs.first), "int64_t"), p(c(pairs.second), "int64_t"),
                      *(p(c(a, dtype=float), "double") for a in (pairs.distance, pairs.s, pairs.t, share)),
                      p(edges, "int64_t"), p(x, "double"), p(v, "double"), p(inverse_mass, "double"),
                      p(inverse_area, "double"), *(float(value) for value in law), p(normal_force, "double"),
                      p(friction_force, "double"))


# ---------------------------------------------------------------------------- numpy twins (tests, references)
def closest_segment_points(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray,
                           q2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(s, t, distance [m], sin^2 of the angle) of the closest points of the segments p1 q1 and p2 q2 (n, 3) each
    ([Ericson2005, sec. 5.1.9], the branches of the compiled routine; segments of positive length)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2

    def dot(u, w):
        return np.einsum("ij,ij->i", u, w)

    a, e, f, c, b = dot(d1, d1), dot(d2, d2), dot(d2, r), dot(d1, r), dot(d1, d2)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 0.0, np.clip((b * f - c * e) / np.where(denom > 0.0, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e
    low, high = t < 0.0, t > 1.0
    s = np.where(low, np.clip(-c / a, 0.0, 1.0), np.where(high, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    gap = p1 + s[:, None] * d1 - p2 - t[:, None] * d2
    return s, t, np.linalg.norm(gap, axis=1), denom / (a * e)


def brute_force_pairs(x: np.ndarray, edges: np.ndarray, radius: float, tolerance: float,
                      interior: bool = True) -> EdgePairs:
    """The pairs of `compiled_pairs` by testing every pair of edges (numpy; small meshes only)."""
    a, b = np.triu_indices(len(edges), k=1)
    ea, eb = edges[a], edges[b]
    shared = (ea[:, :, None] == eb[:, None, :]).any(axis=(1, 2))
    a, b, ea, eb = a[~shared], b[~shared], ea[~shared], eb[~shared]
    s, t, distance, sine2 = closest_segment_points(x[ea[:, 0]], x[ea[:, 1]], x[eb[:, 0]], x[eb[:, 1]])
    keep = distance < radius
    if interior:
        keep &= (sine2 > PARALLEL) & (s > tolerance) & (s < 1.0 - tolerance) & (t > tolerance) & (t < 1.0 - tolerance)
    return EdgePairs(a[keep].astype(np.int64), b[keep].astype(np.int64), distance[keep], s[keep], t[keep])


def respond_numpy(pairs: EdgePairs, share: np.ndarray, edges: np.ndarray, x: np.ndarray, v: np.ndarray,
                  inverse_mass: np.ndarray, inverse_area: np.ndarray,
                  law: tuple[float, float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The (N, 3) normal and friction forces [N] of `respond` (module docstring), vectorised over the pairs."""
    penalty, d_c, zeta, mu, dt = law
    nodes = np.concatenate([edges[pairs.first], edges[pairs.second]], axis=1)           # (n, 4)
    w = np.stack([1.0 - pairs.s, pairs.s, pairs.t - 1.0, -pairs.t], axis=1)
    offset = np.einsum("ij,ijk->ik", w, x[nodes])
    v_rel = np.einsum("ij,ijk->ik", w, v[nodes])
    tiny = pairs.distance < 1e-9 * d_c
    normal = offset / np.where(tiny, 1.0, pairs.distance)[:, None]
    if tiny.any():
        face = np.cross(x[nodes[tiny, 1]] - x[nodes[tiny, 0]], x[nodes[tiny, 3]] - x[nodes[tiny, 2]])
        normal[tiny] = face / np.linalg.norm(face, axis=1)[:, None]
    im = np.einsum("ij,ij->i", w ** 2, inverse_mass[nodes])
    ia = np.einsum("ij,ij->i", w ** 2, inverse_area[nodes])
    active = (im > 0.0) & (ia > 0.0)
    m_eff = 1.0 / np.where(active, im, 1.0)
    spring = np.where(active, penalty * share / np.where(active, ia, 1.0), 0.0)
    v_n = np.einsum("ij,ij->i", v_rel, normal)
    elastic = spring * (d_c - pairs.distance)
    f_n = elastic + np.clip(-2.0 * zeta * np.sqrt(spring * m_eff) * v_n, -elastic, elastic)
    f_t = np.zeros_like(normal)
    if mu > 0.0:
        v_t = v_rel - v_n[:, None] * normal
        speed = np.linalg.norm(v_t, axis=1)
        f_t = -(np.minimum(mu * f_n, m_eff * speed / dt) / np.where(speed > 0.0, speed, 1.0))[:, None] * v_t
    out = []
    for pair_force in (f_n[:, None] * normal, f_t):
        total = np.zeros_like(x)
        for k in range(3):
            total[:, k] = np.bincount(nodes.ravel(), (w * pair_force[:, k:k + 1]).ravel(), minlength=len(x))
        out.append(total)
    return out[0], out[1]
