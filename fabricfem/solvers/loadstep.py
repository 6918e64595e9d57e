"""Adaptive load stepping: halve the step on divergence, scale it towards a target Newton iteration count."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from fabricfem.solvers.newton import NewtonResult, NewtonSolver, SolverError


@dataclass
class LoadStep:
    load_factor: float
    iterations: int
    residual_norms: list[float]


def solve_load_path(model, targets: Sequence[float] | float, solver: NewtonSolver | None = None,
                    initial_step: float | None = None, min_step: float = 1e-6, max_step: float | None = None,
                    target_iterations: int = 12, growth: float = 1.5, extrapolate: bool = True,
                    on_target: Callable[[float], None] | None = None,
                    progress: Callable[[LoadStep], None] | None = None) -> list[LoadStep]:
    """Drive the load factor of `model` from its current value through the increasing `targets`.

    Each target is reached exactly (`on_target(lambda)` is called there). A step whose Newton
    solve fails (divergence, NaN, too many iterations, or a "converged" state refused by the solver's
    guard, SolverError from NewtonSolver.solve) is undone and retried at half size. After a step that
    converged in n Newton iterations the next step is scaled by target_iterations / n, clipped to
    [1/2, growth]: it grows when Newton needed fewer than `target_iterations`, shrinks when it needed
    more. Every step, the first (`initial_step`, default span / 10) included, is capped by `max_step`
    (default: the whole span). The way to each target is cut into equal steps no longer than the
    current step, the last of which ends exactly on the target (the load factor there is the target
    itself, not a sum of increments). With
    `extrapolate`, each step starts from the secant predictor through the last two converged states
    (increments are measured before the director is re-based, so they stay valid after it). When the
    step falls below `min_step` a SolverError is raised carrying the last converged load factor
    and the model is left in that last converged state.
    """
    targets = [float(t) for t in np.atleast_1d(targets)]
    if any(b <= a for a, b in zip(targets, targets[1:])):
        raise ValueError(f"targets must increase strictly, got {targets}")
    solver = solver or NewtonSolver(model)
    lam = float(model.load_factor.value)
    span = targets[-1] - lam
    if span <= 0:
        raise ValueError(f"targets must exceed the current load factor {lam}")
    for name, value in (("initial_step", initial_step), ("max_step", max_step)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if not (isinstance(target_iterations, (int, np.integer)) and target_iterations >= 1):
        raise ValueError(f"target_iterations must be an integer >= 1, got {target_iterations!r}")
    max_step = max_step or span
    step = min(initial_step or span / 10.0, max_step)
    history: list[LoadStep] = []
    increment, increment_dlam = None, None  # last converged increment of the state, for the predictor
    for target in targets:
        while lam < target:
            # equal steps of at most `step` to the target (no sliver before it); the last one lands on it
            n_left = max(1, int(np.ceil((target - lam) / step - 1e-9)))
            trial = target if n_left == 1 else lam + (target - lam) / n_left
            saved = model.w.x.array.copy()
            if extrapolate and increment is not None:
                # Secant predictor: w = w_n + (dlambda / dlambda_prev) (w_n - w_{n-1})
                model.w.x.array[:] += (trial - lam) / increment_dlam * increment
            model.set_load_factor(trial)
            try:
                result = solver.solve()
            except SolverError as refused:   # an absurd "converged" state: a failure like any other
                result = NewtonResult(False, solver.snes.getIterationNumber() if hasattr(solver, "snes") else 0,
                                      refused.reason or str(refused))
            if result.converged:
                increment, increment_dlam = model.w.x.array - saved, trial - lam
                lam = trial
                model.after_converged_step()
                record = LoadStep(lam, result.iterations, result.residual_norms)
                history.append(record)
                if progress:
                    progress(record)
                scale = min(max(target_iterations / max(result.iterations, 1), 0.5), growth)
                step = min(step * scale, max_step)
                continue
            model.w.x.array[:] = saved
            model.set_load_factor(lam)
            step *= 0.5
            if step < min_step:
                raise SolverError(
                    f"load stepping failed at load factor {trial:.6g}: Newton {result.reason} after "
                    f"{result.iterations} iterations and the step fell below {min_step:g}; "
                    f"last converged load factor {lam:.6g} (state restored to it)",
                    last_converged_load_factor=lam, reason=result.reason)
        if on_target:
            on_target(lam)
    return history
