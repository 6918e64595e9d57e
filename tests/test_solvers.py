"""Newton (quadratic convergence), load stepping failure handling and arc-length continuation."""
import numpy as np
import pytest

from fabricfem.solvers.arclength import acceleration_factor, arc_length
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.verify import references
from fabricfem.verify.cantilevers import SEED_EI, SEED_L, SEED_WIDTH, seed_cantilever
from fabricfem.verify.plates import NU, SIDE, THICKNESS, E, quarter_plate


def test_newton_converges_quadratically():
    """Clamped plate at large deflection (w/t ~ 1, membrane stiffening): on the step from lambda = 1 to 1.5
    the residual falls by at least two orders per iteration once it is below 10% of its start and above
    the round-off floor (Newton's quadratic convergence with the exact UFL Jacobian), and
    r_{k+1} <= C r_k^2 with C < 1 for those steps."""
    model = quarter_plate(8)
    D = references.plate_rigidity(E, NU, THICKNESS)
    model.add_pressure(-THICKNESS * D / (references.CLAMPED_PLATE_UNIFORM * SIDE ** 4))
    solver = NewtonSolver(model)
    model.set_load_factor(1.0)
    assert solver.solve().converged
    model.set_load_factor(1.5)
    result = solver.solve()
    assert result.converged and result.iterations <= 6
    r = np.array(result.residual_norms)
    floor = 1e-10 * model.F_ref.norm() * 10
    near = [k for k in range(len(r) - 1) if r[k] < 0.1 * r[0] and r[k] > floor]
    assert len(near) >= 2, f"no iteration in the asymptotic range: {r}"
    for k in near:
        assert r[k + 1] < 1e-2 * r[k], f"iteration {k}: {r[k]:.2e} -> {r[k + 1]:.2e}"
    C = [r[k + 1] / r[k] ** 2 for k in near]
    assert max(C) < 1.0, C


def test_load_stepping_failure_reports_last_converged_state():
    """With a Newton limited to 1 iteration no step can converge: the stepper halves down to min_step,
    restores the last converged state (zero) and raises SolverError carrying load factor 0; no NaN."""
    model, _ = seed_cantilever(8)
    model.add_edge_traction("right", (0.0, 0.0, -10 * SEED_EI / SEED_L ** 2 / SEED_WIDTH))
    solver = NewtonSolver(model, {"snes_max_it": 1})
    with pytest.raises(SolverError) as info:
        solve_load_path(model, 1.0, solver=solver, initial_step=1.0, min_step=0.1)
    assert info.value.last_converged_load_factor == 0.0
    assert "last converged load factor 0" in str(info.value)
    assert np.all(np.isfinite(model.w.x.array)) and np.allclose(model.w.x.array, 0.0)


def test_load_stepping_retries_with_smaller_steps():
    """A step too large for a 6-iteration Newton is halved and the path still reaches its target."""
    model, _ = seed_cantilever(8)
    model.add_edge_traction("right", (0.0, 0.0, -SEED_EI / SEED_L ** 2 / SEED_WIDTH))
    solver = NewtonSolver(model, {"snes_max_it": 6})
    history = solve_load_path(model, 5.0, solver=solver, initial_step=5.0)
    assert history[-1].load_factor == pytest.approx(5.0)
    assert history[0].load_factor < 5.0  # the first try was cut


def test_acceleration_factor_eq20():
    assert acceleration_factor(1, 5, 10) == 1.0
    assert acceleration_factor(2, 5, 10) == pytest.approx(0.5)
    assert acceleration_factor(3, 6, 3) == pytest.approx(2.0)


def test_arc_length_follows_elastica():
    """Arc-length continuation of the [Eischen2000] tip-loaded cantilever: every converged point (lambda_k, w_k)
    lies on the elastica (scipy ODE) within 1%, the path reaches lambda = 10, and each step satisfies the
    constraint of eq. 19."""
    model, _ = seed_cantilever(12)
    model.add_edge_traction("right", (0.0, 0.0, -SEED_EI / SEED_L ** 2 / SEED_WIDTH))
    tip = np.array([SEED_L, 0.0, 0.0])
    points = []
    history = arc_length(model, ds=0.5, max_steps=80, lambda_max=10.0, target_iterations=4,
                         on_step=lambda s: points.append((s.load_factor, -model.node_value(tip)[2] / SEED_L)))
    assert points[-1][0] >= 10.0
    assert len(points) >= 5
    for lam, w in points:
        assert w == pytest.approx(references.elastica_tip_load(lam)["w"], rel=1e-2), lam
    lengths = [h.arc_length for h in history]
    assert len(set(np.round(lengths, 12))) > 1  # the arc length adapts (eq. 20)


def test_many_solvers_do_not_fill_the_petsc_options_table():
    """Each solver has its own options prefix; the options are removed once applied, so creating
    hundreds of solvers in one process (a study, the test suite) never exhausts PETSc's table
    (PETSc error 55). The options still take effect: snes_max_it = 3 is what SNES reports."""
    from petsc4py import PETSc
    model, _ = seed_cantilever(4)
    before = len(PETSc.Options().getAll())
    for _ in range(600):
        NewtonSolver(model, {"snes_max_it": 3}).destroy()
    solver = NewtonSolver(model, {"snes_max_it": 3})
    assert solver.snes.getTolerances()[3] == 3
    assert len(PETSc.Options().getAll()) == before
