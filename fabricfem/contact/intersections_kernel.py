"""The compiled pass of the intersecting-pair count (fabricfem.contact.intersections, whose module docstring states
the method): one C function lists the triangle pairs of a part of the surface that pass the broad phase and, in the
same loop, decides each by the plane and interval tests, leaving the degenerate pairs to libigl.

Broad phase: a uniform grid of cells of edge h >= 2 r_max (r_max the largest circumradius about the centroid; h is
doubled while the dense grid would hold more than 4 T + 64 cells), the triangles sorted by cell (a counting sort,
cells in lexicographic order); triangle p (position in that order) meets the later triangles of its own cell and
all triangles of the 13 cells after it among its 26 neighbours, so each pair within reach is met once, by the
earlier of its two positions. Part k of `parts` is the run [k T / parts, (k + 1) T / parts) of positions: every
part computes the centroids and radii of all triangles (r_max, the cells) and sorts them, but gathers the boxes and
nodes only of the positions its pairs reach (up to the end of the layer of cells after its last triangle's).
The workspace (`workspace(T)` bytes) is the caller's, kept between calls.

The filters and tests round as the numpy expressions they replace (compiled with ROUNDING_FLAGS: no contracted
multiply-adds): centroid ((p0 + p1) + p2) / 3, Euclidean norms ((v0^2 + v1^2) + v2^2)^(1/2) (numpy's add.reduce
over a row of three; a radius is the root of the largest square, equal to the largest root: the rounded square
root is monotone), the dot products of numpy's einsum over three terms, (u0 w0 + u2 w2) + u1 w1, np.cross's
products. A pair is kept when its centroids' squared distance ((d0^2 + d1^2) + d2^2) is at most (2 r_max)^2 (the
leaf test of scipy's cKDTree.query_pairs, the broad phase this grid replaced), it shares no node, its bounding boxes
overlap and its centroids are at most r_i + r_j apart. Then (`narrow_pair`, the triangle of the smaller index first):
the plane test [Guigue2003], the degenerate cases (flag 2: libigl decides) and the interval test [Moller1997].
"""
from __future__ import annotations

from mpi4py import MPI

from fabricfem.forms.jit import ROUNDING_FLAGS, built_once

CDEF = """
int64_t workspace(int64_t T);
int64_t crossings(int64_t T, const double* x, const int64_t* tri, int64_t part, int64_t parts, double degenerate,
                  int64_t narrow, void* work, int64_t capacity, int64_t* pairs, int64_t* flags);
"""

SOURCE = r"""
#include <math.h>
#include <stdint.h>

static double norm3(const double* v) { return sqrt((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2]); }

/* np.cross(u1 - u0, u2 - u0) */
static void plane(const double* const u[3], double* n)
{
  const double a0 = u[1][0] - u[0][0], a1 = u[1][1] - u[0][1], a2 = u[1][2] - u[0][2];
  const double b0 = u[2][0] - u[0][0], b1 = u[2][1] - u[0][1], b2 = u[2][2] - u[0][2];
  n[0] = a1 * b2 - a2 * b1, n[1] = a2 * b0 - a0 * b2, n[2] = a0 * b1 - a1 * b0;
}

/* signed distances x |n| of the nodes of w to the plane (u0, n): einsum "ij,ikj->ik" */
static void sides(const double* const u[3], const double* n, const double* const w[3], double* s)
{
  for (int k = 0; k < 3; ++k)
  {
    const double d0 = w[k][0] - u[0][0], d1 = w[k][1] - u[0][1], d2 = w[k][2] - u[0][2];
    s[k] = (n[0] * d0 + n[2] * d2) + n[1] * d1;
  }
}

static int straddles(const double* s)
{
  return !((s[0] > 0.0 && s[1] > 0.0 && s[2] > 0.0) || (s[0] < 0.0 && s[1] < 0.0 && s[2] < 0.0));
}

static double extent(const double* const u[3])     /* np.ptp(u, axis=0).max() */
{
  double e = 0.0;
  for (int k = 0; k < 3; ++k)
  {
    const double hi = fmax(fmax(u[0][k], u[1][k]), u[2][k]), lo = fmin(fmin(u[0][k], u[1][k]), u[2][k]);
    e = k == 0 ? hi - lo : fmax(e, hi - lo);
  }
  return e;
}

/* [Moller1997, eq. 4]: the interval of the line (direction d) inside the triangle u, whose nodes' signed distances
   to the other plane are s (none zero); v the node alone on its side */
static void interval(const double* const u[3], const double* s, const double* d, double* lo, double* hi)
{
  double p[3];
  for (int k = 0; k < 3; ++k)
    p[k] = (u[k][0] * d[0] + u[k][2] * d[2]) + u[k][1] * d[1];
  const int positive = (s[0] > 0.0) + (s[1] > 0.0) + (s[2] > 0.0);
  int v = 0;
  while (v < 2 && (s[v] > 0.0) != (positive == 1))
    ++v;
  const int w1 = (v + 1) % 3, w2 = (v + 2) % 3;
  const double t1 = p[v] + (p[w1] - p[v]) * s[v] / (s[v] - s[w1]);
  const double t2 = p[v] + (p[w2] - p[v]) * s[v] / (s[v] - s[w2]);
  *lo = t1 < t2 ? t1 : t2, *hi = t1 < t2 ? t2 : t1;
}

/* 0: apart, 1: intersecting, 2: degenerate (a node on or near the other's plane, nearly parallel planes) */
static int narrow_pair(const double* x, const int64_t* ta, const int64_t* tb, double degenerate)
{
  const double* a[3] = {x + 3 * ta[0], x + 3 * ta[1], x + 3 * ta[2]};
  const double* b[3] = {x + 3 * tb[0], x + 3 * tb[1], x + 3 * tb[2]};
  double na[3], nb[3], sa[3], sb[3];
  plane(a, na), sides(a, na, b, sb);           /* nodes of b against the plane of a [Guigue2003] */
  plane(b, nb), sides(b, nb, a, sa);
  if (!straddles(sb) || !straddles(sa))
    return 0;
  const double ea = extent(a), eb = extent(b), size = ea < eb ? eb : ea;
  const double la = norm3(na), lb = norm3(nb), fa = degenerate * size * lb, fb = degenerate * size * la;
  for (int k = 0; k < 3; ++k)
    if (!(fabs(sa[k]) > fa) || !(fabs(sb[k]) > fb))
      return 2;
  const double d[3] = {na[1] * nb[2] - na[2] * nb[1], na[2] * nb[0] - na[0] * nb[2], na[0] * nb[1] - na[1] * nb[0]};
  if (!(norm3(d) > degenerate * (la * lb)))
    return 2;
  double loa, hia, lob, hib;
  interval(a, sa, d, &loa, &hia);
  interval(b, sb, d, &lob, &hib);
  return (loa < lob ? lob : loa) <= (hia < hib ? hia : hib);
}

/* the triangles' centroids and circumradii about them (4 T: x, y, z, r); returns r_max */
static double spheres(int64_t T, const double* x, const int64_t* tri, double* cr)
{
  double rmax = 0.0;
  for (int64_t t = 0; t < T; ++t)
  {
    const double* p[3] = {x + 3 * tri[3 * t], x + 3 * tri[3 * t + 1], x + 3 * tri[3 * t + 2]};
    double* c = cr + 4 * t;
    for (int k = 0; k < 3; ++k)
      c[k] = ((p[0][k] + p[1][k]) + p[2][k]) / 3.0;
    double r2 = 0.0;                 /* sqrt is monotone: the largest root is the root of the largest square */
    for (int m = 0; m < 3; ++m)
    {
      const double d0 = p[m][0] - c[0], d1 = p[m][1] - c[1], d2 = p[m][2] - c[2], e = (d0 * d0 + d1 * d1) + d2 * d2;
      r2 = e > r2 ? e : r2;
    }
    c[3] = sqrt(r2), rmax = c[3] > rmax ? c[3] : rmax;
  }
  return rmax;
}

typedef struct { double lo[3], hi[3]; int64_t n[3], id, key; } box_t;
typedef struct { int64_t T, C, dims[3]; double *cr, *sc; box_t* box; int64_t *key, *start; } grid_t;

int64_t workspace(int64_t T) { return (8 * T + T * (int64_t)sizeof(box_t) / 8 + T + 4 * T + 65) * 8; }

static void layout(int64_t T, void* work, grid_t* g)
{
  g->T = T, g->cr = work, g->sc = g->cr + 4 * T, g->box = (box_t*)(g->sc + 4 * T);
  g->key = (int64_t*)(g->box + T), g->start = g->key + T;
}

/* the grid's cell edge (>= reach, doubled while the dense grid would hold more than 4 T + 64 cells), dims, C */
static double cells(grid_t* g, const double* lo, const double* hi, double reach)
{
  double h = reach * (1.0 + 1e-6);
  if (!(h > 0.0) || !isfinite(h))
    h = 1.0;
  for (;; h *= 2.0)
  {
    double count = 1.0;
    for (int k = 0; k < 3; ++k)
      count *= floor((hi[k] - lo[k]) / h) + 1.0;
    if (count <= 4.0 * g->T + 64.0)
      break;
  }
  for (int k = 0; k < 3; ++k)
    g->dims[k] = (int64_t)floor((hi[k] - lo[k]) / h) + 1;
  g->C = g->dims[0] * g->dims[1] * g->dims[2];
  return h;
}

/* the end of the sorted positions that position q's forward cells reach (the end of the row of cells after q's
   row): start holds the cells' starts */
static int64_t reached(const grid_t* g, int64_t q)
{
  int64_t lo = 0, hi = g->C;                        /* the cell c of q: start[c] <= q < start[c + 1] */
  while (hi - lo > 1)
  {
    const int64_t mid = (lo + hi) / 2;
    if (g->start[mid] <= q)
      lo = mid;
    else
      hi = mid;
  }
  const int64_t layer = g->dims[1] * g->dims[2], row = (lo / layer + 2) * layer;
  return g->start[row < g->C ? row : g->C];
}

/* the triangles sorted by cell (counting sort, stable): start (C + 1); sc (their centroids and radii) and box at
   the sorted positions [first, end) that the pairs of positions [first, last) reach */
static void grid(grid_t* g, const double* x, const int64_t* tri, double reach, int64_t first, int64_t last)
{
  const int64_t T = g->T;
  double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {0.0, 0.0, 0.0};
  for (int k = 0; k < 3 && T > 0; ++k)
  {
    lo[k] = hi[k] = g->cr[k];
    for (int64_t t = 1; t < T; ++t)
      lo[k] = fmin(lo[k], g->cr[4 * t + k]), hi[k] = fmax(hi[k], g->cr[4 * t + k]);
  }
  const double inverse = 1.0 / cells(g, lo, hi, reach);    /* the cells' margin (1e-6) covers its round-off */
  int64_t* s = g->start;
  for (int64_t c = 0; c <= g->C; ++c)
    s[c] = 0;
  for (int64_t t = 0; t < T; ++t)
  {
    int64_t c[3];
    for (int k = 0; k < 3; ++k)
    {
      c[k] = (int64_t)floor((g->cr[4 * t + k] - lo[k]) * inverse);
      c[k] = c[k] < 0 ? 0 : (c[k] >= g->dims[k] ? g->dims[k] - 1 : c[k]);
    }
    g->key[t] = (c[0] * g->dims[1] + c[1]) * g->dims[2] + c[2];
    ++s[g->key[t] + 1];
  }
  for (int64_t c = 0; c < g->C; ++c)
    s[c + 1] += s[c];
  const int64_t end = last > first ? reached(g, last - 1) : first;
  for (int64_t t = 0; t < T; ++t)
  {
    const int64_t q = s[g->key[t]]++;
    if (q < first || q >= end)
      continue;
    box_t* b = g->box + q;
    const double* p[3] = {x + 3 * tri[3 * t], x + 3 * tri[3 * t + 1], x + 3 * tri[3 * t + 2]};
    for (int k = 0; k < 4; ++k)
      g->sc[4 * q + k] = g->cr[4 * t + k];
    for (int k = 0; k < 3; ++k)
    {
      b->lo[k] = fmin(fmin(p[0][k], p[1][k]), p[2][k]), b->hi[k] = fmax(fmax(p[0][k], p[1][k]), p[2][k]);
      b->n[k] = tri[3 * t + k];
    }
    b->id = t, b->key = g->key[t];
  }
  for (int64_t c = g->C; c > 0; --c)               /* s[c] was the end of cell c: shift back to starts */
    s[c] = s[c - 1];
  s[0] = 0;
}

/* the broad phase's filters (module docstring) for sorted positions p, q */
static int candidate(const grid_t* g, int64_t p, int64_t q, double reach2)
{
  const double *u = g->sc + 4 * p, *w = g->sc + 4 * q;
  const double d[3] = {u[0] - w[0], u[1] - w[1], u[2] - w[2]};
  if (!((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2] <= reach2))
    return 0;
  const box_t *a = g->box + p, *b = g->box + q;
  for (int k = 0; k < 3; ++k)
    if (a->n[k] == b->n[0] || a->n[k] == b->n[1] || a->n[k] == b->n[2])
      return 0;
  for (int k = 0; k < 3; ++k)
    if (!(a->lo[k] <= b->hi[k] && b->lo[k] <= a->hi[k]))
      return 0;
  return norm3(d) <= u[3] + w[3];
}

/* the run of sorted positions [from, to) of the cells (c0, c1, c2 - 1 .. c2 + 1) within the grid */
static void run(const grid_t* g, int64_t c0, int64_t c1, int64_t c2, int64_t* from, int64_t* to)
{
  *from = *to = 0;
  if (c0 < 0 || c0 >= g->dims[0] || c1 < 0 || c1 >= g->dims[1])
    return;
  const int64_t row = (c0 * g->dims[1] + c1) * g->dims[2];
  *from = g->start[row + (c2 > 0 ? c2 - 1 : 0)];
  *to = g->start[row + (c2 + 1 < g->dims[2] ? c2 + 2 : g->dims[2])];
}

/* the pairs (i < j) of part `part` of `parts` passing the broad phase (narrow = 0, flags 0) or, with narrow = 1,
   those intersecting (flag 1) or degenerate (flag 2), written while fewer than `capacity`; returns their number
   (more than capacity: call again with a larger one). `work`: workspace(T) bytes, 8-byte aligned */
int64_t crossings(int64_t T, const double* x, const int64_t* tri, int64_t part, int64_t parts, double degenerate,
                  int64_t narrow, void* work, int64_t capacity, int64_t* pairs, int64_t* flags)
{
  grid_t g;
  layout(T, work, &g);
  const double reach = 2.0 * spheres(T, x, tri, g.cr), reach2 = reach * reach;
  const int64_t first = part * T / parts, last = (part + 1) * T / parts;
  grid(&g, x, tri, reach, first, last);
  const int64_t layer = g.dims[1] * g.dims[2];
  int64_t n = 0;
  for (int64_t p = first; p < last; ++p)
  {
    const box_t* a = g.box + p;
    const int64_t c0 = a->key / layer, c1 = a->key / g.dims[2] % g.dims[1], c2 = a->key % g.dims[2];
    for (int o = 0; o < 5; ++o)       /* the 13 cells after p's own: runs along the last axis of the grid */
    {
      const int64_t dx = o < 2 ? 0 : 1, dy = o == 0 ? 0 : (o == 1 ? 1 : o - 3);
      int64_t from, to;
      run(&g, c0 + dx, c1 + dy, c2, &from, &to);
      if (o == 0)
        from = p + 1;
      for (int64_t q = from; q < to; ++q)
      {
        if (!candidate(&g, p, q, reach2))
          continue;
        const int64_t i = a->id < g.box[q].id ? a->id : g.box[q].id, j = a->id ^ g.box[q].id ^ i;
        const int flag = narrow ? narrow_pair(x, tri + 3 * i, tri + 3 * j, degenerate) : 0;
        if (narrow && !flag)
          continue;
        if (n < capacity)
          pairs[2 * n] = i, pairs[2 * n + 1] = j, flags[n] = flag;
        ++n;
      }
    }
  }
  return n;
}
"""


def module() -> tuple[object, object]:
    """(lib, ffi) of the compiled pass, built on first use by this process (COMM_SELF: the count is called by
    one rank or by all)."""
    return built_once("fabricfem_intersections", CDEF, SOURCE, MPI.COMM_SELF, ROUNDING_FLAGS)
