"""Adaptive load stepping: halve the step on divergence, grow it again after easy steps."""
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
                    easy_iterations: int = 5, growth: float = 1.5, extrapolate: bool = True,
                    on_target: Callable[[float], None] | None = None,
                    progress: Callable[[LoadStep], None] | None = None) -> list[LoadStep]:
    """Drive the load factor of `model` from its current value through the increasing `targets`.

    Each target is reached exactly (`on_target(lambda)` is called there). A step whose Newton
    solve fails (divergence, NaN, too many iterations, or a "converged" state refused by the solver's
    guard, SolverError from NewtonSolver.solve) is undone and retried at half size; a
    step that converges within `easy_iterations` lets the next one grow by `growth`. With
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
    step = initial_step or span / 10.0
    max_step = max_step or span
    history: list[LoadStep] = []
    increment, increment_dlam = None, None  # last converged increment of the state, for the predictor
    for target in targets:
        while lam < target - 1e-14 * max(1.0, abs(target)):
            trial = min(lam + step, target)
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
                if result.iterations <= easy_iterations:
                    step = min(step * growth, max_step)
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
