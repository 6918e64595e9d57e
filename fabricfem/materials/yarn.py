"""Yarn material: Bonet-Burton transversely isotropic hyperelasticity [Man2006, sec. 4.3.4], SI units.

Strain energy per unit reference volume [J/m^3 = Pa] ([Man2006, eqs. 4.66-4.68], Bonet & Burton 1998):

    psi     = psi_iso + psi_ti                                                   (4.66)
    psi_iso = mu/2 (I1 - 3) - mu ln J + lambda/2 (J - 1)^2                        (4.67)
    psi_ti  = [alpha + beta ln J + gamma (I4 - 1)] (I4 - 1) - alpha/2 (I5 - 1)    (4.68)

with I1 = tr C, J = sqrt(det C), I4 = A.C A, I5 = A.C^2 A, A the unit yarn axis in the
reference configuration. All five parameters are in Pa. The UFL forms are in fabricfem.forms.yarn;
this module holds the parameter set, its validation, the conversion from engineering constants
and a vectorised numpy version of the stress (eq. 4.69).

Small-strain stiffness (derived by linearising eq. 4.69 about C = I, S = D : E; checked with sympy).
Voigt order (11, 22, 33, 23, 13, 12) with engineering shear strains and the axis A = e1:

    C11 = lambda + 2 mu + 4 beta + 8 gamma - 4 alpha
    C12 = C13 = lambda + 2 beta
    C22 = C33 = lambda + 2 mu,   C23 = lambda
    C44 = mu        (transverse shear G_TT = (C22 - C23)/2)
    C55 = C66 = mu - alpha      (axial shear G_LT)

Engineering constants (E_L, E_T, G_LT, nu_LT, nu_TT; nu_LT = -eps_T / eps_L under axial stress,
nu_TT = -eps_T' / eps_T under transverse stress) give the compliance; its inverse is, with
m = E_T / E_L and D = 1 - nu_TT - 2 nu_LT^2 m,

    C11 = E_L (1 - nu_TT) / D,   C12 = nu_LT E_T / D,
    C22 = E_T (1 - nu_LT^2 m) / ((1 + nu_TT) D),   C23 = E_T (nu_TT + nu_LT^2 m) / ((1 + nu_TT) D),

hence mu = E_T / (2 (1 + nu_TT)), lambda = C23, alpha = mu - G_LT, beta = (C12 - lambda)/2,
gamma = (C11 + lambda - 2 mu - 2 C12 + 4 alpha)/8. A transversely isotropic linear material has
five independent constants and the map (lambda, mu, alpha, beta, gamma) -> (C11, C12, C22, C23, C66)
is linear and triangular, so the conversion is one-to-one; it is a bijection between admissible
(positive-definite) parameter sets, and inadmissible input raises ValueError naming the parameter.
Note that published versions of the conversion differ (a factor 2 on beta, n = E_L/E_T inverted);
the formulas above belong to eq. 4.68 exactly as written and are checked by fabricfem verify
bonet-burton-constants.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

AXIS_TOLERANCE = 1e-10  # |A| must be 1 to this (relative) accuracy: A enters I4 quadratically


def _finite(name: str, value: float) -> float:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value)):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _positive(name: str, value: float) -> float:
    if _finite(name, value) <= 0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return float(value)


def unit_axis(A, name: str = "A") -> np.ndarray:
    """Validated yarn axis: array (..., 3) of unit vectors (|A| = 1 within AXIS_TOLERANCE)."""
    A = np.asarray(A, dtype=float)
    if A.shape[-1:] != (3,) or not np.all(np.isfinite(A)):
        raise ValueError(f"{name} must be finite 3-vectors, got shape {A.shape}")
    norm = np.linalg.norm(A, axis=-1)
    if np.any(np.abs(norm - 1.0) > AXIS_TOLERANCE):
        raise ValueError(f"{name} (yarn axis) must be a unit vector, got |{name}| = {norm}")
    return A


@dataclass(frozen=True)
class EngineeringConstants:
    """Transversely isotropic engineering constants, axis L = yarn axis, T = transverse [Pa].

    E_L, E_T: Young's moduli along and across the axis; G_LT: axial shear modulus;
    nu_LT: -eps_T/eps_L under axial stress; nu_TT: -eps_T'/eps_T under transverse stress.
    Admissible (positive-definite compliance): E_L, E_T, G_LT > 0, -1 < nu_TT < 1,
    2 nu_LT^2 E_T / E_L < 1 - nu_TT.
    """

    E_L: float
    E_T: float
    G_LT: float
    nu_LT: float
    nu_TT: float

    def __post_init__(self):
        _positive("E_L", self.E_L)
        _positive("E_T", self.E_T)
        _positive("G_LT", self.G_LT)
        _finite("nu_LT", self.nu_LT)
        if not -1.0 < _finite("nu_TT", self.nu_TT) < 1.0:
            raise ValueError(f"nu_TT = {self.nu_TT!r} must lie in (-1, 1) for a positive-definite law")
        if 2.0 * self.nu_LT ** 2 * self.E_T / self.E_L >= 1.0 - self.nu_TT:
            bound = math.sqrt((1.0 - self.nu_TT) * self.E_L / (2.0 * self.E_T))
            raise ValueError(f"nu_LT = {self.nu_LT!r} is not admissible: |nu_LT| must be below "
                             f"sqrt((1 - nu_TT) E_L / (2 E_T)) = {bound:.6g} for a positive-definite law")

    @property
    def G_TT(self) -> float:
        """Transverse shear modulus E_T / (2 (1 + nu_TT)) [Pa] (isotropy in the transverse plane)."""
        return self.E_T / (2.0 * (1.0 + self.nu_TT))

    @property
    def nu_TL(self) -> float:
        """Minor Poisson ratio nu_LT E_T / E_L (symmetry of the compliance)."""
        return self.nu_LT * self.E_T / self.E_L


@dataclass(frozen=True)
class YarnMaterial:
    """Parameters of eqs. 4.67-4.68 [Pa]: lmbda (lambda), mu, alpha, beta, gamma.

    Validated for a positive-definite small-strain stiffness (see the module docstring):
    mu > 0, G_LT = mu - alpha > 0, lmbda + mu > 0, C11 (2 lmbda + 2 mu) > 2 C12^2 (a lower
    bound on gamma given the others).
    """

    lmbda: float
    mu: float
    alpha: float = 0.0
    beta: float = 0.0
    gamma: float = 0.0
    name: str = "yarn"

    def __post_init__(self):
        _positive("mu", self.mu)
        for name in ("lmbda", "alpha", "beta", "gamma"):
            _finite(name, getattr(self, name))
        if self.alpha >= self.mu:
            raise ValueError(f"alpha = {self.alpha!r} must be below mu = {self.mu!r} "
                             "(axial shear modulus G_LT = mu - alpha > 0)")
        if self.lmbda + self.mu <= 0:
            raise ValueError(f"lmbda (lambda) = {self.lmbda!r} must exceed -mu = {-self.mu!r} "
                             "(transverse bulk stiffness lambda + mu > 0)")
        C = self.small_strain_stiffness
        if C[0, 0] * (C[1, 1] + C[1, 2]) <= 2.0 * C[0, 1] ** 2:
            c12, c22, c23 = C[0, 1], C[1, 1], C[1, 2]
            bound = (2.0 * c12 ** 2 / (c22 + c23) - (self.lmbda + 2 * self.mu + 4 * self.beta - 4 * self.alpha)) / 8.0
            raise ValueError(f"gamma = {self.gamma!r} is not admissible: with these lmbda, mu, alpha, beta "
                             f"the law is positive definite only for gamma > {bound:.6g}")

    @classmethod
    def from_engineering_constants(cls, E_L: float, E_T: float, G_LT: float, nu_LT: float, nu_TT: float,
                                   name: str = "yarn") -> "YarnMaterial":
        """Parameters of eq. 4.68 reproducing the given small-strain constants [Pa] (module docstring)."""
        ec = EngineeringConstants(E_L, E_T, G_LT, nu_LT, nu_TT)
        m = ec.E_T / ec.E_L
        D = 1.0 - ec.nu_TT - 2.0 * ec.nu_LT ** 2 * m
        C11 = ec.E_L * (1.0 - ec.nu_TT) / D
        C12 = ec.nu_LT * ec.E_T / D
        C23 = ec.E_T * (ec.nu_TT + ec.nu_LT ** 2 * m) / ((1.0 + ec.nu_TT) * D)
        mu = ec.G_TT
        lmbda = C23
        alpha = mu - ec.G_LT
        beta = (C12 - lmbda) / 2.0
        gamma = (C11 + lmbda - 2.0 * mu - 2.0 * C12 + 4.0 * alpha) / 8.0
        return cls(lmbda, mu, alpha, beta, gamma, name=name)

    @classmethod
    def isotropic(cls, E: float, nu: float, name: str = "yarn") -> "YarnMaterial":
        """Neo-Hookean part only (alpha = beta = gamma = 0) with the Lame constants of E [Pa], nu."""
        _positive("E", E)
        if not -1.0 < _finite("nu", nu) < 0.5:
            raise ValueError(f"nu = {nu!r} must lie in (-1, 0.5)")
        return cls(E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu)), name=name)

    @property
    def small_strain_stiffness(self) -> np.ndarray:
        """6x6 stiffness [Pa] at C = I for the axis A = e1, Voigt (11, 22, 33, 23, 13, 12), engineering shear."""
        lm, mu, a, b, g = self.lmbda, self.mu, self.alpha, self.beta, self.gamma
        c11 = lm + 2 * mu + 4 * b + 8 * g - 4 * a
        c12 = lm + 2 * b
        C = np.zeros((6, 6))
        C[:3, :3] = [[c11, c12, c12], [c12, lm + 2 * mu, lm], [c12, lm, lm + 2 * mu]]
        C[3, 3] = mu
        C[4, 4] = C[5, 5] = mu - a
        return C

    def engineering_constants(self) -> EngineeringConstants:
        """Small-strain constants from the inverse of small_strain_stiffness."""
        S = np.linalg.inv(self.small_strain_stiffness)
        return EngineeringConstants(E_L=1.0 / S[0, 0], E_T=1.0 / S[1, 1], G_LT=1.0 / S[5, 5],
                                    nu_LT=-S[0, 1] / S[0, 0], nu_TT=-S[1, 2] / S[1, 1])

    def stress(self, F, A) -> np.ndarray:
        """Second Piola-Kirchhoff stress [Pa], eq. 4.69, numpy, vectorised over leading axes.

        F: deformation gradients (..., 3, 3) with det F > 0; A: unit yarn axes (..., 3)."""
        F = np.asarray(F, dtype=float)
        if F.shape[-2:] != (3, 3) or not np.all(np.isfinite(F)):
            raise ValueError(f"F must be finite 3x3 matrices, got shape {F.shape}")
        J = np.linalg.det(F)
        if np.any(J <= 0):
            raise ValueError(f"F must have det F > 0, got min det F = {J.min()}")
        A = unit_axis(A)
        C = np.swapaxes(F, -1, -2) @ F
        Cinv = np.linalg.inv(C)
        I = np.eye(3)
        CA = np.einsum("...ij,...j->...i", C, A)
        I4 = np.einsum("...i,...i->...", A, CA)
        AA = np.einsum("...i,...j->...ij", A, A)
        ACA = np.einsum("...i,...j->...ij", A, CA)
        Jx, I4x = J[..., None, None], I4[..., None, None]
        S_iso = self.mu * (I - Cinv) + self.lmbda * Jx * (Jx - 1.0) * Cinv                    # eq. 4.69, iso
        S_ti = (self.beta * (I4x - 1.0) * Cinv                                                 # eq. 4.69, ti
                + 2.0 * (self.alpha + self.beta * np.log(Jx) + 2.0 * self.gamma * (I4x - 1.0)) * AA
                - self.alpha * (ACA + np.swapaxes(ACA, -1, -2)))
        return S_iso + S_ti


# Thesis sec. 4.3.4-4.3.5 parameter sets [Pa]
THESIS_TRANSVERSELY_ISOTROPIC = YarnMaterial(lmbda=0.4457e9, mu=0.5154e9, alpha=0.2714e9, beta=0.06548e9,
                                             gamma=10.54e9, name="Kevlar KM2 yarn (thesis, transversely isotropic)")
THESIS_ISOTROPIC = YarnMaterial(lmbda=48.82e9, mu=32.55e9, name="Kevlar KM2 yarn ([Man2006, sec. 4.3.5.1], isotropic)")
