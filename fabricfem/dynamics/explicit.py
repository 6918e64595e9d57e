"""Explicit central differences with the lumped mass of [Man2006, eq. 2.82] (Newmark beta = 0, gamma = 1/2).

    d^{n+1} = d^n + dt v^n + dt^2 / 2 a^n                                            (eq. 2.76, beta = 0)
    v~      = v^n + dt / 2 a^n
    (M_L + dt/2 C_L) a^{n+1} = lambda(t_{n+1}) F_ref - f_int(d^{n+1}) - C_L v~ - b K_M v~   (eq. 2.84)
    v^{n+1} = v~ + dt / 2 a^{n+1}

C_L = a M_L + eta M_L^translational / (rho t) is diagonal and treated implicitly (still explicit: a division);
the stiffness-proportional part b K_M(d^n) acts on the predictor velocity v~ (a matrix-vector product).
Dirichlet rows: d = lambda(t) g, a = 0, v = (d^{n+1} - d^n) / dt there.

The step must not exceed the critical time step (fabricfem.dynamics.stability, [Man2006, eqs. 2.86-2.87]);
a larger one is refused (ValueError) unless force=True. Units: SI.

Rotary-inertia mass scaling (`rotary_inertia_scale` s >= 1, default 1): the rotational lumped masses
are multiplied by s (fabricfem.dynamics.mass), which lowers the thickness-shear frequency by sqrt(s)
(fabricfem.dynamics.stability) and leaves static answers unchanged; the critical step is estimated
with s.

Mass scaling (`mass_scale` S >= 1, default 1): every lumped mass (translations and rotations) is multiplied by
S, which lowers every frequency by sqrt(S) and lengthens the critical step by sqrt(S) [Belytschko2000, ch. 6]; the
damping C and the loads (gravity) stay those of the physical mass, so a quasi-static answer is unchanged
while the inertia forces grow by S: the kinetic over the strain energy of the scaled model is the check.
The critical step to check against (`dt_crit`) must then be given for the scaled mass.

Contact (`contact`, optional): an ExplicitHook (fabricfem.solvers.system) with `forces(integrator, t, rhs)`
(penalty: adds nodal contact forces at d^{n+1} to the right-hand side before the division by the diagonal) and
`correct(integrator, t)` (forward-increment Lagrange multipliers, [Man2006, Box 5]: modifies a^{n+1} after
the division so that the next predictor lands on the body), see fabricfem.contact.explicit. A sequence of such
layers is called in its order (the body contact first, then the seams of fabricfem.contact.seams, so that the
stitched nodes end the step together).

Safe step (`step_check_every` N, default None: off): every N steps the largest frequency of the current state is
estimated (fabricfem.dynamics.safe_step.FrequencyTracker, power iteration on M^-1 K(d) of the acting system) and
the step is shortened to step_safety x dt_crit(omega) ([Man2006, eq. 2.86], Rayleigh damping as in
stability.critical_time_step) when it is longer; never lengthened. `step_reductions` counts the shortenings,
`omega_tracked` is the last estimate [rad/s].

Compiled loop (`compiled`, default "auto"): when no Python hook acts in a step (one MPI rank, no contact or seams,
no wrapped step such as the strain limit's projection, diagonal damping; fabricfem.dynamics.compiled_loop
`reason_not_compiled`), `run` takes the steps between records and safe-step checks in one C call with the same
arithmetic (same trajectory to round-off); otherwise, or with compiled=False, the Python loop below. compiled=True
refuses (ValueError with the reason) a run the compiled loop cannot take. `route` says which loop ran last
("compiled" or "python: <reason>"); the compiled loop adds the wall time of its C calls to timings["compiled_steps"]
(and leaves "internal_forces" and "contact" alone).

Vector passes (`vector_passes`, default True): the Python loop's vector work around the internal force and the
hooks (the predictor, the right-hand side with the diagonal damping, the division, the corrector and the Dirichlet
rows' velocity) runs as four compiled passes over the owned entries that round as the PETSc calls they replace
(fabricfem.dynamics.explicit_update, checked once per process; the same values to the bit); with a damping matrix
(stiffness-proportional damping), or vector_passes False, the PETSc calls.

Changing the step (`set_time_step`, e.g. a run that shortens it as the fabric stiffens): M + dt/2 C is rebuilt at
the next step and the hooks that keep quantities of the step (TimeStepListener, e.g. the seams' masses) are told.
"""
from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np
from dolfinx.fem import petsc as fem_petsc

from fabricfem.dynamics import stability
from fabricfem.dynamics.compiled_loop import CompiledLoop, reason_not_compiled
from fabricfem.dynamics.explicit_update import StepPasses, matches_petsc
from fabricfem.dynamics.mass import InertiaDamping, rotary_scale
from fabricfem.dynamics.newmark import DynamicsError, LoadFactor, TimeIntegrator
from fabricfem.dynamics.safe_step import FrequencyTracker
from fabricfem.solvers.system import ExplicitHook, TimeStepListener


def _check_step(dt: float, dt_crit: float, force: bool) -> None:
    """ValueError naming `dt` when it exceeds the critical step dt_crit [s] and force is False."""
    if isinstance(dt, (int, float, np.floating)) and dt > dt_crit and not force:
        raise ValueError(f"dt = {dt:.6g} s exceeds the critical time step dt_crit = {dt_crit:.6g} s of central "
                         f"differences ([Man2006, eqs. 2.86-2.87], ratio {dt / dt_crit:.3g}); use a smaller dt or "
                         f"force=True")


def _hooks(contact) -> list[ExplicitHook]:
    """The hooks of the `contact` argument (None, one hook or a sequence), TypeError naming `contact` for an object
    without `forces` and `correct`."""
    hooks = [] if contact is None else list(contact) if isinstance(contact, (list, tuple)) else [contact]
    for hook in hooks:
        if not isinstance(hook, ExplicitHook):
            raise TypeError(f"contact: {type(hook).__name__} has no forces(integrator, t, rhs) / "
                            f"correct(integrator, t) (fabricfem.solvers.system.ExplicitHook)")
    return hooks


class CentralDifference(TimeIntegrator):
    """Explicit central-difference integrator (lumped mass, no linear solves).

    Args:
        model, dt, load_factor, rayleigh, air_drag, energy_bound: see TimeIntegrator.
        force: allow dt above the critical time step (for stability studies; a blow-up still stops the run).
        dt_crit: critical time step [s] to check against (default: stability.critical_time_step(model, rayleigh)).
        damping_update_every: re-evaluate K_M(d^n) of the stiffness-proportional damping every this many steps.
        rotary_inertia_scale: s >= 1 multiplying the rotational lumped masses (module docstring).
        mass_scale: S >= 1 multiplying every lumped mass, not the damping nor the loads (module docstring).
        contact: explicit contact layer (ExplicitHook) or a sequence of them (module docstring), e.g.
            fabricfem.contact.explicit.ExplicitBodyContact, fabricfem.contact.seams.SeamTies.
        step_check_every: steps between the safe-step estimates (module docstring); None: no estimates.
        step_safety: the step's fraction of 2 / omega of the tracked frequency (default STEP_SAFETY["eigenvalue"]).
        compiled: "auto" (the compiled loop when it applies), True (required) or False (module docstring).
    """

    def __init__(self, model, dt: float, load_factor: LoadFactor = 1.0, rayleigh: tuple[float, float] = (0.0, 0.0),
                 air_drag: float = 0.0, force: bool = False, dt_crit: float | None = None,
                 energy_bound: float | str | None = "auto", damping_update_every: int = 1,
                 rotary_inertia_scale: float = 1.0, contact: ExplicitHook | Sequence[ExplicitHook] | None = None,
                 mass_scale: float = 1.0, step_check_every: int | None = None,
                 step_safety: float = stability.STEP_SAFETY["eigenvalue"], compiled: bool | str = "auto"):
        if compiled not in (True, False, "auto"):
            raise ValueError(f"compiled must be True, False or 'auto', got {compiled!r}")
        scale = rotary_scale(rotary_inertia_scale)
        if isinstance(mass_scale, bool) or not (isinstance(mass_scale, (int, float)) and mass_scale >= 1.0):
            raise ValueError(f"mass_scale must be a number >= 1, got {mass_scale!r}")
        if dt_crit is None:
            dt_crit = stability.critical_time_step(model, rayleigh, rotary_inertia_scale=scale,
                                                   mass_scale=mass_scale)
        if not (dt_crit > 0):
            raise ValueError(f"dt_crit must be positive, got {dt_crit!r}")
        _check_step(dt, dt_crit, force)
        if int(damping_update_every) < 1:
            raise ValueError(f"damping_update_every must be >= 1, got {damping_update_every!r}")
        super().__init__(model, dt, load_factor, rayleigh, air_drag, lumped=True, energy_bound=energy_bound)
        if scale != 1.0:
            self.ops = InertiaDamping(self.model, lumped=True, rayleigh=rayleigh, air_drag=air_drag,
                                      rotary_inertia_scale=scale)
        self.rotary_inertia_scale = scale
        self.mass_scale = float(mass_scale)
        if self.mass_scale != 1.0:
            self.ops.mass_diag.scale(self.mass_scale)     # C = a M of the physical mass: damping_diag unchanged
        self.contact = contact
        self._hooks = _hooks(contact)
        self.dt_crit = float(dt_crit)
        self.force = bool(force)
        self.damping_update_every = int(damping_update_every)
        m = self.ops.mass_diag.getArray(readonly=True)
        free = m.copy()
        free[self.bc_rows] = 1.0
        if free.size and free.min() <= 0:
            raise ValueError("the lumped mass has non-positive entries on free dofs")
        self._v_pred = model.create_vector()
        self._rhs = model.create_vector()
        self._denominator = None
        # wall time [s] spent in the internal-force assembly and in the contact hooks since construction
        self.timings = {"internal_forces": 0.0, "contact": 0.0}
        if step_check_every is not None and not (isinstance(step_check_every, int) and step_check_every >= 1):
            raise ValueError(f"step_check_every must be a positive integer or None, got {step_check_every!r}")
        if not (isinstance(step_safety, (int, float)) and 0.0 < step_safety <= 1.0):
            raise ValueError(f"step_safety must lie in (0, 1], got {step_safety!r}")
        self.step_check_every, self.step_safety = step_check_every, float(step_safety)
        self._scaled_rayleigh = (rayleigh[0] / self.mass_scale, rayleigh[1])   # (a, b) on the scaled mass
        self.tracker = FrequencyTracker(self) if step_check_every else None
        self.step_reductions = 0
        self.omega_tracked = 0.0
        self.compiled, self.route, self._loop = compiled, "", None
        # the step's vector work by compiled passes with PETSc's rounding (`_step_passes`); False: PETSc's calls
        self.vector_passes, self._passes = True, None

    @property
    def velocity_predictor(self):
        """v~ = v^n + dt/2 a^n of the current step (PETSc Vec) [m/s, rad/s]."""
        return self._v_pred

    @property
    def denominator(self):
        """M_L + dt/2 C_L (diagonal PETSc Vec, 1 on Dirichlet rows) [kg, kg m^2]."""
        if self._denominator is None:
            self._set_denominator()
        return self._denominator

    def _set_denominator(self):
        """M_L + dt/2 C_L (diagonal), 1 on Dirichlet rows."""
        self._denominator = self.ops.mass_diag.copy()
        self._denominator.axpy(0.5 * self.dt, self.ops.damping_diag)
        self._denominator.getArray()[self.bc_rows] = 1.0

    def set_time_step(self, dt: float) -> None:
        """Take steps of dt [s] from the next step on: M + dt/2 C is rebuilt then, and every hook that keeps
        quantities of the step (TimeStepListener) is told by its `on_time_step(dt)`. Refused (ValueError naming
        `dt`) for a non-positive or non-finite dt and, unless the integrator was built with force=True, for dt above
        the critical step `dt_crit`."""
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite time step [s], got {dt!r}")
        _check_step(dt, self.dt_crit, self.force)
        self.dt = float(dt)
        if self._denominator is not None:
            self._denominator.destroy()
            self._denominator = None
        for hook in self._hooks:
            if isinstance(hook, TimeStepListener):
                hook.on_time_step(self.dt)

    def blowup_advice(self) -> str:
        ratio = self.dt / self.dt_crit
        return (f"the explicit step dt = {self.dt:.4g} s is above the stability limit of the current state "
                f"({ratio:.3g} of dt_crit = {self.dt_crit:.4g} s; try dt_fraction {0.6 * ratio:.2g}, or a step "
                f"check: step_check_every)")

    def _safe_step(self) -> None:
        """Shorten dt to step_safety x dt_crit(omega of the current state) when it is longer (module docstring)."""
        self.omega_tracked = self.tracker.estimate(self.d)
        if self.omega_tracked <= 0.0:
            return
        limit = self.step_safety * stability.critical_time_step(self.model, self._scaled_rayleigh, self.omega_tracked)
        if self.dt > limit:
            self.set_time_step(limit)
            self.step_reductions += 1

    def step(self) -> int:
        if self.tracker is not None and self.step_count % self.step_check_every == 0:
            self._safe_step()
        dt = self.dt
        if self._denominator is None:
            self._set_denominator()
        t_new = self.t + dt
        passes = self._step_passes()
        # d^{n+1} = d^n + dt v^n + dt^2/2 a^n ; v~ = v^n + dt/2 a^n
        if passes is not None:
            passes.predict(self.d, self.v, self.a, self._v_pred, dt)
        else:
            d_old_bc = self.d.getArray(readonly=True)[self.bc_rows].copy()
            self.d.axpy(dt, self.v)
            self.d.axpy(0.5 * dt ** 2, self.a)
            self.v.copy(self._v_pred)
            self._v_pred.axpy(0.5 * dt, self.a)
        lam = self.load(t_new)
        self.model.set_load_factor(lam)
        fem_petsc.set_bc(self.d, self.model.bcs)  # prescribed displacements lambda(t) g
        if self.ops.stiffness_ufl is not None and self.step_count % self.damping_update_every == 0:
            self._sync_model()
            self.ops.freeze(self.d)
        rhs = self._rhs
        tic = time.perf_counter()
        self.system.internal_force(self.d, rhs)  # f_int(d^{n+1}) (+ terms); copies d^{n+1} into the model's Function
        toc = time.perf_counter()
        self.timings["internal_forces"] += toc - tic
        if passes is not None:      # rhs = lambda F_ref - f_int - C v~
            damping = self.ops.damping_diag if self.ops.has_damping else None
            passes.balance(rhs, self.model.F_ref, float(self.model.load_factor.value), damping, self._v_pred,
                           self._cv)
        else:
            rhs.scale(-1.0)
            rhs.axpy(float(self.model.load_factor.value), self.model.F_ref)
            if self.ops.has_damping:
                self.ops.damping_action(self._v_pred, self._cv)
                rhs.axpy(-1.0, self._cv)
        if self._hooks:
            tic = time.perf_counter()
            for hook in self._hooks:
                hook.forces(self, t_new, rhs)            # penalty contact: nodal forces at d^{n+1}
            self.timings["contact"] += time.perf_counter() - tic
        if passes is not None:
            passes.accelerate(self.a, rhs, self._denominator)
        else:
            self.zero_bc_rows(rhs)
            self.a.pointwiseDivide(rhs, self._denominator)
        if self._hooks:
            tic = time.perf_counter()
            for hook in self._hooks:
                hook.correct(self, t_new)                # [Man2006, Box 5]: a^{n+1} += a^c
            self.timings["contact"] += time.perf_counter() - tic
        if passes is not None:      # v^{n+1} = v~ + dt/2 a^{n+1}; (d^{n+1} - d^n) / dt on the Dirichlet rows
            passes.correct(self.v, self._v_pred, self.a, self.d, dt)
        else:
            self._v_pred.copy(self.v)
            self.v.axpy(0.5 * dt, self.a)
            d_new_bc = self.d.getArray(readonly=True)[self.bc_rows]
            self.v.getArray()[self.bc_rows] = (d_new_bc - d_old_bc) / dt
        self.t = t_new
        return 0

    def _step_passes(self) -> StepPasses | None:
        """The compiled passes of the step's vector work (fabricfem.dynamics.explicit_update), or None for the PETSc
        calls: with `vector_passes` False, a damping matrix (stiffness-proportional damping), or passes that do not
        round as PETSc does on this machine."""
        if not self.vector_passes or self.ops.C is not None:
            return None
        if self._passes is None:
            self._passes = StepPasses(self.bc_rows) if matches_petsc() else False
        return self._passes or None

    def compiled_reason(self) -> str:
        """Why `run` takes the Python loop ("" when the compiled loop applies; module docstring)."""
        if self.compiled is False:
            return "compiled = False"
        if "step" in vars(self) or type(self).step is not CentralDifference.step:
            return "the step is wrapped or overridden (e.g. the strain limit's projection)"
        return reason_not_compiled(self)

    def _advance(self, n_steps, output_every, record, report, should_stop, history) -> None:
        """TimeIntegrator._advance, by the compiled loop where it applies (module docstring)."""
        reason = self.compiled_reason()
        if reason and self.compiled is True:
            raise ValueError(f"compiled=True, but the compiled explicit loop does not apply: {reason}")
        self.route = f"python: {reason}" if reason else "compiled"
        if reason:
            return super()._advance(n_steps, output_every, record, report, should_stop, history)
        if self._loop is None:
            self._loop = CompiledLoop(self)
        self._loop.advance(n_steps, output_every, record, report, should_stop, history)

    def destroy(self):
        if self.tracker is not None:
            self.tracker.destroy()
        for vec in (self._v_pred, self._rhs):
            vec.destroy()
        if self._denominator is not None:
            self._denominator.destroy()
        super().destroy()


def runs_stably(model, dt: float, n_steps: int, reset: bool = True, rotary_inertia_scale: float = 1.0) -> bool:
    """Run n_steps central-difference steps from rest (forced past the critical-step check); False if
    the blow-up check (DynamicsError) stopped the run. Used to measure stability limits by bisection."""
    model.w.x.array[:] = 0.0
    # energy_bound "auto": 10 x the loads' work
    integrator = CentralDifference(model, dt, force=True, rotary_inertia_scale=rotary_inertia_scale)
    try:
        integrator.run(n_steps, output_every=n_steps)
        return True
    except DynamicsError:
        return False
    finally:
        integrator.destroy()
        if reset:
            model.w.x.array[:] = 0.0
