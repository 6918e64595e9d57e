"""The compiled per-step loops of cloth-cloth contact (fabricfem.contact.self_contact): a narrow phase over a kept
list of candidate pairs and the penalty-friction response of the pairs.

Verlet list ([Verlet1967]; the skin of [Bridson2002, sec. 6] in a molecular-dynamics form): the candidates are the
pairs (vertex p, triangle t) closer than d_c + s at the positions x0 of the last search (s the skin [m]). As long as
no node has moved more than s / 2 from x0, the distance of every pair has changed by less than s (a vertex and a
triangle's closest point each moved less than s / 2), so every pair now closer than d_c is a candidate: the narrow
phase (`narrow`) computes the exact distance of each candidate with the search's own closest-point routine
(fabricfem.contact.proximity.CLOSEST_C) and keeps those closer than d_c, the same pairs as a new search. When a
node has moved further it returns None and the caller searches again.

`respond` is the law of fabricfem.contact.self_contact (its module docstring; the numpy `_respond` there is its
twin for the tests) in one loop over the pairs, which must come grouped by vertex (the search and the narrow
phase emit them so): the feature share s = 1 / (pairs of the same vertex whose closest point lies on the same
feature) counted within the vertex's group. Forces [N] are added to the (N, 3) normal and friction arrays.
Units: metres, seconds, kilograms, newtons.
"""
from __future__ import annotations

import functools

import numpy as np

from fabricfem.contact.proximity import CLOSEST_C, Pairs
from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

CDEF = """
int64_t narrow_candidates(int64_t N, const double* x, const double* x0, double limit, int64_t M, const int64_t* cand_p,
                          const int64_t* cand_t, const int64_t* tri, double radius, int64_t* pair_p, int64_t* pair_t,
                          double* distance, double* bary);
void respond_pairs(int64_t n, const int64_t* pair_p, const int64_t* pair_t, const double* distance, const double* bary,
                   const int64_t* tri, const double* x, const double* v, const double* inverse_mass,
                   const double* area, double penalty, double contact_distance, double zeta, double mu, double dt,
                   double tolerance, double* normal_force, double* friction_force);
"""

SOURCE = CLOSEST_C + r"""
/* the candidates closer than radius at x, in their order; -1 when a node moved more than `limit` from x0 */
int64_t narrow_candidates(int64_t N, const double* x, const double* x0, double limit, int64_t M, const int64_t* cand_p,
                          const int64_t* cand_t, const int64_t* tri, double radius, int64_t* pair_p, int64_t* pair_t,
                          double* distance, double* bary)
{
  const double limit2 = limit * limit;
  for (int64_t i = 0; i < 3 * N; i += 3)
  {
    const double a = x[i] - x0[i], b = x[i + 1] - x0[i + 1], c = x[i + 2] - x0[i + 2];
    if (a * a + b * b + c * c > limit2)
      return -1;
  }
  const double r2 = radius * radius;
  int64_t n = 0;
  for (int64_t m = 0; m < M; ++m)
  {
    const int64_t p = cand_p[m], t = cand_t[m];
    double w[3];
    const double s = closest(x + 3 * p, x + 3 * tri[3 * t], x + 3 * tri[3 * t + 1], x + 3 * tri[3 * t + 2], w);
    if (!(s < r2))
      continue;
    pair_p[n] = p, pair_t[n] = t, distance[n] = sqrt(s);
    bary[3 * n] = w[0], bary[3 * n + 1] = w[1], bary[3 * n + 2] = w[2];
    ++n;
  }
  return n;
}

static void feature(const int64_t* nodes, const double* w, double tolerance, int64_t* key)
{
  for (int k = 0; k < 3; ++k)
    key[k] = w[k] > tolerance ? nodes[k] : -1;
  for (int i = 0; i < 2; ++i)       /* sort the three */
    for (int k = 0; k < 2 - i; ++k)
      if (key[k] > key[k + 1])
      {
        const int64_t tmp = key[k];
        key[k] = key[k + 1], key[k + 1] = tmp;
      }
}

void respond_pairs(int64_t n, const int64_t* pair_p, const int64_t* pair_t, const double* distance, const double* bary,
                   const int64_t* tri, const double* x, const double* v, const double* inverse_mass,
                   const double* area, double penalty, double contact_distance, double zeta, double mu, double dt,
                   double tolerance, double* normal_force, double* friction_force)
{
  int64_t g0 = 0;
  while (g0 < n)
  {
    int64_t g1 = g0 + 1;
    while (g1 < n && pair_p[g1] == pair_p[g0])
      ++g1;
    for (int64_t i = g0; i < g1; ++i)
    {
      const int64_t p = pair_p[i];
      const int64_t* nodes = tri + 3 * pair_t[i];
      const double* w = bary + 3 * i;
      int64_t key[3], other[3];
      feature(nodes, w, tolerance, key);
      int count = 0;
      for (int64_t j = g0; j < g1; ++j)
      {
        feature(tri + 3 * pair_t[j], bary + 3 * j, tolerance, other);
        count += key[0] == other[0] && key[1] == other[1] && key[2] == other[2];
      }
      double xc[3], vr[3], normal[3], offset[3], e1[3], e2[3];
      for (int k = 0; k < 3; ++k)
      {
        xc[k] = w[0] * x[3 * nodes[0] + k] + w[1] * x[3 * nodes[1] + k] + w[2] * x[3 * nodes[2] + k];
        vr[k] = v[3 * p + k] - (w[0] * v[3 * nodes[0] + k] + w[1] * v[3 * nodes[1] + k] + w[2] * v[3 * nodes[2] + k]);
        offset[k] = x[3 * p + k] - xc[k];
        e1[k] = x[3 * nodes[1] + k] - x[3 * nodes[0] + k], e2[k] = x[3 * nodes[2] + k] - x[3 * nodes[0] + k];
      }
      contact_normal(e1, e2, offset, distance[i], 1e-9 * contact_distance, normal);
      const double vn = dot3(vr, normal);
      const double im = inverse_mass[p] + w[0] * w[0] * inverse_mass[nodes[0]]
                        + w[1] * w[1] * inverse_mass[nodes[1]] + w[2] * w[2] * inverse_mass[nodes[2]];
      const double m_eff = im > 0.0 ? 1.0 / im : INFINITY;
      const double spring = penalty * area[p] / count;
      const double damper = 2.0 * zeta * sqrt(spring * (isfinite(m_eff) ? m_eff : 0.0));
      const double fn = fmax(spring * (contact_distance - distance[i]) - damper * vn, 0.0);
      double ff[3];
      coulomb_friction(vr, vn, normal, mu, fn, m_eff, dt, ff);
      for (int k = 0; k < 3; ++k)
      {
        const double f = fn * normal[k];
        normal_force[3 * p + k] += f, friction_force[3 * p + k] += ff[k];
        for (int q = 0; q < 3; ++q)
        {
          normal_force[3 * nodes[q] + k] -= w[q] * f;
          friction_force[3 * nodes[q] + k] -= w[q] * ff[k];
        }
      }
    }
    g0 = g1;
  }
}
"""

def _module(comm):
    """(lib, ffi) of the compiled loops, built on first use (rank 0 of `comm` builds, the others wait)."""
    return built_once("fabricfem_cloth_kernel", CDEF, SOURCE, comm, KERNEL_FLAGS)


def narrow(x: np.ndarray, x0: np.ndarray, limit: float, candidates: Pairs, triangles: np.ndarray, radius: float,
           comm) -> Pairs | None:
    """The candidate pairs closer than `radius` [m] at the positions x (N, 3) [m], in the candidates' order; None
    when a node moved more than `limit` [m] from x0 (module docstring). `triangles` (T, 3) int64 C-contiguous."""
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    M = len(candidates)
    out = (np.empty(M, np.int64), np.empty(M, np.int64), np.empty(M), np.empty((M, 3)))
    n = lib.narrow_candidates(len(x), p(x, "double"), p(x0, "double"), float(limit), M,
                              p(candidates.vertex, "int64_t"), p(candidates.triangle, "int64_t"),
                              p(triangles, "int64_t"), float(radius), p(out[0], "int64_t"), p(out[1], "int64_t"),
                              p(out[2], "double"), p(out[3], "double"))
    if n < 0:
        return None
    return Pairs(out[0][:n], out[1][:n], out[2][:n], out[3][:n])


def respond(pairs: Pairs, triangles: np.ndarray, x: np.ndarray, v: np.ndarray, inverse_mass: np.ndarray,
            area: np.ndarray, law: tuple[float, float, float, float, float, float], normal_force: np.ndarray,
            friction_force: np.ndarray, comm) -> None:
    """Add the pairs' forces [N] to normal_force and friction_force (N, 3) (module docstring). x, v (N, 3) [m],
    [m/s]; inverse_mass (N,) 1/m [1/kg] (0 for a held node); area (N,) [m^2]; law = (k_N [Pa/m], d_c [m], zeta,
    mu, dt [s], feature tolerance). Every array C-contiguous of its dtype; the pairs grouped by vertex."""
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    lib.respond_pairs(len(pairs), p(pairs.vertex, "int64_t"), p(pairs.triangle, "int64_t"),
                      p(np.ascontiguousarray(pairs.distance), "double"), p(np.ascontiguousarray(pairs.bary), "double"),
                      p(triangles, "int64_t"), p(x, "double"), p(v, "double"), p(inverse_mass, "double"),
                      p(area, "double"), *(float(c) for c in law), p(normal_force, "double"),
                      p(friction_force, "double"))
