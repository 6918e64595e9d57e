"""UFL form of a membrane strain energy fitted to homogenized unit-cell data [Man2006, sec. 4.3.6, 6.2.2].

The thesis' "hierarchical" route (sec. 6.2.2) casts the homogenized stress-strain relation of the unit
cell as a strain-energy function the macroscale shell can use (sec. 4.3.6). Here that energy per unit
reference area [J/m^2] is a polynomial of the Voigt membrane strain eps = (E11, E22, gamma12 = 2 E12)
(Green-Lagrange strain in the warp/weft frame), even in gamma12:

    W(eps) = sum_k c_k E11^a_k E22^b_k gamma12^p_k,   p_k even, a_k + b_k + p_k >= 2,

so that W(0) = 0, the resultant N = dW/deps (N11, N22, N12 in N/m) vanishes at eps = 0 and
W(E11, E22, -gamma12) = W(E11, E22, gamma12). fabricfem.materials.fitted fits and stores the c_k.

convex_ridge_energy is the law that is convex by construction (fabricfem.materials.fitted.ConvexMembraneLaw):

    W(eps) = 1/2 eps.A0.eps + sum_k c_k sum_(l in L_k) phi_k(l.eps),   c_k >= 0,

phi_k = <x - s>^n = max(x - s, 0)^n (n >= 3, C2, onset s >= 0) or x^n (n even), L_k a direction and
its gamma-mirror.
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


def convex_ridge_energy(strain_voigt, groups: Sequence[Sequence[Sequence[float]]],
                        profiles: Sequence[tuple[str, int, float]], parameters):
    """W = 1/2 eps.A0.eps + sum_k c_k sum_(l in groups[k]) phi_k(l.eps) [J/m^2] of the Voigt strain
    (E11, E22, 2 E12).

    groups: per term, the unit directions l (each a 3-vector) sharing its coefficient; profiles: per
    term (kind, power, onset s), kind "macaulay" (phi = max(x - s, 0)^n, ufl.max_value) or "even" (phi = x^n);
    parameters: a UFL vector (fem.Constant of shape (9 + K,)) or a sequence of floats holding A0
    row-major [N/m] then the K coefficients c_k [J/m^2].
    """
    if len(groups) != len(profiles) or not groups:
        raise ValueError(f"groups and profiles must be non-empty and of equal length, got {len(groups)} and "
                         f"{len(profiles)}")
    eps = [strain_voigt[i] for i in range(3)]
    energy = 0.5 * sum(parameters[3 * i + j] * eps[i] * eps[j] for i in range(3) for j in range(3))
    for k, (group, (kind, power, shift)) in enumerate(zip(groups, profiles)):
        for l in group:
            x = sum(float(l[i]) * eps[i] for i in range(3) if l[i] != 0.0)
            if kind == "macaulay":
                x = ufl.max_value(x - float(shift), 0.0)
            elif kind != "even":
                raise ValueError(f"profiles: kind must be 'macaulay' or 'even', got {kind!r}")
            energy = energy + parameters[9 + k] * x ** int(power)
    return energy
