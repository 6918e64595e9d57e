"""Yarn-yarn contact (fabricfem.contact.yarn): projection, return mapping, bad input, MPI equality."""
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.contact.yarn import (
    ContactParameters,
    closest_point_on_triangles,
    project_onto_quads,
    symmetric_return_map,
)


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


# ------------------------------------------------------------------ crushed elements
def _ti_cell_without_contact():
    from fabricfem.materials.yarn import THESIS_TRANSVERSELY_ISOTROPIC
    from fabricfem.meshes.unit_cell import unit_cell
    from fabricfem.meshes.yarn_geometry import PlainWeave
    from fabricfem.weave.unit_cell import ContactUnitCell
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

    def update(self, step):
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
    from fabricfem.weave.unit_cell import ADMISSIBLE_DET_RATIO, crush_guard
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
    from fabricfem.weave.unit_cell import MAX_CUTS
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
    from fabricfem.weave.unit_cell import MAX_CUTS
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


# ------------------------------------------------------------------ fixed facet sets (active-set strategy)
def test_triangle_plane_projection_extrapolates_closed_form():
    """project_onto_triangle_planes: the orthogonal projection onto the plane of the fixed triangle with
    unclamped linear shape functions. Unit square quad in z = 0 (tensor order): a point above (1.1, 0.3)
    lies beyond triangle 0 = (v0, v1, v3) (the edge x = 1): foot (1.1, 0.3, 0), distance |z|, and the
    triangle's linear shape functions 1 - x, x - y, y extrapolated (weight of v0 = -0.1 < 0)."""
    from fabricfem.contact.yarn import project_onto_triangle_planes, triangle_of
    quad = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    x = np.array([[1.1, 0.3, -0.2]])
    point, weights, dist = project_onto_triangle_planes(x, quad[None], np.array([0]))
    np.testing.assert_allclose(point, [[1.1, 0.3, 0.0]], atol=1e-14)
    np.testing.assert_allclose(dist, [0.2], rtol=1e-14)
    np.testing.assert_allclose(weights, [[1 - 1.1, 1.1 - 0.3, 0.0, 0.3]], atol=1e-14)  # v0, v1, v2, v3
    # triangle_of reads the triangle back from closest-point weights (v2 carries none on triangle 0)
    assert triangle_of(np.array([[0.2, 0.5, 0.0, 0.3], [0.2, 0.0, 0.5, 0.3]])).tolist() == [0, 1]


def test_fixed_facet_foot_point_is_continuous_where_the_closest_point_jumps():
    """Why the facets are fixed: a roof of two quads meeting at the ridge y = 0 (slopes +-theta, outward
    normal up), a slave point penetrated by depth d below the ridge, moved across the ridge's bisector
    plane y = 0 by +-e. Closest-point projection (project_onto_quads): the foot point jumps from one roof
    face to the other, by 2 d sin(theta) cos(theta) in y (closed form: the foot of (y, -d) on the face
    z = -tan(theta) |y| is at y_f = (y - d tan(theta)) cos^2(theta) for y > 0). Fixed facet (the plane
    of one face): the foot point moves by exactly 2 e cos^2(theta) (linear in the point): continuous."""
    from fabricfem.contact.yarn import project_onto_quads, project_onto_triangle_planes
    theta, d, e = 0.3, 0.05, 1e-6
    t = np.tan(theta)
    right = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, -t], [1.0, 1.0, -t]])   # y >= 0 face
    left = np.array([[0.0, -1.0, -t], [1.0, -1.0, -t], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])   # y <= 0 face
    pts = np.array([[0.5, e, -d], [0.5, -e, -d]])
    feet = []
    for x in pts:
        pr, _, _, dr = project_onto_quads(x[None], right[None])
        pl, _, _, dl = project_onto_quads(x[None], left[None])
        feet.append(pr[0] if dr[0] <= dl[0] else pl[0])
    jump = feet[0][1] - feet[1][1]
    # foot y of the right face for y = e: (e + d tan) cos^2 (the point lies below the face: -d < -t e)
    np.testing.assert_allclose(feet[0][1], (e + d * t) * np.cos(theta) ** 2, rtol=1e-9)
    np.testing.assert_allclose(jump, 2 * (e + d * t) * np.cos(theta) ** 2, rtol=1e-9)   # ~ 2 d sin cos: a jump
    fixed = [project_onto_triangle_planes(x[None], right[None], np.array([0]))[0][0] for x in pts]
    np.testing.assert_allclose(fixed[0][1] - fixed[1][1], 2 * e * np.cos(theta) ** 2, rtol=1e-6)  # continuous


def _cylinders_with_friction(rtol: float):
    from fabricfem.verify.yarn_contact import RADIUS, CrossedCylinders, default_penalty
    params = ContactParameters(penalty=default_penalty(1.0), friction=0.3, tolerance=1e-5 * RADIUS,
                               max_augmentations=20, consistent_tangent=True)
    model = CrossedCylinders(params, comm=MPI.COMM_SELF, core=8, ring=1, stations=8)
    model.newton.rtol = rtol
    return model


def test_fixed_sets_reach_a_consistent_equilibrium_on_crossed_cylinders():
    """solve_with_fixed_sets on the coarse crossed cylinders (mu = 0.3), pressed by d and pulled by 0.2 d
    (partial slip), Newton tolerance 1e-9 of the force scale. Every accepted solve (each augmentation)
    must (1) have |R| below that tolerance for its accepted law (the fixed facet set, or the unfixed law
    after the polishing solve), (2) obey Coulomb at every active
    node (stick: t_T = t*, |t*| <= mu lambda_N; slip: |t_T| = mu lambda_N), (3) have every foot point
    closest within the penetration tolerance; and the final contact force must be (4) that of plain
    Newton on the unfixed law (solve_with_contact alone, an independent path) within 1.5e-3 relative: both
    stop their augmentations once the penetration is below 1e-5 R = 1e-3 d, and F ~ d^1.5 (Hertz) is
    fixed by that only to 1.5e-3 (the friction history through the augmentations differs by as much)."""
    from fabricfem.contact.yarn import solve_with_contact, solve_with_fixed_sets
    from fabricfem.verify.yarn_contact import APPROACH
    forces, checked = {}, []
    for mode in ("plain", "fixed"):
        m = _cylinders_with_friction(1e-9)
        c, newton, fs = m.contact, m.newton, m.force_scale
        tol = newton.rtol * fs

        def accept() -> bool:
            return newton.assemble_residual().norm() <= tol

        def fixed_sets_checked():
            result = solve_with_fixed_sets(lambda: newton.solve(fs, m.R), c, accept)
            assert result.converged, result
            facet, tri, why = c.accepted_sets
            if why == "set unchanged":  # the fixed-set law; otherwise the unfixed law was accepted
                c.freeze(facet, tri)
            norm = newton.assemble_residual().norm()
            st = c.state
            c.unfreeze()
            free = c.evaluate()
            act = st["active"]
            limit = c.params.friction * c.lam_N[act]
            t_T, trial, slip = st["traction"][act], st["trial"][act], st["slip"][act]
            size = np.linalg.norm(t_T, axis=1)
            assert norm <= tol                                                                 # (1)
            assert np.all(size <= limit * (1 + 1e-12))                                           # (2)
            assert np.all(np.linalg.norm(trial[~slip], axis=1) <= limit[~slip] * (1 + 1e-12))
            np.testing.assert_allclose(t_T[~slip], trial[~slip], rtol=1e-12, atol=0)
            np.testing.assert_allclose(size[slip], limit[slip], rtol=1e-12)
            assert np.all(st["dist"][act] <= free["dist"][act] + c.params.tolerance)            # (3)
            checked.append((int(slip.sum()), int(act.sum()), why))
            return result
        for k, dx in enumerate((0.0, 0.2), start=1):
            m.motion.value[:] = [dx * APPROACH, 0.0, -APPROACH]
            solve = (lambda: newton.solve(fs, m.R)) if mode == "plain" else fixed_sets_checked
            rep = solve_with_contact(solve, c, k)
        forces[mode] = rep.force
    print("accepted solves (slipping, active):", checked)
    assert any(0 < n < a for n, a, _ in checked)  # partial slip: both branches present in an accepted state
    assert np.linalg.norm(forces["fixed"] - forces["plain"]) <= 1.5e-3 * np.linalg.norm(forces["plain"])  # (4)


def test_friction_tangent_is_consistent_on_sliding_cylinders():
    """The finite-difference friction tangent (YarnContact._tangential_tangent, with the normal one) is the
    derivative of the contact forces: at the pressed coarse cylinders with every active node sliding
    (mu = 0.3, tangential multipliers set beyond the cone), the
    directional difference quotient of the contact residual along a random perturbation v of the
    contact stencil dofs must match K v with an error that shrinks linearly with the step (O(h): a
    consistent tangent; measured 6.6e-3 -> 6.4e-4). With the closed-form friction part (no rotation of
    P(n)) the error stalls instead (measured 6.8e-3 -> 1.8e-3 relative to K v): this test fails on it."""
    from petsc4py import PETSc as P

    from fabricfem.contact.yarn import solve_with_contact
    from fabricfem.verify.yarn_contact import APPROACH
    m = _cylinders_with_friction(1e-8)
    c, newton, fs = m.contact, m.newton, m.force_scale
    m.motion.value[:] = [0.0, 0.0, -APPROACH]
    solve_with_contact(lambda: newton.solve(fs, m.R), c, 1)
    # a sliding state: tangential multipliers twice the cone along x (the law at fixed multipliers, Box 7)
    c.lam_T = np.outer(2.0 * c.params.friction * c.lam_N, [1.0, 0.0, 0.0])
    st = c.evaluate()
    act = np.flatnonzero(st["active"])
    assert len(act) and st["slip"][act].all()
    b = newton.b.duplicate()

    def contact_residual():
        b.set(0.0)
        c.add_residual(newton.u.vector, b)
        return b.copy()
    C0 = contact_residual()
    A = newton.A.duplicate()
    A.zeroEntries()
    c.add_jacobian(newton.u.vector, A)
    dofs = c._dofs(np.column_stack([c.slave[act], st["cur_quads"][act], st["ref_quads"][act]])).ravel()
    dofs = np.unique(dofs[dofs >= 0])
    v = b.duplicate()
    arr = np.zeros(v.getLocalSize())
    arr[dofs] = np.random.default_rng(1).standard_normal(len(dofs)) * 1e-3 * APPROACH
    v.setArray(arr)
    Kv = b.duplicate()
    A.mult(v, Kv)
    x0 = newton.u.vector.copy()
    errors = []
    for h in (1.0, 0.1):
        newton.u.vector.axpy(h, v)
        newton.u.vector.ghostUpdate(addv=P.InsertMode.INSERT, mode=P.ScatterMode.FORWARD)
        diff = contact_residual()
        diff.axpy(-1.0, C0)
        diff.scale(1.0 / h)
        diff.axpy(-1.0, Kv)   # (R(u + h v) - R(u)) / h - K v
        errors.append(diff.norm() / Kv.norm())
        x0.copy(newton.u.vector)
        newton.u.vector.ghostUpdate(addv=P.InsertMode.INSERT, mode=P.ScatterMode.FORWARD)
    # O(h): the error drops ~10x with h (5x allows for round-off in the differences), and is small
    assert errors[1] < errors[0] / 5.0 and errors[1] < 1e-3, errors


class _ScriptedUzawa:
    """A contact whose Uzawa map diverges (violation x1.1 per update) while eps_N is below 10 x its start and
    contracts (x0.3) above: the pattern measured on the crushed TI crossing (solve_with_contact docstring)."""

    def __init__(self, growth: float):
        self.params = ContactParameters(penalty=1.0, tolerance=1e-3, max_augmentations=30, penalty_growth=growth)
        self.violation_now, self.dropped_active, self.penalties = 1e-2, 0, []

    def violation(self):
        return self.violation_now, 0.5 * self.violation_now

    def augment(self):
        self.penalties.append(self.params.penalty)
        self.violation_now *= 1.1 if self.params.penalty < 10.0 else 0.3

    def totals(self):
        return np.zeros(3), 0.0, 0.0, 0, 0

    def commit(self):
        pass


def test_uzawa_penalty_grows_after_two_growing_violations():
    """Violations 1e-2, 1.1e-2, 1.21e-2 (grown twice): eps_N x10 before the third update, then 3.63e-3,
    1.09e-3, 3.27e-4 <= 1e-3: converged after 5 augmentations with one growth; without growth
    (penalty_growth = 1) the same contact never converges and SolverError names the augmentations."""
    from fabricfem.contact.yarn import solve_with_contact
    from fabricfem.solvers.newton import NewtonResult, SolverError
    newton = lambda: NewtonResult(True, 1, "converged", [])   # noqa: E731
    growing = _ScriptedUzawa(10.0)
    report = solve_with_contact(newton, growing)
    assert growing.penalties == [1.0, 1.0, 10.0, 10.0, 10.0]
    assert report.augmentations == 5 and report.penalty_growths == 1
    assert report.max_penetration == pytest.approx(1e-2 * 1.21 * 0.3 ** 3, rel=1e-12)
    with pytest.raises(SolverError, match="after 30 augmentations"):
        solve_with_contact(newton, _ScriptedUzawa(1.0))
    with pytest.raises(ValueError, match="penalty_growth"):
        ContactParameters(penalty=1.0, penalty_growth=0.5)
