"""Bonet-Burton transversely isotropic hyperelastic yarn law in UFL ([Man2006, sec. 4.3.4], eqs. 4.66-4.69).

Energies are per unit reference volume [Pa]; C = F^T F is the right Cauchy-Green tensor, A the unit
yarn axis in the reference configuration, I4 = A.C A, I5 = A.C^2 A. Parameters (lmbda, mu, alpha,
beta, gamma) are floats or fem.Constant in Pa; see fabricfem.materials.yarn for their validation
and for the conversion from engineering constants.

Usage: C = ufl.variable(F.T * F); S = second_piola_kirchhoff(yarn_energy(C, A, params), C).
"""
from __future__ import annotations

import ufl


def _invariants(C, A):
    """J = sqrt(det C), ln J, I1 = tr C, I4 = A.C A, I5 = A.C^2 A."""
    detC = ufl.det(C)
    return ufl.sqrt(detC), 0.5 * ufl.ln(detC), ufl.tr(C), ufl.dot(A, C * A), ufl.dot(A, C * C * A)


def neo_hookean_energy(C, lmbda, mu):
    """psi_iso = mu/2 (I1 - 3) - mu ln J + lambda/2 (J - 1)^2 [Pa]."""
    detC = ufl.det(C)
    J, lnJ, I1 = ufl.sqrt(detC), 0.5 * ufl.ln(detC), ufl.tr(C)
    return 0.5 * mu * (I1 - 3) - mu * lnJ + 0.5 * lmbda * (J - 1) ** 2  # eq. 4.67


def bonet_burton_energy(C, A, alpha, beta, gamma):
    """psi_ti = [alpha + beta ln J + gamma (I4 - 1)] (I4 - 1) - alpha/2 (I5 - 1) [Pa]."""
    _, lnJ, _, I4, I5 = _invariants(C, A)
    return (alpha + beta * lnJ + gamma * (I4 - 1)) * (I4 - 1) - 0.5 * alpha * (I5 - 1)  # eq. 4.68


def yarn_energy(C, A, params):
    """psi = psi_iso + psi_ti (eq. 4.66); params has attributes lmbda, mu, alpha, beta, gamma [Pa]."""
    return (neo_hookean_energy(C, params.lmbda, params.mu)
            + bonet_burton_energy(C, A, params.alpha, params.beta, params.gamma))


def second_piola_kirchhoff(psi, C):
    """S = 2 dpsi/dC [Pa]; C must be the ufl.variable that psi was built from."""
    return 2 * ufl.diff(psi, C)


def yarn_stress(F, A, params):
    """Second Piola-Kirchhoff stress of the yarn law at the deformation gradient F (automatic differentiation)."""
    C = ufl.variable(F.T * F)
    return second_piola_kirchhoff(yarn_energy(C, A, params), C)


def closed_form_stress(C, A, lmbda, mu, alpha, beta, gamma):
    """S = S_iso + S_ti written out as in eq. 4.69 [Pa] (reference for the automatic derivative)."""
    J, lnJ, _, I4, _ = _invariants(C, A)
    I, Cinv = ufl.Identity(3), ufl.inv(C)
    AA, CA = ufl.outer(A, A), C * A
    S_iso = mu * (I - Cinv) + lmbda * J * (J - 1) * Cinv                              # eq. 4.69, iso
    S_ti = (beta * (I4 - 1) * Cinv + 2 * (alpha + beta * lnJ + 2 * gamma * (I4 - 1)) * AA
            - alpha * (ufl.outer(A, CA) + ufl.outer(CA, A)))                          # eq. 4.69, ti
    return S_iso + S_ti
