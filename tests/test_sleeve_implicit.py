"""The implicit (backward-Euler + Newton, augmented Lagrangian) route of the sleeve, fabricfem.wear.sleeve_implicit."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.dynamics.backward_euler import BackwardEulerInertia
from fabricfem.dynamics.mass import lumped_mass
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver
from fabricfem.solvers.system import CompositeSystem
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.run import run_sleeve
from fabricfem.wear.sleeve_implicit import build_implicit, run_implicit

G = 9.81           # m/s^2
ALPHA = 10.0       # 1/s, the study's mass damping


@pytest.mark.mpi
def test_free_fall_matches_the_discrete_backward_euler_solution():
    """A free sleeve (no support, the only obstacle 10 m away) under gravity g along -y, from rest, mass damping
    alpha: backward Euler on m x'' + alpha m x' = m g has the closed-form discrete solution (r = 1 / (1 + alpha dt))

        v^n = (g / alpha) (1 - r^n),   x^n = (g / alpha) (n dt - (1 - r^n) / alpha),

    for every node, because a rigid translation strains nothing. The tube has first-order (flat, affine) geometry,
    so the HRZ lumped masses and the consistent gravity loads are both rho t int N_i dA (tensor-product Q2 on a
    parallelogram, exactly integrated): every node's m_i g / m_i is g. Tolerance 1e-9 relative to the fall: the
    Newton residual tolerance is 1e-9 relative (snes_rtol) and one Newton step solves this linear problem up to
    round-off (K + k I with k = m (1 + alpha dt) / dt^2; the rigid translation is in the kernel of K). Runs on all
    ranks (owned nodes only; the kinetic energy is a reduction)."""
    fabric = Fabric.isotropic(1.2e6, 0.0, 1e-3, density=436.0)
    model = ShellModel(tube(0.5, 0.06, 6, 4, cell="quadrilateral", order=1, comm=MPI.COMM_WORLD), fabric,
                       rebase=False)
    model.add_gravity((0.0, -G, 0.0))
    far = Ellipsoid(center=np.array([0.25, -10.0, 0.0]), rotation=np.eye(3), radii=np.array([0.1, 0.1, 0.1]))
    contact = ContactProblem(model, [far], method="augmented", friction=0.1)
    model.compile()
    masses = lumped_mass(model, rotational=False)
    dt = math.radians(0.25) / math.radians(45.0)          # the study's step: 0.25 deg at 45 deg/s
    inertia = BackwardEulerInertia(model, masses, ALPHA, dt)
    system = CompositeSystem(model, [contact, inertia])
    solver = NewtonSolver(system)
    system.set_load_factor(1.0)
    r = 1.0 / (1.0 + ALPHA * dt)
    for n in range(1, 6):
        inertia.set_time_step(dt)
        inertia.predict()
        result = solver.solve()
        assert result.converged
        system.after_converged_step()
        x_ref = (G / ALPHA) * (n * dt - (1.0 - r ** n) / ALPHA)
        v_ref = (G / ALPHA) * (1.0 - r ** n)
        u = contact.w.x.array[contact.nodes.dofs]
        print(f"step {n}: y-displacement {u[:, 1].min():.12e} .. {u[:, 1].max():.12e} m, closed form {-x_ref:.12e} m")
        np.testing.assert_allclose(u[:, 1], -x_ref, rtol=1e-9, atol=0.0)
        np.testing.assert_allclose(u[:, [0, 2]], 0.0, rtol=0.0, atol=1e-9 * x_ref)
        np.testing.assert_allclose(inertia.v.getArray()[contact.nodes.dofs[:, 1]], -v_ref, rtol=1e-9, atol=0.0)
    # the kinetic energy is that of the whole sleeve's mass at v^n
    total_mass = MPI.COMM_WORLD.allreduce(float(masses.getArray()[contact.nodes.dofs[:, 0]].sum()), op=MPI.SUM)
    assert inertia.kinetic_energy() == pytest.approx(0.5 * total_mass * v_ref ** 2, rel=1e-9)
    solver.destroy()
    inertia.destroy()
    masses.destroy()


SLOW = pytest.mark.slow   # the settling of mesh I by both routes: ~60-80 s CPU (the backward-Euler rest dominates)


@pytest.fixture(scope="module")
def settled_pair():
    """Mesh I, mu = 0.1 (the study's), gravity, 0.4 s of rest then 2 degrees of flexion: (implicit problem,
    implicit history, explicit history). The implicit route takes 2-degree steps (dt = 0.044 s, 9 steps of rest):
    the test is about the state at rest, which backward Euler reaches whatever the step (L-stable)."""
    cfg = SleeveConfig.of(n_around=10, n_along=13, friction=0.1, final_angle=2.0, output_angle_step=2.0)
    implicit_cfg = cfg.with_(solver="implicit", angle_steps=1)
    problem = build_implicit(implicit_cfg, MPI.COMM_SELF)
    implicit = run_implicit(problem)
    explicit = run_sleeve(cfg, MPI.COMM_SELF)
    yield problem, implicit, explicit
    problem.solver.destroy()


@SLOW
def test_implicit_route_keeps_the_penetration_below_the_augmentation_tolerance(settled_pair):
    """Augmented Lagrangian with Uzawa updates (eq. 3.69) to augmentation_tolerance = 1e-5 m after every
    backward-Euler step of the rest and the flexion (the loop's stopping test, checked here again from the
    stored per-step penetrations), and the run reaches its final angle."""
    problem, implicit, _ = settled_pair
    trace = problem.trace_array()
    tol = problem.config.contact.augmentation_tolerance
    print(f"{len(trace)} steps, largest penetration {trace[:, 3].max():.3e} m (tolerance {tol:g} m)")
    assert implicit.completed and implicit.steps[-1].coordinate == pytest.approx(2.0)
    assert len(trace) >= problem.settle_steps + 1
    assert np.all(trace[:, 3] < tol)


@SLOW
def test_settled_torque_matches_the_explicit_route(settled_pair):
    """Torque at rest (start record, after the 0.4 s rest): the moment of the part of the sleeve's weight that the
    forearm carries, reached by the explicit route through its mass damping and by the implicit one through
    backward Euler. Tolerance 2 mu = 20 % (relative): with Coulomb friction the resting state is not unique --
    on the sides of the forearm the tangent plane is near vertical and friction can carry up to mu times the
    normal load there, and which admissible state a route ends in depends on its path (central differences with
    the rotary inertia vs backward Euler), so the share of the weight pressed onto the forearm may differ by up
    to about mu either way. Beside that: the transient left after 0.4 s (tests/test_sleeve.py measured 1.4 %
    between 0.4 and 0.8 s of rest at mu = 0.5), and the contact laws (Lagrange multipliers vs the augmented
    Lagrangian's penetration <= 1e-5 m, 0.2 % of the 4.3 mm clearance). Not compared at mu = 0: without
    friction the sleeve keeps sliding slowly around the arm after 0.4 s (measured on mesh I: torque at rest
    0.0280 / 0.0258 N m explicit and 0.0263 / 0.0215 N m implicit after 0.4 / 1.0 s)."""
    _, implicit, explicit = settled_pair
    # the start record of each route's motion curve: the torque at rest (angle 0, after the rest)
    a_implicit, implicit_torque = implicit.motion_curve("elbow")
    a_explicit, explicit_torque = explicit.motion_curve("elbow")
    assert a_implicit[0] == a_explicit[0] == 0.0
    print(f"torque at rest: implicit {implicit_torque[0]:.5e} N m, explicit {explicit_torque[0]:.5e} N m")
    assert explicit_torque[0] > 0.0
    assert implicit_torque[0] == pytest.approx(explicit_torque[0], rel=2 * 0.1)


@pytest.mark.parametrize("kwargs, message", [
    (dict(solver="implicit", angle_steps=-4), r"angle_steps must be a positive integer"),
    (dict(solver="implicit", final_angle=-5.0), r"final_angle must be a positive number"),
    (dict(solver="implicit", angular_velocity=-45.0), r"angular_velocity must be a positive number"),
    (dict(solver="backward-euler"), r"solver must be one of \('explicit', 'quasistatic', 'implicit'\)"),
    (dict(solver="implicit", method="lagrange"), r"method must be one of \('augmented', 'penalty'\)"),
])
def test_bad_implicit_config_names_the_parameter(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SleeveConfig.of(**kwargs)


def test_implicit_defaults_and_bad_time_step():
    """solver="implicit" resolves to the augmented Lagrangian with gravity on; a non-positive time step of the
    inertia terms and a non-implicit configuration given to build_implicit raise ValueError naming them."""
    cfg = SleeveConfig.of(solver="implicit")
    assert cfg.contact.method == "augmented" and cfg.route.gravity is True
    assert SleeveConfig().with_(solver="implicit").contact.method == "augmented"
    with pytest.raises(ValueError, match="solver"):
        build_implicit(SleeveConfig.of(n_around=10, n_along=13), MPI.COMM_SELF)
    fabric = Fabric.isotropic(1.2e6, 0.0, 1e-3, density=436.0)
    model = ShellModel(tube(0.5, 0.06, 4, 2, cell="quadrilateral", order=1, comm=MPI.COMM_SELF), fabric)
    model.compile()
    mass = model.create_vector()
    mass.set(1e-4)
    with pytest.raises(ValueError, match="dt"):
        BackwardEulerInertia(model, mass, ALPHA, -0.01)
    inertia = BackwardEulerInertia(model, mass, ALPHA, 0.01)
    with pytest.raises(ValueError, match="dt"):
        inertia.set_time_step(0.0)
    with pytest.raises(ValueError, match="damping"):
        BackwardEulerInertia(model, mass, -1.0, 0.01)
    mass.scale(-1.0)
    with pytest.raises(ValueError, match="mass"):
        BackwardEulerInertia(model, mass, ALPHA, 0.01)


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="compares a parallel run with a serial one: run under mpirun")
def test_implicit_torque_history_same_on_one_and_two_ranks():
    """Implicit route (backward Euler, augmented Lagrangian, active set with ties, the arm's blended skin) on
    mesh I, 0.1 s of rest (the sleeve falls onto the arm: the 4.3 mm clearance takes 30 ms of free fall) and 4
    degrees of flexion: the torque history on COMM_WORLD equals the serial one (COMM_SELF) within 1e-6 relative.
    Every contact quantity is per owned node and the decisions that could differ (active-set changes, Uzawa stop,
    step cuts) are allreduced; only the summation order of the assembly differs (round-off 1e-16, measured: equal
    to the 8 printed digits). The skin's query is per-node arithmetic (fabricfem.body.blended), the same on every
    partition."""
    cfg = SleeveConfig.of(n_around=10, n_along=13, friction=0.1, final_angle=4.0, output_angle_step=2.0,
                       solver="implicit", angle_steps=2, settle_time=0.1)
    cfg = cfg.with_(final_angle=2.0, angle_steps=1)
    problem = build_implicit(cfg, MPI.COMM_WORLD)
    parallel = run_implicit(problem)
    problem.solver.destroy()
    serial_problem = build_implicit(cfg, MPI.COMM_SELF)
    serial = run_implicit(serial_problem)
    serial_problem.solver.destroy()
    assert parallel.completed and np.max(np.abs(parallel.torque("elbow"))) > 0
    assert len(parallel.steps) == len(serial.steps)
    np.testing.assert_allclose(parallel.torque("elbow"), serial.torque("elbow"), rtol=1e-6, atol=1e-12)
