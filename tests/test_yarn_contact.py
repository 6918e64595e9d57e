"""Yarn-yarn contact (fabricfem.contact.yarn): projection, return mapping, bad input, MPI equality."""
import numpy as np
import pytest
from mpi4py import MPI

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
