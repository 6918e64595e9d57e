"""Velocity-level correction of cloth-cloth proximity pairs: inelastic impulses with Coulomb friction, compiled
([Bridson2002, sec. 7.1-7.2]), the part of cloth-cloth contact (fabricfem.contact.self_contact) that a stack of
layers pressed together cannot push through.

The penalty of fabricfem.contact.self_contact has its stiffness capped by the explicit step (a spring stiffer than
the shell would shorten the critical step); in a fold of three or more layers pressed onto the body by the exact
(Lagrange) body contact, that capped spring gives way and the layers pass through each other. The impulses act on
the velocities instead, so no stiffness enters the step.

Kinematics of central differences (fabricfem.dynamics.explicit): after the division, the step's acceleration
a^{n+1} is known and the next positions are x^{n+2} = x^{n+1} + dt u with u = v~ + dt a^{n+1} [m/s] (the same
predictor that the body contact's forward-increment Lagrange step corrects [Man2006, Box 5]). The correction changes
u by du = dt da, that is a^{n+1} by da = du / dt (and v^{n+1} = v~ + dt/2 a^{n+1} by du / 2).

For every pair closer than the contact distance d_c at x^{n+1} (the vertex-triangle pairs with weights
w = (1, -w_a, -w_b, -w_c) on (p, a, b, c), the edge-edge pairs with w = (1 - s, s, -(1 - t), -t), both with
sum_k w_k = 0) and its unit normal n (as in the penalty law):

    u_rel = sum_k w_k u_k,   u_N = u_rel . n,   1 / m_eff = sum_k w_k^2 / m_k                 ([Bridson2002, sec. 7.1])
    if u_N < 0 (the pair approaches: it would end the step closer than its distance, which is below d_c):
        J_N = -m_eff u_N                              (inelastic: the relative normal velocity becomes 0)
        (J_N = -u_N / max_k |w_k| / m_k where that is smaller: see below)
        u_T = u_rel - u_N n,   J_T = -m_eff min(mu |u_N|, |u_T|) u_T / |u_T|                   ([Bridson2002, sec. 7.2])
        (with the same bound as J_N where it applies)
        u_k += w_k (J_N n + J_T) / m_k

m_k the lumped masses M + dt/2 C [kg] of the step's division (1 / m_k = 0 for a held node). The impulse
distribution by w_k / m_k is the one of [Bridson2002, sec. 7.1] (their I / m weighted by the barycentric
coordinates, normalised by 1 / m_eff): it sets the pair's relative normal velocity to 0 exactly and conserves
linear momentum (sum_k m_k du_k = sum_k w_k J = 0). The friction removes at most mu times the normal change of
the relative velocity (Coulomb's bound; the relative tangential velocity stops when it is smaller).

Held nodes (a prescribed displacement, or on the body: 1 / m_k = 0) take no impulse. A pair whose free nodes all
carry small weights (a vertex on the body over a triangle whose closest point lies near a held node) would give
its free node a change u_N / w: the normal impulse is bounded so that no node's velocity changes by more than
|u_N| (J_N <= |u_N| / max_k |w_k| / m_k; without the bound the sleeve's run diverged at 123-126 degrees), and
such a pair's approach is only partly removed. Such a pair acts in one pass of the step only: its remaining
approach (1 - w) |u_N| would take another |u_N| in every pass, and a free node of weight w gained up to `passes` x
|u_N| (in the pants walk with 8 passes, 4.7 to 102 m/s in one step, the start of a blow-up:
docs/findings/2026-11-28-seam-contact.md, "The second fault"). The friction impulse takes the same bound (m_eff
replaced by 1 / max(1 / m_eff, max_k |w_k| / m_k)), so that no node's velocity changes by more than |u_T| in
friction and |J_T| <= mu J_N holds for the bounded J_N: with m_eff alone a free node of weight w took u_T / w,
overshot the held nodes' motion and grew by about (1 / w - 1) per step (an edge-edge pair with three nodes on the
body diverged the pants walk, docs/findings/2026-11-28-seam-contact.md).

Restoring (`restore_rate` r [1/s], default 0): the target of the relative normal velocity is r (d_c - delta)
instead of 0, so that a pair inside d_c separates towards it within about 1 / r, which the capped penalty does not
ensure (the analogue of the limited repulsion of [Bridson2002, sec. 7.1]); r = 0: only the approach is removed.

Passes: the pairs are treated in turn (Gauss-Seidel: each pair sees the velocities its predecessors left), all
vertex-triangle pairs then all edge-edge pairs, for `passes` passes or until a pass applies no impulse (a pair
approaching by less than 1e-12 of sum_k |w_k| |u_k|, the round-off of the u_rel an impulse left at 0, takes
none); in a stack the later passes carry the correction through the layers. Impulses only push (never pull a pair
together), so the correction only takes out approach and kinetic energy.

Parallel: every rank holds the gathered positions and velocities of all nodes (fabricfem.contact.cloth_surface)
and the same pairs in the same order, runs the same passes, and adds the changes of its owned nodes to its rows:
the pairs across rank boundaries are treated as on one rank (the scatter of the penalty forces). The global node
numbers depend on the partition, and a Gauss-Seidel sweep on the order of its pairs: the pairs are therefore swept
in an order of the reference geometry (`canonical`: each node ranked by its reference position), the same on any
number of ranks.
Units: metres, seconds, kilograms; impulses in N s.
"""
from __future__ import annotations

import functools

import numpy as np

from fabricfem.contact.edge_contact import EdgePairs
from fabricfem.contact.proximity import CLOSEST_C, Pairs
from fabricfem.forms.jit import KERNEL_FLAGS, built_once, pointer

CDEF = """
int64_t impulse_passes(int64_t n_vt, const int64_t* pair_p, const int64_t* pair_t, const double* vt_distance,
                       const double* bary, const int64_t* tri, int64_t n_ee, const int64_t* first,
                       const int64_t* second, const double* ee_distance, const double* s, const double* t,
                       const int64_t* edges, const double* x, double contact_distance, const double* inverse_mass,
                       double mu, double restore_rate, int64_t passes, double* u, double* normal_impulse,
                       double* friction_impulse, double* normals, int64_t* acted);
"""

SOURCE = "#pragma GCC diagnostic ignored \"-Wunused-function\"\n" + CLOSEST_C + r"""
#define ROUND_OFF 1e-12
/* the four nodes and weights of pair i: vertex-triangle pairs first (i < n_vt), then edge-edge pairs */
static void pair_nodes(int64_t i, int64_t n_vt, const int64_t* pair_p, const int64_t* pair_t, const double* bary,
                       const int64_t* tri, const int64_t* first, const int64_t* second, const double* s,
                       const double* t, const int64_t* edges, int64_t* node, double* w)
{
  if (i < n_vt)
  {
    node[0] = pair_p[i], w[0] = 1.0;
    for (int q = 0; q < 3; ++q)
      node[q + 1] = tri[3 * pair_t[i] + q], w[q + 1] = -bary[3 * i + q];
    return;
  }
  const int64_t j = i - n_vt;
  node[0] = edges[2 * first[j]], node[1] = edges[2 * first[j] + 1];
  node[2] = edges[2 * second[j]], node[3] = edges[2 * second[j] + 1];
  w[0] = 1.0 - s[j], w[1] = s[j], w[2] = -(1.0 - t[j]), w[3] = -t[j];
}

/* the pair's unit normal at x: sum_k w_k x_k / distance, or the normal of the plane of its two edges (the
   triangle's e1 = b - a, e2 = c - a; the edges' e_a, e_b) for a distance below `tiny` */
static void pair_normal(const int64_t* node, const double* w, int edge_pair, const double* x, double distance,
                        double tiny, double* normal)
{
  double offset[3] = {0.0, 0.0, 0.0}, e1[3], e2[3];
  for (int q = 0; q < 4; ++q)
    for (int k = 0; k < 3; ++k)
      offset[k] += w[q] * x[3 * node[q] + k];
  for (int k = 0; k < 3; ++k)
  {
    e1[k] = x[3 * node[edge_pair ? 1 : 2] + k] - x[3 * node[edge_pair ? 0 : 1] + k];
    e2[k] = x[3 * node[3] + k] - x[3 * node[edge_pair ? 2 : 1] + k];
  }
  contact_normal(e1, e2, offset, distance, tiny, normal);
}

/* the inelastic impulse with friction of one pair on u; 0 if it did not act, 1 if it acted, 2 if it acted with
   the bound of its small-weight free nodes (max_k |w_k| / m_k above 1 / m_eff) */
static int pair_impulse(const int64_t* node, const double* w, const double* normal, const double* inverse_mass,
                        double mu, double target, double* u, double* normal_impulse, double* friction_impulse)
{
  double ur[3] = {0.0, 0.0, 0.0}, im = 0.0, scale = 0.0, largest = 0.0;
  for (int q = 0; q < 4; ++q)
  {
    const double* uq = u + 3 * node[q];
    for (int k = 0; k < 3; ++k)
      ur[k] += w[q] * uq[k];
    im += w[q] * w[q] * inverse_mass[node[q]];
    largest = fmax(largest, fabs(w[q]) * inverse_mass[node[q]]);
    scale += fabs(w[q]) * sqrt(dot3(uq, uq));
  }
  const double un = dot3(ur, normal) - target;     /* below the target normal velocity */
  if (!(im > 0.0) || !(un < -ROUND_OFF * scale))    /* by more than the round-off of u_rel */
    return 0;
  const double bound = fmax(im, largest);           /* no node's change above |u_N| (and |u_T| in friction) */
  const double jn = -un / bound;
  double ut[3], jt[3] = {0.0, 0.0, 0.0};
  for (int k = 0; k < 3; ++k)
    ut[k] = ur[k] - un * normal[k];
  const double speed = sqrt(dot3(ut, ut));
  if (mu > 0.0 && speed > 0.0)
  {
    const double scale = fmin(-mu * un, speed) / (speed * bound);   /* |J_T| <= mu J_N */
    for (int k = 0; k < 3; ++k)
      jt[k] = -scale * ut[k];
  }
  for (int q = 0; q < 4; ++q)
    for (int k = 0; k < 3; ++k)
    {
      const double jnk = w[q] * jn * normal[k], jtk = w[q] * jt[k];
      u[3 * node[q] + k] += (jnk + jtk) * inverse_mass[node[q]];
      normal_impulse[3 * node[q] + k] += jnk, friction_impulse[3 * node[q] + k] += jtk;
    }
  return largest > im ? 2 : 1;
}

/* `passes` Gauss-Seidel passes over the pairs (module docstring); returns the passes taken (-1 if out of memory),
   acted[i] the number of passes in which pair i acted */
int64_t impulse_passes(int64_t n_vt, const int64_t* pair_p, const int64_t* pair_t, const double* vt_distance,
                       const double* bary, const int64_t* tri, int64_t n_ee, const int64_t* first,
                       const int64_t* second, const double* ee_distance, const double* s, const double* t,
                       const int64_t* edges, const double* x, double contact_distance, const double* inverse_mass,
                       double mu, double restore_rate, int64_t passes, double* u, double* normal_impulse,
                       double* friction_impulse, double* normals, int64_t* acted)
{
  const int64_t n = n_vt + n_ee;
  int64_t node[4];
  double w[4];
  for (int64_t i = 0; i < n; ++i)
  {
    pair_nodes(i, n_vt, pair_p, pair_t, bary, tri, first, second, s, t, edges, node, w);
    pair_normal(node, w, i >= n_vt, x, i < n_vt ? vt_distance[i] : ee_distance[i - n_vt],
                1e-9 * contact_distance, normals + 3 * i);
    acted[i] = 0;
  }
  char* bounded = calloc(n > 0 ? n : 1, 1);     /* the pair acted with its bound: once per step */
  if (bounded == NULL)
    return -1;
  int64_t pass = 0;
  while (pass < passes)
  {
    ++pass;
    int64_t count = 0;
    for (int64_t i = 0; i < n; ++i)
    {
      if (bounded[i])
        continue;
      pair_nodes(i, n_vt, pair_p, pair_t, bary, tri, first, second, s, t, edges, node, w);
      const double gap = contact_distance - (i < n_vt ? vt_distance[i] : ee_distance[i - n_vt]);
      const int hit = pair_impulse(node, w, normals + 3 * i, inverse_mass, mu, restore_rate * fmax(gap, 0.0), u,
                                   normal_impulse, friction_impulse);
      bounded[i] = hit == 2;
      acted[i] += hit > 0, count += hit > 0;
    }
    if (count == 0)
      break;
  }
  free(bounded);
  return pass;
}
"""


def _module(comm):
    """(lib, ffi) of the compiled passes, built on first use (rank 0 of `comm` builds, the others wait)."""
    return built_once("fabricfem_cloth_impulses", CDEF, SOURCE, comm, KERNEL_FLAGS)


def apply(pairs: Pairs, edge_pairs: EdgePairs, triangles: np.ndarray, edges: np.ndarray, x: np.ndarray,
          u: np.ndarray, inverse_mass: np.ndarray, contact_distance: float, mu: float, passes: int,
          comm, restore_rate: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The passes of impulses (module docstring) on the velocities u (N, 3) [m/s], changed in place.

    Args:
        pairs, edge_pairs: the vertex-triangle and edge-edge pairs closer than d_c at x (N, 3) [m].
        triangles (T, 3), edges (E, 2): int64 node indices; inverse_mass (N,) 1 / m [1/kg] (0 for a held node).
        contact_distance: d_c [m] (only its 1e-9 fraction is used: below it the normal is the edges' plane's).
        mu: Coulomb coefficient [-]; passes: the most Gauss-Seidel passes (>= 1).
        restore_rate: r [1/s]: the target relative normal velocity r (d_c - delta) (module docstring).

    Returns:
        (normal impulses (N, 3) [N s], friction impulses (N, 3) [N s], acted (n_pairs + n_edge_pairs,) the passes
        in which each pair acted, the passes taken).
    """
    lib, ffi = _module(comm)
    p = functools.partial(pointer, ffi)
    c = np.ascontiguousarray
    N, n = len(x), len(pairs) + len(edge_pairs)
    normal, friction = np.zeros((N, 3)), np.zeros((N, 3))
    normals, acted = np.zeros((n, 3)), np.zeros(n, dtype=np.int64)
    taken = lib.impulse_passes(
        len(pairs), p(c(pairs.vertex, dtype=np.int64), "int64_t"), p(c(pairs.triangle, dtype=np.int64), "int64_t"),
        p(c(pairs.distance, dtype=float), "double"), p(c(pairs.bary, dtype=float), "double"),
        p(triangles, "int64_t"), len(edge_pairs), p(c(edge_pairs.first, dtype=np.int64), "int64_t"),
        p(c(edge_pairs.second, dtype=np.int64), "int64_t"),
        *(p(c(a, dtype=float), "double") for a in (edge_pairs.distance, edge_pairs.s, edge_pairs.t)),
        p(edges, "int64_t"), p(x, "double"), float(contact_distance), p(inverse_mass, "double"), float(mu),
        float(restore_rate), int(passes), p(u, "double"), p(normal, "double"), p(friction, "double"),
        p(normals, "double"), p(acted, "int64_t"))
    if taken < 0:
        raise MemoryError("impulse_passes: out of memory")
    return normal, friction, acted, int(taken)


def node_ranks(reference: np.ndarray) -> np.ndarray:
    """(N,) int64 rank of every node in the lexicographic order of its reference position (N, 3) [m] (x, then y,
    then z): a numbering that does not depend on the partition."""
    order = np.lexsort(reference.T[::-1])
    ranks = np.empty(len(order), dtype=np.int64)
    ranks[order] = np.arange(len(order), dtype=np.int64)
    return ranks


def canonical(pairs: Pairs, edge_pairs: EdgePairs, triangles: np.ndarray, edges: np.ndarray,
              ranks: np.ndarray) -> tuple[Pairs, EdgePairs]:
    """The pairs in the order of the nodes' ranks (`node_ranks`): vertex-triangle pairs by (vertex, the triangle's
    sorted node ranks), edge-edge pairs by their two edges' sorted node ranks (the lower edge first)."""
    tri = np.sort(ranks[triangles[pairs.triangle]], axis=1)
    vt = np.lexsort((tri[:, 2], tri[:, 1], tri[:, 0], ranks[pairs.vertex]))
    a = np.sort(ranks[edges[edge_pairs.first]], axis=1)
    b = np.sort(ranks[edges[edge_pairs.second]], axis=1)
    swap = (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] > b[:, 1]))
    lo, hi = np.where(swap[:, None], b, a), np.where(swap[:, None], a, b)
    ee = np.lexsort((hi[:, 1], hi[:, 0], lo[:, 1], lo[:, 0]))
    return pairs.subset(vt), edge_pairs.subset(ee)


def checked_passes(value: object) -> int:
    """The number of passes: an int >= 0 (0: no impulses), else ValueError naming `passes`."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"passes must be an integer >= 0, got {value!r}")
    return int(value)
