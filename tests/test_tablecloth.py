"""Tablecloth drape helpers [Eischen2000, sec. 4.4]: reading admissibility, hem fold count, flatness imperfection
and the backward-Euler drop step of fabricfem.verify.drape (the cases themselves are run by test_verify)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.dynamics.backward_euler import BackwardEulerInertia
from fabricfem.dynamics.mass import lumped_mass
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.solvers.system import CompositeSystem
from fabricfem.verify.drape import (
    CLOTH_L,
    CLOTH_WEIGHT,
    STANDARD_GRAVITY,
    TABLE_HALF,
    reading_admissibility,
    shortest_path_over_table,
    tablecloth_problem,
)
from fabricfem.verify.particles_cases import (
    CLOTH_H,
    IMPERFECTION_AMPLITUDE,
    TABLECLOTH_EXPERIMENT,
    flatness_imperfection,
    hem_folds,
)


def test_shortest_path_closed_forms():
    """Points where the shortest path over the table is known in closed form (lengths / L): on the table plane
    beyond an edge midpoint (straight, 0.5); on the face x = a at depth d and lateral offset y, the path over
    the top and down the face unfolds into a straight line, sqrt((a + d)^2 + y^2): below the edge midpoint
    (y = 0: a + d) and below the table corner (y = a). Sampling error of the edge crossing: the length is
    stationary there, so an offset of 1e-4 L (the sampling step) changes it by ~1e-8 L; 1e-7."""
    a = TABLE_HALF / CLOTH_L
    assert shortest_path_over_table((0.5, 0.0, 0.0)) == pytest.approx(0.5, abs=1e-12)
    assert shortest_path_over_table((a, 0.0, -0.3)) == pytest.approx(a + 0.3, abs=1e-12)
    assert shortest_path_over_table((a, a, -0.3)) == pytest.approx(math.hypot(a + 0.3, a), abs=1e-7)


def test_reading_admissibility_of_the_experiment_row():
    """Drop reading: the corner (0.39, 0.39) L with 0.38 L below the top lies sqrt(2 x 0.19^2 + 0.38^2) =
    0.465 L from the table corner, more than the 0.424 L of cloth there: the path from the centre is longer
    than the half-diagonal (strain > 0, measured 0.042). Floor reading: slack for both nodes. Bounds from
    the table-corner path: strain <= (sqrt(2) 0.2 + 0.465) / (sqrt(2) / 2) - 1 = 0.058 (an upper bound of
    the shortest path) and the straight line from the centre, 0.65 L in the drop reading, as a lower one."""
    adm = reading_admissibility(TABLECLOTH_EXPERIMENT)
    through_corner = (math.sqrt(2) * 0.2 + math.sqrt(2 * 0.19 ** 2 + 0.38 ** 2)) / math.sqrt(0.5) - 1.0
    straight = math.sqrt(2 * 0.39 ** 2 + 0.38 ** 2) / math.sqrt(0.5) - 1.0
    assert straight < adm["drop"]["corner"] <= through_corner + 1e-12
    assert adm["drop"]["corner"] > 0.0
    assert adm["floor"]["corner"] < 0.0 and adm["floor"]["midside"] < 0.0


def test_hem_folds():
    """Synthetic hems: n cos(k theta) has k minima; noise below the tolerance adds none; a flat hem has 0."""
    theta = np.linspace(0.0, 2 * np.pi, 80, endpoint=False)
    for k in (1, 4, 6):
        assert hem_folds(np.cos(k * theta), 0.1) == k
    noisy = np.cos(4 * theta) + 1e-4 * np.random.default_rng(0).standard_normal(80)
    assert hem_folds(noisy, 1e-2) == 4
    assert hem_folds(np.zeros(12), 1e-6) == 0
    with pytest.raises(ValueError, match="height"):
        hem_folds(np.array([0.0, np.nan, 1.0]), 0.1)


def test_flatness_imperfection_range_and_determinism():
    """Heights in [0, h / 2] (the stated amplitude), reaching both ends on the cloth, identical on every call."""
    g = np.linspace(-0.5 * CLOTH_L, 0.5 * CLOTH_L, 201)
    X, Y = np.meshgrid(g, g)
    z = flatness_imperfection(X, Y)
    assert IMPERFECTION_AMPLITUDE == pytest.approx(0.5 * CLOTH_H)
    assert z.min() >= 0.0 and z.max() <= IMPERFECTION_AMPLITUDE
    assert z.max() > 0.9 * IMPERFECTION_AMPLITUDE and z.min() < 0.1 * IMPERFECTION_AMPLITUDE
    np.testing.assert_array_equal(z, flatness_imperfection(X, Y))


@pytest.mark.mpi
def test_backward_euler_step_free_fall():
    """The drop step on a sheet that does not touch the table (lifted 1 m above it): a rigid fall, whose
    backward-Euler recurrence is exact in closed form: v_{k+1} = (v_k - g dt) / (1 + c dt),
    z_{k+1} = z_k + dt v_{k+1} (uniform lumped mass and weight: every node falls alike). Newton tolerance
    1e-10 relative: 1e-8 on the displacement."""
    rho_area = CLOTH_WEIGHT / STANDARD_GRAVITY
    problem, _ = tablecloth_problem(5, 0.0, density=rho_area / CLOTH_H, comm=MPI.COMM_WORLD)
    problem.system.compile()
    problem.system.set_load_factor(1.0)
    problem.model.w.x.array[:] = 0.0
    uz = np.asarray(problem.model.W.sub(0).sub(2).collapse()[1])
    problem.model.w.x.array[uz] = 1.0        # 1 m above the table: no contact
    c, dt = 1.5, 0.01
    step = BackwardEulerInertia(problem.model, lumped_mass(problem.model), c, dt)
    system = CompositeSystem(problem.model, [problem, step])
    solver = NewtonSolver(system, {"snes_max_it": 20})
    z, v = 1.0, 0.0
    for _ in range(5):
        assert solver.solve().converged
        system.after_converged_step()
        v = (v - STANDARD_GRAVITY * dt) / (1.0 + c * dt)
        z += dt * v
    corner = problem.node_value((0.1, 0.1, 0.0))
    assert corner[2] == pytest.approx(z, abs=1e-8)
    assert abs(corner[0]) < 1e-8 and abs(corner[1]) < 1e-8
    solver.destroy()
    step.destroy()
