"""Geometrically nonlinear Naghdi shell in total Lagrangian form on a manifold mesh.

Kinematics ([Eischen2000, eqs. 1-6]; [Man2006, ch. 2]): the mid-surface moves from phi0 to
phi = phi0 + u and the unit director moves from the reference normal n0 to d.
With the tangential gradient of the embedded surface (3x3 tensors acting on the
tangent plane) the strain measures read, coordinate-free,

    membrane      E   = 1/2 (F^T F - F0^T F0)                              [Eischen2000, eq. 3]
    transverse    g   = F^T d - F0^T n0                                     [Eischen2000, eq. 4]
    bending       K   = -1/2 (F^T grad d + grad d^T F)
                        + 1/2 (F0^T grad n0 + grad n0^T F0)                 ([Eischen2000, eq. 5], symmetrised)

with F = grad phi, F0 = grad phi0. Components are taken in the orthonormal
material frame (e1 = warp, e2 = weft) of the reference surface. The director is
parametrised by two rotations about the reference director frame (n0, t1, t2),

    d = cos(th1) cos(th2) n0 + cos(th1) sin(th2) t1 - sin(th1) t2,

so th2 is a right-handed rotation about t2 and th1 one about t1. Measured from the
local frame (not a global axis) there is no singularity on closed surfaces; the
frame can be re-based on the current director between load steps so that only
increments are parametrised (fabricfem.shell.ShellModel.rebase_director).

Locking is avoided by partial selective reduced integration (PSRI [ArnoldBrezzi1997], as in FEniCSx-Shells):
membrane and shear energies are split into alpha (full) and 1 - alpha (reduced quadrature) with
alpha = min(1, t_eq^2 / h^2), t_eq the thickness equivalent to the actual bending and membrane stiffnesses
(`equivalent_thickness`: t itself when D = t^3 / 12 Q).
"""
from __future__ import annotations

import math

import numpy as np
import ufl


def director(theta, n0, t1, t2):
    """Unit director from the two rotation angles theta = (th1, th2) [rad] and the frame (n0, t1, t2)."""
    c1, s1 = ufl.cos(theta[0]), ufl.sin(theta[0])
    c2, s2 = ufl.cos(theta[1]), ufl.sin(theta[1])
    return c1 * c2 * n0 + c1 * s2 * t1 - s1 * t2


def material_frame(F0, t1, t2):
    """Orthonormal warp/weft vectors e1, e2 in the reference tangent plane (Gram-Schmidt of F0 t1, F0 t2)."""
    a1 = F0 * t1
    e1 = a1 / ufl.sqrt(ufl.dot(a1, a1))
    a2 = F0 * t2 - ufl.dot(F0 * t2, e1) * e1
    e2 = a2 / ufl.sqrt(ufl.dot(a2, a2))
    return e1, e2


def membrane_strain(F, F0):
    """Green-Lagrange membrane strain tensor E = (F^T F - F0^T F0) / 2 [Eischen2000, eq. 3]."""
    return 0.5 * (F.T * F - F0.T * F0)


def area_stretch(F, F0, t1, t2):
    """J = da / dA = |F e1 x F e2| of the mid-surface, (e1, e2) the orthonormal reference frame (Nanson)."""
    e1, e2 = material_frame(F0, t1, t2)
    a = ufl.cross(F * e1, F * e2)
    return ufl.sqrt(ufl.dot(a, a))


def bending_strain(F, F0, d, n0):
    """Change of curvature K ([Eischen2000, eq. 5], symmetrised), sign chosen so K > 0 bends towards -n0."""
    grad_d, grad_n0 = ufl.grad(d), ufl.grad(n0)
    return -0.5 * (F.T * grad_d + grad_d.T * F) + 0.5 * (F0.T * grad_n0 + grad_n0.T * F0)


def shear_strain(F, F0, d, n0):
    """Transverse shear strain vector g = F^T d - F0^T n0 [Eischen2000, eq. 4]."""
    return F.T * d - F0.T * n0


def voigt(T, e1, e2):
    """In-plane Voigt components [T11, T22, 2 T12] of a surface tensor in the frame (e1, e2)."""
    return ufl.as_vector([ufl.dot(e1, T * e1), ufl.dot(e2, T * e2), 2.0 * ufl.dot(e1, T * e2)])


def quadratic_energy(strain_voigt, C):
    """1/2 eps . C eps for a Voigt strain and a 3x3 stiffness C (UFL tensor)."""
    return 0.5 * ufl.dot(strain_voigt, C * strain_voigt)


def kawabata_energy(kappa, coefficients):
    """Energy per unit area of M(K) = sum_i a_i K^i extended oddly [Eischen2000, eq. 15]: sum_i a_i |K|^(i+1) / (i+1)."""
    return sum(a * abs(kappa) ** (i + 2) / (i + 2) if i > 0 else a * kappa ** 2 / 2
               for i, a in enumerate(coefficients))


def square_root_energy(kappa, B0, kappa0, eps):
    """Energy of [Peng2022, eq. 9], m = 2 B0 sqrt(kappa0 |K|) up to kappa0 then B0 (|K| + kappa0).

    |K| is regularised as r = sqrt(K^2 + eps^2) (eps [1/m] set by the caller): the energy
    4/3 B0 sqrt(kappa0) (r^(3/2) - eps^(3/2)) gives m -> 2 B0 sqrt(kappa0 |K|) for |K| >> eps and a
    finite initial stiffness 2 B0 sqrt(kappa0 / eps) (the exact law has an infinite one); beyond
    r = kappa0 the branch B0 (r^2 - kappa0^2) / 2 + B0 kappa0 (r - kappa0) continues it with
    continuous moment.
    """
    r = ufl.sqrt(kappa ** 2 + eps ** 2)
    w_inner = 4.0 / 3.0 * B0 * ufl.sqrt(kappa0) * (r ** 1.5 - eps ** 1.5)
    w_kink = 4.0 / 3.0 * B0 * ufl.sqrt(kappa0) * (kappa0 ** 1.5 - eps ** 1.5)
    w_outer = w_kink + 0.5 * B0 * (r ** 2 - kappa0 ** 2) + B0 * kappa0 * (r - kappa0)
    return ufl.conditional(ufl.le(r, kappa0), w_inner, w_outer)


def bending_energy(kappa_voigt, D, law=None, eps=None):
    """Bending energy per unit area: 1/2 K.D K, or a nonlinear law on K11, K22 plus linear coupling and twist."""
    if law is None:
        return quadratic_energy(kappa_voigt, D)
    k11, k22, k12x2 = kappa_voigt[0], kappa_voigt[1], kappa_voigt[2]
    coupling = D[0, 1] * k11 * k22 + 0.5 * D[2, 2] * k12x2 ** 2
    if hasattr(law, "coefficients"):
        return kawabata_energy(k11, law.coefficients) + kawabata_energy(k22, law.coefficients) + coupling
    return (square_root_energy(k11, law.B0, law.kappa0, eps)
            + square_root_energy(k22, law.B0, law.kappa0, eps) + coupling)


def equivalent_thickness(A: np.ndarray, D: np.ndarray) -> float:
    """Thickness t_eq [m] of the PSRI weight for a membrane stiffness A [N/m] and a bending stiffness D [N m]
    (Voigt 3x3 each): t_eq = sqrt(12 max(D11 / A11, D22 / A22)).

    [ArnoldBrezzi1997] split the membrane-shear energy of a shell whose bending energy carries t^3 / 12 and
    whose membrane-shear energy t, so that the fully integrated part alpha t (psi_m + psi_s) has the stiffness
    of the bending energy at the mesh scale: alpha t = t^3 / h^2, alpha = t^2 / h^2. With stiffnesses given
    independently (a fabric's bending rigidity B measured apart from its tensile modulus) the same balance
    reads alpha A = 12 D / h^2, i.e. alpha = t_eq^2 / h^2 with t_eq^2 = 12 D / A: for D = t^3 / 12 Q and
    A = t Q it is t^2 whatever Q, for D11 = B1 it is 12 B1 (1 - nu12 nu21) / (E1 t). Of the two material
    directions the stiffer in bending (the larger ratio) sets the weight: its hourglass modes are the ones the
    reduced rule would leave least restrained (docs/shell.md, "Locking")."""
    return math.sqrt(12.0 * max(D[0, 0] / A[0, 0], D[1, 1] / A[1, 1]))


def psri_weight(psri_thickness, cell_size) -> ufl.core.expr.Expr:
    """PSRI weight alpha = min(1, t_eq^2 / h^2) of the fully integrated membrane and shear energy [ArnoldBrezzi1997]
    (t_eq [m]: `equivalent_thickness`, h [m] the cell size); at most 1, so that the reduced rule's weight
    1 - alpha is never negative (a cell smaller than t_eq is integrated fully: it does not lock)."""
    return ufl.min_value(psri_thickness ** 2 / cell_size ** 2, 1.0)


def psri_measures(mesh, full_degree: int = 4, reduced_degree: int = 2):
    """Full and reduced quadrature measures for partial selective reduced integration."""
    dx_full = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": full_degree})
    dx_reduced = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": reduced_degree})
    return dx_full, dx_reduced


def naghdi_energy(u, theta, phi0, n0, director_base, warp_weft, A, D, shear_stiffness, psri_thickness,
                  law=None, law_eps=None, degrees=(4, 2), cell_size=None, membrane_density=None):
    """Total strain energy of the shell with PSRI (UFL form of rank 0).

    u: displacement [m]; theta: rotations [rad]; phi0: reference position (P2 Function);
    n0: reference unit normal; director_base = (a3, a1, a2): the frame the rotations are
    measured from (a3 = n0 initially); warp_weft = (t1, t2): reference material directions;
    A = t Q [N/m] membrane stiffness; D [N m] bending stiffness (Voigt 3x3);
    shear_stiffness = k_s G13 t [N/m]; psri_thickness: t_eq of the PSRI weight [m] (`equivalent_thickness`,
    `psri_weight`); cell_size: h of the PSRI weight [m] (default ufl.CellDiameter,
    which FFCx supports on affine cells only: pass a DG0 field on curved meshes);
    membrane_density: optional callable W(eps) [J/m^2] of the Voigt membrane strain (E11, E22, 2 E12)
    replacing 1/2 eps.A eps (a fitted law, forms.fitted); it is PSRI-split like the quadratic one.
    """
    mesh = u.ufl_domain()
    F0 = ufl.grad(phi0)
    F = F0 + ufl.grad(u)
    d = director(theta, *director_base)
    e1, e2 = material_frame(F0, *warp_weft)
    eps_m = voigt(membrane_strain(F, F0), e1, e2)
    kappa = voigt(bending_strain(F, F0, d, n0), e1, e2)
    gamma_vec = shear_strain(F, F0, d, n0)
    gamma = ufl.as_vector([ufl.dot(gamma_vec, e1), ufl.dot(gamma_vec, e2)])

    psi_m = quadratic_energy(eps_m, A) if membrane_density is None else membrane_density(eps_m)
    psi_b = bending_energy(kappa, D, law, law_eps)
    psi_s = 0.5 * shear_stiffness * ufl.dot(gamma, gamma)

    dx_full, dx_reduced = psri_measures(mesh, *degrees)
    h = ufl.CellDiameter(mesh) if cell_size is None else cell_size
    alpha = psri_weight(psri_thickness, h)
    return (psi_b * dx_full + alpha * (psi_m + psi_s) * dx_full
            + (1.0 - alpha) * (psi_m + psi_s) * dx_reduced)


# The reference quantities of the shell at a quadrature point, packed in this order (name, length): the material
# frame e1, e2; g_i = F0 e_i; s0_i = g_i . n0; the director base a3, a1, a2; and, for the bending energy, the
# derivatives of the base along e_j, (grad a) e_j, and the reference curvature k0 = voigt(1/2 (F0^T grad n0 +
# grad n0^T F0)) [Eischen2000, eq. 5]. Everything here is fixed during a dynamic run (the base is not re-based).
REFERENCE_MEMBRANE_SHEAR = (("e1", 3), ("e2", 3), ("g1", 3), ("g2", 3), ("s0", 2), ("a3", 3), ("a1", 3), ("a2", 3))
REFERENCE_BENDING = (("Da3_1", 3), ("Da3_2", 3), ("Da1_1", 3), ("Da1_2", 3), ("Da2_1", 3), ("Da2_2", 3), ("k0", 3))


def reference_layout(bending: bool) -> tuple[tuple[str, int], ...]:
    """(name, length) of the packed reference quantities, with or without the bending ones."""
    return REFERENCE_MEMBRANE_SHEAR + (REFERENCE_BENDING if bending else ())


def reference_parts(phi0, n0, director_base, warp_weft, bending: bool) -> list:
    """The reference quantities of `reference_layout(bending)`, one UFL vector each, in the layout's order."""
    F0 = ufl.grad(phi0)
    e1, e2 = material_frame(F0, *warp_weft)
    g1, g2 = F0 * e1, F0 * e2
    a3, a1, a2 = director_base
    parts = [e1, e2, g1, g2, ufl.as_vector([ufl.dot(g1, n0), ufl.dot(g2, n0)]), a3, a1, a2]
    if bending:
        for a in (a3, a1, a2):
            parts += [ufl.grad(a) * e1, ufl.grad(a) * e2]
        grad_n0 = ufl.grad(n0)
        parts.append(voigt(0.5 * (F0.T * grad_n0 + grad_n0.T * F0), e1, e2))
    return parts


def stacked(parts) -> ufl.core.expr.Expr:
    """One UFL vector of the components of `parts` (vectors), in order (to evaluate at quadrature points)."""
    return ufl.as_vector([p[i] for p in parts for i in range(p.ufl_shape[0])])


def reference_quantities(phi0, n0, director_base, warp_weft, bending: bool):
    """The reference quantities of `reference_layout(bending)` as one UFL vector (to evaluate at quadrature points)."""
    return stacked(reference_parts(phi0, n0, director_base, warp_weft, bending))


def _unpack(packed, bending: bool) -> dict:
    """Named UFL views of a packed reference vector (reference_layout)."""
    views, start = {}, 0
    for name, length in reference_layout(bending):
        views[name] = ufl.as_vector([packed[start + i] for i in range(length)])
        start += length
    return views


def strains_on_reference(u, theta, packed, bending: bool):
    """Membrane (Voigt), shear and, if `bending`, bending (Voigt) strains of the Naghdi shell from the packed
    reference quantities (reference_quantities): the strains of `naghdi_energy` written in the frame,

        eps_m = [g1.Du1 + |Du1|^2 / 2, g2.Du2 + |Du2|^2 / 2, g1.Du2 + g2.Du1 + Du1.Du2]      [Eischen2000, eq. 3]
        gamma_i = (g_i + Du_i) . d - s0_i                                                [Eischen2000, eq. 4]
        K_ij = -1/2 ((g_i + Du_i) . D_j d + D_i d . (g_j + Du_j)) + k0_ij                [Eischen2000, eq. 5]

    with Du_i = (grad u) e_i and D_j d = (grad d) e_j by the chain rule through the angles and the base."""
    r = _unpack(packed, bending)
    du = [ufl.grad(u) * r["e1"], ufl.grad(u) * r["e2"]]
    g = [r["g1"], r["g2"]]
    fe = [g[0] + du[0], g[1] + du[1]]
    eps_m = ufl.as_vector([ufl.dot(g[0], du[0]) + 0.5 * ufl.dot(du[0], du[0]),
                           ufl.dot(g[1], du[1]) + 0.5 * ufl.dot(du[1], du[1]),
                           ufl.dot(g[0], du[1]) + ufl.dot(g[1], du[0]) + ufl.dot(du[0], du[1])])
    a3, a1, a2 = r["a3"], r["a1"], r["a2"]
    d = director(theta, a3, a1, a2)
    gamma = ufl.as_vector([ufl.dot(fe[i], d) - r["s0"][i] for i in range(2)])
    if not bending:
        return eps_m, gamma, None
    c1, s1 = ufl.cos(theta[0]), ufl.sin(theta[0])
    c2, s2 = ufl.cos(theta[1]), ufl.sin(theta[1])

    def d_along(j: int):
        dth = ufl.grad(theta) * r[f"e{j + 1}"]
        return (c1 * c2 * r[f"Da3_{j + 1}"] + c1 * s2 * r[f"Da1_{j + 1}"] - s1 * r[f"Da2_{j + 1}"]
                + (-s1 * c2 * dth[0] - c1 * s2 * dth[1]) * a3 + (-s1 * s2 * dth[0] + c1 * c2 * dth[1]) * a1
                - c1 * dth[0] * a2)

    dd = [d_along(0), d_along(1)]
    k0 = r["k0"]
    kappa = ufl.as_vector([-ufl.dot(fe[0], dd[0]) + k0[0], -ufl.dot(fe[1], dd[1]) + k0[1],
                           -(ufl.dot(fe[0], dd[1]) + ufl.dot(dd[0], fe[1])) + k0[2]])
    return eps_m, gamma, kappa


def naghdi_energy_on_reference(u, theta, reference_full, reference_reduced, A, D, shear_stiffness, psri_thickness,
                               law=None, law_eps=None, degrees=(4, 2), cell_size=None, membrane_density=None):
    """`naghdi_energy` with the reference geometry read from packed quadrature data (reference_quantities at the
    points of the full and the reduced PSRI rule: Quadrature-element coefficients of those degrees) instead of
    being recomputed from the P2 fields at every evaluation; the same energy up to round-off.

    Returns the two parts (on the full rule, on the reduced rule) as separate forms: FFCx 0.5 cannot compare two
    Quadrature elements with different points within one form."""
    mesh = u.ufl_domain()
    eps_full, gamma_full, kappa = strains_on_reference(u, theta, reference_full, bending=True)
    eps_red, gamma_red, _ = strains_on_reference(u, theta, reference_reduced, bending=False)

    def membrane_shear(eps_m, gamma):
        psi_m = quadratic_energy(eps_m, A) if membrane_density is None else membrane_density(eps_m)
        return psi_m + 0.5 * shear_stiffness * ufl.dot(gamma, gamma)

    dx_full, dx_reduced = psri_measures(mesh, *degrees)
    h = ufl.CellDiameter(mesh) if cell_size is None else cell_size
    alpha = psri_weight(psri_thickness, h)
    return ((bending_energy(kappa, D, law, law_eps) + alpha * membrane_shear(eps_full, gamma_full)) * dx_full,
            (1.0 - alpha) * membrane_shear(eps_red, gamma_red) * dx_reduced)


def membrane_energy(u, phi0, t1, t2, A, degree: int = 4, membrane_density=None):
    """Membrane-only (no bending, no shear) strain energy 1/2 E.A E [J] ([Eischen2000, eq. 3], eq. 8), or
    int W(eps) dA with a callable membrane_density W [J/m^2] of the Voigt strain (forms.fitted)."""
    mesh = u.ufl_domain()
    F0 = ufl.grad(phi0)
    F = F0 + ufl.grad(u)
    e1, e2 = material_frame(F0, t1, t2)
    eps_m = voigt(membrane_strain(F, F0), e1, e2)
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": degree})
    psi_m = quadratic_energy(eps_m, A) if membrane_density is None else membrane_density(eps_m)
    return psi_m * dx


def nominal_stress(u, phi0, t1, t2, A, thickness):
    """First Piola-Kirchhoff stress P = F S (3x3, Pa) with S = (A / t) E resolved in the material frame."""
    F0 = ufl.grad(phi0)
    F = F0 + ufl.grad(u)
    e1, e2 = material_frame(F0, t1, t2)
    S_v = A * voigt(membrane_strain(F, F0), e1, e2) / thickness
    S = (S_v[0] * ufl.outer(e1, e1) + S_v[1] * ufl.outer(e2, e2)
         + S_v[2] * (ufl.outer(e1, e2) + ufl.outer(e2, e1)))
    return F * S
