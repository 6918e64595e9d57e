"""UFL form of a membrane strain energy fitted to homogenized unit-cell data (thesis 000, sec. 4.3.6, 6.2.2).

The thesis' "hierarchical" route (sec. 6.2.2) casts the homogenized stress-strain relation of the unit
cell as a strain-energy function the macroscale shell can use (sec. 4.3.6). Here that energy per unit
reference area [J/m^2] is a polynomial of the Voigt membrane strain eps = (E11, E22, gamma12 = 2 E12)
(Green-Lagrange strain in the warp/weft frame), even in gamma12:

    W(eps) = sum_k c_k E11^a_k E22^b_k gamma12^p_k,   p_k even, a_k + b_k + p_k >= 2,

so that W(0) = 0, the resultant N = dW/deps (N11, N22, N12 in N/m) vanishes at eps = 0 and
W(E11, E22, -gamma12) = W(E11, E22, gamma12). fabricfem.fitted_law fits and stores the c_k.
"""
from __future__ import annotations

from typing import Sequence

import ufl


def polynomial_energy(strain_voigt, exponents: Sequence[Sequence[int]], coefficients):
    """W = sum_k c_k E11^a E22^b gamma12^p [J/m^2] of the Voigt strain (E11, E22, 2 E12).

    `coefficients` is a UFL vector (a fem.Constant of shape (K,), so that new coefficients do not
    recompile forms) or a sequence of floats [J/m^2]; `exponents` the K integer triples (a, b, p).
    """
    terms = []
    for k, powers in enumerate(exponents):
        term = coefficients[k]
        for component, power in enumerate(powers):
            if power:
                term = term * strain_voigt[component] ** int(power)
        terms.append(term)
    if not terms:
        raise ValueError("exponents must contain at least one monomial")
    return sum(terms[1:], terms[0])


def polynomial_resultants(strain_voigt, exponents: Sequence[Sequence[int]], coefficients):
    """Membrane resultants N = dW/deps = (N11, N22, N12) [N/m] (second Piola-Kirchhoff, per unit
    reference length) of polynomial_energy, as a UFL vector."""
    eps = ufl.variable(strain_voigt)
    return ufl.diff(polynomial_energy(eps, exponents, coefficients), eps)
