"""Fabric materials at the garment scale (SI units throughout).

A fabric is an orthotropic St. Venant-Kirchhoff sheet in plane stress, with the
material frame (warp = direction 1, weft = direction 2) fixed in the reference
configuration. Bending is linear (rigidity E t^3/12 unless given) or follows a
nonlinear moment-curvature law.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def positive_number(name: str, value: float) -> float:
    """A positive finite real (Python or numpy scalar) as float, else ValueError naming `name`."""
    if not (isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class KawabataBending:
    """Polynomial moment-curvature law M(K) = sum_i alpha_i K^i [Eischen2000, eq. 15].

    `coefficients` are (alpha_1, ..., alpha_n) in SI units: M in N m / m (moment per unit
    width) and K in 1/m. The law is extended as an odd function, M(-K) = -M(K), and must
    start with a positive slope alpha_1 > 0.
    """

    coefficients: tuple[float, ...]

    def __post_init__(self):
        if len(self.coefficients) == 0:
            raise ValueError("KawabataBending.coefficients must not be empty")
        if not all(math.isfinite(a) for a in self.coefficients):
            raise ValueError("KawabataBending.coefficients must be finite")
        positive_number("KawabataBending.coefficients[0] (initial bending rigidity alpha_1)", self.coefficients[0])

    def moment(self, kappa):
        """Moment per unit width [N] at curvature kappa [1/m] (numpy)."""
        k = np.abs(np.asarray(kappa, dtype=float))
        return np.sign(kappa) * sum(a * k ** (i + 1) for i, a in enumerate(self.coefficients))


@dataclass(frozen=True)
class SquareRootBending:
    """Square-root bending law of [Peng2022, eq. 9] (after Abbott, Grosberg and Leaf).

    m = sign(K) 2 B0 sqrt(kappa0 |K|) for |K| <= kappa0, sign(K) (B0 |K| + B0 kappa0) beyond.
    B0 [N m] and kappa0 [1/m].
    """

    B0: float
    kappa0: float

    def __post_init__(self):
        positive_number("SquareRootBending.B0", self.B0)
        positive_number("SquareRootBending.kappa0", self.kappa0)

    def moment(self, kappa):
        k = np.abs(np.asarray(kappa, dtype=float))
        inner = 2.0 * self.B0 * np.sqrt(self.kappa0 * k)
        outer = self.B0 * k + self.B0 * self.kappa0
        return np.sign(kappa) * np.where(k <= self.kappa0, inner, outer)


@dataclass(frozen=True)
class Fabric:
    """Orthotropic St. Venant-Kirchhoff fabric in plane stress.

    Parameters (SI):
        E1, E2: Young's moduli along warp and weft [Pa]
        G12: in-plane shear modulus [Pa]
        nu12: major Poisson ratio (strain in 2 from stress in 1); nu21 = nu12 E2/E1
        thickness: sheet thickness t [m]
        density: mass density [kg/m^3] (areal density = density * thickness)
        G13: transverse shear modulus [Pa] (default G12), shear correction factor 5/6
        bending_rigidity: optional (B1, B2) [N m] overriding E t^3/12 (warp, weft)
        bending_law: optional nonlinear moment-curvature law per direction
        membrane_law: optional fitted membrane energy W(E11, E22, 2 E12) [J/m^2]
            (fabricfem.materials.fitted.FittedMembraneLaw or ConvexMembraneLaw, built with
            fitted_law.fitted_fabric); when given,
            ShellModel uses it instead of 1/2 eps.A eps and E1, E2, G12, nu12 describe its
            small-strain stiffness only
    """

    E1: float
    E2: float
    G12: float
    nu12: float
    thickness: float
    density: float = 0.0
    G13: float | None = None
    bending_rigidity: tuple[float, float] | None = None
    bending_law: KawabataBending | SquareRootBending | None = None
    name: str = "fabric"
    shear_correction: float = field(default=5.0 / 6.0)
    membrane_law: object | None = None

    def __post_init__(self):
        positive_number("E1", self.E1)
        positive_number("E2", self.E2)
        positive_number("G12", self.G12)
        positive_number("thickness", self.thickness)
        if self.G13 is not None:
            positive_number("G13", self.G13)
        if not (math.isfinite(self.density) and self.density >= 0):
            raise ValueError(f"density must be >= 0, got {self.density!r}")
        # Plane-stress stability: 1 - nu12 nu21 > 0, i.e. nu12^2 < E1/E2
        if not math.isfinite(self.nu12) or self.nu12 ** 2 >= self.E1 / self.E2 or self.nu12 <= -1.0:
            raise ValueError(
                f"nu12 = {self.nu12!r} is outside its admissible range "
                f"(-1, sqrt(E1/E2) = {math.sqrt(self.E1 / self.E2):.4g}) for a positive-definite plane-stress law")
        if self.bending_rigidity is not None:
            if len(self.bending_rigidity) != 2:
                raise ValueError("bending_rigidity must be a pair (B1, B2) in N m")
            positive_number("bending_rigidity[0]", self.bending_rigidity[0])
            positive_number("bending_rigidity[1]", self.bending_rigidity[1])
        if self.membrane_law is not None and not (hasattr(self.membrane_law, "parameters")
                                                  and callable(getattr(self.membrane_law, "ufl_energy", None))):
            raise ValueError("membrane_law must be a fitted membrane law (fabricfem.materials.fitted.FittedMembraneLaw "
                             "or ConvexMembraneLaw: .parameters and .ufl_energy(eps, parameters)), got "
                             f"{type(self.membrane_law).__name__}")

    @classmethod
    def isotropic(cls, E: float, nu: float, thickness: float, density: float = 0.0, **kw) -> "Fabric":
        """Isotropic sheet: E1 = E2 = E, G12 = E / (2 (1 + nu))."""
        positive_number("E", E)
        if not (-1.0 < nu < 0.5 + 1e-15) or not math.isfinite(nu):
            raise ValueError(f"Poisson ratio nu = {nu!r} must lie in (-1, 0.5]")
        return cls(E1=E, E2=E, G12=E / (2.0 * (1.0 + nu)), nu12=nu, thickness=thickness, density=density, **kw)

    @property
    def nu21(self) -> float:
        return self.nu12 * self.E2 / self.E1

    @property
    def plane_stress_matrix(self) -> np.ndarray:
        """Q in Voigt form [S11, S22, S12] = Q [E11, E22, 2 E12], in Pa (orthotropic plane stress)."""
        d = 1.0 - self.nu12 * self.nu21
        return np.array([[self.E1 / d, self.nu12 * self.E2 / d, 0.0],
                         [self.nu12 * self.E2 / d, self.E2 / d, 0.0],
                         [0.0, 0.0, self.G12]])

    @property
    def bending_matrix(self) -> np.ndarray:
        """D in Voigt form [M11, M22, M12] = D [K11, K22, 2 K12], in N m.

        t^3/12 Q, or, when bending_rigidity = (B1, B2) is given, that matrix scaled
        congruently (S D S, S diagonal) so that D11 = B1 and D22 = B2 and D stays positive definite.
        """
        D = self.thickness ** 3 / 12.0 * self.plane_stress_matrix
        if self.bending_rigidity is None:
            return D
        s1 = math.sqrt(self.bending_rigidity[0] / D[0, 0])
        s2 = math.sqrt(self.bending_rigidity[1] / D[1, 1])
        S = np.diag([s1, s2, math.sqrt(s1 * s2)])
        return S @ D @ S

    @property
    def areal_density(self) -> float:
        """Mass per unit reference area [kg/m^2]."""
        return self.density * self.thickness

    @property
    def transverse_shear_modulus(self) -> float:
        return self.G12 if self.G13 is None else self.G13
