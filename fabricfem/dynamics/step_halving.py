"""Sub-stepping with step halving on Newton failure, shared by the implicit integrators (Newmark,
fabricfem.dynamics.newmark; generalized-alpha, fabricfem.dynamics.ts): `StepHalving` mixed into a TimeIntegrator,
`SubStep` the outcome of one attempted sub-step. Times in s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fabricfem.dynamics.integrator import DynamicsError, TimeIntegrator

__all__ = ["StepHalving", "SubStep"]


@dataclass
class SubStep:
    """Outcome of one attempted sub-step: converged, the step size used [s], Newton iterations, SNES reason."""
    converged: bool
    dt: float
    iterations: int
    reason: str


class StepHalving:
    """Sub-stepping of an implicit integrator with step halving on Newton failure (mixed into TimeIntegrator).

    A user step advances the state from t0 + k dt to t0 + (k+1) dt (the output grid stays on multiples of dt).
    When the Newton solve of a sub-step fails, the state is restored, the sub-step is halved and retried, down
    to min_dt; after `grow_after` consecutive converged sub-steps it is doubled again (never above dt). Below
    min_dt the run stops with DynamicsError naming the time, the step and the Newton reason, with the last
    converged state restored in the integrator and in model.w. Work and dissipation are booked per sub-step.

    Subclasses implement `_substep(h) -> SubStep`, which advances (t, d, v, a) by h on success and leaves them
    (and model.w) untouched otherwise; `_substep` may itself halve (then SubStep.dt < h).
    """

    def _init_step_halving(self, min_dt: float | None, grow_after: int):
        """Checked min_dt [s] (default dt / 64) and grow_after, zero counters, the sub-step's saved state vectors."""
        min_dt = self.dt / 64.0 if min_dt is None else min_dt
        if not (isinstance(min_dt, (int, float, np.floating)) and math.isfinite(min_dt) and 0 < min_dt <= self.dt):
            raise ValueError(f"min_dt must be a time step [s] in (0, dt = {self.dt:.6g}], got {min_dt!r}")
        if not (isinstance(grow_after, (int, np.integer)) and grow_after >= 1):
            raise ValueError(f"grow_after must be a positive integer, got {grow_after!r}")
        self.min_dt = float(min_dt)
        self.grow_after = int(grow_after)
        self.current_dt = self.dt  # the sub-step size the next step starts with [s]
        self.substeps = 0  # converged sub-steps so far
        self.halvings = 0  # failed Newton solves that led to a smaller sub-step
        self.doublings = 0  # sub-step growths back towards dt
        self._successes = 0
        self.accounts_substeps = True
        self._sub_d_old = self.model.create_vector()
        self._sub_cv_old = self.model.create_vector()

    def _restore_last_converged(self):
        """model.w and the load factor back to the last converged state (t, d)."""
        self.model.set_load_factor(self.load(self.t))
        self._sync_model()

    def _fail(self, name: str, t_fail: float, h: float, reason: str, iterations: int):
        """Restore the last converged state and raise DynamicsError naming the step, time [s], dt [s] and reason."""
        self._restore_last_converged()
        raise DynamicsError(
            f"{name} step {self.step_count + 1}: Newton {reason} after {iterations} iterations at t = {t_fail:.6g} s "
            f"with dt = {h:.3g} s (min_dt = {self.min_dt:.3g} s); state restored to the last converged time "
            f"t = {self.t:.6g} s", self.step_count + 1, t_fail, dt=h, reason=reason, last_converged_time=self.t)

    def step(self) -> int:
        """Advance to the next output time t0 + (k+1) dt; returns the Newton iterations of all sub-steps."""
        t_target = self.t0 + (self.step_count + 1) * self.dt
        resolution = 1e-9 * self.dt
        iterations = 0
        while t_target - self.t > resolution:
            h = min(self.current_dt, t_target - self.t)
            if t_target - self.t - h <= resolution:
                h = t_target - self.t  # land on the grid, no sliver step
            self.d.copy(self._sub_d_old)
            self._cv.copy(self._sub_cv_old)
            lam_old = float(self.model.load_factor.value)
            outcome = self._substep(h)
            iterations += outcome.iterations
            if not outcome.converged:
                if outcome.dt / 2.0 < self.min_dt * (1.0 - 1e-12):
                    self._fail(type(self).__name__, self.t + outcome.dt, outcome.dt, outcome.reason, outcome.iterations)
                self.current_dt = outcome.dt / 2.0
                self.halvings += 1
                self._successes = 0
                continue
            if outcome.dt < h * (1.0 - 1e-12):  # halved inside _substep
                self.halvings += int(round(math.log2(h / outcome.dt)))
                self.current_dt = outcome.dt
                self._successes = 0
            self.substeps += 1
            self._account(self._sub_d_old, lam_old, self._sub_cv_old)
            self._successes += 1
            if self.current_dt < self.dt and self._successes >= self.grow_after:
                self.current_dt = min(2.0 * self.current_dt, self.dt)
                self.doublings += 1
                self._successes = 0
        self.t = t_target
        return iterations

    def _substep(self, h: float) -> SubStep:
        """Advance (t, d, v, a) by h [s] on success; leave them (and model.w) untouched otherwise."""
        raise NotImplementedError

    _state_scalars = TimeIntegrator._state_scalars + ("current_dt", "substeps", "halvings", "doublings",
                                                      "_successes")

    def _destroy_step_halving(self):
        """Free the sub-step's saved state vectors."""
        self._sub_d_old.destroy()
        self._sub_cv_old.destroy()
