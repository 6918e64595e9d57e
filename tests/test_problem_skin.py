"""The implicit contact (ContactProblem) asks the wearer's surface contract (fabricfem.body.skin) and nothing else:
its gaps, normals and segment weights are the skin's query at the same points and time, and the joint torques share
each node's moment among the segments by the skin's weights."""
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import TEST_MESH

from fabricfem import scenes as scene_module
from fabricfem.body.blended import BlendedEllipsoids
from fabricfem.body.motion import joint_torque
from fabricfem.contact.obstacles import ObstacleSkin, Plane
from fabricfem.contact.problem import ContactProblem
from fabricfem.scenes.build import tube_scene_run
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.quasistatic import build_sleeve
from fabricfem.wear.sleeve import ELBOW_AXIS

MESH_I = SleeveConfig.of(n_around=10, n_along=13, solver="quasistatic", friction=0.0, method="penalty")


@pytest.fixture(scope="module")
def sleeve():
    """The quasi-static sleeve on mesh I (no friction, penalty), its contact against the arm's default skin."""
    problem = build_sleeve(MESH_I, MPI.COMM_SELF)
    yield problem
    problem.destroy()


def test_gaps_normals_and_weights_are_the_skins_query(sleeve):
    """At 50 degrees of flexion, on the undeformed and on a displaced sleeve: ContactProblem's gap, normal, segment
    weights and segment of largest weight equal, bit for bit, a BlendedEllipsoids of the same body and width queried
    at the same points and body time (the explicit engine's default skin), and some nodes lie in the elbow's blend
    (weights strictly between 0 and 1), so the blend is exercised; another blend width reaches the skin as given."""
    contact = sleeve.contact
    contact.set_time(sleeve.time_at(50.0))
    skin = BlendedEllipsoids(sleeve.body, contact.blend_width, strict=False)
    rng = np.random.default_rng(5)
    start = contact.w.x.array.copy()
    try:
        for shift in (0.0, 2e-3):
            contact.w.x.array[contact.nodes.dofs] += shift * rng.standard_normal(contact.nodes.dofs.shape)
            s = contact.evaluate()
            q = skin.query(s.position, contact.time)
            np.testing.assert_array_equal(s.position, contact.nodes.reference + contact.w.x.array[contact.nodes.dofs])
            for ours, theirs in ((s.gap, q.gap), (s.normal, q.normal), (s.weights, q.weights), (s.segment, q.segment)):
                np.testing.assert_array_equal(ours, theirs)
            blend = (s.weights[:, 1] > 0.0) & (s.weights[:, 1] < 1.0)
            assert blend.sum() >= 10
        narrow = ContactProblem(sleeve.model, sleeve.body, time=contact.time, blend_width=0.02)
        s = narrow.evaluate()
        q = BlendedEllipsoids(sleeve.body, 0.02, strict=False).query(s.position, contact.time)
        np.testing.assert_array_equal(s.gap, q.gap)
        np.testing.assert_array_equal(s.weights, q.weights)
    finally:
        contact.w.x.array[:] = start
        contact.set_time(sleeve.time_at(0.0))


def test_a_node_in_the_elbows_blend_carries_torque_by_its_weights(sleeve):
    """The undeformed sleeve at 50 degrees: nodes penetrate the flexed forearm, three of them inside the elbow's
    blend (forearm weight strictly between 0 and 1). The penalty forces f = w_i k_N <-g> n from the skin's query, and
    the forearm's torque about the elbow tau = a . sum_i W_i,forearm (x_i - J) x (-f_i), equal the contact's force and
    its 'elbow' monitor (the thesis's resisting torque, forearm only) to round-off; the monitor of both segments
    takes each node's whole moment (weights sum to 1); the blend's nodes change the forearm torque (the nearest
    segment would have given each of them all or nothing)."""
    contact = sleeve.contact
    contact.set_time(sleeve.time_at(50.0))
    try:
        s = contact.evaluate()
        q = BlendedEllipsoids(sleeve.body, contact.blend_width, strict=False).query(s.position, contact.time)
        free = ~contact.nodes.constrained
        force = np.where(free, (contact.nodes.area * contact.penalty * np.maximum(-q.gap, 0.0))[:, None] * q.normal,
                         0.0)
        np.testing.assert_allclose(s.force, force, rtol=1e-13, atol=1e-13 * np.abs(force).max())
        forearm = q.weights[:, list(sleeve.body.segments).index("forearm")]
        in_blend = (forearm > 0.0) & (forearm < 1.0) & (np.linalg.norm(force, axis=1) > 0.0)
        assert in_blend.sum() >= 1
        elbow = sleeve.body.joint_position("elbow", contact.time)
        moments = np.cross(s.position - elbow, -force) @ np.asarray(ELBOW_AXIS)
        expected = float(np.sum(forearm * moments))
        assert contact.torque("elbow") == pytest.approx(expected, rel=1e-12)
        assert contact.torque("elbow_both_segments") == pytest.approx(float(moments.sum()), rel=1e-12)
        nearest_only = float(np.sum(moments[forearm >= 0.5]))       # all or nothing by the larger weight
        assert abs(nearest_only - expected) > 1e-3 * abs(expected)
        assert joint_torque(s.position, -force, elbow, ELBOW_AXIS) == pytest.approx(float(moments.sum()), rel=1e-12)
    finally:
        contact.set_time(sleeve.time_at(0.0))


def test_fixed_obstacles_are_their_nearest_union(sleeve):
    """Without a body the skin is the obstacles' union (ObstacleSkin): the nearest obstacle's own gap and normal,
    the foot x - g n and weight 1 on it; a skin is refused without a Body, and a skin of other segments with one."""
    planes = [Plane((0.0, -0.05, 0.0), (0.0, 1.0, 0.0)), Plane((0.0, 0.0, 0.07), (0.0, 0.0, -1.0))]
    contact = ContactProblem(sleeve.model, planes)
    s = contact.evaluate()
    gaps = np.array([p.gap(s.position)[0] for p in planes])
    nearest = gaps.argmin(axis=0)
    np.testing.assert_array_equal(s.gap, gaps.min(axis=0))
    np.testing.assert_array_equal(s.segment, nearest)
    np.testing.assert_array_equal(s.normal, np.array([p.normal for p in planes])[nearest])
    np.testing.assert_array_equal(s.weights, np.eye(2)[nearest])
    q = ObstacleSkin(planes).query(s.position, 3.0)
    np.testing.assert_allclose(q.foot, s.position - s.gap[:, None] * s.normal)
    with pytest.raises(ValueError, match="skin"):
        ContactProblem(sleeve.model, planes, skin=ObstacleSkin(planes))
    with pytest.raises(ValueError, match="skin"):
        ContactProblem(sleeve.model, sleeve.body, skin=ObstacleSkin(planes))
    with pytest.raises(ValueError, match="blend_width"):
        ContactProblem(sleeve.model, sleeve.body, blend_width=0.0)


def test_the_scenes_blend_width_reaches_the_newton_routes_skin():
    """A tube-on-arm wear scene on its quasi-static route (tests/data/sleeve_quasistatic.toml on mesh I) with
    [body] blend_width = 0.03 m: the route's contact asks a BlendedEllipsoids of the scene's body with that width,
    as the explicit engine's contact would."""
    data = tomllib.loads((Path(__file__).parent / "data" / "sleeve_quasistatic.toml").read_text())
    data["garment"].update(TEST_MESH)
    data["body"]["blend_width"] = 0.03
    run = tube_scene_run(scene_module.validate(data), MPI.COMM_SELF)
    try:
        assert isinstance(run.contact.skin, BlendedEllipsoids) and run.contact.skin.width == 0.03
        assert run.contact.skin.body is run.body
    finally:
        run.destroy()
