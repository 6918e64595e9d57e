"""Contact layer: friction return mapping, nodal contact in the shell, explicit [Man2006, Box 5] projection, joint torque.

The verification cases `capstan-friction` and `signorini-penetration` (fabricfem/verify/contact.py) run
in tests/test_verify.py; here: unit checks against closed forms / finite differences, a physical
explicit test (a particle leaving a sphere), the joint torque against the strip's moment balance, bad
input and serial vs parallel equality.
"""
import math

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.motion import ElbowFlexion
from fabricfem.body.pose import Body, Segment
from fabricfem.contact import ContactProblem, adjacent_segments, box5_step, contact_torque, return_map
from fabricfem.contact.explicit import forward_increment_correction, initial_state, project_along_gradient
from fabricfem.forms.shell import area_stretch
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.verify import contact as cases


# ------------------------------------------------------------------------------------------ friction
def test_return_map_stick_and_slip_closed_form():
    n = np.array([[0.0, 0.0, 1.0]] * 2)
    x = np.array([[1e-6, 0.0, -1e-7], [1e-4, 2e-4, -1e-7]])
    anchor = np.zeros((2, 3))
    p = np.array([100.0, 100.0])
    kT, kN, mu = 1e8, 1e9, 0.3
    fr = return_map(x, anchor, n, p, mu, kT, kN)
    # trial t* = -k_T (tangential slip): |t*| = 100 Pa and 2236 Pa > mu p = 30 Pa -> both slip onto the cone
    trial = -kT * np.array([[1e-6, 0, 0], [1e-4, 2e-4, 0]])
    expected = mu * p[:, None] * trial / np.linalg.norm(trial, axis=1, keepdims=True)
    assert fr.slip.tolist() == [True, True]
    assert np.allclose(fr.traction, expected, rtol=1e-14)
    fr = return_map(x[:1] * 0.1, anchor[:1], n[:1], p[:1], mu, kT, kN)   # |t*| = 10 Pa < 30 Pa: stick
    assert not fr.slip[0] and np.allclose(fr.traction, 0.1 * trial[:1], rtol=1e-14)
    fr = return_map(x, anchor, n, np.zeros(2), mu, kT, kN)              # out of contact: nothing
    assert np.all(fr.traction == 0.0) and np.all(fr.tangent == 0.0)


@pytest.mark.parametrize("scale", [0.1, 10.0])   # stick, slip
def test_return_map_tangent_matches_finite_differences(scale):
    """dt/dx against central differences of the traction with p = k_N (-g) and g = n.(x - x_s) (flat obstacle,
    so the neglected dn/dx vanishes and the tangent must be exact)."""
    n = np.array([[0.0, 0.0, 1.0]])
    kT, kN, mu = 1e8, 1e9, 0.4
    x0 = np.array([[3e-7 * scale, -2e-7 * scale, -1e-7]])   # |t*| = 3.6 Pa (stick) or 360 Pa vs mu p = 40 Pa
    anchor = np.zeros((1, 3))

    def traction(x):
        p = np.maximum(-kN * x[:, 2], 0.0)
        return return_map(x, anchor, n, p, mu, kT, kN)

    fr = traction(x0)
    assert bool(fr.slip[0]) == (scale > 1)
    h = 1e-13
    fd = np.column_stack([(traction(x0 + h * e).traction - traction(x0 - h * e).traction)[0] / (2 * h)
                          for e in np.eye(3)])
    # 1e-6: central differences at h = 1e-6 |x| of a smooth function (truncation ~1e-12, rounding ~1e-10)
    assert np.allclose(fr.tangent[0], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


# -------------------------------------------------------------------------------------- shell contact
def test_contact_tangent_consistent_and_newton_quadratic():
    """Contact stiffness vs finite differences of the nodal forces (error bounded by the neglected curvature
    term |g| / R), and quadratic convergence of Newton on the plate-on-sphere problem."""
    problem = cases.signorini_problem()
    problem.system.compile()
    solver = NewtonSolver(problem.system)
    history = []
    for lam in (0.5, 1.0):
        problem.system.set_load_factor(lam)
        res = solver.solve()
        assert res.converged
        history.append(res.residual_norms)
        problem.system.after_converged_step()
    norms = history[-1]
    # quadratic: the last reductions square the residual (ratio r_{k+1} / r_k^2 bounded, r drops by >1e4)
    assert len(norms) <= 10, norms
    assert norms[-2] < 1e-4 * norms[-3] or norms[-1] < 1e-12, norms
    state = problem.model.w.x.array.copy()
    s0 = problem.evaluate(state)
    active = s0.pressure > 0
    assert active.sum() >= 1
    rng = np.random.default_rng(0)
    direction = rng.standard_normal(state.shape)
    h = 1e-10
    f_plus = problem.evaluate(state + h * direction).force
    f_minus = problem.evaluate(state - h * direction).force
    d = direction[problem.nodes.dofs]
    fd = -(f_plus - f_minus)[active] / (2 * h)
    K = np.einsum("nij,nj->ni", s0.stiffness, d)[active]
    bound = 10.0 * np.max(-s0.gap) / cases.SPHERE_RADIUS + 1e-6
    assert np.linalg.norm(fd - K) <= bound * np.linalg.norm(K)


def test_stick_points_move_with_the_body():
    """After a converged step with friction, turning the sphere by a small angle about the vertical axis
    (angular velocity omega over dt) drags the sticking nodes: their trial traction is
    k_T P v_s dt with v_s = Ellipsoid.surface_velocity (the stick points ride on the body); relative 1e-4
    (rigid rotation vs its linearisation: O(omega dt) = 1e-6, plus the normal change at O(dt))."""
    from fabricfem.body.motion import rotation_about
    problem = cases.signorini_problem()
    problem.mu = 0.5
    cases.solve_signorini(problem)
    before = problem.evaluate()
    omega, dt = np.array([0.0, 0.0, 2.0]), 5e-7
    base = cases.sphere()
    turned = Ellipsoid(base.center, rotation_about(omega / np.linalg.norm(omega), np.linalg.norm(omega) * dt),
                       base.radii)
    problem.set_obstacles([turned])
    after = problem.evaluate()
    v_s = base.surface_velocity(before.position, np.zeros(3), omega)
    n = after.normal
    expected = problem.tangential_penalty * (v_s * dt - np.sum(v_s * dt * n, axis=1, keepdims=True) * n)
    stick = (after.pressure > 0) & ~after.slip & (np.linalg.norm(before.traction, axis=1) < 1e-9)
    change = after.traction - before.traction
    assert np.count_nonzero(stick & (np.linalg.norm(expected, axis=1) > 0)) >= 1
    assert np.allclose(change[stick], expected[stick], rtol=1e-4, atol=1e-4 * np.abs(expected[stick]).max())


def test_pressure_field_integrates_to_nodal_normal_forces():
    """int p_h dA = sum_i w_i p_i (w_i = int phi_i dA) for the reference pressure, and int p_h J dA = sum_i
    a_i p_i^cur (a_i = int phi_i J dA) for the pressure on the body: both fields integrate to the sum of the
    nodal normal forces."""
    problem = cases.solve_signorini(cases.signorini_problem())
    s = problem.evaluate()
    nodal = problem.comm.allreduce(float(np.sum(problem.nodes.area * s.pressure)), op=MPI.SUM)
    p = problem.pressure_field(per="reference")
    integral = problem.comm.allreduce(fem.assemble_scalar(fem.form(p * ufl.dx)), op=MPI.SUM)
    assert integral == pytest.approx(nodal, rel=1e-12)
    assert integral > 0.0
    model = problem.model
    F0 = ufl.grad(model.phi0)
    J = area_stretch(F0 + ufl.grad(ufl.split(model.w)[0]), F0, model.t1, model.t2)
    p_current = problem.pressure_field()
    integral_current = problem.comm.allreduce(fem.assemble_scalar(fem.form(
        p_current * J * ufl.dx(metadata={"quadrature_degree": 4}))), op=MPI.SUM)
    assert integral_current == pytest.approx(nodal, rel=1e-12)


def test_capstan_torque_balances_end_tensions():
    """Moment of the contact forces on the cylinder about its axis (contact_torque, normal + friction) equals
    the moment of the two end forces on the strip (moment balance of the strip, an independent sum of the
    edge traction and the support reaction); the normal forces alone pass through the axis."""
    r = cases.capstan_ratio(0.3, 0.5 * math.pi)
    problem = r["problem"]
    s = problem.evaluate()
    axis = np.array([0.0, 1.0, 0.0])
    torque = contact_torque(s.position, -s.force, s.segment, [0], np.zeros(3), axis, problem.comm)
    normal_only = contact_torque(s.position, -(problem.nodes.area * s.pressure)[:, None] * s.normal, s.segment,
                                 [0], np.zeros(3), axis, problem.comm)
    # end forces on the strip: held end -T1 b t_start at the left edge, reaction at the right edge
    width = cases.CAPSTAN_WIDTH
    left = problem.node_value(_edge_point(problem, "left"))
    right = problem.node_value(_edge_point(problem, "right"))
    p_left = _edge_point(problem, "left") + left
    p_right = _edge_point(problem, "right") + right
    alpha0 = 0.5 * math.pi + 0.25 * math.pi
    t_start = np.array([math.sin(alpha0), 0.0, -math.cos(alpha0)])
    f_left = -cases.CAPSTAN_T1 * width * t_start
    f_right = np.array([problem.reaction("right", "u", 0), 0.0, problem.reaction("right", "u", 2)])
    moment_ends = np.cross(p_left, f_left)[1] + np.cross(p_right, f_right)[1]
    # the strip's moment balance: M(ends) + M(contact on strip) = 0 -> torque on body = M(ends); 1e-3
    # relative: the end forces are applied at the three edge nodes, taken here at the middle one (the
    # edges stay straight, nu = 0), and the reaction is summed at Newton's tolerance
    assert torque == pytest.approx(moment_ends, rel=1e-3)
    assert abs(normal_only) < 1e-6 * abs(torque)
    # and its size: (T2 - T1) R b
    assert abs(torque) == pytest.approx((r["ratio"] - 1) * cases.CAPSTAN_T1 * cases.CAPSTAN_RADIUS * width, rel=1e-2)


def _edge_point(problem, tag: str) -> np.ndarray:
    """Reference position of the middle node of an end edge of the capstan strip (theta = pi/2)."""
    alpha = 0.75 * math.pi if tag == "left" else 0.25 * math.pi
    radius = cases.CAPSTAN_RADIUS - cases.CAPSTAN_INTERFERENCE
    return np.array([radius * math.cos(alpha), 0.0, radius * math.sin(alpha)])


def test_joint_torque_adjacent_segments_closed_form():
    """Forces on the forearm count for the elbow, those on a segment not attached to it do not."""
    body = Body([Segment("upper_arm", "shoulder", "elbow", "upper_arm_marker", (0.17, 0.05, 0.05)),
                 Segment("forearm", "elbow", "wrist", "forearm_marker", (0.13, 0.04, 0.04))], ElbowFlexion())
    assert adjacent_segments(body, "wrist") == ["forearm"]
    assert set(adjacent_segments(body, "elbow")) == {"upper_arm", "forearm"}
    points = np.array([[0.5, 0.0, 0.04], [0.1, 0.0, 0.05]])
    forces = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])
    # about the wrist (0.602, 0, 0) along z, only the forearm point (segment 1): (0.5 - 0.602) * 1 = -0.102
    tau = contact_torque(points, forces, np.array([1, 0]), [1], body.joint_position("wrist", 0.0), (0, 0, 1))
    assert tau == pytest.approx(-0.102, rel=1e-12)
    with pytest.raises(ValueError, match="joint"):
        adjacent_segments(body, "knee")


# ------------------------------------------------------------------------------------------ explicit
def test_explicit_particle_leaves_sphere_at_two_thirds():
    """A frictionless particle sliding from rest at angle theta0 from the top of a sphere leaves it at
    cos(theta) = 2/3 cos(theta0) (energy + normal force zero). [Man2006, Box 5] with dt = 1e-4 s, R = 1 m: measured
    error 2e-3 at dt = 1e-3 and 2e-4 at 1e-4 (first order in dt); tolerance 1e-3."""
    R, g, dt, theta0 = 1.0, 9.81, 1e-4, 0.1
    body = Ellipsoid(np.zeros(3), np.eye(3), np.full(3, R))
    x = np.array([[R * math.sin(theta0), 0.0, R * math.cos(theta0)]])
    v, a = initial_state(x, np.zeros((1, 3)), np.array([[0.0, 0.0, -g]]), np.ones(1), dt, [body])  # in contact
    touched = False
    for n in range(100000):
        x, v, a, c = box5_step(x, v, a, np.ones(1), dt, lambda p, t: np.tile([0.0, 0.0, -g], (len(p), 1)),
                               n * dt, lambda t: [body])
        assert body.distance(x)[0] >= -1e-12   # never inside after a step
        if c.active[0]:
            touched = True
        elif touched:
            break
    cos_departure = x[0, 2] / np.linalg.norm(x[0])
    assert cos_departure == pytest.approx(2.0 / 3.0 * math.cos(theta0), rel=1e-3)


def test_forward_increment_multiplier_is_mass_times_correction():
    body = Ellipsoid(np.zeros(3), np.eye(3), np.array([0.2, 0.1, 0.1]))
    x_trial = np.array([[0.0, 0.0, 0.099], [0.0, 0.0, 0.2]])
    m = np.array([2.0, 1.0])
    out = forward_increment_correction(x_trial, m, 1e-3, [body])
    assert out.active.tolist() == [True, False]
    assert np.allclose(out.position[0], [0.0, 0.0, 0.1], atol=1e-15)   # gradient at the apex axis: straight up
    assert np.allclose(out.multiplier[0], -2.0 * np.array([0.0, 0.0, 1e-3]) / 1e-6, rtol=1e-9)
    assert np.all(out.force[1] == 0.0)
    projected, moved = project_along_gradient(np.array([[0.15, 0.05, 0.0]]), [body])
    assert moved[0] and abs(body.implicit(projected)[0]) < 1e-12


# ------------------------------------------------------------------------------------------ bad input
def _quad_model(cell: str = "quadrilateral"):
    return ShellModel(plate(0.1, 0.1, 2, 2, cell=cell, comm=MPI.COMM_SELF), Fabric.isotropic(1e6, 0.3, 1e-3))


@pytest.mark.parametrize("kwargs, name", [({"friction": -0.1}, "friction"), ({"penalty": 0.0}, "penalty"),
                                          ({"penalty": -1.0}, "penalty"), ({"tangential_penalty": 0.0},
                                                                             "tangential_penalty"),
                                          ({"method": "lagrange"}, "method")])
def test_bad_parameters_raise(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ContactProblem(_quad_model(), [cases.sphere()], **kwargs)


def test_triangles_rejected():
    with pytest.raises(ValueError, match="mesh.*quadrilateral"):
        ContactProblem(_quad_model("triangle"), [cases.sphere()])


def test_bad_obstacles_and_masses():
    with pytest.raises(ValueError, match="obstacles"):
        ContactProblem(_quad_model(), [])
    with pytest.raises(ValueError, match="masses"):
        forward_increment_correction(np.zeros((2, 3)), np.array([1.0, -1.0]), 1e-3, [cases.sphere()])
    with pytest.raises(ValueError, match="dt"):
        forward_increment_correction(np.zeros((1, 3)), np.ones(1), 0.0, [cases.sphere()])


# ------------------------------------------------------------------------------------------------ MPI
@pytest.mark.mpi
def test_total_contact_force_serial_equals_parallel():
    """The plate-on-sphere solution on COMM_WORLD (2 ranks under mpirun) and on COMM_SELF (serial, on each
    rank): total contact force and its moment about the origin agree to 1e-8 relative."""
    results = []
    for comm in (MPI.COMM_SELF, MPI.COMM_WORLD):
        problem = cases.solve_signorini(cases.signorini_problem(n=6, comm=comm))
        s = problem.evaluate()
        total = problem.total_force()
        moment = comm.allreduce(np.cross(s.position, s.force).sum(axis=0), op=MPI.SUM)
        results.append((total, moment, problem.max_penetration()))
    (f1, m1, p1), (f2, m2, p2) = results
    assert np.allclose(f1, f2, rtol=1e-8, atol=1e-8 * np.abs(f1).max())
    assert np.allclose(m1, m2, rtol=1e-8, atol=1e-8 * np.abs(m1).max())
    assert p1 == pytest.approx(p2, rel=1e-8)
