"""The C source of the mesh skin's compiled queries (`fabricfem.body.mesh_query`, where the method is described).

Data (`skin_mesh`, arrays owned by `CompiledSkin`): the rest vertices (V, 3) [m], faces (F, 3), dense weights
(V, K) and their nonzeros as CSR (wstart, wseg, wval), each vertex's only segment or -1 (vertex_segment), the
topology of `fabricfem.body.mesh_distance.Topology`, the tree (left/right children or -1, first/count of a leaf's
triangles in perm, node_segment: the segment all of a node's vertices follow rigidly or -1, mask: the bits of the
segments its vertices follow, rest_lo/rest_hi the rest boxes, lo/hi the boxes at the pose numbered stamp, n_blended
the nodes without a rigid segment) and the posed vertices vposed at the pose numbered vstamp. Units: metres.
"""
from __future__ import annotations

from fabricfem.body.mesh_distance import FEATURE_TOLERANCE, FOOT_NORMAL_DISTANCE

LEAF_SIZE = 4            # triangles per leaf of the tree
HALVING_DEPTH = 64       # below this depth the tree halves its triangle lists (depth <= 64 + log2 F)
STACK_DEPTH = 256        # the search's stack: at most depth + 1 entries
MAX_SEGMENTS = 62        # a body's segments (a node's segments are the bits of an int64)

STRUCT = """
typedef struct {
    int64_t nv, nf, k, nodes, n_blended;
    double *rest; int64_t *faces; double *weights;
    int64_t *wstart; int64_t *wseg; double *wval; int64_t *vertex_segment;
    int64_t *face_edges; int64_t *edge_faces; int64_t *ring_start; int64_t *ring_face; int64_t *ring_corner;
    int64_t *left; int64_t *right; int64_t *first; int64_t *count; int64_t *perm; int64_t *node_segment;
    int64_t *mask; int64_t *stamp; double *rest_lo; double *rest_hi; double *lo; double *hi;
    int64_t *vstamp; double *vposed;
    int64_t *shift_slot; double *shift; double box_grow;
} skin_mesh;
"""

CDEF = STRUCT + """
int64_t skin_build(skin_mesh *m, double *centroid);
double skin_maps(int64_t k, const double *points, const double *fraction, const double *rest_c,
                 const double *rest_r, double g, double *a, double *b);
double skin_travel(int64_t k, const double *a, const double *b, const double *a0, const double *b0,
                   const double *center, const double *radius);
void skin_pose(const skin_mesh *m, const double *a, const double *b, double *posed);
int64_t skin_query(skin_mesh *m, const double *a, const double *b, int rigid, int64_t epoch, int64_t n,
                   const double *x, double travel, double margin, double *x0, double *g0, double *s0, double *gap,
                   double *foot, double *normal, double *weights, int64_t *tri, double *bary);
"""

HEADER = f"""
#include <math.h>
#include <stdint.h>
#define LEAF {LEAF_SIZE}
#define STACK {STACK_DEPTH}
#define DEEP {HALVING_DEPTH}
#define MAXSEG {MAX_SEGMENTS}
#define FEATURE {FEATURE_TOLERANCE!r}
#define FOOT_NORMAL {FOOT_NORMAL_DISTANCE!r}
"""

HELPERS = r"""
static inline double mn(double a, double b) { return a < b ? a : b; }
static inline double mx(double a, double b) { return a > b ? a : b; }
static inline void sub(const double *a, const double *b, double *c) { for (int i = 0; i < 3; ++i) c[i] = a[i] - b[i]; }
static inline double dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline void cross(const double *a, const double *b, double *c) {
    c[0] = a[1] * b[2] - a[2] * b[1]; c[1] = a[2] * b[0] - a[0] * b[2]; c[2] = a[0] * b[1] - a[1] * b[0];
}
static inline void unit(double *a) {
    double l = sqrt(dot(a, a)); if (l < 1e-300) l = 1e-300;
    for (int i = 0; i < 3; ++i) a[i] /= l;
}

/* the posed vertex v: A_s v0 + b_s for a vertex of one segment s, sum_k w_k (A_k v0 + b_k) otherwise, plus the
   pose's shift of a blended vertex (implicit skinning: m->shift set for the pose, NULL for linear blend skinning) */
static inline void posed_vertex(const skin_mesh *m, const double *a, const double *b, int64_t v, double *out) {
    const double *p = m->rest + 3 * v;
    int64_t s = m->vertex_segment[v];
    if (s >= 0) { for (int i = 0; i < 3; ++i) out[i] = dot(a + 9 * s + 3 * i, p) + b[3 * s + i]; return; }
    out[0] = out[1] = out[2] = 0.0;
    for (int64_t e = m->wstart[v]; e < m->wstart[v + 1]; ++e) {
        const double *as = a + 9 * m->wseg[e], *bs = b + 3 * m->wseg[e];
        double w = m->wval[e];
        for (int i = 0; i < 3; ++i) out[i] += w * (dot(as + 3 * i, p) + bs[i]);
    }
    if (m->shift && m->shift_slot[v] >= 0)
        for (int i = 0; i < 3; ++i) out[i] += m->shift[3 * m->shift_slot[v] + i];
}

static double box_distance(const double *lo, const double *hi, const double *x) {
    double d = 0.0;
    for (int i = 0; i < 3; ++i) { double o = mx(lo[i] - x[i], 0.0) + mx(x[i] - hi[i], 0.0); d += o * o; }
    return d;
}

/* [Ericson2005, sec. 5.1.5]: the barycentric coordinates of the closest point of triangle abc to p */
static void closest_on_triangle(const double *p, const double *a, const double *b, const double *c, double *bary) {
    double ab[3], ac[3], ap[3], bp[3], cp[3];
    sub(b, a, ab); sub(c, a, ac); sub(p, a, ap);
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    bary[0] = 1.0; bary[1] = 0.0; bary[2] = 0.0;
    if (d1 <= 0.0 && d2 <= 0.0) return;
    sub(p, b, bp);
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) { bary[0] = 0.0; bary[1] = 1.0; return; }
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) { double v = d1 / (d1 - d3); bary[0] = 1.0 - v; bary[1] = v; return; }
    sub(p, c, cp);
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) { bary[0] = 0.0; bary[2] = 1.0; return; }
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) { double w = d2 / (d2 - d6); bary[0] = 1.0 - w; bary[2] = w; return; }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        bary[0] = 0.0; bary[1] = 1.0 - w; bary[2] = w; return;
    }
    double sum = va + vb + vc;
    if (!(sum > 0.0)) return;                               /* a degenerate triangle: its first corner */
    bary[1] = vb / sum; bary[2] = vc / sum; bary[0] = 1.0 - bary[1] - bary[2];
}

/* the squared distance of x to the triangle with corners p (3 x 3), and the foot's barycentric coordinates */
static double corner_distance(const double *x, const double *p, double *b) {
    closest_on_triangle(x, p, p + 3, p + 6, b);
    double d2 = 0.0;
    for (int i = 0; i < 3; ++i) { double o = x[i] - (b[0] * p[i] + b[1] * p[3 + i] + b[2] * p[6 + i]); d2 += o * o; }
    return d2;
}

/* the corners of triangle f posed at the pose numbered `epoch`: each vertex posed once per pose (vposed, vstamp) */
static void posed_corners(skin_mesh *m, const double *a, const double *b, int64_t epoch, int64_t f, double *p) {
    for (int c = 0; c < 3; ++c) {
        int64_t v = m->faces[3 * f + c];
        double *q = m->vposed + 3 * v;
        if (m->vstamp[v] != epoch) { posed_vertex(m, a, b, v, q); m->vstamp[v] = epoch; }
        for (int i = 0; i < 3; ++i) p[3 * c + i] = q[i];
    }
}
"""

TREE = r"""
static void box_of(const skin_mesh *m, const double *v, int64_t start, int64_t count, double *lo, double *hi) {
    double l0 = INFINITY, l1 = INFINITY, l2 = INFINITY, h0 = -INFINITY, h1 = -INFINITY, h2 = -INFINITY;
    for (int64_t t = start; t < start + count; ++t)
        for (int c = 0; c < 3; ++c) {
            const double *p = v + 3 * m->faces[3 * m->perm[t] + c];
            l0 = mn(l0, p[0]); l1 = mn(l1, p[1]); l2 = mn(l2, p[2]);
            h0 = mx(h0, p[0]); h1 = mx(h1, p[1]); h2 = mx(h2, p[2]);
        }
    lo[0] = l0; lo[1] = l1; lo[2] = l2; hi[0] = h0; hi[1] = h1; hi[2] = h2;
}

static int64_t build_node(skin_mesh *m, const double *centroid, int64_t start, int64_t count, int depth) {
    int64_t node = m->nodes++;
    box_of(m, m->rest, start, count, m->rest_lo + 3 * node, m->rest_hi + 3 * node);
    m->first[node] = start; m->count[node] = count; m->left[node] = -1; m->right[node] = -1;
    if (count <= LEAF) return node;
    double clo[3] = {INFINITY, INFINITY, INFINITY}, chi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int64_t t = start; t < start + count; ++t)
        for (int i = 0; i < 3; ++i) {
            double c = centroid[3 * m->perm[t] + i];
            clo[i] = mn(clo[i], c);
            chi[i] = mx(chi[i], c);
        }
    int axis = 0;
    for (int i = 1; i < 3; ++i) if (chi[i] - clo[i] > chi[axis] - clo[axis]) axis = i;
    double middle = 0.5 * (clo[axis] + chi[axis]);
    int64_t i = start, j = start + count - 1;
    while (i <= j) {                       /* partition: centroids below the middle first */
        if (centroid[3 * m->perm[i] + axis] < middle) ++i;
        else { int64_t s = m->perm[i]; m->perm[i] = m->perm[j]; m->perm[j] = s; --j; }
    }
    int64_t half = i - start;
    if (half == 0 || half == count || depth >= DEEP) half = count / 2;   /* coincident centroids, or deep: halve */
    m->left[node] = build_node(m, centroid, start, half, depth + 1);
    m->right[node] = build_node(m, centroid, start + half, count - half, depth + 1);
    return node;
}

/* the tree on the rest pose (centroid: scratch of 3F doubles); nodes numbered parent before children, each
   node's rigid segment, the list of the others. Returns the number of nodes (at most 2F - 1). */
int64_t skin_build(skin_mesh *m, double *centroid) {
    m->nodes = 0;
    for (int64_t t = 0; t < m->nf; ++t) {
        m->perm[t] = t;
        for (int i = 0; i < 3; ++i) {
            double c = 0.0;
            for (int k = 0; k < 3; ++k) c += m->rest[3 * m->faces[3 * t + k] + i];
            centroid[3 * t + i] = c / 3.0;
        }
    }
    if (m->nf > 0) build_node(m, centroid, 0, m->nf, 0);
    for (int64_t v = 0; v < m->nv; ++v) m->vstamp[v] = -1;
    for (int64_t node = m->nodes - 1; node >= 0; --node) {
        int64_t s;
        if (m->left[node] < 0) {
            s = m->vertex_segment[m->faces[3 * m->perm[m->first[node]]]];
            for (int64_t t = m->first[node]; t < m->first[node] + m->count[node]; ++t)
                for (int c = 0; c < 3; ++c) if (m->vertex_segment[m->faces[3 * m->perm[t] + c]] != s) s = -1;
        } else {
            s = m->node_segment[m->left[node]];
            if (m->node_segment[m->right[node]] != s) s = -1;
        }
        m->node_segment[node] = s;
    }
    m->n_blended = 0;
    for (int64_t node = m->nodes - 1; node >= 0; --node) {      /* the segments a node's vertices follow */
        int64_t mask = 0;
        if (m->left[node] < 0) {
            for (int64_t t = m->first[node]; t < m->first[node] + m->count[node]; ++t)
                for (int c = 0; c < 3; ++c) {
                    int64_t v = m->faces[3 * m->perm[t] + c];
                    for (int64_t e = m->wstart[v]; e < m->wstart[v + 1]; ++e) mask |= (int64_t) 1 << m->wseg[e];
                }
        } else {
            mask = m->mask[m->left[node]] | m->mask[m->right[node]];
        }
        m->mask[node] = mask;
        m->stamp[node] = -1;
        if (m->node_segment[node] < 0) ++m->n_blended;
    }
    return m->nodes;
}

/* a box of a node at the pose (a, b): the union over the segments k its vertices follow of its rest box mapped by
   A_k, b_k (half extents |A_k| h about A_k c + b_k). A posed vertex sum_k w_k (A_k v + b_k) is a convex combination
   of points of those boxes, so it lies in their union's box [Bergen1997] (a bound, looser than a refit) */
static void mapped_box(const skin_mesh *m, const double *a, const double *b, int64_t node, double *lo, double *hi) {
    const double *rl = m->rest_lo + 3 * node, *rh = m->rest_hi + 3 * node;
    double c[3], h[3];
    for (int j = 0; j < 3; ++j) {
        c[j] = 0.5 * (rl[j] + rh[j]); h[j] = 0.5 * (rh[j] - rl[j]); lo[j] = INFINITY; hi[j] = -INFINITY;
    }
    for (int64_t s = 0; s < m->k; ++s) {
        if (!((m->mask[node] >> s) & 1)) continue;
        const double *as = a + 9 * s;
        for (int j = 0; j < 3; ++j) {
            double centre = dot(as + 3 * j, c) + b[3 * s + j];
            double half = fabs(as[3 * j]) * h[0] + fabs(as[3 * j + 1]) * h[1] + fabs(as[3 * j + 2]) * h[2];
            half += m->box_grow;                                 /* the pose's largest shift (implicit skinning) */
            half += 1e-12 * (fabs(centre) + half);              /* round-off: the box contains its vertices */
            lo[j] = mn(lo[j], centre - half); hi[j] = mx(hi[j], centre + half);
        }
    }
}
"""

POSE = r"""
/* the maps rest -> pose of the k segments from their joints and markers `points` (3k, 3): the proximal joints,
   the distal joints, the markers. Returns max |A^T A - I| (0 to round-off for rigid maps, g = 1). */
double skin_maps(int64_t k, const double *points, const double *fraction, const double *rest_c,
                 const double *rest_r, double g, double *a, double *b) {
    double error = 0.0;
    for (int64_t s = 0; s < k; ++s) {
        const double *j1 = points + 3 * s, *j2 = points + 3 * (k + s), *mk = points + 3 * (2 * k + s);
        double axis[3], c[3], e1[3], e2[3], e3[3], off[3], r[3][3], grow[3] = {1.0, g, g};
        sub(j2, j1, axis);
        for (int i = 0; i < 3; ++i) { c[i] = j1[i] + fraction[s] * axis[i]; e1[i] = axis[i]; }
        unit(e1);
        sub(mk, c, off);
        double along = dot(off, e1);
        for (int i = 0; i < 3; ++i) e2[i] = off[i] - along * e1[i];
        unit(e2);
        cross(e1, e2, e3);
        for (int i = 0; i < 3; ++i) { r[i][0] = e1[i]; r[i][1] = e2[i]; r[i][2] = e3[i]; }
        const double *r0 = rest_r + 9 * s;
        double *as = a + 9 * s;
        for (int i = 0; i < 3; ++i)
            for (int l = 0; l < 3; ++l) {
                double sum = 0.0;
                for (int j = 0; j < 3; ++j) sum += r[i][j] * grow[j] * r0[3 * l + j];
                as[3 * i + l] = sum;
            }
        for (int i = 0; i < 3; ++i) b[3 * s + i] = c[i] - dot(as + 3 * i, rest_c + 3 * s);
        for (int i = 0; i < 3; ++i)
            for (int l = 0; l < 3; ++l) {
                double ata = as[i] * as[l] + as[3 + i] * as[3 + l] + as[6 + i] * as[6 + l];
                error = mx(error, fabs(ata - (i == l ? 1.0 : 0.0)));
            }
    }
    return error;
}

/* a bound on the largest vertex displacement between two poses: max_s |dA_s|_F R_s + |dA_s c_s + db_s| */
double skin_travel(int64_t k, const double *a, const double *b, const double *a0, const double *b0,
                   const double *center, const double *radius) {
    double move = 0.0;
    for (int64_t s = 0; s < k; ++s) {
        double da[9], frob = 0.0, shift[3];
        for (int i = 0; i < 9; ++i) { da[i] = a[9 * s + i] - a0[9 * s + i]; frob += da[i] * da[i]; }
        for (int i = 0; i < 3; ++i) shift[i] = dot(da + 3 * i, center + 3 * s) + b[3 * s + i] - b0[3 * s + i];
        move = mx(move, sqrt(frob) * radius[s] + sqrt(dot(shift, shift)));
    }
    return move;
}

void skin_pose(const skin_mesh *m, const double *a, const double *b, double *posed) {
    for (int64_t v = 0; v < m->nv; ++v) posed_vertex(m, a, b, v, posed + 3 * v);
}
"""

QUERY = r"""
/* the angle-weighted pseudonormal [Baerentzen2005] of the feature of triangle f at barycentric coordinates bary */
static void pseudonormal(skin_mesh *m, const double *a, const double *b, int64_t epoch, int64_t f,
                         const double *bary, double *n) {
    int small = 0, corner = 0, big = 0;
    double p[9], q[9], e1[3], e2[3];
    for (int i = 0; i < 3; ++i) {
        if (bary[i] < FEATURE) { if (!small) corner = i; ++small; }
        if (bary[i] > bary[big]) big = i;
    }
    if (small < 2) {
        const int64_t *pair = small ? m->edge_faces + 2 * m->face_edges[3 * f + corner] : &f;
        n[0] = n[1] = n[2] = 0.0;
        for (int side = 0; side < (small ? 2 : 1); ++side) {      /* the face, or the edge's two faces */
            posed_corners(m, a, b, epoch, pair[side], p);
            sub(p + 3, p, e1); sub(p + 6, p, e2); cross(e1, e2, q); unit(q);
            for (int i = 0; i < 3; ++i) n[i] += q[i];
        }
        unit(n); return;
    }
    int64_t vertex = m->faces[3 * f + big];
    n[0] = n[1] = n[2] = 0.0;
    for (int64_t r = m->ring_start[vertex]; r < m->ring_start[vertex + 1]; ++r) {
        int64_t k = m->ring_corner[r];
        double x[3];
        posed_corners(m, a, b, epoch, m->ring_face[r], p);
        sub(p + 3 * ((k + 1) % 3), p + 3 * k, e1); sub(p + 3 * ((k + 2) % 3), p + 3 * k, e2);
        cross(e1, e2, x);
        double angle = atan2(sqrt(dot(x, x)), dot(e1, e2));
        unit(x);
        for (int i = 0; i < 3; ++i) n[i] += angle * x[i];
    }
    unit(n);
}

/* the box distance of a node: rigid (and the maps rigid): its rest box to the point in its segment's frame;
   otherwise its mapped box (`mapped_box`), computed once per pose (`epoch`) on the first visit */
static inline double node_distance(skin_mesh *m, const double *a, const double *b, int rigid, int64_t epoch,
                                   int64_t node, const double *x, const double *xl) {
    int64_t s = rigid ? m->node_segment[node] : -1;
    if (s >= 0) return box_distance(m->rest_lo + 3 * node, m->rest_hi + 3 * node, xl + 3 * s);
    if (m->stamp[node] != epoch) {
        mapped_box(m, a, b, node, m->lo + 3 * node, m->hi + 3 * node);
        m->stamp[node] = epoch;
    }
    return box_distance(m->lo + 3 * node, m->hi + 3 * node, x);
}

static double leaf_distance(skin_mesh *m, const double *a, const double *b, int rigid, int64_t epoch, int64_t f,
                            const double *x, const double *xl, double *bary) {
    double p[9];
    int64_t s = rigid ? m->vertex_segment[m->faces[3 * f]] : -1;
    if (s >= 0 && m->vertex_segment[m->faces[3 * f + 1]] == s && m->vertex_segment[m->faces[3 * f + 2]] == s) {
        for (int c = 0; c < 3; ++c) for (int i = 0; i < 3; ++i) p[3 * c + i] = m->rest[3 * m->faces[3 * f + c] + i];
        return corner_distance(xl + 3 * s, p, bary);
    }
    posed_corners(m, a, b, epoch, f, p);
    return corner_distance(x, p, bary);
}

/* the closest triangle of x: squared distance, *tri (on entry a triangle to start from, or -1), bary. Rigid maps:
   the rigid nodes searched in their segment's rest frame, A_s^T (x - b_s) (distances are invariant) */
static double search(skin_mesh *m, const double *a, const double *b, int rigid, int64_t epoch, const double *x,
                     int64_t *tri, double *bary) {
    double xl[3 * MAXSEG], best = INFINITY, bb[3];
    int64_t stack[STACK];
    int top = 0;
    if (rigid)
        for (int64_t s = 0; s < m->k; ++s) {
            double d[3];
            sub(x, b + 3 * s, d);
            for (int i = 0; i < 3; ++i)
                xl[3 * s + i] = a[9 * s + i] * d[0] + a[9 * s + 3 + i] * d[1] + a[9 * s + 6 + i] * d[2];
        }
    if (*tri >= 0 && *tri < m->nf) best = leaf_distance(m, a, b, rigid, epoch, *tri, x, xl, bary);
    else *tri = m->nf;
    stack[top++] = 0;
    while (top > 0) {
        int64_t node = stack[--top];
        if (node_distance(m, a, b, rigid, epoch, node, x, xl) >= best) continue;
        if (m->left[node] < 0) {
            for (int64_t t = m->first[node]; t < m->first[node] + m->count[node]; ++t) {
                int64_t f = m->perm[t];
                double d2 = leaf_distance(m, a, b, rigid, epoch, f, x, xl, bb);
                if (d2 < best || (d2 == best && f < *tri)) {
                    best = d2; *tri = f;
                    for (int i = 0; i < 3; ++i) bary[i] = bb[i];
                }
            }
            continue;
        }
        int64_t l = m->left[node], r = m->right[node];
        double dl = node_distance(m, a, b, rigid, epoch, l, x, xl), dr = node_distance(m, a, b, rigid, epoch, r, x, xl);
        if (dl <= dr) { if (dr < best) stack[top++] = r; if (dl < best) stack[top++] = l; }
        else { if (dl < best) stack[top++] = l; if (dr < best) stack[top++] = r; }
    }
    return best;
}

/* the points x (n, 3) against the skin at the maps (a, b) (`epoch`: a number of its own for every pose), with the
   active set (margin < 0: every point searched). Writes the searched points' gap, foot, normal, weights, triangle
   and barycentric coordinates and their state (x0, g0, s0); the others get gap = +inf, foot = x, their normal and
   weights kept. Returns the number searched, or -1 - p for a point p that is not finite. */
int64_t skin_query(skin_mesh *m, const double *a, const double *b, int rigid, int64_t epoch, int64_t n,
                   const double *x, double travel, double margin, double *x0, double *g0, double *s0, double *gap,
                   double *foot, double *normal, double *weights, int64_t *tri, double *bary) {
    int64_t searched = 0;
    for (int64_t p = 0; p < n; ++p) {
        const double *xp = x + 3 * p;
        double *fp = foot + 3 * p, *bp = bary + 3 * p, off[3], pseudo[3], corners[9];
        if (!(isfinite(xp[0]) && isfinite(xp[1]) && isfinite(xp[2]))) return -1 - p;
        if (margin >= 0.0) {
            sub(xp, x0 + 3 * p, off);
            if (g0[p] - sqrt(dot(off, off)) - (travel - s0[p]) > margin) {
                gap[p] = INFINITY; for (int i = 0; i < 3; ++i) fp[i] = xp[i];
                continue;
            }
        }
        ++searched;
        double d2 = search(m, a, b, rigid, epoch, xp, tri + p, bp);
        posed_corners(m, a, b, epoch, tri[p], corners);
        for (int i = 0; i < 3; ++i) fp[i] = bp[0] * corners[i] + bp[1] * corners[3 + i] + bp[2] * corners[6 + i];
        pseudonormal(m, a, b, epoch, tri[p], bp, pseudo);
        sub(xp, fp, off);
        double sign = dot(off, pseudo) >= 0.0 ? 1.0 : -1.0, distance = sqrt(mx(d2, 0.0));
        for (int i = 0; i < 3; ++i) normal[3 * p + i] = distance > FOOT_NORMAL ? sign * off[i] / distance : pseudo[i];
        gap[p] = sign * distance;
        double w[3], total = 0.0;
        for (int i = 0; i < 3; ++i) { w[i] = mn(mx(bp[i], 0.0), 1.0); total += w[i]; }
        const int64_t *c = m->faces + 3 * tri[p];
        for (int64_t s = 0; s < m->k; ++s) {
            double sum = 0.0;
            for (int i = 0; i < 3; ++i) sum += w[i] / total * m->weights[m->k * c[i] + s];
            weights[m->k * p + s] = sum;
        }
        for (int i = 0; i < 3; ++i) x0[3 * p + i] = xp[i];
        g0[p] = gap[p]; s0[p] = travel;
    }
    return searched;
}
"""

SOURCE = HEADER + STRUCT + HELPERS + TREE + POSE + QUERY
