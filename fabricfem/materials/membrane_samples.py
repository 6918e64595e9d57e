"""The data a fitted membrane law is built from ([Man2006, sec. 4.3.6]): in-plane samples of the homogenized unit
cell, strains (E11, E22, gamma12 = 2 E12) [-] with resultants N = h_cell S [N/m] (fabricfem.materials.fitted,
module docstring), and the check of a measured small-strain stiffness A0 [N/m].
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

__all__ = ["MembraneSamples", "membrane_state", "orthotropic_stiffness", "positive", "sample_unit_cell",
           "samples_from_steps"]


def positive(name: str, value: float) -> float:
    """A positive finite real (not a bool) as float, else ValueError naming `name`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) \
            or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class MembraneSamples:
    """n in-plane states: strains (n, 3) = (E11, E22, 2 E12) and resultants (n, 3) = (N11, N22, N12) [N/m]."""

    strains: np.ndarray
    resultants: np.ndarray

    def __post_init__(self):
        for name in ("strains", "resultants"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.ndim != 2 or a.shape[1] != 3 or len(a) == 0:
                raise ValueError(f"{name} must be an (n, 3) array with n >= 1, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                bad = int(np.sum(~np.all(np.isfinite(a), axis=1)))
                raise ValueError(f"{name} contains non-finite values ({bad} of {len(a)} samples)")
            object.__setattr__(self, name, a)
        if len(self.strains) != len(self.resultants):
            raise ValueError(f"resultants: {len(self.resultants)} rows for {len(self.strains)} strains")

    def __len__(self) -> int:
        """The number of states n."""
        return len(self.strains)

    def __add__(self, other: "MembraneSamples") -> "MembraneSamples":
        """Both sample sets, self's first."""
        return MembraneSamples(np.vstack([self.strains, other.strains]),
                               np.vstack([self.resultants, other.resultants]))


def membrane_state(E: np.ndarray, S: np.ndarray, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """In-plane Voigt strain (E11, E22, 2 E12) and resultant h (S11, S22, S12) [N/m] of a 3x3 Green-Lagrange
    strain E and homogenized second Piola-Kirchhoff stress S [Pa] (eqs. 4.59, 4.64)."""
    E, S = np.asarray(E, dtype=float), np.asarray(S, dtype=float)
    return (np.array([E[0, 0], E[1, 1], 2.0 * E[0, 1]]),
            thickness * np.array([S[0, 0], S[1, 1], S[0, 1]]))


def samples_from_steps(steps: Iterable, thickness: float) -> MembraneSamples:
    """MembraneSamples of unit-cell steps (fabricfem.weave.homogenize.UnitCellStep: Phi, E, S); N = thickness S.

    Every Phi must be in-plane (Phi_13 = Phi_23 = Phi_31 = Phi_32 = 0): the membrane law knows
    nothing of transverse shear.
    """
    thickness = positive("thickness", thickness)
    strains, resultants = [], []
    for step in steps:
        Phi = np.asarray(step.Phi, dtype=float)
        if np.any(np.abs(Phi[[0, 1, 2, 2], [2, 2, 0, 1]]) > 1e-12):
            raise ValueError(f"steps: Phi must be in-plane (no 13, 23, 31, 32 components), got {Phi.tolist()}")
        e, n = membrane_state(step.E, step.S, thickness)
        strains.append(e)
        resultants.append(n)
    if not strains:
        raise ValueError("steps must contain at least one unit-cell step")
    return MembraneSamples(np.array(strains), np.array(resultants))


def sample_unit_cell(problem, Phis: Sequence[np.ndarray], thickness: float, steps: int = 1) -> MembraneSamples:
    """Run a fabricfem.weave.homogenize.UnitCellProblem from the undeformed cell to each in-plane Phi in `steps`
    increments (every converged increment is a sample) and return the MembraneSamples (N = thickness S)."""
    collected = []
    for Phi in Phis:
        problem.u.x.array[:] = 0.0  # each path starts from the undeformed cell
        collected.extend(problem.solve(np.asarray(Phi, dtype=float), steps).steps)
    return samples_from_steps(collected, thickness)


def orthotropic_stiffness(A0, definite: bool) -> np.ndarray:
    """A0 [N/m] (3x3 Voigt) checked: finite, symmetric, non-zero, A13 = A23 = 0 (W even in the shear strain),
    positive definite (`definite`) or semi-definite; ValueError naming initial_stiffness otherwise."""
    A = np.array(A0, dtype=float)
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ValueError(f"initial_stiffness must be a finite 3x3 matrix [N/m], got {A0!r}")
    size = float(np.abs(A).max())
    if not size > 0 or np.abs(A - A.T).max() > 1e-12 * size:
        raise ValueError(f"initial_stiffness must be symmetric and non-zero, got {A.tolist()}")
    if abs(A[0, 2]) > 1e-12 * size or abs(A[1, 2]) > 1e-12 * size:
        raise ValueError("initial_stiffness: A13 and A23 must vanish (W is even in the shear strain)")
    lowest = np.linalg.eigvalsh(A)[0]
    if lowest < 0 or (definite and lowest <= 0):
        raise ValueError(f"initial_stiffness must be positive {'definite' if definite else 'semi-definite'} "
                         f"(eigenvalues {np.linalg.eigvalsh(A).tolist()} N/m), got {A.tolist()}")
    return A
