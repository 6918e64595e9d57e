"""A membrane strain-energy function fitted to homogenized unit-cell data [Man2006, sec. 4.3.6, 6.2.2].

The thesis leaves the link between the unit cell (ch. 4) and the garment-scale shell (ch. 2) open:
the homogenized relations "can not be applied to the clothing simulation unless they are cast as a
strain energy function definition" (sec. 4.3.6); sec. 6.2.2 calls this the hierarchical multiscale
approach. This module does exactly that for the in-plane (membrane) response.

Data model (SI):
    strains     eps = (E11, E22, gamma12 = 2 E12): in-plane Green-Lagrange strain (eq. 4.59) in the
                warp/weft frame, Voigt form with the engineering shear, dimensionless.
    resultants  N = (N11, N22, N12) [N/m]: membrane second Piola-Kirchhoff stress resultants per unit
                reference length. The unit cell returns the homogenized S [Pa] averaged over the
                bounding box |Y| = A_cell h_cell with the volume fraction (eqs. 4.64-4.65), so
                N = h_cell S_ab, h_cell being the fabric thickness (the cell height) [m].
    energy      W(eps) [J/m^2] per unit reference area with N = dW/deps, i.e. N11 = dW/dE11,
                N22 = dW/dE22, N12 = dW/dgamma12 (forms.fitted.polynomial_energy).

Fit: W is a polynomial even in gamma12 (warp/weft symmetry of the weave: shearing one way or the
other costs the same), with no constant and no linear term (W(0) = 0, N(0) = 0). Its coefficients
enter N linearly, so they solve a linear least-squares problem on the resultants (S = dW/dE).
Convexity: the Hessian of W must be positive definite on a grid covering the data (their convex hull,
mirrored in gamma12, plus the origin); if it is not, the fit is repaired by cutting planes (convex
quadratic programme: least squares subject to v.H(x)v >= margin at the offending points x along
their offending directions v) and rejected with ValueError if the repaired fit no longer matches the
data within `max_residual`. That polynomial is convex only where it was checked (the data hull).

ConvexMembraneLaw (fit_convex_law) is convex at EVERY strain by construction: W = 1/2 eps.A0.eps plus a
non-negative combination of convex C2 ridge functions phi(l.eps) (Macaulay powers and ramps, even powers),
fitted by non-negative least squares; its Hessian is >= A0 everywhere (see its docstring). Both laws offer
energy/resultants/tangent (numpy), initial_stiffness, to_dict/from_dict (the fabric JSON "membrane" entry, told
apart by "type": membrane_law_from_dict) and parameters/ufl_energy for fabricfem.shell.ShellModel.
"""
from __future__ import annotations

from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.materials.convex_law import (
    CONVEX_LAW_TYPE,
    DEFAULT_DIRECTIONS,
    ConvexMembraneLaw,
    convex_gradient_basis,
    default_convex_terms,
    energy_basis,
    fit_convex_law,
)
from fabricfem.materials.membrane_samples import (
    MembraneSamples,
    membrane_state,
    positive,
    sample_unit_cell,
    samples_from_steps,
)
from fabricfem.materials.polynomial_law import (
    LAW_TYPE,
    FittedMembraneLaw,
    convexity_points,
    energy_exponents,
    fit_membrane_law,
    gradient_basis,
    hessian_basis,
)

# the laws and their data live in membrane_samples, polynomial_law and convex_law; their names are importable here
__all__ = ["CONVEX_LAW_TYPE", "DEFAULT_DIRECTIONS", "LAW_TYPE", "MEMBRANE_LAW_TYPES", "ConvexMembraneLaw",
           "FittedMembraneLaw", "MembraneSamples", "convex_gradient_basis", "convexity_points", "default_convex_terms",
           "energy_basis", "energy_exponents", "fit_convex_law", "fit_membrane_law", "fitted_fabric", "gradient_basis",
           "hessian_basis", "membrane_law_from_dict", "membrane_state", "sample_unit_cell", "samples_from_steps"]


def fitted_fabric(law: FittedMembraneLaw | ConvexMembraneLaw, thickness: float, density: float = 0.0, *,
                  bending_rigidity: tuple[float, float] | None = None,
                  bending_law: KawabataBending | SquareRootBending | None = None,
                  G13: float | None = None, name: str = "fitted fabric") -> Fabric:
    """A Fabric whose membrane energy is the fitted law (ShellModel uses W instead of 1/2 eps.A eps).

    E1, E2, G12, nu12 are those of the law's small-strain stiffness A0 = t Q (Voigt, N/m), used for the
    default bending rigidity t^3/12 Q, the transverse shear default G13 = G12 and linearised
    operators: Q = A0 / t, nu12 = Q12 / Q22, E1 = Q11 - Q12^2 / Q22, E2 = Q22 - Q12^2 / Q11, G12 = Q33.
    """
    if not isinstance(law, (FittedMembraneLaw, ConvexMembraneLaw)):
        raise ValueError(f"law must be a FittedMembraneLaw or ConvexMembraneLaw, got {type(law).__name__}")
    t = positive("thickness", thickness)
    Q = law.initial_stiffness / t
    if abs(Q[0, 2]) > 1e-12 * abs(Q[0, 0]) or abs(Q[1, 2]) > 1e-12 * abs(Q[1, 1]):
        raise ValueError("law: the small-strain stiffness couples stretch and shear (not orthotropic)")
    if not (Q[0, 0] > 0 and Q[1, 1] > 0 and Q[2, 2] > 0 and Q[0, 0] * Q[1, 1] > Q[0, 1] ** 2):
        raise ValueError(f"law: the small-strain stiffness A0 = {law.initial_stiffness.tolist()} N/m is not "
                         "positive definite; the fabric needs a positive initial stiffness")
    return Fabric(E1=float(Q[0, 0] - Q[0, 1] ** 2 / Q[1, 1]), E2=float(Q[1, 1] - Q[0, 1] ** 2 / Q[0, 0]),
                  G12=float(Q[2, 2]), nu12=float(Q[0, 1] / Q[1, 1]), thickness=t, density=density, G13=G13,
                  bending_rigidity=bending_rigidity, bending_law=bending_law, name=name, membrane_law=law)


MEMBRANE_LAW_TYPES = {LAW_TYPE: FittedMembraneLaw, CONVEX_LAW_TYPE: ConvexMembraneLaw}


def membrane_law_from_dict(data: dict) -> FittedMembraneLaw | ConvexMembraneLaw:
    """The membrane law of a stored fabric's "membrane" entry, by its "type"."""
    kind = data.get("type")
    if kind not in MEMBRANE_LAW_TYPES:
        raise ValueError(f"membrane.type must be one of {sorted(MEMBRANE_LAW_TYPES)}, got {kind!r}")
    return MEMBRANE_LAW_TYPES[kind].from_dict(data)
