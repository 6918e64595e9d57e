"""Arc-length continuation with the adaptive step of Eischen and Bigliani [Eischen2000, eqs. 17-26].

Equilibrium F_ext(lambda) - P(Phi) = 0 with F_ext = lambda F_ref (eq. 17) is augmented by the
constraint of [Eischen2000, eq. 19] in a scaled norm,

    f = [ w (Phi - Phi_n).(Phi - Phi_n) + psi^2 (lambda - lambda_n)^2 ]^(1/2) - gamma_n ds = 0,
    w = 1 / (N u_ref^2),

whose arc length is accelerated by gamma_n = N_p / N_{n-1} (eq. 20). N is the global length of the state
vector Phi (displacements [m] and director angles [rad]) and u_ref [m] a characteristic displacement, so that
w |dPhi|^2 = (RMS of dPhi / u_ref)^2: the step ds is dimensionless and means the same on every mesh (the RMS of
a discretised field does not grow with the number of nodes, |dPhi| does, like sqrt(N)). By default u_ref is the
RMS of the tangent response to the reference load, K^-1 F_ref at the start state, so that in the linear range
an arc length ds is a load-factor step ds / sqrt(1 + psi^2). (w = 1 is eq. 19 itself, the seed's form: there ds
has the units of the state and must be re-chosen for every mesh.) The scaling is a change of units of the state,
Phi' = sqrt(w) Phi, under which eqs. 21-22 keep their form with the dot products weighted by w. Each corrector
iteration solves K du_I = F_ref and K du_II = F_ext - P with one factorisation (eqs. 23-25) and updates

    dlambda = -[ f (f + gamma_n ds) + w (Phi - Phi_n).du_II ] / [ psi^2 (lambda - lambda_n) + w (Phi - Phi_n).du_I ]
                                                                                                          (eq. 21)
    dPhi    = dlambda du_I + du_II                                                                        (eq. 22)

psi (default 1) weighs the load factor against the scaled state, as in Schweizerhof and Wriggers. Only
load-controlled problems qualify: prescribed displacements must be zero.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from petsc4py import PETSc

from fabricfem.solvers.newton import SolverError, prefixed_options


@dataclass
class ArcLengthStep:
    """One converged step: load factor lambda, corrector iterations, arc length used (dimensionless, in the scaled
    norm of the module docstring), the residual norms |P - lambda F_ref| [N] of its iterations and the
    characteristic displacement u_ref [m] of the norm."""

    load_factor: float
    iterations: int
    arc_length: float
    residual_norms: list[float] = field(default_factory=list)
    u_ref: float = 1.0


def acceleration_factor(step_index: int, target_iterations: int, last_iterations: int) -> float:
    """gamma_n of [Eischen2000, eq. 20]: 1 for the first step, N_p / N_{n-1} afterwards."""
    if step_index <= 1:
        return 1.0
    return target_iterations / max(last_iterations, 1)


class _ArcLengthSolver:
    """The linear algebra of one arc-length step of a model ([Eischen2000, eqs. 21-25]): the tangent K, factorised
    once per iteration (MUMPS LU unless petsc_options say otherwise) for both K du_I = F_ref and K du_II = F_ext - P,
    the predictor along du_I and the corrector iterations. psi scales the load factor against the state (eq. 19),
    u_ref [m] the state (the weight w = 1 / (N u_ref^2) of the module docstring; None: the RMS of the first
    predictor's K^-1 F_ref); convergence as documented in arc_length (rtol, stol, max_iterations)."""

    PREFIX = "fabricfem_arclength_"

    def __init__(self, model, psi: float, u_ref: float | None, rtol: float, stol: float, max_iterations: int,
                 petsc_options: dict | None):
        model.compile()
        self.model, self.psi, self.rtol, self.stol, self.max_iterations = model, psi, rtol, stol, max_iterations
        self.K = model.create_matrix()
        self.residual, self.du_I, self.du_II = model.create_vector(), model.create_vector(), model.create_vector()
        self.size = self.du_I.getSize()      # N, the global length of the state vector
        self.u_ref = u_ref
        self.ksp = PETSc.KSP().create(model.comm)
        self.ksp.setOperators(self.K)
        self.ksp.setOptionsPrefix(self.PREFIX)
        self.ksp_options = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps",
                            **(petsc_options or {})}
        with prefixed_options(self.PREFIX, self.ksp_options):
            self.ksp.setFromOptions()
        self.fscale = max(model.F_ref.norm(), 1e-300)  # |F_ref|

    def linear_solve(self, rhs: PETSc.Vec, out: PETSc.Vec) -> None:
        """K out = rhs; the options are in the database while the LU factor is set up (MUMPS ICNTL)."""
        with prefixed_options(self.PREFIX, self.ksp_options):
            self.ksp.solve(rhs, out)

    def assemble_and_factor(self, xv: PETSc.Vec, lam: float) -> None:
        """residual = P(xv) - lam F_ref and K = dP/dx at xv, K set as the operator (factorised at the next solve)."""
        self.model.set_load_factor(lam)
        self.model.residual(xv, self.residual)  # residual = P - lambda F_ref
        self.model.jacobian(xv, self.K)
        self.ksp.setOperators(self.K)

    def predict(self, x: PETSc.Vec, lam_n: float, length: float, direction: tuple | None) -> float:
        """Predictor along the tangent du_I = K^-1 F_ref from the converged state x (lam_n): x moves by dlam du_I
        with |(dPhi, psi dlam)| = length, the sign along the previous increment `direction` (dPhi, dlambda);
        returns lam_n + dlam."""
        psi = self.psi
        self.assemble_and_factor(x, lam_n)
        self.linear_solve(self.model.F_ref, self.du_I)
        if self.u_ref is None:
            self.u_ref = float(np.sqrt(self.du_I.dot(self.du_I) / self.size))
            if not (np.isfinite(self.u_ref) and self.u_ref > 0.0):
                raise ValueError(f"u_ref: the tangent response K^-1 F_ref has RMS {self.u_ref!r}; give u_ref [m]")
        w = self.weight
        dlam = length / np.sqrt(w * self.du_I.dot(self.du_I) + psi ** 2)
        if direction is not None and (w * self.du_I.dot(direction[0]) + psi ** 2 * direction[1]) < 0:
            dlam = -dlam
        x.axpy(dlam, self.du_I)
        return lam_n + dlam

    @property
    def weight(self) -> float:
        """w = 1 / (N u_ref^2) [1/m^2] of the scaled constraint (module docstring)."""
        return 1.0 / (self.size * self.u_ref ** 2)

    def correct(self, x: PETSc.Vec, x_n: PETSc.Vec, lam_n: float, lam: float, length: float
                ) -> tuple[bool, int, list[float], float]:
        """Corrector iterations (eqs. 21-22) on x (in place) and lam with the constraint of eq. 19 about (x_n,
        lam_n). Returns (converged, iterations, residual norms |P - lambda F_ref|, lam)."""
        psi, du_I, du_II, residual, w = self.psi, self.du_I, self.du_II, self.residual, self.weight
        norms, converged, it = [], False, 0
        for it in range(1, self.max_iterations + 1):
            self.assemble_and_factor(x, lam)
            rnorm = residual.norm()
            norms.append(rnorm)
            delta = x - x_n
            ell = np.sqrt(w * delta.dot(delta) + psi ** 2 * (lam - lam_n) ** 2)
            f = ell - length
            if not np.isfinite(rnorm):
                break
            if rnorm < self.rtol * self.fscale * max(abs(lam), 1.0) and abs(f) < 1e-9 * length:
                converged = True
                break
            self.linear_solve(self.model.F_ref, du_I)
            residual.scale(-1.0)  # F_ext - P
            self.linear_solve(residual, du_II)
            dl = -(f * (f + length) + w * delta.dot(du_II)) / (psi ** 2 * (lam - lam_n) + w * delta.dot(du_I))  # eq. 21
            du_II.axpy(dl, du_I)  # the correction of eq. 22
            x.axpy(1.0, du_II)
            lam += dl
            delta.destroy()
            # Converged when the correction is at round-off (like SNES's step criterion)
            if (du_II.norm() <= self.stol * x.norm() and abs(dl) <= self.stol * max(abs(lam), 1.0)
                    and abs(f) < 1e-6 * length):
                converged = True
                break
        return converged, it, norms, lam

    def destroy(self) -> None:
        """Free the solver (the matrix and vectors go with the garbage collector, as before)."""
        self.ksp.destroy()


def arc_length(model, ds: float, max_steps: int, lambda_max: float | None = None,
               target_iterations: int = 5, psi: float = 1.0, max_iterations: int = 20,
               rtol: float = 1e-9, stol: float = 1e-10, gamma_bounds: tuple[float, float] = (0.25, 2.0),
               on_step: Callable[[ArcLengthStep], None] | None = None,
               petsc_options: dict | None = None, u_ref: float | None = None) -> list[ArcLengthStep]:
    """Trace the equilibrium path from the model's current state in `max_steps` arc-length steps
    (or until lambda_max is passed; the last step then ends beyond it).

    ds: initial arc length, dimensionless, in the scaled norm [w |dPhi|^2 + psi^2 dlambda^2]^(1/2) with
    w = 1 / (N u_ref^2) (module docstring): with the default u_ref a step of ds is a load-factor step of
    ds / sqrt(1 + psi^2) in the linear range, on any mesh. u_ref: characteristic displacement [m] > 0 of
    the norm (the state's RMS change is measured in it); None: the RMS of K^-1 F_ref at the start state.
    Divergence of a step halves ds and retries; below 1e-6 of the initial ds a SolverError is raised with
    the last converged load factor. A step has converged when |F_ext - P| < rtol |F_ref| max(1, |lambda|)
    and the constraint holds, or when the Newton correction is below stol relative to the state.
    """
    if model.has_prescribed_values:
        raise ValueError("arc_length: prescribed non-zero displacements/rotations are not supported; "
                         "use loads (F_ext = lambda F_ref)")
    if not ds > 0:
        raise ValueError(f"ds: must be positive, got {ds}")
    if u_ref is not None and not (np.isfinite(u_ref) and u_ref > 0):
        raise ValueError(f"u_ref: must be a positive displacement [m] or None, got {u_ref!r}")
    solver = _ArcLengthSolver(model, psi, u_ref, rtol, stol, max_iterations, petsc_options)
    x = model.create_vector()
    model.w.vector.copy(x)
    lam_n = float(model.load_factor.value)
    x_n = x.copy()
    direction = None  # previous converged increment (dPhi, dlambda) for the predictor sign
    history: list[ArcLengthStep] = []
    last_iterations = target_iterations
    ds_min = 1e-6 * ds
    for n in range(1, max_steps + 1):
        gamma = float(np.clip(acceleration_factor(n, target_iterations, last_iterations), *gamma_bounds))  # eq. 20
        length = gamma * ds
        while True:
            x_n.copy(x)
            lam = solver.predict(x, lam_n, length, direction)
            converged, it, norms, lam = solver.correct(x, x_n, lam_n, lam, length)
            if converged:
                break
            length *= 0.5
            ds *= 0.5
            if length < ds_min:
                model.set_state(x_n)
                model.set_load_factor(lam_n)
                raise SolverError(f"arc-length step {n} diverged (residual {norms[-1] if norms else float('nan'):.3e}) "
                                  f"and the arc length fell below {ds_min:.3g}; last converged load factor {lam_n:.6g}",
                                  last_converged_load_factor=lam_n, reason="ARC_LENGTH_DIVERGED")
        increment = x - x_n
        direction = (increment, lam - lam_n)
        x.copy(x_n)
        lam_n = lam
        model.set_state(x)
        model.set_load_factor(lam)
        last_iterations = it
        record = ArcLengthStep(lam, it, length, norms, solver.u_ref)
        history.append(record)
        if on_step:
            on_step(record)
        if lambda_max is not None and lam >= lambda_max:
            break
    solver.destroy()
    return history
