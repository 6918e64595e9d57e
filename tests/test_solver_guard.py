"""The Newton solver refuses absurd "converged" states (fabricfem.solvers.newton module docstring).

The absurd states are made on purpose: a model whose tangent is 1e12 times too soft -- the tangent of a
sheet that has just lost its only support has a free rigid mode, and the Newton step along it is huge --
solved with SNES type ksponly, which takes one Newton step and reports CONVERGED_ITS whatever the step
gives (the easiest way to make SNES accept a state). A residual with a NaN entry gives a non-finite state.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.solvers.newton import DEFAULT_MAX_INCREMENT_RATIO, NewtonSolver, SolverError, convergence_order
from fabricfem.verify import references
from fabricfem.verify.cantilevers import SEED_EI, SEED_L, SEED_WIDTH, seed_cantilever

SMALL_LOAD = 0.01   # tip load P L^2 / EI: tip deflection w / L ~ lam / 3 = 3e-3 (nearly linear)
ONE_STEP = {"snes_type": "ksponly"}


class _LostSupport:
    """A model whose tangent is `scale` times the true one at load factors above `above` (the tangent of a
    sheet that lost its support: the Newton step is 1 / scale times too long), and whose residual has a NaN
    entry with `nan`."""

    def __init__(self, model, scale: float = 1e-12, above: float = -1.0, nan: bool = False):
        self.model, self.scale, self.above, self.nan = model, scale, above, nan

    def __getattr__(self, name):
        return getattr(self.__dict__["model"], name)

    def jacobian(self, x, A):
        self.model.jacobian(x, A)
        if float(self.model.load_factor.value) > self.above:
            A.scale(self.scale)

    def residual(self, x, b):
        self.model.residual(x, b)
        if self.nan and b.getLocalSize() > 0:
            b.getArray()[0] = np.nan


def _cantilever():
    """[Eischen2000] cantilever (8 elements) with the tip load SMALL_LOAD EI / L^2 per unit load factor."""
    model, _ = seed_cantilever(8)
    model.add_edge_traction("right", (0.0, 0.0, -SMALL_LOAD * SEED_EI / SEED_L ** 2 / SEED_WIDTH))
    return model


@pytest.mark.mpi
def test_absurd_increment_raises_and_restores_the_start_state():
    """One Newton step with the 1e12-times-too-soft tangent moves the tip by ~3e9 m (1e12 x 3e-3 L) on a
    ~1 m strip: SNES says CONVERGED_ITS, the solver raises SolverError ABSURD_INCREMENT, the model keeps
    its start state, on every rank alike."""
    model = _cantilever()
    solver = NewtonSolver(_LostSupport(model), ONE_STEP)
    model.set_load_factor(1.0)
    with pytest.raises(SolverError) as info:
        solver.solve()
    assert info.value.reason == "ABSURD_INCREMENT"
    message = str(info.value)
    assert "ABSURD_INCREMENT" in message and "bounding-box diagonal" in message and "CONVERGED_ITS" in message
    assert info.value.last_converged_load_factor is None   # no solve converged before
    assert np.all(model.w.x.array == 0.0)                  # the start state (flat), not the absurd one
    reasons = MPI.COMM_WORLD.allgather(info.value.reason)
    assert reasons == ["ABSURD_INCREMENT"] * MPI.COMM_WORLD.size


def test_non_finite_state_raises():
    """A NaN in the residual gives a NaN state after the one step: SolverError NON_FINITE_STATE (before the
    guard it was returned as an unconverged result only when SNES noticed; ksponly does not)."""
    model = _cantilever()
    solver = NewtonSolver(_LostSupport(model, scale=1.0, nan=True), ONE_STEP)
    model.set_load_factor(1.0)
    with pytest.raises(SolverError, match="NON_FINITE_STATE") as info:
        solver.solve()
    assert info.value.reason == "NON_FINITE_STATE"
    assert np.all(np.isfinite(model.w.x.array))


def test_residual_growth_raises():
    """A tangent 2.5 times too soft (scale 0.4): the Newton step overshoots, the error becomes -1.5 times the
    start's and so does the residual (nearly linear problem). From the flat start x1 = dx1, so with
    snes_stol 2 the step test ||dx|| < 2 ||x|| is met at the first iterate: SNES says
    CONVERGED_SNORM_RELATIVE with a residual that grew, the solver raises RESIDUAL_GREW (the check that caught
    the tablecloth's linear convergence by the step test to a state with residual 1e6 N, see the module
    docstring of fabricfem.solvers.newton)."""
    model = _cantilever()
    solver = NewtonSolver(_LostSupport(model, scale=0.4), {"snes_stol": 2.0})
    model.set_load_factor(1.0)
    with pytest.raises(SolverError, match="RESIDUAL_GREW") as info:
        solver.solve()
    assert info.value.reason == "RESIDUAL_GREW"
    assert "CONVERGED_SNORM_RELATIVE" in str(info.value)
    assert np.all(model.w.x.array == 0.0)


def test_load_stepping_cuts_refused_steps_and_reports_the_last_good_load_factor():
    """The tangent loses its support above lambda = 0.5: the first try at 1.0 is refused and cut to 0.5
    (accepted), every later try above 0.5 is refused and halved until the step is below min_step; the
    stepper then raises naming ABSURD_INCREMENT with the last good load factor 0.5 and the state there
    (the tip deflection of the elastica at lambda 0.5 x SMALL_LOAD within 1%: the state is the converged one,
    one Newton step from flat at this small load is within 0.1% of the nonlinear solution)."""
    model = _cantilever()
    solver = NewtonSolver(_LostSupport(model, above=0.5), ONE_STEP)
    with pytest.raises(SolverError, match="ABSURD_INCREMENT") as info:
        solve_load_path(model, 1.0, solver=solver, initial_step=1.0, min_step=0.1)
    assert info.value.last_converged_load_factor == 0.5
    assert "last converged load factor 0.5" in str(info.value)
    tip = -model.node_value(np.array([SEED_L, 0.0, 0.0]))[2] / SEED_L
    assert tip == pytest.approx(references.elastica_tip_load(0.5 * SMALL_LOAD)["w"], rel=1e-2)


@pytest.mark.mpi
def test_normal_solve_is_unaffected():
    """A normal Newton solve (default options) converges as before: tip deflection of the seed cantilever
    under P L^2 / EI = 0.01 against the elastica within 1% (8 quadratic elements; the same tolerance as
    tests/test_solvers.py's arc-length check), quadratic convergence order >= 1.5 on its last iterations,
    and the guard's measure (tip ~3e-3 L) is far below its limit."""
    model = _cantilever()
    solver = NewtonSolver(model)
    model.set_load_factor(1.0)
    result = solver.solve()
    assert result.converged and result.reason.startswith("CONVERGED")
    assert solver.last_converged_load_factor == 1.0
    assert solver.model_size == pytest.approx(math.hypot(SEED_L, SEED_WIDTH), rel=1e-12)
    tip = -model.node_value(np.array([SEED_L, 0.0, 0.0]))[2] / SEED_L
    assert tip == pytest.approx(references.elastica_tip_load(SMALL_LOAD)["w"], rel=1e-2)
    assert tip * SEED_L < 1e-3 * DEFAULT_MAX_INCREMENT_RATIO * solver.model_size


def test_options_reach_the_factorization_and_bad_ratio_is_refused():
    """Options read when the LU factor is set up (MUMPS ICNTL) are in the database during the solve: before,
    they were removed after setFromOptions and silently ignored (ICNTL(4) stayed 0)."""
    model = _cantilever()
    solver = NewtonSolver(model, {"mat_mumps_icntl_14": 50})
    model.set_load_factor(1.0)
    assert solver.solve().converged
    assert solver.snes.getKSP().getPC().getFactorMatrix().getMumpsIcntl(14) == 50
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="max_increment_ratio"):
            NewtonSolver(model, max_increment_ratio=bad)


def test_convergence_order():
    """Linear sequence r_k = 2^-k: order 1; quadratic r_k+1 = r_k^2: order 2."""
    assert convergence_order([1.0, 0.5, 0.25, 0.125]) == pytest.approx(1.0)
    assert convergence_order([1e-1, 1e-2, 1e-4]) == pytest.approx(2.0)
    assert math.isnan(convergence_order([1.0, 0.5]))
