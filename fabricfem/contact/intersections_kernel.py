"""The compiled pass of the intersecting-pair count (fabricfem.contact.intersections, whose module docstring states
the method): one C function lists the triangle pairs of a part of the surface that pass the broad phase and, in the
same loop, decides each by the plane and interval tests, leaving the degenerate pairs to libigl.

Broad phase: a uniform grid of cells of edge h >= 2 r_max (r_max the largest circumradius about the centroid; h is
doubled while the dense grid would hold more than 4 T + 64 cells), the triangles sorted by cell (a counting sort,
cells in lexicographic order); triangle p (position in that order) meets the later triangles of its own cell and
all triangles of the 13 cells after it among its 26 neighbours, so each pair within reach is met once, by the
earlier of its two positions. Part k of `parts` is the run [k T / parts, (k + 1) T / parts) of positions.

The filters and tests round as the numpy expressions they replace (compiled with ROUNDING_FLAGS: no contracted
multiply-adds): centroid ((p0 + p1) + p2) / 3, Euclidean norms ((v0^2 + v1^2) + v2^2)^(1/2) (numpy's add.reduce
over a row of three), the dot products of numpy's einsum over three terms, (u0 w0 + u2 w2) + u1 w1, np.cross's
products. A pair is kept when its centroids' squared distance ((d0^2 + d1^2) + d2^2) is at most (2 r_max)^2 (the
leaf test of scipy's cKDTree.query_pairs, the broad phase this grid replaced), it shares no node, its bounding boxes
overlap and its centroids are at most r_i + r_j apart. Then (`narrow`, the triangle of the smaller index first):
the plane test [Guigue2003], the degenerate cases (flag 2: libigl decides) and the interval test [Moller1997].
"""
from __future__ import annotations

from mpi4py import MPI

from fabricfem.forms.jit import ROUNDING_FLAGS, built_once

CDEF = """
int64_t crossings(int64_t T, const double* x, const int64_t* tri, int64_t part, int64_t parts, double degenerate,
                  int64_t narrow, int64_t capacity, int64_t* pairs, int64_t* flags);
"""

SOURCE = r"""
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

typedef struct { double c[3], r, lo[3], hi[3]; int64_t n[3], id, cell[3]; } box_t;

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

/* the triangles' centroids, circumradii about them, bounding boxes; returns r_max */
static double boxes(int64_t T, const double* x, const int64_t* tri, box_t* box)
{
  double rmax = 0.0;
  for (int64_t t = 0; t < T; ++t)
  {
    box_t* b = box + t;
    const double* p[3] = {x + 3 * tri[3 * t], x + 3 * tri[3 * t + 1], x + 3 * tri[3 * t + 2]};
    for (int k = 0; k < 3; ++k)
    {
      b->c[k] = ((p[0][k] + p[1][k]) + p[2][k]) / 3.0;
      b->lo[k] = fmin(fmin(p[0][k], p[1][k]), p[2][k]), b->hi[k] = fmax(fmax(p[0][k], p[1][k]), p[2][k]);
      b->n[k] = tri[3 * t + k];
    }
    b->r = 0.0, b->id = t;
    for (int m = 0; m < 3; ++m)
    {
      const double d[3] = {p[m][0] - b->c[0], p[m][1] - b->c[1], p[m][2] - b->c[2]}, r = norm3(d);
      b->r = r > b->r ? r : b->r;
    }
    rmax = b->r > rmax ? b->r : rmax;
  }
  return rmax;
}

/* the cells (edge >= reach) of the triangles, sorted by cell into `sorted`; start (cells + 1) of each cell's run;
   returns the number of cells and the grid's dimensions in dims, or -1 (no memory) */
static int64_t grid(int64_t T, const box_t* box, double reach, box_t* sorted, int64_t** start, int64_t* dims)
{
  double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {0.0, 0.0, 0.0};
  for (int k = 0; k < 3 && T > 0; ++k)
  {
    lo[k] = hi[k] = box[0].c[k];
    for (int64_t t = 1; t < T; ++t)
      lo[k] = fmin(lo[k], box[t].c[k]), hi[k] = fmax(hi[k], box[t].c[k]);
  }
  double h = reach * (1.0 + 1e-6), cells;
  if (!(h > 0.0) || !isfinite(h))
    h = 1.0;
  for (;;)
  {
    cells = 1.0;
    for (int k = 0; k < 3; ++k)
      cells *= floor((hi[k] - lo[k]) / h) + 1.0;
    if (cells <= 4.0 * T + 64.0)
      break;
    h *= 2.0;
  }
  for (int k = 0; k < 3; ++k)
    dims[k] = (int64_t)floor((hi[k] - lo[k]) / h) + 1;
  const int64_t C = dims[0] * dims[1] * dims[2];
  int64_t* s = calloc(C + 1, sizeof(int64_t));
  int64_t* key = malloc((T + 1) * sizeof(int64_t));
  if (!s || !key)
    return free(s), free(key), -1;
  for (int64_t t = 0; t < T; ++t)
  {
    int64_t c[3];
    for (int k = 0; k < 3; ++k)
    {
      c[k] = (int64_t)floor((box[t].c[k] - lo[k]) / h);
      c[k] = c[k] < 0 ? 0 : (c[k] >= dims[k] ? dims[k] - 1 : c[k]);
    }
    key[t] = (c[0] * dims[1] + c[1]) * dims[2] + c[2];
    ++s[key[t] + 1];
  }
  for (int64_t c = 0; c < C; ++c)
    s[c + 1] += s[c];
  for (int64_t t = 0; t < T; ++t)                  /* counting sort, stable */
  {
    box_t* b = sorted + s[key[t]]++;
    *b = box[t];
    b->cell[0] = key[t] / (dims[1] * dims[2]), b->cell[1] = key[t] / dims[2] % dims[1], b->cell[2] = key[t] % dims[2];
  }
  for (int64_t c = C; c > 0; --c)                  /* s[c] was the end of cell c: shift back to starts */
    s[c] = s[c - 1];
  s[0] = 0;
  free(key);
  *start = s;
  return C;
}

/* the broad phase's filters (module docstring) */
static int candidate(const box_t* p, const box_t* q, double reach2)
{
  const double d[3] = {p->c[0] - q->c[0], p->c[1] - q->c[1], p->c[2] - q->c[2]};
  if (!((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2] <= reach2))
    return 0;
  for (int u = 0; u < 3; ++u)
    if (p->n[u] == q->n[0] || p->n[u] == q->n[1] || p->n[u] == q->n[2])
      return 0;
  for (int k = 0; k < 3; ++k)
    if (!(p->lo[k] <= q->hi[k] && q->lo[k] <= p->hi[k]))
      return 0;
  return norm3(d) <= p->r + q->r;
}

/* the pairs (i < j) of part `part` of `parts` passing the broad phase (narrow = 0, flags 0) or, with narrow = 1,
   those intersecting (flag 1) or degenerate (flag 2), written while fewer than `capacity`; returns their number
   (more than capacity: call again with a larger one), -1 when out of memory */
int64_t crossings(int64_t T, const double* x, const int64_t* tri, int64_t part, int64_t parts, double degenerate,
                  int64_t narrow, int64_t capacity, int64_t* pairs, int64_t* flags)
{
  box_t* box = malloc((2 * T + 1) * sizeof(box_t));
  int64_t *start = NULL, dims[3], n = 0;
  if (!box)
    return -1;
  box_t* sorted = box + T;
  const double reach = 2.0 * boxes(T, x, tri, box), reach2 = reach * reach;
  if (grid(T, box, reach, sorted, &start, dims) < 0)
    return free(box), -1;
  for (int64_t p = part * T / parts; p < (part + 1) * T / parts; ++p)
  {
    const box_t* a = sorted + p;
    for (int o = 13; o < 27; ++o)                 /* own cell (o = 13), then the 13 cells after it */
    {
      const int64_t c0 = a->cell[0] + o / 9 - 1, c1 = a->cell[1] + o / 3 % 3 - 1, c2 = a->cell[2] + o % 3 - 1;
      if (c0 < 0 || c0 >= dims[0] || c1 < 0 || c1 >= dims[1] || c2 < 0 || c2 >= dims[2])
        continue;
      const int64_t c = (c0 * dims[1] + c1) * dims[2] + c2;
      for (int64_t q = o == 13 ? p + 1 : start[c]; q < start[c + 1]; ++q)
      {
        const box_t* b = sorted + q;
        if (!candidate(a, b, reach2))
          continue;
        const int64_t i = a->id < b->id ? a->id : b->id, j = a->id < b->id ? b->id : a->id;
        const int flag = narrow ? narrow_pair(x, tri + 3 * i, tri + 3 * j, degenerate) : 0;
        if (narrow && !flag)
          continue;
        if (n < capacity)
          pairs[2 * n] = i, pairs[2 * n + 1] = j, flags[n] = flag;
        ++n;
      }
    }
  }
  free(start), free(box);
  return n;
}
"""


def module() -> tuple[object, object]:
    """(lib, ffi) of the compiled pass, built on first use by this process (COMM_SELF: the count is called by
    one rank or by all)."""
    return built_once("fabricfem_intersections", CDEF, SOURCE, MPI.COMM_SELF, ROUNDING_FLAGS)
