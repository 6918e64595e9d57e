"""Implicit Newmark time integration of the shell ([Man2006, sec. 2.3.1.6], eqs. 2.75-2.85, Box 2).

Each step solves the effective residual in the end-of-step displacement d = d^{n+1} with SNES Newton:

    G(d) = f_int(d) - lambda(t_{n+1}) F_ref + M a(d) + C v(d) = 0                         (eq. 2.84)
    a(d) = (d - d~) / (beta dt^2),  d~ = d^n + dt v^n + (1/2 - beta) dt^2 a^n            (eq. 2.76)
    v(d) = v~ + gamma dt a(d),      v~ = v^n + (1 - gamma) dt a^n                         (eq. 2.76)

with tangent K(d) + M / (beta dt^2) + gamma C / (beta dt) (eq. 2.85 written for d instead of a: the same
Newton iterates, scaled). The thesis calls gamma "alpha". M is constant (linearised director, see
fabricfem.dynamics.mass), C = a M + b K_M(d^n) + C_air is frozen during a step (eq. 2.85).
Trapezoidal rule: beta = 1/4, gamma = 1/2 (no numerical dissipation; energy-conserving for linear problems).

Rotations: the director base is not re-based during a dynamic run (fabricfem.dynamics.integrator).

Step halving (`StepHalving`, fabricfem.dynamics.step_halving, shared with fabricfem.dynamics.ts): when the
Newton solve of a step fails, the state is restored and the step halved and retried down to min_dt (default
dt/64), then doubled again after `grow_after` converged sub-steps (never above dt); outputs stay at multiples
of dt. Below min_dt the run stops with DynamicsError (time, dt, Newton reason) and the last converged state in
the integrator and model.w.

The common run loop (energy bookkeeping, blow-up check, outputs, progress) lives in `TimeIntegrator`
(fabricfem.dynamics.integrator), which the explicit central-difference scheme (Newmark with beta = 0) shares;
it and the step halving's names are importable from here too.
"""
from __future__ import annotations

import math

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fabricfem.dynamics.integrator import (
    DynamicsError,
    History,
    LoadFactor,
    TimeIntegrator,
    node_monitor,
    progress_printer,
)
from fabricfem.dynamics.step_halving import StepHalving, SubStep
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.solvers.system import add_term_jacobians

__all__ = ["DynamicsError", "History", "LoadFactor", "NewmarkIntegrator", "StepHalving", "SubStep", "TimeIntegrator",
           "node_monitor", "progress_printer"]


class _EffectiveSystem:
    """Model-like adapter giving NewtonSolver the effective residual and tangent of one Newmark step."""

    def __init__(self, integrator: "NewmarkIntegrator"):
        self.it = integrator
        model = integrator.model
        self.model = model
        self.comm = model.comm
        self.w = model.w
        self.F_ref = model.F_ref
        self.c_mass = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        self.c_damp = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        extra = integrator.ops.jacobian_form(self.c_mass, self.c_damp)
        jac = model.jacobian_form if extra is None else model.jacobian_form + extra
        self._J = fem.form(jac)
        self._acc = model.create_vector()
        self._vel = model.create_vector()
        self._tmp = model.create_vector()
        self._diag = None

    def compile(self):
        pass

    def set_state(self, x: PETSc.Vec):
        self.model.set_state(x)

    def set_coefficients(self, dt: float, beta: float, gamma: float):
        """The step's factors 1 / (beta dt^2) on M and gamma / (beta dt) on C (dt [s]) and the lumped diagonal."""
        self.c_mass.value = 1.0 / (beta * dt ** 2)
        self.c_damp.value = gamma / (beta * dt)
        self._diag = self.it.ops.jacobian_diagonal(float(self.c_mass.value), float(self.c_damp.value))
        if self._diag is not None:
            self.it.zero_bc_rows(self._diag)

    def create_vector(self) -> PETSc.Vec:
        return self.model.create_vector()

    def create_matrix(self) -> PETSc.Mat:
        return fem_petsc.create_matrix(self._J)

    def residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """G(x) = f_int(x) - lambda F_ref + M a(x) + C v(x); Dirichlet rows x - lambda g."""
        it = self.it
        it.system.residual(x, b)
        x.copy(self._acc)  # a(x) = (x - d~) / (beta dt^2)
        self._acc.axpy(-1.0, it.d_pred)
        self._acc.scale(float(self.c_mass.value))
        it.v_pred.copy(self._vel)  # v(x) = v~ + gamma dt a(x)
        self._vel.axpy(it.gamma * it.dt, self._acc)
        it.ops.mass_action(self._acc, self._tmp)
        self.it.zero_bc_rows(self._tmp)
        b.axpy(1.0, self._tmp)
        if it.ops.has_damping:
            it.ops.damping_action(self._vel, self._tmp)
            self.it.zero_bc_rows(self._tmp)
            b.axpy(1.0, self._tmp)

    def jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        """A = K(x) + M / (beta dt^2) + gamma C / (beta dt) (eq. 2.85 for d) with Dirichlet rows, plus the terms'."""
        x.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self._J, bcs=self.model.bcs)
        A.assemble()
        if self._diag is not None:
            A.setDiagonal(self._diag, addv=PETSc.InsertMode.ADD_VALUES)
        add_term_jacobians(self.it.system, x, A)  # e.g. contact: they see the state x set above


class NewmarkIntegrator(StepHalving, TimeIntegrator):
    """Implicit Newmark (beta, gamma) with SNES Newton per step ([Man2006, Box 2], eqs. 2.76, 2.84-2.85).

    Args:
        beta, gamma: Newmark parameters; unconditionally stable for gamma >= 1/2 and beta >= (gamma + 1/2)^2 / 4
            (Hughes, The Finite Element Method, sec. 9.1); other values raise ValueError. Default: trapezoidal.
        newton_options: PETSc options for the SNES (see fabricfem.solvers.newton.DEFAULT_OPTIONS).
        min_dt: smallest sub-step [s] of the step halving on Newton failure (default dt / 64; min_dt = dt
            disables halving); grow_after: converged sub-steps before the sub-step is doubled again (see
            StepHalving). Outputs stay at multiples of dt.
        Other arguments: see TimeIntegrator (consistent mass unless lumped=True).
    """

    def __init__(self, model, dt: float, beta: float = 0.25, gamma: float = 0.5, load_factor: LoadFactor = 1.0,
                 rayleigh: tuple[float, float] = (0.0, 0.0), air_drag: float = 0.0, lumped: bool = False,
                 newton_options: dict | None = None, energy_bound: float | str | None = "auto",
                 min_dt: float | None = None, grow_after: int = 4):
        for name, value in (("beta", beta), ("gamma", gamma)):
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if gamma < 0.5:
            raise ValueError(f"gamma = {gamma} < 1/2: Newmark amplifies the solution (need gamma >= 1/2)")
        if beta < (gamma + 0.5) ** 2 / 4.0 - 1e-14:
            raise ValueError(f"beta = {beta} < (gamma + 1/2)^2 / 4 = {(gamma + 0.5) ** 2 / 4:.6g}: the implicit "
                             f"Newmark scheme would be only conditionally stable (use CentralDifference for beta = 0)")
        super().__init__(model, dt, load_factor, rayleigh, air_drag, lumped, energy_bound)
        self._init_step_halving(min_dt, grow_after)
        self.beta, self.gamma = float(beta), float(gamma)
        self.d_pred = model.create_vector()
        self.v_pred = model.create_vector()
        self.effective = _EffectiveSystem(self)  # the step's residual and tangent, what Newton drives
        self._coefficient_dt = self.dt
        self.effective.set_coefficients(self.dt, self.beta, self.gamma)
        # stol 1e-8: near round-off the residual of thin shells stagnates (ill-conditioned K) while the Newton
        # update is ~1e-9 of the solution; the full-step Newton only takes steps that small when converged.
        options = {"snes_atol": 1e-12 * max(model.F_ref.norm(), 1e-300), "snes_stol": 1e-8}
        options.update(newton_options or {})
        self.solver = NewtonSolver(self.effective, options)

    _state_scalars = StepHalving._state_scalars + ("_coefficient_dt",)

    def restore(self, state: dict):
        """TimeIntegrator.restore, then the step's coefficients for the restored sub-step size."""
        super().restore(state)
        self.effective.set_coefficients(self._coefficient_dt, self.beta, self.gamma)

    def _substep(self, h: float) -> SubStep:
        """One Newmark step of size h from (t, d, v, a); on Newton failure nothing but model.w is changed."""
        beta, gamma = self.beta, self.gamma
        if h != self._coefficient_dt:
            self.effective.set_coefficients(h, beta, gamma)
            self._coefficient_dt = h
        t_new = self.t + h
        # predictors d~, v~ (eq. 2.76 with a* = 0)
        self.d.copy(self.d_pred)
        self.d_pred.axpy(h, self.v)
        self.d_pred.axpy((0.5 - beta) * h ** 2, self.a)
        self.v.copy(self.v_pred)
        self.v_pred.axpy((1.0 - gamma) * h, self.a)
        self.ops.freeze(self.d)  # C = a M + b K_M(d^n) (eq. 2.85)
        self.model.set_load_factor(self.load(t_new))
        self.d_pred.copy(self.model.w.vector)
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        try:
            result = self.solver.solve()
        except SolverError as refused:  # an absurd "converged" state (NewtonSolver guard): a failed sub-step
            self._restore_last_converged()
            return SubStep(False, h, self.solver.snes.getIterationNumber(), refused.reason)
        if not result.converged:
            self._restore_last_converged()
            return SubStep(False, h, result.iterations, result.reason)
        self.model.w.vector.copy(self.d)
        # a^{n+1} = (d - d~) / (beta dt^2), v^{n+1} = v~ + gamma dt a^{n+1}
        self.d.copy(self.a)
        self.a.axpy(-1.0, self.d_pred)
        self.a.scale(1.0 / (beta * h ** 2))
        self.v_pred.copy(self.v)
        self.v.axpy(gamma * h, self.a)
        self.t = t_new
        return SubStep(True, h, result.iterations, result.reason)

    def destroy(self):
        """Free the Newton solver, the predictors and the state vectors."""
        self.solver.destroy()
        for vec in (self.d_pred, self.v_pred):
            vec.destroy()
        self._destroy_step_halving()
        super().destroy()
