"""The failsafe of cloth-cloth contact (fabricfem.contact.impact_zones, [Bridson2002, sec. 7.3-7.4]) against closed
forms, conservation laws and the independent intersection count: the CCD time of a vertex moving through a fixed
triangle (t = d / v) and of two crossing edges; a zone's rigid velocity conserves linear and angular momentum; two
sheets thrown through each other within one step stay uncrossed (fabricfem.contact.intersections) with the zones
and cross without them; held nodes colliding among themselves are released into the zone's rigid motion; 1 and 2
ranks agree; a non-finite velocity stops the step with its reason."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact import impact_zones
from fabricfem.contact.intersections import intersecting_pairs
from fabricfem.contact.self_contact import SelfContact
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.stability import critical_time_step
from fabricfem.meshes.gmsh_io import mesh_from_gmsh
from fabricfem.shell import ShellModel
from fabricfem.verify import self_contact as case

NONE = np.zeros(0, dtype=np.int64)
GAP = 8e-3           # m between the thrown sheets (the first step, before any check, must not reach across)


def test_vertex_through_triangle_collides_at_d_over_v():
    """A vertex d = 4 mm above the triangle (0,0,0), (1,0,0), (0,1,0), over its interior, falling at v = 1 m/s in a
    step of 10 ms: the collision time is d / v = 4 ms, 0.4 of the step; moving away, or passing beside the
    triangle, it does not collide."""
    x = np.array([[0.2, 0.3, 4e-3], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    u, dt = np.zeros((4, 3)), 0.01
    u[0, 2] = -1.0
    tri = np.array([[1, 2, 3]], dtype=np.int64)
    no_edges = np.zeros((0, 2), dtype=np.int64)

    def when(x, u):
        hit, time = impact_zones.detect(np.array([0]), np.array([0]), tri, NONE, NONE, no_edges, x, dt * u, 1e-6,
                                        MPI.COMM_SELF)
        return bool(hit[0]), time[0]

    hit, time = when(x, u)
    assert hit and time * dt == pytest.approx(4e-3 / 1.0, rel=1e-12)
    assert not when(x, -u)[0]
    beside = x.copy()
    beside[0, :2] = (0.8, 0.8)
    assert not when(beside, u)[0]
    # the triangle rising at 0.5 m/s as well: t = d / (v_p + v_triangle)
    u[1:, 2] = 0.5
    hit, time = when(x, u)
    assert hit and time * dt == pytest.approx(4e-3 / 1.5, rel=1e-12)


def test_crossing_edges_collide_at_d_over_v():
    """Two crossed edges 3 mm apart closing at 0.75 m/s (a step of 10 ms): they meet at 4 ms (0.4 of the step)."""
    x = np.array([[-1.0, 0.0, 3e-3], [1.0, 0.0, 3e-3], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    u = np.zeros((4, 3))
    u[:2, 2], u[2:, 2] = -0.5, 0.25
    hit, time = impact_zones.detect(NONE, NONE, np.zeros((0, 3), dtype=np.int64), np.array([0]), np.array([1]),
                                    np.array([[0, 1], [2, 3]], dtype=np.int64), x, 0.01 * u, 1e-6, MPI.COMM_SELF)
    assert hit[0] and time[0] == pytest.approx(0.4, rel=1e-12)


def test_held_edges_crossing_in_the_step_are_released_into_one_rigid_zone():
    """Two crossed edges 1 mm apart whose four nodes are all held (infinite mass, as nodes held on the skin), one edge
    closing on the other at 0.2 m/s in a step of 10 ms (2 mm): a zone of held nodes keeps their velocities, so
    without the release the step ends with the collision left, and so it does when the four are not releasable (a
    prescribed motion); with it (from round 1) the four nodes take the zone's rigid velocity with their masses:
    the collision is gone, the linear momentum sum m u is kept (to 1e-15)
    and the four move rigidly (no relative velocity along their offsets)."""
    x0 = np.array([[-1.0, 0.0, 1e-3], [1.0, 0.0, 1e-3], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    mass, held = np.array([1.0, 2.0, 3.0, 0.5]), np.ones(4, dtype=bool)
    edges = np.array([[0, 1], [2, 3]], dtype=np.int64)

    def candidates(u):
        return NONE, NONE, np.zeros((0, 3), dtype=np.int64), np.array([0]), np.array([1]), edges

    # no release; the release; the release of nodes whose motion is prescribed (not releasable): refused
    for release, releasable, left in ((100, None, 1), (1, None, 0), (1, np.zeros(4, dtype=bool), 1)):
        u = np.zeros((4, 3))
        u[:2, 2] = -0.2
        momentum = mass @ u
        report = impact_zones.resolve(candidates, x0, u, 0.01, mass, held, 1e-6, 4, MPI.COMM_SELF, release=release,
                                      releasable=releasable)
        assert report["left"] == left and report["released"] == (4 if left == 0 else 0)
        if left == 0:
            np.testing.assert_allclose(mass @ u, momentum, atol=1e-15)
            du, dx = u[:, None] - u[None], x0[:, None] - x0[None]
            np.testing.assert_allclose(np.sum(du * dx, axis=2), 0.0, atol=1e-15)   # rigid: no stretching


def test_rigid_zone_conserves_momentum():
    """Two zones (merged from pairs sharing nodes) of random nodes, masses, velocities: each zone's rigid velocity
    keeps its linear momentum sum m u and angular momentum sum m x x u to round-off, is rigid (the relative
    velocity of two nodes is normal to their offset), and the nodes outside the zones are untouched; in a zone with a
    held node, the held node keeps its velocity."""
    rng = np.random.default_rng(3)
    x, u, m = rng.normal(size=(10, 3)), rng.normal(size=(10, 3)), rng.uniform(0.5, 2.0, 10)
    parent = np.full(10, -1, dtype=np.int64)
    assert impact_zones.merge(np.array([[0, 1, 2, 3], [3, 4, 5, 1], [6, 7, 8, 7]]), parent, MPI.COMM_SELF) == 9
    after = u.copy()
    impact_zones.rigid(parent, x, after, m, np.zeros(10, dtype=bool), MPI.COMM_SELF)
    for zone in (np.arange(6), np.arange(6, 9)):
        mz, xz = m[zone, None], x[zone]
        scale = float(np.abs(mz * u[zone]).sum() * (1.0 + np.abs(xz).max()))
        np.testing.assert_allclose((mz * after[zone]).sum(0), (mz * u[zone]).sum(0), rtol=0, atol=1e-15 * scale)
        np.testing.assert_allclose((mz * np.cross(xz, after[zone])).sum(0), (mz * np.cross(xz, u[zone])).sum(0),
                                   rtol=0, atol=1e-14 * scale)
        du, dx = after[zone][:, None] - after[zone][None], xz[:, None] - xz[None]
        assert np.abs(np.einsum("ijk,ijk->ij", du, dx)).max() < 1e-13
    np.testing.assert_array_equal(after[9], u[9])
    held = np.zeros(10, dtype=bool)
    held[6] = True
    after = u.copy()
    impact_zones.rigid(parent, x, after, m, held, MPI.COMM_SELF)
    np.testing.assert_allclose(after[6:9], np.broadcast_to(u[6], (3, 3)), rtol=0, atol=1e-14)


def test_free_nodes_far_from_few_held_nodes_are_not_flung():
    """A zone of two held nodes 2 mm apart, moving nearly together (0.03 m/s, 0.01 m/s apart: a rotation of 5 rad/s
    fits them), and four free nodes 0.1 m away: the rotation is not extrapolated beyond the held nodes' extent, so
    no free node moves faster than the held nodes' mean speed plus their relative speed (a full rigid fit gives
    them 0.67-0.73 m/s, over 20 times the held nodes' speed); the held nodes keep their velocities."""
    rng = np.random.default_rng(5)
    x = np.vstack([[[0.0, 0.0, 0.0], [2e-3, 0.0, 0.0]], 0.1 + 0.01 * rng.normal(size=(4, 3))])
    u, m = np.zeros((6, 3)), rng.uniform(0.5, 2.0, 6)
    u[0] = (0.0, 0.03, 0.0)
    u[1] = (0.0, 0.03, 0.01)
    u[2:] = rng.normal(size=(4, 3))
    held = np.array([True, True, False, False, False, False])
    parent = np.full(6, -1, dtype=np.int64)
    impact_zones.merge(np.array([[0, 1, 2, 3], [3, 4, 5, 0]]), parent, MPI.COMM_SELF)
    after = u.copy()
    impact_zones.rigid(parent, x, after, m, held, MPI.COMM_SELF)
    np.testing.assert_array_equal(after[:2], u[:2])
    mean = (m[:2, None] * u[:2]).sum(0) / m[:2].sum()
    bound = np.linalg.norm(mean) + np.linalg.norm(u[1] - u[0])
    assert np.linalg.norm(after[2:], axis=1).max() <= bound


def _two_sheets(zones: bool, comm) -> tuple[SelfContact, CentralDifference]:
    """Two free cotton sheets (case._two_rectangles, 6 x 4 cells, GAP apart) with self-contact (penalty 1e-3 Pa/m,
    the impulses' 4 passes, impact `zones`) and their explicit integrator at 0.8 of the critical step, at rest."""
    fmesh = mesh_from_gmsh(lambda m: case._two_rectangles(m, 6, 4, GAP), (1.0, 0.0, 0.0),
                           (0.0, 0.0, 1.0), comm, name="two-sheets")
    model = ShellModel(fmesh, case.cotton())
    model.compile()
    contact = SelfContact(model, penalty=1e-3, passes=4, zones=zones)
    dt = 0.8 * critical_time_step(model, (0.0, 0.0), rotary_inertia_scale=case.ROTARY_SCALE)
    return contact, CentralDifference(model, dt, rotary_inertia_scale=case.ROTARY_SCALE, contact=[contact],
                                      energy_bound=None)


def _thrown_through(zones: bool, steps: int = 6, comm=MPI.COMM_WORLD) -> tuple[int, np.ndarray, dict]:
    """Two free sheets (case._two_rectangles, GAP apart), the upper one thrown down tilting, at a speed rising
    linearly across it from 0 (at x = -0.095 m) to 6 mm a step (at x = 0.095 m): its fast side passes the lower
    sheet within its second step (proximity cannot see it coming), its slow side stays above, so that without a response
    the two cross along a line; the impulses' 4 passes on; no gravity, no damping, a penalty of 1e-3 Pa/m. Returns
    the intersecting triangle pairs after `steps` (fabricfem.contact.intersections), the positions (N, 3) [m] in
    the reference order, the zones' totals."""
    contact, integrator = _two_sheets(zones, comm)
    dt = integrator.dt
    nodes = contact.surface.nodes
    upper = nodes.reference[:, 2] > 0.5 * case.THICKNESS
    fast = 6.0 * case.THICKNESS / dt                                # m/s at the fast side
    v = integrator.v.getArray()
    v[nodes.dofs[upper, 2]] = -fast * (nodes.reference[upper, 0] + 0.095) / 0.19
    for _ in range(steps):
        integrator.step()
    x = contact.surface.positions(integrator.d.getArray(readonly=True))
    order = np.lexsort(np.round(contact.surface.reference / 1e-9).T)
    integrator.destroy()
    return intersecting_pairs(x, contact.surface.triangles), x[order], contact.zone_totals


def test_sheets_thrown_through_each_other_stay_uncrossed_with_zones():
    """The tilted throw (up to 6 mm a step from 8 mm apart): without the zones the upper sheet crosses the lower one
    (intersecting triangle pairs, though the impulses act); with them no triangle pair intersects and the
    collisions were resolved within the iterations in every step."""
    crossed, _, _ = _thrown_through(zones=False)
    assert crossed > 0
    held, _, totals = _thrown_through(zones=True)
    assert held == 0
    assert totals["collisions"] > 0 and totals["unresolved_steps"] == 0


def test_non_finite_velocity_stops_the_step_with_its_reason():
    """A NaN velocity entering the cloth-cloth correction (impulses and zones on) raises ValueError naming the
    stage, the time and the node, the reason the wear loop reports (fabricfem.wear.engine), instead of a
    RuntimeWarning and NaN carried on; impact zones refuse a zero mass (a zone of no mass has no rigid
    velocity)."""
    contact, integrator = _two_sheets(True, MPI.COMM_SELF)
    integrator.v.getArray()[contact.surface.nodes.dofs[3, 2]] = np.nan
    stage = r"self-contact: non-finite or faster than 1000 m/s predicted velocities .* at t = .* "
    with pytest.raises(ValueError, match=stage + r"node \d+, \|u\| = nan m/s\)"):
        integrator.step()
    integrator.destroy()
    x, u = np.zeros((4, 3)), np.zeros((4, 3))
    with pytest.raises(ValueError, match="impact zones: the lumped masses must be positive"):
        impact_zones.resolve(None, x, u, 1e-3, np.array([1.0, 0.0, 1.0, 1.0]), np.zeros(4, bool), 1e-6, 2,
                             MPI.COMM_SELF)


def test_a_step_faster_than_the_blow_up_speed_stops_with_its_reason():
    """A finite state that moves a node by more than BLOW_UP_SPEED x dt in one step (here 1 m in a step of about
    1e-5 s) raises ValueError in the contact's forces naming the stage and the speed, before the broad phase: a
    blown-up state that stays finite put every triangle into one hash cell, and the pants walk with impulses then
    spent minutes per step instead of stopping."""
    contact, integrator = _two_sheets(False, MPI.COMM_SELF)
    integrator.step()
    integrator.d.getArray()[contact.surface.nodes.dofs[3, 2]] += 1.0
    with pytest.raises(ValueError, match=r"faster than 1000 m/s step motion / dt .* node 3, \|u\| = [0-9.e+]+ m/s"):
        integrator.step()
    integrator.destroy()


def test_refused_zones():
    """A non-boolean `zones` is refused naming the scene key."""
    model = case.fold_model(MPI.COMM_SELF)
    with pytest.raises(ValueError, match="impact_zones"):
        SelfContact(model, zones=1)


@pytest.mark.mpi
def test_one_and_two_ranks_agree_with_zones():
    """The sheets thrown through each other with the zones acting: the ranks of COMM_WORLD and one rank agree within
    1e-6 m."""
    _, x_world, _ = _thrown_through(True, comm=MPI.COMM_WORLD)
    _, x_self, _ = _thrown_through(True, comm=MPI.COMM_SELF)
    np.testing.assert_allclose(x_world, x_self, rtol=0, atol=1e-6)
