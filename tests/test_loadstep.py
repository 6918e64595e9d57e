"""Load stepping: steps adapt to a target Newton iteration count, `max_step` caps every step, targets are exact."""
import numpy as np
import pytest

from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify.cantilevers import rollup, strip_model


def test_rollup_needs_fewer_steps_than_fixed_stepping():
    """Roll-up to m = 1 from a first step of 0.05: the old stepper grew a step only after <= 5 Newton
    iterations, and every roll-up step takes 9, so it took 20 equal steps (the same as max_step = 0.05,
    measured: 20). Steps that now grow towards target_iterations = 12 need fewer (measured: 14); the
    last converged load factor is exactly 1.0 and every target is hit exactly."""
    _, positions, _, history = rollup()
    fixed = rollup_steps(max_step=0.05)
    assert len(fixed) == 20
    assert len(history) < len(fixed)
    assert history[-1].load_factor == 1.0
    assert sorted(positions) == [0.25, 0.5, 0.75, 1.0]
    assert {0.25, 0.5, 0.75, 1.0} <= {s.load_factor for s in history}


def rollup_steps(**kwargs) -> list:
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 40)
    model.add_edge_moment("right", (0.0, -2.0 * np.pi * 1e7 * 1e-9 / 12.0 / 1.0, 0.0))
    return solve_load_path(model, [0.25, 0.5, 0.75, 1.0], initial_step=0.05, **kwargs)


@pytest.mark.parametrize("max_step", [0.03, 0.1])
def test_max_step_caps_every_step_including_the_first(max_step):
    """initial_step = 0.5 > max_step: no increment of the load factor, the first included, exceeds max_step;
    targets 0.1, 0.2, 0.3 (not exact binary sums) are each reached exactly."""
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 10)
    model.add_edge_traction("right", (0.0, 0.0, -1e-3))
    history = solve_load_path(model, [0.1, 0.2, 0.3], initial_step=0.5, max_step=max_step)
    lambdas = np.array([0.0] + [s.load_factor for s in history])
    assert np.all(np.diff(lambdas) <= max_step * (1 + 1e-12))
    assert lambdas[-1] == 0.3
    assert {0.1, 0.2} <= set(lambdas.tolist())


@pytest.mark.parametrize("name, kwargs", [("initial_step", {"initial_step": -0.1}),
                                          ("max_step", {"max_step": float("nan")}),
                                          ("target_iterations", {"target_iterations": 0})])
def test_bad_step_parameters_are_refused_by_name(name, kwargs):
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 2)
    with pytest.raises(ValueError, match=name):
        solve_load_path(model, 1.0, **kwargs)
