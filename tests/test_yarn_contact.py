"""Yarn-yarn contact (fabricfem.contact.yarn): projection, return mapping, bad input, MPI equality."""
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.contact.yarn import (ContactParameters, closest_point_on_triangles, project_onto_quads,
                                    symmetric_return_map)


def test_projection_above_flat_quad_closed_form():
    # unit square quad in z = 0, tensor order; points above the inside, beyond an edge, beyond a corner
    quad = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    x = np.array([[0.3, 0.6, 0.25], [1.5, 0.4, 0.2], [-0.3, -0.4, -0.1]])
    point, weights, normal, dist = project_onto_quads(x, np.broadcast_to(quad, (3, 4, 3)))
    # closed forms: foot (0.3, 0.6, 0) at height 0.25; edge x = 1 foot (1, 0.4, 0); corner (0, 0, 0)
    np.testing.assert_allclose(point, [[0.3, 0.6, 0], [1, 0.4, 0], [0, 0, 0]], atol=1e-14)
    np.testing.assert_allclose(dist, [0.25, np.hypot(0.5, 0.2), np.sqrt(0.09 + 0.16 + 0.01)], rtol=1e-14)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-14)  # interior: facet normal
    np.testing.assert_allclose(normal[1], np.array([0.5, 0, 0.2]) / np.hypot(0.5, 0.2), atol=1e-14)  # edge: along x - p
    np.testing.assert_allclose(((x - point) * normal).sum(1), dist * [1, 1, -1], rtol=1e-14)  # signed gap
    # weights reproduce the foot point and sum to one (linear shape functions)
    np.testing.assert_allclose(np.einsum("nk,kj->nj", weights, quad), point, atol=1e-14)
    np.testing.assert_allclose(weights.sum(1), 1.0, rtol=1e-14)


def test_projection_onto_cylindrical_patch_closed_form():
    # facets of a cylinder of radius R about the x axis (angles +-h/2 around the top): a point above
    # the top at height z has its foot on the chord plane z = R cos(h/2): gap = z - R cos(h/2)
    R, h = 2.0, 0.2
    a = np.array([-h / 2, h / 2])
    quad = np.array([[-1, R * np.sin(a[0]), R * np.cos(a[0])], [1, R * np.sin(a[0]), R * np.cos(a[0])],
                     [-1, R * np.sin(a[1]), R * np.cos(a[1])], [1, R * np.sin(a[1]), R * np.cos(a[1])]])
    z = np.array([2.3, 1.9])
    x = np.column_stack([np.zeros(2), np.zeros(2), z])
    point, _, normal, dist = project_onto_quads(x, np.broadcast_to(quad, (2, 4, 3)))
    gap = ((x - point) * normal).sum(1)
    np.testing.assert_allclose(gap, z - R * np.cos(h / 2), rtol=1e-13)
    np.testing.assert_allclose(np.abs(gap), dist, rtol=1e-13)


def test_closest_point_rejects_degenerate_triangle():
    a = np.zeros((1, 3))
    with pytest.raises(ValueError, match="degenerate"):
        closest_point_on_triangles(np.ones((1, 3)), a, a, a)


def test_return_map_single_node_stick_and_slip():
    eps_T, n = 1e3, np.array([0.0, 0.0, 1.0])
    P = (np.eye(3) - np.outer(n, n))[None]
    limit = np.array([2.0])
    # stick: |t*| = 1.5 <= mu lambda_N = 2, traction = trial, tangent -eps_T P
    trial = np.array([[0.9, -1.2, 0.0]])
    t, D, slip = symmetric_return_map(trial, limit, eps_T, P)
    assert not slip[0]
    np.testing.assert_allclose(t, trial)
    np.testing.assert_allclose(D[0], -eps_T * P[0])
    # slip: |t*| = 5 > 2: traction on the cone along the trial (eq. 3.75), tangent -(2 eps_T / 5)(P - tau tau)
    trial = np.array([[3.0, 4.0, 0.0]])
    t, D, slip = symmetric_return_map(trial, limit, eps_T, P)
    assert slip[0]
    np.testing.assert_allclose(t, [[1.2, 1.6, 0.0]], rtol=1e-14)
    tau = np.array([0.6, 0.8, 0.0])
    np.testing.assert_allclose(D[0], -(2.0 * eps_T / 5.0) * (P[0] - np.outer(tau, tau)), rtol=1e-14)
    # the slip tangent is the derivative of the return map (finite differences, step 1e-6 of |t*|)
    dt = np.array([1e-6, -2e-6, 0.0])
    t2, _, _ = symmetric_return_map(trial + dt, limit, eps_T, P)
    np.testing.assert_allclose((t2 - t)[0], (D[0] @ dt) / -eps_T, atol=1e-11)


@pytest.mark.parametrize("kwargs, name", [
    (dict(penalty=1e9, friction=-0.1), "friction"),
    (dict(penalty=0.0), "penalty"),
    (dict(penalty=-1.0), "penalty"),
    (dict(penalty=1e9, tangential_penalty=0.0), "tangential_penalty"),
    (dict(penalty=1e9, tolerance=-1.0), "tolerance"),
    (dict(penalty=1e9, max_augmentations=0), "max_augmentations"),
])
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ContactParameters(**kwargs)


def _pressed_cylinders(comm):
    from fabricfem.verify.yarn_contact import APPROACH, CrossedCylinders, default_penalty
    # coarse mesh, frictionless AL: enough to compare partitions
    model = CrossedCylinders(ContactParameters(penalty=default_penalty(1.0), tolerance=1e-5 * APPROACH),
                             comm=comm, core=8, ring=1, stations=8)
    rep = model.step(np.array([0.0, 0.0, -APPROACH]), 1)
    return rep


@pytest.mark.mpi
def test_mpi_equals_serial():
    """The pressed coarse cylinders give the same contact force on COMM_WORLD (2 ranks under mpirun) as
    on COMM_SELF: every rank sees the gathered surfaces, so only round-off of the parallel LU differs
    (tolerance 1e-8 relative, far above round-off, far below any physical effect)."""
    world = _pressed_cylinders(MPI.COMM_WORLD)
    serial = _pressed_cylinders(MPI.COMM_SELF)
    np.testing.assert_allclose(world.force, serial.force, rtol=1e-8, atol=1e-8 * abs(serial.force[2]))
    assert world.active == serial.active
    assert world.augmentations == serial.augmentations


def test_case_yarn_contact_patch():
    """The verification case (Hertz force, AL penetration, penalty -> AL, Coulomb stick/slip)."""
    from fabricfem.verify.yarn_contact import yarn_contact_patch
    results = yarn_contact_patch()
    failed = [r for r in results if not r.passed]
    assert not failed, failed


# ------------------------------------------------------------------ crushed elements (issue 5)
def _ti_cell_without_contact():
    from fabricfem.materials_yarn import THESIS_TRANSVERSELY_ISOTROPIC
    from fabricfem.meshes.unit_cell import unit_cell
    from fabricfem.meshes.yarn_geometry import PlainWeave
    from fabricfem.unit_cell_contact import ContactUnitCell
    cell = unit_cell(PlainWeave.balanced(), "quarter", "coarse", MPI.COMM_SELF)
    return ContactUnitCell(cell, THESIS_TRANSVERSELY_ISOTROPIC, contact=None)


def test_deformation_check_homogeneous_and_inverted_closed_form():
    """det F at the Gauss points for homogeneous deformations, where it is known exactly: u* = 0 under
    Phi = diag(1.1, 0.9, 1.2) gives det F = 1.188 everywhere; u* = G X with G = diag(0, 0, -2) under
    Phi = 1 gives F = diag(1, 1, -1), an inverted (mirrored) state with det F = -1, which the
    energy (J = sqrt(det C) = 1) cannot see. Tolerance 1e-12: affine fields are interpolated exactly
    by trilinear hexahedra, only round-off remains."""
    model = _ti_cell_without_contact()
    check, problem = model.deformation, model.problem
    problem.Phi.value[:] = np.diag([1.1, 0.9, 1.2])
    assert check.minimum() == pytest.approx(1.188, abs=1e-12)
    assert np.allclose(check.local(), 1.188, atol=1e-12)
    problem.Phi.value[:] = np.eye(3)
    problem.u.interpolate(lambda x: np.vstack([0.0 * x[0], 0.0 * x[1], -2.0 * x[2]]))
    assert check.minimum() == pytest.approx(-1.0, abs=1e-12)
    det, where = check.worst()
    assert det == pytest.approx(-1.0, abs=1e-12) and where.shape == (3,)


class _ScalarNewton:
    """Stand-in for MPCNewtonSolver on one scalar unknown x (a PETSc Vec of size 1): the Newton update
    is x <- x - s du with du = -1 (the full step moves x from 0 to 1), the residual |R| = |1 - x| decreases
    along the step; det F = 1 - 1.5 x (the full step would invert, det = -0.5)."""

    def __init__(self):
        self.u = type("U", (), {})()
        self.u.vector = PETSc.Vec().createSeq(1)
        self.u.vector.set(0.0)

    def _update(self, step):
        self.u.vector.array[0] += step

    def assemble_residual(self):
        r = PETSc.Vec().createSeq(1)
        r.set(1.0 - self.u.vector.array[0])
        return r


class _ScalarCheck:
    def __init__(self, newton):
        self.newton = newton

    def minimum(self):
        return 1.0 - 1.5 * self.newton.u.vector.array[0]


def test_admissible_backtrack_rejects_inverting_and_crushing_steps():
    """The line search keeps the largest step 2^-k with det F > ADMISSIBLE_DET_RATIO x det F(start):
    with det F = 1 - 1.5 s (start 1) and ratio 0.5 that is s < 1/3, so s = 1/4 (closed form); the full
    step (det F = -0.5, inverted) and s = 1/2 (det F = 0.25, crushed by 75% in one iteration) are rejected."""
    from fabricfem.solvers.mpc_newton import backtrack
    from fabricfem.unit_cell_contact import ADMISSIBLE_DET_RATIO, crush_guard
    assert ADMISSIBLE_DET_RATIO == 0.5  # the closed form above assumes it
    newton = _ScalarNewton()
    backtrack(newton, rnorm=1.0, admissible_step=lambda: crush_guard(_ScalarCheck(newton)))
    assert newton.u.vector.array[0] == 0.25


def _refusing(model, largest: float, ceiling: float = np.inf):
    """Wrap the model's Newton solve so that it fails (as a real divergence would) whenever the load
    increment from the last converged Phi exceeds `largest` (max |Phi_ij - Phi_ij,converged|) or
    Phi_11 exceeds `ceiling`."""
    from fabricfem.solvers.newton import NewtonResult
    newton, problem = model.problem.newton, model.problem
    real = newton.solve

    def solve(force_scale, length_scale):
        if np.abs(problem.Phi.value - model.Phi).max() > largest or problem.Phi.value[0, 0] > ceiling:
            return NewtonResult(False, 25, "DIVERGED_MAX_IT", [1.0])
        return real(force_scale, length_scale)
    newton.solve = solve


def test_step_cutting_triggers_and_recovers():
    """A load step Phi11 = Phi22: 1 -> 1.02 whose solver only converges for increments <= 0.006: the
    controller halves 0.02 -> 0.01 -> 0.005 (converges), doubles back to 0.01 (fails), halves, ...:
    exactly 4 sub-increments of 0.005 (counted by hand from the halve/double rule). The end state must
    be the equilibrium that a direct single step reaches (hyperelasticity without contact is path
    independent): S within 1e-4 relative (both solves stop at |R| <= 1e-5 of the force scale; S is
    a volume average of the stresses, whose error is of that order, 10x margin)."""
    target = np.diag([1.02, 1.02, 1.0])
    direct = _ti_cell_without_contact()
    S_direct = direct.solve(target, 1)[-1].S
    model = _ti_cell_without_contact()
    _refusing(model, 0.006)
    step = model.solve(target, 1)[-1]
    assert step.sub_increments == 4
    assert len(step.newton_iterations) == 4
    assert np.linalg.norm(step.S - S_direct) <= 1e-4 * np.linalg.norm(S_direct)
    assert np.array_equal(model.Phi, target)


def test_step_cutting_gives_up_with_clear_error():
    """A solver that never converges: after MAX_CUTS halvings the SolverError names the load step, the
    failed and last converged Phi and the most crushed element (det F and position), never NaN;
    the state stays the last converged one (Phi = 1, u* = 0)."""
    from fabricfem.solvers.newton import SolverError
    from fabricfem.unit_cell_contact import MAX_CUTS
    model = _ti_cell_without_contact()
    _refusing(model, 0.0)
    with pytest.raises(SolverError, match=rf"load step 1\) after {MAX_CUTS} cuts.*smallest det F there 1 in the "
                                          r"element at X = \["):
        model.solve(np.diag([1.02, 1.02, 1.0]), 1)
    assert np.array_equal(model.Phi, np.eye(3))
    assert np.abs(model.problem.u.x.array).max() == 0.0
    assert model.steps == []


def test_step_cutting_keeps_furthest_converged_state():
    """Increments <= 0.006 converge, but nothing beyond Phi11 = 1.012: following the halve/double rule
    by hand (0.005 -> 1.005, 1.01; 0.00125 -> 1.01125; 0.000625 = 0.02 / 2^MAX_CUTS -> 1.011875; then
    every trial fails down to the smallest cut) the step stops with a SolverError and the furthest
    converged state, Phi11 = 1.011875 after 4 sub-increments, is kept as the last step. Its S must be
    the equilibrium of a direct solve at that Phi (path independence without contact; 1e-4 relative
    as in test_step_cutting_triggers_and_recovers)."""
    from fabricfem.solvers.newton import SolverError
    from fabricfem.unit_cell_contact import MAX_CUTS
    assert MAX_CUTS == 5  # the hand count above assumes it
    model = _ti_cell_without_contact()
    _refusing(model, 0.006, ceiling=1.012)
    with pytest.raises(SolverError, match="load step 1"):
        model.solve(np.diag([1.02, 1.02, 1.0]), 1)
    reached = np.diag([1.011875, 1.011875, 1.0])
    assert len(model.steps) == 1
    last = model.steps[-1]
    np.testing.assert_allclose(last.Phi, reached, rtol=0, atol=1e-14)
    np.testing.assert_allclose(model.Phi, reached, rtol=0, atol=1e-14)
    assert last.sub_increments == 4
    S_direct = _ti_cell_without_contact().solve(reached, 1)[-1].S
    assert np.linalg.norm(last.S - S_direct) <= 1e-4 * np.linalg.norm(S_direct)
