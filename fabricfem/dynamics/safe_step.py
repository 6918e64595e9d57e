"""The largest frequency of the operator that acts, tracked during an explicit run, and the step it allows.

The critical step of central differences is dt_crit = 2 / omega_max [Man2006, eq. 2.86] with omega_max^2 the
largest eigenvalue of M^-1 K(d) on the free dofs. The estimates of fabricfem.dynamics.stability are those of the
reference state; the tangent K(d) of the current state can be stiffer (a pinned corner carrying the sheet, strain
stiffening; measured in docs/findings/2026-11-27-safe-step.md). `FrequencyTracker` follows omega_max(d) by power
iteration on M^-1 K(d) [Belytschko2000, ch. 6], K(d) phi taken as a finite difference of the internal forces of
the system that acts (shell, bending, contact terms):

    K(d) phi ~ (f_int(d + e phi) - f_int(d)) / e,      omega^2 ~ phi^T K phi / phi^T M phi   (Rayleigh quotient)

Each estimate does `iterations` power steps from the previous vector (warm start: over a run the iterations
accumulate, and the mode that grows is followed), i.e. iterations + 1 internal-force evaluations. The Rayleigh
quotient is a lower bound of omega_max^2; the step safety (dt <= safety x 2 / omega) covers the rest.
"""
from __future__ import annotations

import math

import numpy as np
from petsc4py import PETSc

# the finite-difference increment of the internal forces: e = FD_STEP x max(1, max |d|) [m or rad] for max |phi| = 1
FD_STEP = 1e-7


class FrequencyTracker:
    """Power iteration on M^-1 K(d) of an explicit integrator's system (module docstring).

    Args:
        integrator: the CentralDifference whose system (internal_force), lumped mass (ops.mass_diag, with its
            rotary and mass scaling) and Dirichlet rows (bc_rows) are used.
        iterations: power steps per estimate (>= 1).
    """

    def __init__(self, integrator, iterations: int = 3):
        if not (isinstance(iterations, int) and iterations >= 1):
            raise ValueError(f"iterations must be a positive integer, got {iterations!r}")
        self.integrator, self.iterations = integrator, iterations
        self.phi = integrator.model.create_vector()
        rng = np.random.default_rng(1 + integrator.model.comm.rank)
        self.phi.getArray()[:] = rng.uniform(-1.0, 1.0, self.phi.getLocalSize())
        self._x, self._f0, self._f1 = (integrator.model.create_vector() for _ in range(3))
        self.omega = 0.0            # last estimate [rad/s]

    def _normalize(self) -> None:
        """phi on the free rows only, max |phi| = 1."""
        self.phi.getArray()[self.integrator.bc_rows] = 0.0
        size = self.phi.norm(PETSc.NormType.INFINITY)
        if size > 0.0:
            self.phi.scale(1.0 / size)

    def estimate(self, d) -> float:
        """omega [rad/s] of the state d (PETSc Vec of the integrator's layout): `iterations` power steps on
        M^-1 K(d) from the stored vector. The model's state (its Function) is left at a perturbed d: call this before
        a step's own internal-force evaluation, which sets it again."""
        integ = self.integrator
        system, mass = integ.system, integ.ops.mass_diag
        step = FD_STEP * max(1.0, d.norm(PETSc.NormType.INFINITY))
        system.internal_force(d, self._f0)
        quotient = 0.0
        for _ in range(self.iterations):
            self._normalize()
            d.copy(self._x)
            self._x.axpy(step, self.phi)
            system.internal_force(self._x, self._f1)
            self._f1.axpy(-1.0, self._f0)
            self._f1.scale(1.0 / step)                   # K(d) phi
            self._f1.getArray()[integ.bc_rows] = 0.0
            m_phi = self.phi.copy()
            m_phi.pointwiseMult(m_phi, mass)
            quotient = self.phi.dot(self._f1) / self.phi.dot(m_phi)
            m_phi.destroy()
            self.phi.pointwiseDivide(self._f1, mass)     # M^-1 K phi
        self._normalize()
        self.omega = math.sqrt(max(quotient, 0.0))
        return self.omega

    def destroy(self) -> None:
        """Free the vectors."""
        for vec in (self.phi, self._x, self._f0, self._f1):
            vec.destroy()


__all__ = ["FD_STEP", "FrequencyTracker"]
