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
"""
from __future__ import annotations

import numpy as np
import ufl
from ffcx.element_interface import create_element, create_quadrature

from fabricfem.forms import shell as shell_forms
from fabricfem.forms.jit import compile_c

# Packed reference quantities per quadrature point (name, length): those of fabricfem.forms.shell.reference_layout
# with the material directions e_i replaced by c_i = J^+ e_i, the directions in reference-cell coordinates (so that
# (grad u) e_i = grad_xi u c_i), and |J| the surface's area factor and alpha the PSRI weight of the cell
# (fabricfem.forms.shell.psri_weight) appended.
_EXTRA = (("detJ", 1), ("alpha", 1))
KERNEL_FULL = (("c1", 2), ("c2", 2)) + shell_forms.reference_layout(True)[2:] + _EXTRA
KERNEL_REDUCED = (("c1", 2), ("c2", 2)) + shell_forms.reference_layout(False)[2:] + _EXTRA
LAWS = {"linear": 0, "kawabata": 1, "square_root": 2}


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
    defines = {"NU": uf.shape[2], "NT": tf.shape[2], "NQF": len(wf), "NQR": len(wr), "LAW": LAWS[law],
               "NLAW": n_law, "SF": sum(n for _, n in KERNEL_FULL), "SR": sum(n for _, n in KERNEL_REDUCED),
               **{f"AT_{name}": start for name, start in _offsets(KERNEL_FULL).items()}}
    head = "".join(f"#define {k} {v}\n" for k, v in defines.items())
    tables = (f"static const double WF[NQF] = {_table(wf)};\nstatic const double WR[NQR] = {_table(wr)};\n"
              f"static const double UF[NQF][3][NU] = {_table(uf)};\nstatic const double TF[NQF][3][NT] = {_table(tf)};\n"
              f"static const double UR[NQR][3][NU] = {_table(ur)};\nstatic const double TR[NQR][3][NT] = {_table(tr)};\n")
    return head + tables + KERNEL_C


KERNEL_C = r"""
#ifndef _GNU_SOURCE
#define _GNU_SOURCE                /* sincos */
#endif
#include <math.h>
#include <stdint.h>

static inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* bending moments M = dW_b/d kap (fabricfem.forms.shell.bending_energy); c: A (9), D (9), ks, law parameters */
static void moments(const double* kap, const double* D, const double* law, double* M)
{
#if LAW == 0
  for (int i = 0; i < 3; ++i)
    M[i] = 0.5 * ((D[3 * i] + D[i]) * kap[0] + (D[3 * i + 1] + D[3 + i]) * kap[1] + (D[3 * i + 2] + D[6 + i]) * kap[2]);
#else
  for (int i = 0; i < 2; ++i)
  {
    const double k = kap[i];
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
    M[i] = m;
  }
  M[0] += D[1] * kap[1];
  M[1] += D[1] * kap[0];
  M[2] = D[8] * kap[2];
#endif
}

/* One rule's contribution: bending (1 on the full rule) with weight 1, membrane and shear with weight
   alpha (full) or 1 - alpha (reduced). */
static inline void rule(double (*restrict Au)[NU], double (*restrict At)[NT], const double (*u)[NU],
                        const double (*th)[NT], const double* restrict c, const double* restrict ref, int nq, int size,
                        const double* weights, const double (*U)[3][NU], const double (*T)[3][NT], int bending)
{
  const double* Am = c;
  const double* D = c + 9;
  const double ks = c[18];
  const double* law = c + 19;
  for (int q = 0; q < nq; ++q)
  {
    const double* r = ref + q * size;
    const double *c1 = r + AT_c1, *c2 = r + AT_c2, *g1 = r + AT_g1, *g2 = r + AT_g2, *s0 = r + AT_s0,
                 *a3 = r + AT_a3, *a1 = r + AT_a1, *a2 = r + AT_a2;
    const double detJ = r[size - 2], alpha = r[size - 1];
    const double scale = weights[q] * detJ;
    const double wm = bending ? alpha : 1.0 - alpha;
    /* derivatives of the basis along e1, e2 */
    double DU[2][NU], DT[2][NT];
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
    /* the state and its derivatives along e1, e2 at the point (node-contiguous loops: vectorised) */
    double du[2][3] = {{0}}, t[2] = {0}, dt[2][2] = {{0}};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < NU; ++a)
      {
        du[0][k] += u[k][a] * DU[0][a];
        du[1][k] += u[k][a] * DU[1][a];
      }
    for (int k = 0; k < 2; ++k)
      for (int a = 0; a < NT; ++a)
      {
        t[k] += th[k][a] * T[q][0][a];
        dt[0][k] += th[k][a] * DT[0][a];
        dt[1][k] += th[k][a] * DT[1][a];
      }
    double f1[3], f2[3];
    for (int k = 0; k < 3; ++k)
    {
      f1[k] = g1[k] + du[0][k];
      f2[k] = g2[k] + du[1][k];
    }
    /* [Eischen2000, eq. 3] */
    const double eps[3] = {dot3(g1, du[0]) + 0.5 * dot3(du[0], du[0]), dot3(g2, du[1]) + 0.5 * dot3(du[1], du[1]),
                           dot3(g1, du[1]) + dot3(g2, du[0]) + dot3(du[0], du[1])};
    double C1, S1, C2, S2;          /* sincos: the values of sin and cos in one call */
    sincos(t[0], &S1, &C1);
    sincos(t[1], &S2, &C2);
    double d[3], d1[3], d2[3];
    for (int k = 0; k < 3; ++k)
    {
      d[k] = C1 * C2 * a3[k] + C1 * S2 * a1[k] - S1 * a2[k];
      d1[k] = -S1 * C2 * a3[k] - S1 * S2 * a1[k] - C1 * a2[k];
      d2[k] = -C1 * S2 * a3[k] + C1 * C2 * a1[k];
    }
    /* [Eischen2000, eq. 4] */
    const double gam[2] = {dot3(f1, d) - s0[0], dot3(f2, d) - s0[1]};
    double N[3], Q[2], M[3] = {0.0, 0.0, 0.0};
    for (int i = 0; i < 3; ++i)
      N[i] = wm * 0.5 * ((Am[3 * i] + Am[i]) * eps[0] + (Am[3 * i + 1] + Am[3 + i]) * eps[1]
                         + (Am[3 * i + 2] + Am[6 + i]) * eps[2]);
    Q[0] = wm * ks * gam[0];
    Q[1] = wm * ks * gam[1];
    double Dd[2][3], P1[3], P2[3], Tk[2] = {dot3(f1, d1) * Q[0] + dot3(f2, d1) * Q[1],
                                               dot3(f1, d2) * Q[0] + dot3(f2, d2) * Q[1]};
    double S[2][2] = {{0.0, 0.0}, {0.0, 0.0}};
    if (bending)
    {
      const double* Da[3][2] = {{r + AT_Da3_1, r + AT_Da3_2}, {r + AT_Da1_1, r + AT_Da1_2},
                                {r + AT_Da2_1, r + AT_Da2_2}};
      const double* k0 = r + AT_k0;
      double d11[3], d12[3], d22[3];
      for (int k = 0; k < 3; ++k)
      {
        d11[k] = -C1 * C2 * a3[k] - C1 * S2 * a1[k] + S1 * a2[k];
        d12[k] = S1 * S2 * a3[k] - S1 * C2 * a1[k];
        d22[k] = -C1 * C2 * a3[k] - C1 * S2 * a1[k];
      }
      for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 3; ++k)
          Dd[j][k] = C1 * C2 * Da[0][j][k] + C1 * S2 * Da[1][j][k] - S1 * Da[2][j][k] + d1[k] * dt[j][0]
                     + d2[k] * dt[j][1];
      /* [Eischen2000, eq. 5] */
      const double kap[3] = {-dot3(f1, Dd[0]) + k0[0], -dot3(f2, Dd[1]) + k0[1],
                             -(dot3(f1, Dd[1]) + dot3(Dd[0], f2)) + k0[2]};
      moments(kap, D, law, M);
      double h[2][3];
      for (int k = 0; k < 3; ++k)
      {
        h[0][k] = M[0] * f1[k] + M[2] * f2[k];
        h[1][k] = M[1] * f2[k] + M[2] * f1[k];
      }
      for (int j = 0; j < 2; ++j)
      {
        double dDd0[3], dDd1[3];   /* d(D_j d)/d th_1, d(D_j d)/d th_2 */
        for (int k = 0; k < 3; ++k)
        {
          dDd0[k] = -S1 * C2 * Da[0][j][k] - S1 * S2 * Da[1][j][k] - C1 * Da[2][j][k] + d11[k] * dt[j][0]
                    + d12[k] * dt[j][1];
          dDd1[k] = -C1 * S2 * Da[0][j][k] + C1 * C2 * Da[1][j][k] + d12[k] * dt[j][0] + d22[k] * dt[j][1];
        }
        Tk[0] -= dot3(h[j], dDd0);
        Tk[1] -= dot3(h[j], dDd1);
        S[0][j] = -dot3(h[j], d1);
        S[1][j] = -dot3(h[j], d2);
      }
    }
    else
    {
      for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 3; ++k)
          Dd[j][k] = 0.0;
    }
    for (int k = 0; k < 3; ++k)
    {
      P1[k] = scale * (N[0] * f1[k] + N[2] * f2[k] + Q[0] * d[k] - M[0] * Dd[0][k] - M[2] * Dd[1][k]);
      P2[k] = scale * (N[1] * f2[k] + N[2] * f1[k] + Q[1] * d[k] - M[1] * Dd[1][k] - M[2] * Dd[0][k]);
    }
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < NU; ++a)
        Au[k][a] += P1[k] * DU[0][a] + P2[k] * DU[1][a];
    for (int k = 0; k < 2; ++k)
    {
      const double tk = scale * Tk[k], sk0 = scale * S[k][0], sk1 = scale * S[k][1];
      for (int a = 0; a < NT; ++a)
        At[k][a] += tk * T[q][0][a] + sk0 * DT[0][a] + sk1 * DT[1][a];
    }
  }
}

/* dolfinx (ufcx) cell kernel: A += R(state) of one cell; w = [state (3 NU + 2 NT), full rule (NQF x SF),
   reduced rule (NQR x SR)], c = [A (9), D (9), ks, law (NLAW)] */
void naghdi_force(double* restrict A, const double* restrict w, const double* restrict c,
                  const double* restrict coordinate_dofs, const int* restrict entity_local_index,
                  const uint8_t* restrict quadrature_permutation)
{
  /* the state and the residual component-major (the dofs are node-major: u at 3 a + k, th at 3 NU + 2 a + k) */
  double u[3][NU], th[2][NT], Au[3][NU] = {{0}}, At[2][NT] = {{0}};
  for (int a = 0; a < NU; ++a)
    for (int k = 0; k < 3; ++k)
      u[k][a] = w[3 * a + k];
  for (int a = 0; a < NT; ++a)
    for (int k = 0; k < 2; ++k)
      th[k][a] = w[3 * NU + 2 * a + k];
  const double* full = w + 3 * NU + 2 * NT;
  rule(Au, At, u, th, c, full, NQF, SF, WF, UF, TF, 1);
  rule(Au, At, u, th, c, full + NQF * SF, NQR, SR, WR, UR, TR, 0);
  for (int a = 0; a < NU; ++a)
    for (int k = 0; k < 3; ++k)
      A[3 * a + k] += Au[k][a];
  for (int a = 0; a < NT; ++a)
    for (int k = 0; k < 2; ++k)
      A[3 * NU + 2 * a + k] += At[k][a];
}
"""


def compile_kernel(source: str, comm, flags: tuple[str, ...]) -> int:
    """Compile the kernel's `source` (fabricfem.forms.jit.compile_c) and return the address of its `naghdi_force`
    (an int for dolfinx's Form)."""
    module = compile_c("fabricfem_naghdi", "void naghdi_force(double*, const double*, const double*, const double*, "
                       "const int*, const uint8_t*);", source, comm, flags)
    return int(module.ffi.cast("uintptr_t", module.ffi.addressof(module.lib, "naghdi_force")))
