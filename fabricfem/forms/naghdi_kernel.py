"""The Naghdi shell's internal force as a hand-written C cell kernel (the explicit routes' hot loop).

FFCx expands the derivative of `naghdi_energy_on_reference` component by component: about 1500 scalar
operations per point of the full rule (docs/findings/2026-11-26-hand-kernel.md). This kernel evaluates the same
force from the strains and their variations written out once ([Eischen2000, eqs. 3-5], frame components):

    Du_i = (grad u) e_i = sum_a u_a (c_i . grad_xi N_a),  c_i = J^+ e_i      (J^+: pseudo-inverse of the Jacobian)
    eps  = [g1.Du1 + |Du1|^2/2, g2.Du2 + |Du2|^2/2, g1.Du2 + g2.Du1 + Du1.Du2]        [Eischen2000, eq. 3]
    d    = c1 c2 a3 + c1 s2 a1 - s1 a2,  c_k = cos th_k, s_k = sin th_k             (fabricfem.forms.shell.director)
    gam_i = (g_i + Du_i) . d - s0_i                                                  [Eischen2000, eq. 4]
    kap  = [-f1.D1d, -f2.D2d, -(f1.D2d + f2.D1d)] + k0,  f_i = g_i + Du_i            [Eischen2000, eq. 5]
    D_j d = c1 c2 Da3_j + c1 s2 Da1_j - s1 Da2_j + d,1 D_j th1 + d,2 D_j th2        (chain rule, d,k = dd/dth_k)

and the residual R = int (N . d eps + Q . d gam + M . d kap) dA with N = dW/d eps, Q = dW/d gam, M = dW/d kap
(PSRI: bending on the full rule; membrane and shear weighted alpha on the full and 1 - alpha on the reduced
rule, alpha = min(1, t_eq^2 / h^2) per cell, fabricfem.forms.shell.psri_weight). Collected per basis function:

    R_u[a]  = sum_q w |J| (P1 D1N_a + P2 D2N_a),  P1 = N1 f1 + N3 f2 + Q1 d - M1 D1d - M3 D2d
                                                 P2 = N2 f2 + N3 f1 + Q2 d - M2 D2d - M3 D1d
    R_th[a] = sum_q w |J| (T_k N_a + S_k1 D1N_a + S_k2 D2N_a),
              T_k = sum_i Q_i f_i . d,k - sum_j h_j . d(D_j d)/d th_k,   S_kj = -h_j . d,k,
              h1 = M1 f1 + M3 f2,  h2 = M2 f2 + M3 f1

The fixed geometry (c_i, g_i, s0_i, the director base a3, a1, a2 and its derivatives along e_j, k0, |J| and alpha)
comes packed at the quadrature points (`kernel_reference_quantities`, evaluated by
fabricfem.shell_reference.ReferenceAtQuadrature); the basis tables are tabulated by basix at the same points and
written into the source. Bending laws: linear (M = D kap), Kawabata and square root on K11, K22 with linear
coupling and twist, as `fabricfem.forms.shell.bending_energy`. A fitted membrane law is not covered (its model
keeps the FFCx form). The kernel is compiled with cffi (fabricfem.forms.jit.compile_c).

Batched: the kernel computes LANES cells at once, each quantity a GCC vector of LANES doubles (the cell innermost;
one 512-bit register, so every operation is one SIMD instruction), the sines and cosines by glibc's vector libmvec
where the compiler targets AVX-512 (libm's sincos per cell otherwise). `naghdi_cells` is its assembly: the state
gathered from the state vector, the reference quantities pre-arranged once per batch (`batched_reference`), the
cells' residuals added cell after cell in dolfinx's order; a short last batch repeats its last cell in the spare
lanes and drops their result. `naghdi_force` (dolfinx's one-cell kernel signature, for dolfinx's own assembly)
runs the same code with the cell in every lane. Each lane does the operations of the former one-cell kernel, the
products c1 c2, c1 s2, s1 c2, s1 s2 hoisted: the residual agrees with it to round-off (2e-16 relative,
docs/findings/2026-11-28-batched-kernel.md).
"""
from __future__ import annotations

import cffi
import numpy as np
import ufl
from ffcx.element_interface import create_element, create_quadrature

from fabricfem.forms import shell as shell_forms
from fabricfem.forms.jit import compile_c, pointer

# Packed reference quantities per quadrature point (name, length): those of fabricfem.forms.shell.reference_layout
# with the material directions e_i replaced by c_i = J^+ e_i, the directions in reference-cell coordinates (so that
# (grad u) e_i = grad_xi u c_i), and |J| the surface's area factor and alpha the PSRI weight of the cell
# (fabricfem.forms.shell.psri_weight) appended.
_EXTRA = (("detJ", 1), ("alpha", 1))
KERNEL_FULL = (("c1", 2), ("c2", 2)) + shell_forms.reference_layout(True)[2:] + _EXTRA
KERNEL_REDUCED = (("c1", 2), ("c2", 2)) + shell_forms.reference_layout(False)[2:] + _EXTRA
LAWS = {"linear": 0, "kawabata": 1, "square_root": 2}
# cells a call of the kernel: one 512-bit register of doubles (docs/findings/2026-11-28-batched-kernel.md)
LANES = 8


def kernel_reference_quantities(phi0, n0, director_base, warp_weft, psri_thickness, cell_size, bending: bool):
    """The quantities of KERNEL_FULL (bending) or KERNEL_REDUCED as one UFL vector, to evaluate at quadrature points
    (psri_thickness, cell_size [m]: the PSRI weight's t_eq and h, fabricfem.forms.shell.psri_weight)."""
    mesh = phi0.ufl_domain()
    parts = shell_forms.reference_parts(phi0, n0, director_base, warp_weft, bending)
    K = ufl.JacobianInverse(mesh)
    parts[0], parts[1] = K * parts[0], K * parts[1]
    parts += [ufl.as_vector([abs(ufl.JacobianDeterminant(mesh))]),
              ufl.as_vector([shell_forms.psri_weight(psri_thickness, cell_size)])]
    return shell_forms.stacked(parts)


def _offsets(layout) -> dict[str, int]:
    """Start of each quantity of a packed layout (name, length) in a point's values. The kernel reads both rules with
    the full rule's offsets (AT_*) and |J|, alpha as their last two values (tests/test_shell_reference.py)."""
    starts = np.cumsum([0] + [n for _, n in layout])
    return {name: int(start) for (name, _), start in zip(layout, starts)}


def law_parameters(law, law_eps) -> tuple[str, np.ndarray]:
    """(law name of LAWS, its parameters for the kernel's constant array) of a bending law (None: linear)."""
    if law is None:
        return "linear", np.zeros(1)
    if hasattr(law, "coefficients"):
        return "kawabata", np.asarray(law.coefficients, dtype=float)
    return "square_root", np.array([law.B0, law.kappa0, law_eps], dtype=float)


def _table(array: np.ndarray) -> str:
    """C initialiser of a numpy array (nested braces), full precision."""
    if array.ndim == 1:
        return "{" + ", ".join(repr(float(x)) for x in array) + "}"
    return "{" + ",\n".join(_table(a) for a in array) + "}"


def _basis(element, cellname: str, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(weights (Q,), tables (Q, 3, n): value, d/dxi_1, d/dxi_2 of the n basis functions) at FFCx's points."""
    points, weights = create_quadrature(cellname, degree, "default")
    tables = np.asarray(create_element(element).tabulate(1, points))     # (3, Q, n)
    return np.asarray(weights), np.ascontiguousarray(tables.transpose(1, 0, 2))


def kernel_source(u_element, theta_element, cellname: str, degrees: tuple[int, int], law: str,
                  n_law: int) -> str:
    """C source of the kernel for the displacement and rotation elements (scalar ufl elements), the PSRI rules'
    degrees and a bending law (LAWS, with n_law parameters)."""
    wf, uf = _basis(u_element, cellname, degrees[0])
    _, tf = _basis(theta_element, cellname, degrees[0])
    wr, ur = _basis(u_element, cellname, degrees[1])
    _, tr = _basis(theta_element, cellname, degrees[1])
    defines = {"LANES": LANES, "NU": uf.shape[2], "NT": tf.shape[2], "NQF": len(wf), "NQR": len(wr), "LAW": LAWS[law],
               "NLAW": n_law, "SF": sum(n for _, n in KERNEL_FULL), "SR": sum(n for _, n in KERNEL_REDUCED),
               **{f"AT_{name}": start for name, start in _offsets(KERNEL_FULL).items()}}
    head = "".join(f"#define {k} {v}\n" for k, v in defines.items())
    tables = (f"static const double WF[NQF] = {_table(wf)};\nstatic const double WR[NQR] = {_table(wr)};\n"
              f"static const double UF[NQF][3][NU] = {_table(uf)};\nstatic const double TF[NQF][3][NT] = {_table(tf)};\n"
              f"static const double UR[NQR][3][NU] = {_table(ur)};\nstatic const double TR[NQR][3][NT] = {_table(tr)};\n")
    return head + tables + KERNEL_C + LOOPS_C


def empty_source(source: str) -> str:
    """The assembly floor's source for a kernel's `source`: its #defines, the loops (LOOPS_C) and a cells_force that
    only zeroes R (fabricfem.benchmarks.internal_force)."""
    head = "".join(line for line in source.splitlines(keepends=True) if line.startswith("#define "))
    return head + EMPTY_C + LOOPS_C


KERNEL_C = r"""
#ifndef _GNU_SOURCE
#define _GNU_SOURCE                /* sincos */
#endif
#include <math.h>
#include <stdint.h>

#define NDOF (3 * NU + 2 * NT)
#define NREF (NQF * SF + NQR * SR)
#ifndef COUNTING                   /* the roofline's FLOP counter brings its own lane type */
typedef double vd __attribute__((vector_size(8 * LANES)));   /* one value of LANES cells (GCC vector extension) */
typedef double vdu __attribute__((vector_size(8 * LANES), aligned(8)));   /* the same, read from any address */
#endif

static inline vd dot3(const vdu* a, const vdu* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

#if defined(__AVX512F__) && LANES == 8 && !defined(COUNTING)
vd _ZGVeN8v_sin(vd);               /* glibc's libmvec: sin and cos of 8 doubles (3e-16 from libm's sincos) */
vd _ZGVeN8v_cos(vd);
static inline void sincos_lanes(vd t, vd* s, vd* c)
{
  *s = _ZGVeN8v_sin(t);
  *c = _ZGVeN8v_cos(t);
}
#else
static inline void sincos_lanes(vd t, vd* s, vd* c)
{
  for (int l = 0; l < LANES; ++l)
  {
    double sl, cl;
    sincos(t[l], &sl, &cl);        /* the values of sin and cos in one call */
    (*s)[l] = sl;
    (*c)[l] = cl;
  }
}
#endif

/* bending moments M = dW_b/d kap (fabricfem.forms.shell.bending_energy); c: A (9), D (9), ks, law parameters */
static void moments(const vd* kap, const double* D, const double* law, vd* M)
{
#if LAW == 0
  for (int i = 0; i < 3; ++i)
    M[i] = 0.5 * ((D[3 * i] + D[i]) * kap[0] + (D[3 * i + 1] + D[3 + i]) * kap[1] + (D[3 * i + 2] + D[6 + i]) * kap[2]);
#else
  for (int l = 0; l < LANES; ++l)
    for (int i = 0; i < 2; ++i)
    {
      const double k = kap[i][l];
#if LAW == 1
      /* [Eischen2000, eq. 15]: W = a0 k^2 / 2 + sum_{n>0} a_n |k|^(n+2) / (n+2) */
      double m = law[0] * k;
      for (int n = 1; n < NLAW; ++n)
        m += law[n] * pow(fabs(k), n + 1) * (k > 0.0 ? 1.0 : (k < 0.0 ? -1.0 : 0.0));
#else
      /* [Peng2022, eq. 9], regularised: r = sqrt(k^2 + eps^2) */
      const double B0 = law[0], k0 = law[1], eps = law[2];
      const double r = sqrt(k * k + eps * eps);
      const double m = r <= k0 ? 2.0 * B0 * sqrt(k0) * sqrt(r) * k / r : B0 * k + B0 * k0 * k / r;
#endif
      M[i][l] = m;
    }
  M[0] += D[1] * kap[1];
  M[1] += D[1] * kap[0];
  M[2] = D[8] * kap[2];
#endif
}

/* The bending part at a point of the full rule: D_j d (Dd), the curvatures' moments M and their terms of the
   rotations' residual (Tk -=, S) (module docstring). r: the point's reference quantities. */
static inline void bend(const vdu* r, vd C1, vd S1, vd C2, vd S2, const vd* d1, const vd* d2, const vd (*dt)[2],
                        const vd* f1, const vd* f2, const double* D, const double* law, vd (*Dd)[3], vd* M, vd* Tk,
                        vd (*S)[2])
{
  const vdu* Da[3][2] = {{r + AT_Da3_1, r + AT_Da3_2}, {r + AT_Da1_1, r + AT_Da1_2}, {r + AT_Da2_1, r + AT_Da2_2}};
  const vdu* k0 = r + AT_k0;
  const vd C1C2 = C1 * C2, C1S2 = C1 * S2, S1C2 = S1 * C2, S1S2 = S1 * S2;
  vd d11[3], d12[3], d22[3];
  for (int k = 0; k < 3; ++k)
  {
    d11[k] = -C1C2 * r[AT_a3 + k] - C1S2 * r[AT_a1 + k] + S1 * r[AT_a2 + k];
    d12[k] = S1S2 * r[AT_a3 + k] - S1C2 * r[AT_a1 + k];
    d22[k] = -C1C2 * r[AT_a3 + k] - C1S2 * r[AT_a1 + k];
  }
  for (int j = 0; j < 2; ++j)
    for (int k = 0; k < 3; ++k)
      Dd[j][k] = C1C2 * Da[0][j][k] + C1S2 * Da[1][j][k] - S1 * Da[2][j][k] + d1[k] * dt[j][0] + d2[k] * dt[j][1];
  /* [Eischen2000, eq. 5] */
  const vd kap[3] = {-dot3(f1, Dd[0]) + k0[0], -dot3(f2, Dd[1]) + k0[1], -(dot3(f1, Dd[1]) + dot3(Dd[0], f2)) + k0[2]};
  moments(kap, D, law, M);
  vd h[2][3];
  for (int k = 0; k < 3; ++k)
  {
    h[0][k] = M[0] * f1[k] + M[2] * f2[k];
    h[1][k] = M[1] * f2[k] + M[2] * f1[k];
  }
  for (int j = 0; j < 2; ++j)
  {
    vd dDd0[3], dDd1[3];           /* d(D_j d)/d th_1, d(D_j d)/d th_2 */
    for (int k = 0; k < 3; ++k)
    {
      dDd0[k] = -S1C2 * Da[0][j][k] - S1S2 * Da[1][j][k] - C1 * Da[2][j][k] + d11[k] * dt[j][0] + d12[k] * dt[j][1];
      dDd1[k] = -C1S2 * Da[0][j][k] + C1C2 * Da[1][j][k] + d12[k] * dt[j][0] + d22[k] * dt[j][1];
    }
    Tk[0] -= dot3(h[j], dDd0);
    Tk[1] -= dot3(h[j], dDd1);
    S[0][j] = -dot3(h[j], d1);
    S[1][j] = -dot3(h[j], d2);
  }
}

/* One rule's contribution for LANES cells (ref: the rule's reference quantities, `size` values a point, cell
   innermost): bending (1 on the full rule) with weight 1, membrane and shear with weight alpha (full) or 1 - alpha
   (reduced). */
static inline void rule(vd (*restrict Au)[NU], vd (*restrict At)[NT], const vd (*u)[NU], const vd (*th)[NT],
                        const double* restrict c, const vdu* restrict ref, int nq, int size,
                        const double* weights, const double (*U)[3][NU], const double (*T)[3][NT], int bending)
{
  const double* Am = c;
  const double* D = c + 9;
  const double ks = c[18];
  const double* law = c + 19;
  for (int q = 0; q < nq; ++q)
  {
    const vdu* r = ref + q * size;
    for (int s = 0; s < size; ++s)   /* the next batch's values at this point (NREF on): from memory meanwhile */
      __builtin_prefetch(r + NREF + s);
    const vdu *c1 = r + AT_c1, *c2 = r + AT_c2, *g1 = r + AT_g1, *g2 = r + AT_g2, *s0 = r + AT_s0, *a3 = r + AT_a3,
              *a1 = r + AT_a1, *a2 = r + AT_a2;
    const vd scale = weights[q] * r[size - 2];
    const vd wm = bending ? r[size - 1] : 1.0 - r[size - 1];
    /* derivatives of the basis along e1, e2 */
    vd DU[2][NU], DT[2][NT];
    for (int a = 0; a < NU; ++a)
    {
      DU[0][a] = c1[0] * U[q][1][a] + c1[1] * U[q][2][a];
      DU[1][a] = c2[0] * U[q][1][a] + c2[1] * U[q][2][a];
    }
    for (int a = 0; a < NT; ++a)
    {
      DT[0][a] = c1[0] * T[q][1][a] + c1[1] * T[q][2][a];
      DT[1][a] = c2[0] * T[q][1][a] + c2[1] * T[q][2][a];
    }
    /* the state and its derivatives along e1, e2 at the point */
    vd du[2][3], t[2], dt[2][2];
    for (int k = 0; k < 3; ++k)
    {
      du[0][k] = u[k][0] * DU[0][0];
      du[1][k] = u[k][0] * DU[1][0];
      for (int a = 1; a < NU; ++a)
      {
        du[0][k] += u[k][a] * DU[0][a];
        du[1][k] += u[k][a] * DU[1][a];
      }
    }
    for (int k = 0; k < 2; ++k)
    {
      t[k] = th[k][0] * T[q][0][0];
      dt[0][k] = th[k][0] * DT[0][0];
      dt[1][k] = th[k][0] * DT[1][0];
      for (int a = 1; a < NT; ++a)
      {
        t[k] += th[k][a] * T[q][0][a];
        dt[0][k] += th[k][a] * DT[0][a];
        dt[1][k] += th[k][a] * DT[1][a];
      }
    }
    vd f1[3], f2[3];
    for (int k = 0; k < 3; ++k)
    {
      f1[k] = g1[k] + du[0][k];
      f2[k] = g2[k] + du[1][k];
    }
    /* [Eischen2000, eq. 3] */
    const vd eps[3] = {dot3(g1, du[0]) + 0.5 * dot3(du[0], du[0]), dot3(g2, du[1]) + 0.5 * dot3(du[1], du[1]),
                       dot3(g1, du[1]) + dot3(g2, du[0]) + dot3(du[0], du[1])};
    vd C1, S1, C2, S2;
    sincos_lanes(t[0], &S1, &C1);
    sincos_lanes(t[1], &S2, &C2);
    const vd C1C2 = C1 * C2, C1S2 = C1 * S2, S1C2 = S1 * C2, S1S2 = S1 * S2;
    vd d[3], d1[3], d2[3];
    for (int k = 0; k < 3; ++k)
    {
      d[k] = C1C2 * a3[k] + C1S2 * a1[k] - S1 * a2[k];
      d1[k] = -S1C2 * a3[k] - S1S2 * a1[k] - C1 * a2[k];
      d2[k] = -C1S2 * a3[k] + C1C2 * a1[k];
    }
    /* [Eischen2000, eq. 4] */
    const vd gam[2] = {dot3(f1, d) - s0[0], dot3(f2, d) - s0[1]};
    vd N[3], Q[2], M[3] = {{0}};   /* M: set by bend on the full rule */
    for (int i = 0; i < 3; ++i)
      N[i] = wm * 0.5 * ((Am[3 * i] + Am[i]) * eps[0] + (Am[3 * i + 1] + Am[3 + i]) * eps[1]
                         + (Am[3 * i + 2] + Am[6 + i]) * eps[2]);
    Q[0] = wm * ks * gam[0];
    Q[1] = wm * ks * gam[1];
    vd Dd[2][3], Tk[2] = {dot3(f1, d1) * Q[0] + dot3(f2, d1) * Q[1], dot3(f1, d2) * Q[0] + dot3(f2, d2) * Q[1]};
    vd S[2][2];
    if (bending)
      bend(r, C1, S1, C2, S2, d1, d2, dt, f1, f2, D, law, Dd, M, Tk, S);
    for (int k = 0; k < 3; ++k)
    {
      vd p1 = N[0] * f1[k] + N[2] * f2[k] + Q[0] * d[k], p2 = N[1] * f2[k] + N[2] * f1[k] + Q[1] * d[k];
      if (bending)
      {
        p1 = p1 - M[0] * Dd[0][k] - M[2] * Dd[1][k];
        p2 = p2 - M[1] * Dd[1][k] - M[2] * Dd[0][k];
      }
      p1 = scale * p1;
      p2 = scale * p2;
      for (int a = 0; a < NU; ++a)
        Au[k][a] += p1 * DU[0][a] + p2 * DU[1][a];
    }
    for (int k = 0; k < 2; ++k)
    {
      const vd tk = scale * Tk[k];
      if (bending)
      {
        const vd sk0 = scale * S[k][0], sk1 = scale * S[k][1];
        for (int a = 0; a < NT; ++a)
          At[k][a] += tk * T[q][0][a] + sk0 * DT[0][a] + sk1 * DT[1][a];
      }
      else
        for (int a = 0; a < NT; ++a)
          At[k][a] += tk * T[q][0][a];
    }
  }
}

/* The residual of LANES cells into R (NDOF values a cell, dolfinx's dof order: u at 3 a + k, th at
   3 NU + 2 a + k): u, th their state, ref their reference quantities (full rule NQF x SF, reduced rule NQR x SR,
   cell innermost), c = [A (9), D (9), ks, law (NLAW)]. */
static void cells_force(vd* restrict R, const vd (*u)[NU], const vd (*th)[NT], const vdu* restrict ref,
                        const double* restrict c)
{
  const vd zero = {0};
  vd Au[3][NU], At[2][NT];
  for (int a = 0; a < NU; ++a)
    for (int k = 0; k < 3; ++k)
      Au[k][a] = zero;
  for (int a = 0; a < NT; ++a)
    for (int k = 0; k < 2; ++k)
      At[k][a] = zero;
  rule(Au, At, u, th, c, ref, NQF, SF, WF, UF, TF, 1);
  rule(Au, At, u, th, c, ref + NQF * SF, NQR, SR, WR, UR, TR, 0);
  for (int a = 0; a < NU; ++a)
    for (int k = 0; k < 3; ++k)
      R[3 * a + k] = Au[k][a];
  for (int a = 0; a < NT; ++a)
    for (int k = 0; k < 2; ++k)
      R[3 * NU + 2 * a + k] = At[k][a];
}
"""

# the loops around cells_force: dolfinx's one-cell kernel and the batched assembly
LOOPS_C = r"""
/* dolfinx (ufcx) cell kernel: A += R of one cell, every lane on it; w = [state (NDOF), reference (NREF)], c as
   cells_force */
void naghdi_force(double* restrict A, const double* restrict w, const double* restrict c,
                  const double* restrict coordinate_dofs, const int* restrict entity_local_index,
                  const uint8_t* restrict quadrature_permutation)
{
  vd u[3][NU], th[2][NT], ref[NREF], R[NDOF];
  for (int l = 0; l < LANES; ++l)
  {
    for (int a = 0; a < NU; ++a)
      for (int k = 0; k < 3; ++k)
        u[k][a][l] = w[3 * a + k];
    for (int a = 0; a < NT; ++a)
      for (int k = 0; k < 2; ++k)
        th[k][a][l] = w[3 * NU + 2 * a + k];
    for (int s = 0; s < NREF; ++s)
      ref[s][l] = w[NDOF + s];
  }
  cells_force(R, u, th, ref, c);
  for (int j = 0; j < NDOF; ++j)
    A[j] += R[j][0];
}

/* b[dofs] += R of ncells cells at the state x, LANES cells a call of cells_force, added cell after cell as
   dolfinx's assembler adds them. ref: NREF x LANES values per batch of LANES cells (naghdi_kernel.batched_reference:
   the lanes past the last cell repeat it, and their dofs its dofs; their R is dropped); dofs: NDOF per cell. */
void naghdi_cells(double* restrict b, const double* restrict x, const double* restrict ref,
                  const double* restrict c, const int32_t* restrict dofs, int ncells)
{
  vd u[3][NU], th[2][NT], R[NDOF];
  for (int first = 0; first < ncells; first += LANES)
  {
    const int n = ncells - first < LANES ? ncells - first : LANES;
    for (int l = 0; l < LANES; ++l)
    {
      const int32_t* cell = dofs + (int64_t)(first + (l < n ? l : n - 1)) * NDOF;
      for (int a = 0; a < NU; ++a)
        for (int k = 0; k < 3; ++k)
          u[k][a][l] = x[cell[3 * a + k]];
      for (int a = 0; a < NT; ++a)
        for (int k = 0; k < 2; ++k)
          th[k][a][l] = x[cell[3 * NU + 2 * a + k]];
    }
    cells_force(R, u, th, (const vdu*)(ref + (int64_t)first * NREF), c);
    for (int l = 0; l < n; ++l)
    {
      const int32_t* cell = dofs + (int64_t)(first + l) * NDOF;
      for (int j = 0; j < NDOF; ++j)
        b[cell[j]] += R[j][l];
    }
  }
}
"""

# the assembly floor (fabricfem.benchmarks.internal_force): the same loops around a kernel that computes nothing
EMPTY_C = r"""
#include <stdint.h>
#define NDOF (3 * NU + 2 * NT)
typedef double vd __attribute__((vector_size(8 * LANES)));
typedef double vdu __attribute__((vector_size(8 * LANES), aligned(8)));
#define NREF (NQF * SF + NQR * SR)
static void cells_force(vd* restrict R, const vd (*u)[NU], const vd (*th)[NT], const vdu* restrict ref,
                        const double* restrict c)
{
  const vd zero = {0};
  for (int j = 0; j < NDOF; ++j)
    R[j] = zero;
}
"""


CDEF = ("void naghdi_force(double*, const double*, const double*, const double*, const int*, const uint8_t*);\n"
        "void naghdi_cells(double*, const double*, const double*, const double*, const int32_t*, int);")
_CELLS = cffi.FFI()
_CELLS.cdef("typedef void (*naghdi_cells_t)(double*, const double*, const double*, const double*, const int32_t*, "
            "int);")


def compile_kernel(source: str, comm, flags: tuple[str, ...]) -> tuple[int, int]:
    """Compile the kernel's `source` (fabricfem.forms.jit.compile_c) and return the addresses (ints) of its
    `naghdi_force` (one cell, for dolfinx's Form) and `naghdi_cells` (the batched assembly, `assemble_cells`)."""
    module = compile_c("fabricfem_naghdi", CDEF, source, comm, flags, libraries=("mvec", "m"))
    return tuple(int(module.ffi.cast("uintptr_t", module.ffi.addressof(module.lib, name)))
                 for name in ("naghdi_force", "naghdi_cells"))


def batched_reference(packed: np.ndarray, ndofs: int) -> np.ndarray:
    """The reference quantities of dolfinx's packed coefficients (cells, ndofs + NREF: the state's block first) in
    naghdi_cells' layout: (batches, NREF, LANES), the cell innermost, the last batch filled up with its last cell."""
    reference = packed[:, ndofs:]
    pad = -len(reference) % LANES
    reference = np.concatenate([reference, np.repeat(reference[-1:], pad, axis=0)])
    return np.ascontiguousarray(reference.reshape(-1, LANES, reference.shape[1]).transpose(0, 2, 1))


def assemble_cells(address: int, b: np.ndarray, x: np.ndarray, reference: np.ndarray, constants: np.ndarray,
                   dofs: np.ndarray) -> None:
    """b[dofs] += the kernel's residual of the cells at the state x by its `naghdi_cells` at `address` (LANES cells
    a call). b, x: local arrays (owned and ghost entries) [N, N m; m, rad]; reference: `batched_reference`'s;
    dofs (cells, 3 NU + 2 NT) int32, C-contiguous."""
    cells = _CELLS.cast("naghdi_cells_t", address)
    constants = constants if constants.size else np.zeros(1)
    cells(pointer(_CELLS, b, "double"), pointer(_CELLS, x, "double"), pointer(_CELLS, reference, "double"),
          pointer(_CELLS, constants, "double"), pointer(_CELLS, dofs, "int32_t"), len(dofs))
