"""Generalized-alpha time integration of the shell by PETSc TS ALPHA2 (Chung & Hulbert 1993).

The semi-discrete equations of motion ([Man2006, eq. 2.84] before the Newmark substitution)

    M a + C v + f_int(d) - lambda(t) F_ref = 0

are handed to PETSc TS type ALPHA2 as the implicit second-order function F(t, d, v, a). Each step solves,
with SNES Newton, the balance at the intermediate ("alpha") state

    M a_{n+alpha_m} + C v_{n+alpha_f} + f_int(d_{n+alpha_f}) = lambda(t_{n+alpha_f}) F_ref   (Chung-Hulbert eq. 16)
    x_{n+alpha} = x_n + alpha (x_{n+1} - x_n)
    d_{n+1} = d_n + dt v_n + dt^2 ((1/2 - beta) a_n + beta a_{n+1})                          (Newmark eq. 2.76)
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

in PETSc's convention (alpha weights the new state; Chung-Hulbert's alpha_m^CH = 1 - alpha_m here). The
parameters follow from the spectral radius at infinite step rho_inf in [0, 1] (Chung-Hulbert eq. 25):
alpha_m = (2 - rho_inf) / (1 + rho_inf), alpha_f = 1 / (1 + rho_inf), gamma = 1/2 + alpha_m - alpha_f,
beta = (1 + alpha_m - alpha_f)^2 / 4: second order, unconditionally stable, with numerical dissipation of
the high frequencies for rho_inf < 1. rho_inf = 1 is the trapezoidal rule written at the mid-step (no
dissipation; energy-conserving for linear problems).

Tangent handed to SNES (PETSc scales the residual by 1 / alpha_f): K(d_{n+alpha_f}) + shift_v C + shift_a M
with shift_v = gamma / (beta dt), shift_a = alpha_m / (alpha_f beta dt^2). Dirichlet rows: x - lambda g in the
residual, identity rows in the tangent (as in fabricfem.dynamics.newmark). C = a M + b K_M(d_n) + C_air is
frozen during a step [Man2006, eq. 2.85]. The director base stays fixed (see fabricfem.dynamics.newmark).

Start-up: PETSc computes the initial acceleration of each (re)start itself (two backward-Euler half steps and a
backward difference); for rho_inf = 1 the displacements and velocities do not depend on it (only the sum
a_n + a_{n+1} enters), for rho_inf < 1 its error excites the spurious root, which decays by the factor
|lambda_3| < 1 per step. The algorithmic acceleration is kept inside TS: `a` of this integrator stays the
consistent a^0 of `initialize`. Units: SI.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fabricfem.dynamics.newmark import LoadFactor, StepHalving, SubStep, TimeIntegrator
from fabricfem.solvers.newton import _REASONS, DEFAULT_OPTIONS, prefixed_options
from fabricfem.solvers.system import add_term_jacobians

_prefix_counter = itertools.count()
_TS_REASONS = {v: k for k, v in vars(PETSc.TS.ConvergedReason).items() if isinstance(v, int)}


def generalized_alpha_parameters(rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, gamma, beta) of the generalized-alpha method in PETSc's convention (x_{n+alpha} =
    x_n + alpha (x_{n+1} - x_n)) for the spectral radius rho_inf at infinite step (Chung & Hulbert 1993, eq. 25)."""
    rho = float(rho_inf)
    alpha_m_ch = (2.0 * rho - 1.0) / (rho + 1.0)  # Chung-Hulbert eq. 25 (weights the old state)
    alpha_f_ch = rho / (rho + 1.0)
    gamma = 0.5 - alpha_m_ch + alpha_f_ch  # eq. 17: second order
    beta = 0.25 * (1.0 - alpha_m_ch + alpha_f_ch) ** 2  # eq. 20
    return 1.0 - alpha_m_ch, 1.0 - alpha_f_ch, gamma, beta


class GeneralizedAlphaIntegrator(StepHalving, TimeIntegrator):
    """Generalized-alpha integrator (PETSc TS ALPHA2) with the run loop, energies and outputs of TimeIntegrator.

    Args:
        model: ShellModel with a density. Its director re-basing is switched off.
        dt: time step [s] (also the output interval of `run`).
        rho_inf: spectral radius at infinite time step in [0, 1]: 1 = no numerical dissipation, 0 = the
            highest frequencies are annihilated in one step.
        load_factor, rayleigh, air_drag, lumped, energy_bound: see TimeIntegrator.
        newton_options: PETSc options of the SNES (without prefix) overriding fabricfem.solvers.newton
            DEFAULT_OPTIONS and the tolerances below.
        min_dt, grow_after: step halving on Newton failure (see StepHalving); the halving itself is done by
            TS (a failed SNES solve rejects the step and retries with dt / 2, keeping the step's start state).
    """

    resumable = False
    not_resumable = ("PETSc TS ALPHA2 keeps its algorithmic acceleration inside TS and recomputes it at a restart "
                     "(module docstring), so a run restored from a checkpoint would not repeat the uninterrupted "
                     "steps; rerun the scene without --resume")

    def __init__(self, model, dt: float, rho_inf: float = 1.0, load_factor: LoadFactor = 1.0,
                 rayleigh: tuple[float, float] = (0.0, 0.0), air_drag: float = 0.0, lumped: bool = False,
                 newton_options: dict | None = None, energy_bound: float | str | None = "auto",
                 min_dt: float | None = None, grow_after: int = 4):
        if not (isinstance(rho_inf, (int, float, np.floating)) and 0.0 <= rho_inf <= 1.0):
            raise ValueError(f"rho_inf must be a spectral radius in [0, 1], got {rho_inf!r}")
        super().__init__(model, dt, load_factor, rayleigh, air_drag, lumped, energy_bound)
        self._init_step_halving(min_dt, grow_after)
        self.rho_inf = float(rho_inf)
        self.alpha_m, self.alpha_f, self.gamma, self.beta = generalized_alpha_parameters(self.rho_inf)
        self._tmp = model.create_vector()
        self._F = model.create_vector()
        self._X = model.create_vector()
        self._V = model.create_vector()
        self.c_mass = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        self.c_damp = fem.Constant(model.mesh, PETSc.ScalarType(0.0))
        extra = self.ops.jacobian_form(self.c_mass, self.c_damp)
        self._J = fem.form(model.jacobian_form if extra is None else model.jacobian_form + extra)
        self._A = fem_petsc.create_matrix(self._J)
        self._diag_key: tuple[float, float] | None = None
        self._diag: PETSc.Vec | None = None

        self.prefix = f"fabricfem_galpha_{next(_prefix_counter)}_"
        options = dict(DEFAULT_OPTIONS)
        # as NewmarkIntegrator: absolute tolerance from the load scale, stol 1e-8 (stagnating thin-shell residual)
        options.update({"snes_atol": 1e-12 * max(model.F_ref.norm(), 1e-300), "snes_stol": 1e-8})
        options.update(newton_options or {})
        options.update({"ts_alpha_radius": self.rho_inf, "ts_adapt_type": "none",
                        "ts_adapt_scale_solve_failed": 0.5})
        self.options = options
        ts = PETSc.TS().create(model.comm)
        ts.setOptionsPrefix(self.prefix)
        ts.setType(PETSc.TS.Type.ALPHA2)
        ts.setI2Function(self._residual, self._F)
        ts.setI2Jacobian(self._jacobian, self._A)
        ts.setMaxTime(PETSc.INFINITY)
        ts.setMaxSteps(2 ** 30)
        ts.setMaxSNESFailures(-1)  # every SNES failure rejects the step and halves it (bounded by max rejections)
        ts.setErrorIfStepFails(False)
        with prefixed_options(self.prefix, options):
            ts.setFromOptions()
            snes = ts.getSNES()
            snes.setFromOptions()
            snes.getKSP().setFromOptions()
            snes.getKSP().getPC().setFromOptions()
        self.ts = ts
        self.d.copy(self._X)
        self.v.copy(self._V)
        ts.setSolution2(self._X, self._V)
        ts.setTime(self.t)
        ts.setTimeStep(self.dt)

    # ----------------------------------------------------------- callbacks
    def _residual(self, ts, t: float, x: PETSc.Vec, xdot: PETSc.Vec, xddot: PETSc.Vec, F: PETSc.Vec):
        """F = f_int(x) - lambda(t) F_ref + M xddot + C xdot; Dirichlet rows x - lambda(t) g."""
        self.model.set_load_factor(self.load(t))
        self.system.residual(x, F)
        self.ops.mass_action(xddot, self._tmp)
        self.zero_bc_rows(self._tmp)
        F.axpy(1.0, self._tmp)
        if self.ops.has_damping:
            self.ops.damping_action(xdot, self._tmp)
            self.zero_bc_rows(self._tmp)
            F.axpy(1.0, self._tmp)

    def _jacobian(self, ts, t: float, x: PETSc.Vec, xdot: PETSc.Vec, xddot: PETSc.Vec, shift_v: float,
                  shift_a: float, J: PETSc.Mat, P: PETSc.Mat):
        """P = K(x) + shift_a M + shift_v C with identity Dirichlet rows (+ the terms' tangents of a CompositeSystem)."""
        self.c_mass.value = shift_a
        self.c_damp.value = shift_v
        self.model.set_state(x)
        P.zeroEntries()
        fem_petsc.assemble_matrix(P, self._J, bcs=self.model.bcs)
        P.assemble()
        if self.ops.lumped:
            key = (float(shift_a), float(shift_v))
            if key != self._diag_key:
                if self._diag is not None:
                    self._diag.destroy()
                self._diag = self.ops.jacobian_diagonal(*key)
                self.zero_bc_rows(self._diag)
                self._diag_key = key
            P.setDiagonal(self._diag, addv=PETSc.InsertMode.ADD_VALUES)
        add_term_jacobians(self.system, x, P)  # e.g. contact: they see the state x set above
        if J != P:
            J.assemble()

    # --------------------------------------------------------------- state
    def initialize(self, displacement: PETSc.Vec | None = None, velocity: PETSc.Vec | None = None, t0: float = 0.0):
        """Set d^0, v^0, t0 (see TimeIntegrator.initialize) and restart TS from them."""
        super().initialize(displacement, velocity, t0)
        self.current_dt = self.dt
        self._successes = 0
        self._push_state()

    def _push_state(self):
        """Hand (t, d, v) to TS and make it recompute its start-up acceleration at the next step."""
        self.d.copy(self._X)
        self.v.copy(self._V)
        self.ts.setTime(self.t)
        self.ts.restartStep()

    def _substep(self, h: float) -> SubStep:
        """One TS step of at most h: TS halves it on SNES failure down to min_dt (step rejections)."""
        ts = self.ts
        max_rejections = int(math.floor(math.log2(h / self.min_dt) + 1e-9))
        ts.setMaxStepRejections(max_rejections)
        ts.setTimeStep(h)
        t_before = ts.getTime()
        iterations_before = ts.getSNESIterations()
        self.ops.freeze(self.d)  # C = a M + b K_M(d^n) (eq. 2.85)
        with prefixed_options(self.prefix, self.options):  # read again when the LU factor is set up
            ts.step()
        iterations = ts.getSNESIterations() - iterations_before
        if ts.getConvergedReason() < 0:
            snes_reason = ts.getSNES().getConvergedReason()
            reason = _REASONS.get(snes_reason, str(snes_reason)) if snes_reason < 0 else \
                _TS_REASONS.get(ts.getConvergedReason(), str(ts.getConvergedReason()))
            self._push_state()  # TS's state is the step's start; restart drops its failed acceleration
            self._restore_last_converged()
            return SubStep(False, h / 2.0 ** max_rejections, iterations, reason)
        used = ts.getTime() - t_before
        self._X.copy(self.d)
        self._V.copy(self.v)
        self.t = t_before + used
        self.model.set_load_factor(self.load(self.t))
        self._sync_model()  # model.w held the last alpha-level iterate
        if not (math.isfinite(self.d.norm()) and math.isfinite(self.v.norm())):
            return SubStep(True, used, iterations, "NAN_IN_SOLUTION")  # the blow-up check stops the run
        return SubStep(True, used, iterations, "CONVERGED")

    def step(self) -> int:
        iterations = super().step()
        self.ts.setTime(self.t)  # on the output grid exactly
        return iterations

    def destroy(self):
        self.ts.destroy()
        for obj in (self._tmp, self._F, self._X, self._V, self._A):
            obj.destroy()
        if self._diag is not None:
            self._diag.destroy()
        self._destroy_step_halving()
        super().destroy()
