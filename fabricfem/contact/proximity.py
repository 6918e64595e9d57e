"""Vertex-triangle proximity of a triangulated surface: all (vertex, triangle) pairs closer than a radius.

The pairs are what cloth-cloth contact (fabricfem.contact.self_contact) acts on: a vertex p and a triangle
(a, b, c) of the cloth's surface triangulation whose distance |x_p - x_c| < r, with x_c the closest point of the
triangle to x_p and its barycentric coordinates (w_a, w_b, w_c) [Ericson2005, sec. 5.1.5]. A vertex of the
triangle's own cell (`cell_nodes`) is not paired with it.

Two routes give the same pairs:

* `compiled_pairs`: a spatial hash in C (cffi, fabricfem.forms.jit.compile_c) [Teschner2003]: every triangle is
  inserted into the cells of a uniform grid (cell size: the largest extent of a triangle's box inflated by r)
  that its inflated box touches, each vertex visits the one cell it lies in, and the exact distance of every
  candidate decides, in the same loop. This is the route the explicit step takes.
* `ipctk_pairs`: ipctk's broad phase (`ipctk.HashGrid`, [Li2020]) for the candidates, then `closest_points`
  (numpy) on them. ipctk returns its candidates as a Python list of objects, so the conversion to arrays is a
  loop in Python over the candidates; measured in the commit that added this module (tests check the two routes
  agree).

`closest_points` (numpy, vectorised over pairs) is also the brute-force reference of the tests. Units: metres.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import ipctk
import numpy as np

from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

CDEF = """
int64_t vertex_triangle_pairs(int64_t N, const double* x, int64_t T, const int64_t* tri, const int64_t* tri_cell,
                              const int64_t* cell_nodes, int64_t per_cell, double radius, int64_t capacity,
                              int64_t* pair_p, int64_t* pair_t, double* distance, double* bary);
"""

# the headers and the closest point of a triangle [Ericson2005, sec. 5.1.5], shared with
# fabricfem.contact.cloth_kernel (its narrow phase finds the same distances)
CLOSEST_C = r"""
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

static inline uint64_t bucket(int64_t i, int64_t j, int64_t k, uint64_t mask)
{
  return (((uint64_t)i * 73856093u) ^ ((uint64_t)j * 19349663u) ^ ((uint64_t)k * 83492791u)) & mask;
}

static inline double dot3(const double* u, const double* v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; }

/* the Coulomb friction force ff of a pair [Bridson2002, sec. 7]: the tangential relative velocity vt = vr - vn n
   opposed by min(mu fn, m_eff |vt| / dt) (at most the force that stops the slip in one step); 0 for mu = 0 */
static inline void coulomb_friction(const double* vr, double vn, const double* normal, double mu, double fn,
                                    double m_eff, double dt, double* ff)
{
  ff[0] = ff[1] = ff[2] = 0.0;
  if (!(mu > 0.0))
    return;
  double vt[3];
  for (int k = 0; k < 3; ++k)
    vt[k] = vr[k] - vn * normal[k];
  const double speed = sqrt(dot3(vt, vt));
  const double scale = fmin(mu * fn, m_eff * speed / dt) / (speed > 0.0 ? speed : 1.0);
  for (int k = 0; k < 3; ++k)
    ff[k] = -scale * vt[k];
}

/* the unit contact normal of a pair: offset / distance, or, for two points closer than `tiny`, the unit normal
   e1 x e2 of the plane of the pair's edges e1, e2 */
static inline void contact_normal(const double* e1, const double* e2, const double* offset, double distance,
                                  double tiny, double* normal)
{
  if (distance < tiny)
  {
    normal[0] = e1[1] * e2[2] - e1[2] * e2[1];
    normal[1] = e1[2] * e2[0] - e1[0] * e2[2];
    normal[2] = e1[0] * e2[1] - e1[1] * e2[0];
    const double length = sqrt(dot3(normal, normal));
    for (int k = 0; k < 3; ++k)
      normal[k] /= length;
  }
  else
    for (int k = 0; k < 3; ++k)
      normal[k] = offset[k] / distance;
}

/* closest point of triangle abc to p [Ericson2005, sec. 5.1.5]: barycentric coordinates w, squared distance */
static double closest(const double* p, const double* a, const double* b, const double* c, double* w)
{
  double ab[3], ac[3], ap[3], bp[3], cp[3];
  for (int i = 0; i < 3; ++i)
  {
    ab[i] = b[i] - a[i], ac[i] = c[i] - a[i], ap[i] = p[i] - a[i];
    bp[i] = p[i] - b[i], cp[i] = p[i] - c[i];
  }
  const double d1 = dot3(ab, ap), d2 = dot3(ac, ap), d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
  const double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  if (d1 <= 0.0 && d2 <= 0.0) { w[0] = 1.0, w[1] = 0.0, w[2] = 0.0; }
  else if (d3 >= 0.0 && d4 <= d3) { w[0] = 0.0, w[1] = 1.0, w[2] = 0.0; }
  else if (d6 >= 0.0 && d5 <= d6) { w[0] = 0.0, w[1] = 0.0, w[2] = 1.0; }
  else if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) { const double v = d1 / (d1 - d3); w[0] = 1.0 - v, w[1] = v, w[2] = 0.0; }
  else if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) { const double v = d2 / (d2 - d6); w[0] = 1.0 - v, w[1] = 0.0, w[2] = v; }
  else if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
  {
    const double v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    w[0] = 0.0, w[1] = 1.0 - v, w[2] = v;
  }
  else
  {
    const double denom = 1.0 / (va + vb + vc);
    w[1] = vb * denom, w[2] = vc * denom, w[0] = 1.0 - w[1] - w[2];
  }
  double s = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    const double e = p[i] - (w[0] * a[i] + w[1] * b[i] + w[2] * c[i]);
    s += e * e;
  }
  return s;
}
"""

SOURCE = CLOSEST_C + r"""
/* all (vertex, triangle) pairs closer than radius (a vertex of the triangle's cell excluded); returns their number
   (only the first `capacity` are written), -1 if out of memory */
int64_t vertex_triangle_pairs(int64_t N, const double* x, int64_t T, const int64_t* tri, const int64_t* tri_cell,
                              const int64_t* cell_nodes, int64_t per_cell, double radius, int64_t capacity,
                              int64_t* pair_p, int64_t* pair_t, double* distance, double* bary)
{
  if (T == 0 || N == 0)
    return 0;
  double* box = malloc(sizeof(double) * 6 * T);
  double cell = 0.0;
  for (int64_t t = 0; t < T; ++t)
  {
    double* bx = box + 6 * t;
    for (int i = 0; i < 3; ++i)
    {
      double lo = INFINITY, hi = -INFINITY;
      for (int v = 0; v < 3; ++v)
      {
        const double xv = x[3 * tri[3 * t + v] + i];
        lo = fmin(lo, xv), hi = fmax(hi, xv);
      }
      bx[i] = lo - radius, bx[3 + i] = hi + radius;
      cell = fmax(cell, bx[3 + i] - bx[i]);
    }
  }
  uint64_t size = 1;
  while (size < (uint64_t)(4 * T))
    size <<= 1;
  const uint64_t mask = size - 1;
  int64_t* start = calloc(size + 1, sizeof(int64_t));
  int64_t* seen = malloc(sizeof(int64_t) * T);
  for (int pass = 0; pass < 2; ++pass)     /* pass 0 counts the entries per bucket, pass 1 files them */
  {
    int64_t* entries = pass ? malloc(sizeof(int64_t) * start[size]) : NULL;
    int64_t* fill = pass ? malloc(sizeof(int64_t) * size) : NULL;
    if (pass)
      for (uint64_t b = 0; b < size; ++b)
        fill[b] = start[b];
    for (int64_t t = 0; t < T; ++t)
    {
      const double* bx = box + 6 * t;
      const int64_t i0 = (int64_t)floor(bx[0] / cell), i1 = (int64_t)floor(bx[3] / cell);
      const int64_t j0 = (int64_t)floor(bx[1] / cell), j1 = (int64_t)floor(bx[4] / cell);
      const int64_t k0 = (int64_t)floor(bx[2] / cell), k1 = (int64_t)floor(bx[5] / cell);
      for (int64_t i = i0; i <= i1; ++i)
        for (int64_t j = j0; j <= j1; ++j)
          for (int64_t k = k0; k <= k1; ++k)
          {
            const uint64_t b = bucket(i, j, k, mask);
            if (pass)
              entries[fill[b]++] = t;
            else
              start[b + 1]++;
          }
    }
    if (!pass)
    {
      for (uint64_t b = 0; b < size; ++b)
        start[b + 1] += start[b];
      continue;
    }
    free(fill);
    for (int64_t t = 0; t < T; ++t)
      seen[t] = -1;
    int64_t n = 0;
    const double r2 = radius * radius;
    for (int64_t p = 0; p < N; ++p)
    {
      const double* xp = x + 3 * p;
      const uint64_t b = bucket((int64_t)floor(xp[0] / cell), (int64_t)floor(xp[1] / cell),
                                (int64_t)floor(xp[2] / cell), mask);
      for (int64_t e = start[b]; e < start[b + 1]; ++e)
      {
        const int64_t t = entries[e];
        if (seen[t] == p)
          continue;
        seen[t] = p;
        const double* bx = box + 6 * t;
        if (xp[0] < bx[0] || xp[0] > bx[3] || xp[1] < bx[1] || xp[1] > bx[4] || xp[2] < bx[2] || xp[2] > bx[5])
          continue;
        const int64_t* own = cell_nodes + per_cell * tri_cell[t];
        int mine = 0;
        for (int64_t q = 0; q < per_cell; ++q)
          mine |= own[q] == p;
        if (mine)
          continue;
        double w[3];
        const double s = closest(xp, x + 3 * tri[3 * t], x + 3 * tri[3 * t + 1], x + 3 * tri[3 * t + 2], w);
        if (!(s < r2))
          continue;
        if (n < capacity)
        {
          pair_p[n] = p, pair_t[n] = t, distance[n] = sqrt(s);
          bary[3 * n] = w[0], bary[3 * n + 1] = w[1], bary[3 * n + 2] = w[2];
        }
        ++n;
      }
    }
    free(entries);
    free(start);
    free(seen);
    free(box);
    return n;
  }
  return -1;
}
"""

def _module(comm):
    """(lib, ffi) of the compiled loops, built on first use (rank 0 of `comm` builds, the others wait)."""
    return built_once("fabricfem_proximity", CDEF, SOURCE, comm, KERNEL_FLAGS)


@dataclass
class Pairs:
    """Vertex-triangle pairs closer than the search radius.

    Attributes:
        vertex: (n,) int64 vertex indices p.
        triangle: (n,) int64 triangle indices t.
        distance: (n,) |x_p - x_c| [m].
        bary: (n, 3) barycentric coordinates of the closest point x_c in the triangle's nodes.
    """

    vertex: np.ndarray
    triangle: np.ndarray
    distance: np.ndarray
    bary: np.ndarray

    def __len__(self) -> int:
        return len(self.vertex)

    def sorted(self) -> "Pairs":
        """The pairs ordered by (vertex, triangle) (the routes find them in different orders)."""
        order = np.lexsort((self.triangle, self.vertex))
        return Pairs(self.vertex[order], self.triangle[order], self.distance[order], self.bary[order])

    def subset(self, keep: np.ndarray) -> "Pairs":
        return Pairs(self.vertex[keep], self.triangle[keep], self.distance[keep], self.bary[keep])


def compiled_pairs(x: np.ndarray, triangles: np.ndarray, triangle_cell: np.ndarray, cell_nodes: np.ndarray,
                   radius: float, comm) -> Pairs:
    """All pairs (p, t) with dist(x_p, triangle t) < radius [m], p not a node of t's cell, by the compiled hash.

    Args:
        x: (N, 3) vertex positions [m]; triangles: (T, 3) vertex indices; triangle_cell: (T,) the cell of each
            triangle (a row of `cell_nodes`); cell_nodes: (C, k) the nodes of each cell; comm: for the build.
    """
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    arrays = [np.ascontiguousarray(a, dtype=dt) for a, dt in
              ((x, float), (triangles, np.int64), (triangle_cell, np.int64), (cell_nodes, np.int64))]
    capacity = max(64, 4 * len(x))
    while True:
        out = (np.empty(capacity, np.int64), np.empty(capacity, np.int64), np.empty(capacity),
               np.empty((capacity, 3)))
        n = lib.vertex_triangle_pairs(len(arrays[0]), p(arrays[0], "double"), len(arrays[1]),
                                      p(arrays[1], "int64_t"), p(arrays[2], "int64_t"), p(arrays[3], "int64_t"),
                                      arrays[3].shape[1], float(radius), capacity, p(out[0], "int64_t"),
                                      p(out[1], "int64_t"), p(out[2], "double"), p(out[3], "double"))
        if n < 0:
            raise MemoryError("vertex_triangle_pairs: out of memory")
        if n <= capacity:
            return Pairs(out[0][:n], out[1][:n], out[2][:n], out[3][:n])
        capacity = int(n)


def closest_points(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates (n, 3) of the closest points of the triangles (a, b, c) to the points p, and the
    distances (n,) [m] ([Ericson2005, sec. 5.1.5], the same regions as the compiled search; numpy, all (n, 3))."""
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    w = np.zeros((len(p), 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        total = va + vb + vc
        w[:, 1], w[:, 2] = vb / total, vc / total
        w[:, 0] = 1.0 - w[:, 1] - w[:, 2]
        # the regions in the reverse order of the compiled cascade, so that the first true condition is written last
        va_edge = (va <= 0.0) & (d4 - d3 >= 0.0) & (d5 - d6 >= 0.0)
        s = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        w[va_edge] = np.stack([np.zeros_like(s), 1.0 - s, s], axis=1)[va_edge]
        vb_edge = (vb <= 0.0) & (d2 >= 0.0) & (d6 <= 0.0)
        s = d2 / (d2 - d6)
        w[vb_edge] = np.stack([1.0 - s, np.zeros_like(s), s], axis=1)[vb_edge]
        vc_edge = (vc <= 0.0) & (d1 >= 0.0) & (d3 <= 0.0)
        s = d1 / (d1 - d3)
        w[vc_edge] = np.stack([1.0 - s, s, np.zeros_like(s)], axis=1)[vc_edge]
    for region, k in (((d6 >= 0.0) & (d5 <= d6), 2), ((d3 >= 0.0) & (d4 <= d3), 1), ((d1 <= 0.0) & (d2 <= 0.0), 0)):
        w[region] = np.eye(3)[k]
    closest = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    return w, np.linalg.norm(p - closest, axis=1)


def brute_force_pairs(x: np.ndarray, triangles: np.ndarray, triangle_cell: np.ndarray, cell_nodes: np.ndarray,
                      radius: float) -> Pairs:
    """The pairs of `compiled_pairs` by testing every (vertex, triangle) pair (numpy; small meshes only)."""
    p, t = (g.ravel() for g in np.meshgrid(np.arange(len(x)), np.arange(len(triangles)), indexing="ij"))
    return _narrow(x, triangles, triangle_cell, cell_nodes, radius, p, t)


def ipctk_pairs(x: np.ndarray, triangles: np.ndarray, triangle_cell: np.ndarray, cell_nodes: np.ndarray,
                radius: float) -> Pairs:
    """The pairs of `compiled_pairs` with ipctk's HashGrid as the broad phase (candidates converted in Python)."""
    grid = ipctk.HashGrid()
    faces = np.asfortranarray(triangles, dtype=np.int32)
    grid.build(np.asfortranarray(x, dtype=float), np.asfortranarray(ipctk.edges(faces)), faces, radius / 2.0)
    candidates = grid.detect_face_vertex_candidates()
    pt = np.array([(c.vertex_id, c.face_id) for c in candidates], dtype=np.int64).reshape(-1, 2)
    return _narrow(x, triangles, triangle_cell, cell_nodes, radius, pt[:, 0], pt[:, 1])


def _narrow(x, triangles, triangle_cell, cell_nodes, radius, p, t) -> Pairs:
    """The candidates (p, t) closer than radius whose vertex is not a node of the triangle's cell."""
    own = (cell_nodes[triangle_cell[t]] == p[:, None]).any(axis=1)
    p, t = p[~own], t[~own]
    tri = triangles[t]
    w, dist = closest_points(x[p], x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]])
    keep = dist < radius
    return Pairs(p[keep].astype(np.int64), t[keep].astype(np.int64), dist[keep], w[keep])
