"""A body from a triangulated skin: reading and its refusals, bone heat rigging, posing by the segments, the Skin
contract's queries against the analytic ellipsoid, and the pressure on the skin's vertices."""
import igl
import numpy as np
import pytest
import trimesh
from mpi4py import MPI

from fabricfem.benchmarks.mesh_skin_contact import sleeve_skin
from fabricfem.body import (
    Body,
    JointTrajectory,
    Segment,
    default_arm,
    elbow_flexion,
    lower_body,
    obstacle_walk,
    winter_walking,
)
from fabricfem.body.human import HUMAN_DIMENSIONS, HUMAN_KEYS, HUMAN_PATH, human_rest
from fabricfem.body.mesh_distance import PosedSurface
from fabricfem.body.mesh_skin import MeshSkin, ellipsoid_skin, read_skin, skin_mesh
from fabricfem.body.skin import Skin
from fabricfem.body.skin_pressure import SkinPressureWriter, skin_pressure, vertex_areas
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import tube_flexion_run

needs_human = pytest.mark.skipif(not HUMAN_PATH.is_file(), reason=f"{HUMAN_PATH} absent: the Debian package "
                                 "assimp-testmodels is not installed")


def body_ellipsoid(radii=(0.2, 0.12, 0.08)) -> Body:
    """One segment along x from (0, 0, 1) to (0.4, 0, 1), marker towards +y: centre (0.2, 0, 1), R = I."""
    a, b, m = np.array([0.0, 0.0, 1.0]), np.array([0.4, 0.0, 1.0]), np.array([0.2, 0.3, 1.0])
    kin = JointTrajectory([0.0, 1.0], {"a": [a, a], "b": [b, b], "m": [m, m]})
    return Body([Segment("s", "a", "b", "m", radii)], kin)


def ellipsoid_mesh(body: Body, subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere mapped onto the body's ellipsoid: every vertex on the surface, outward."""
    e = body.pose(0.0)["s"]
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    return e.to_global(sphere.vertices * e.radii), np.asarray(sphere.faces)


def write_mesh(tmp_path, vertices, faces, name="skin.ply") -> str:
    path = tmp_path / name
    trimesh.Trimesh(vertices, faces, process=False).export(str(path))
    return str(path)


def standing_body_mesh(scale: float = 1.0):
    """A 1.7 m tall closed ellipsoid (a stand-in body) in the body frame, times `scale`."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    return scale * (sphere.vertices * [0.15, 0.25, 0.85] + [0.0, 0.0, 0.85]), np.asarray(sphere.faces)


@needs_human
@pytest.mark.parametrize("motion, times", [(winter_walking, (0.2, 0.7, 1.3)), (obstacle_walk, (2.6, 2.9, 3.2))])
def test_the_debian_human_reads_rigs_and_poses_rigidly_mid_segment(motion, times):
    mesh = read_skin(HUMAN_PATH, **HUMAN_KEYS)
    assert len(mesh.faces) == 26756 and len(mesh.dropped) == 4          # the eye shells left out
    assert 1.65 < mesh.height < 1.67 and mesh.volume > 0.05
    body = lower_body(HUMAN_DIMENSIONS, motion(HUMAN_DIMENSIONS))
    skin = MeshSkin(mesh, body, rest_positions=human_rest())
    assert isinstance(skin, Skin)
    assert np.all(skin.weights >= 0.0) and np.allclose(skin.weights.sum(axis=1), 1.0)
    rest = {n: s.pose(human_rest()) for n, s in body.segments.items()}
    for t in times:
        posed, vertices = body.pose(t), skin.surface(t)[0]
        for k, name in enumerate(skin.segment_names):
            if not name.startswith(("thigh", "shank")):
                continue
            e0, e = rest[name], posed[name]
            axial = np.abs((mesh.vertices - e0.center) @ e0.rotation[:, 0])
            rigid = (skin.weights[:, k] == 1.0) & (axial < 0.05)                # near the segment's middle
            assert rigid.sum() > 20, name
            expected = (mesh.vertices[rigid] - e0.center) @ e0.rotation @ e.rotation.T + e.center
            assert np.abs(vertices[rigid] - expected).max() < 1e-12, (name, t)


@needs_human
def test_the_human_with_all_parts_is_refused_for_the_eyes_holes():
    with pytest.raises(ValueError, match=r"^repair: .* 80 boundary edges"):
        read_skin(HUMAN_PATH, components="all", **HUMAN_KEYS)


def test_holes_are_refused_unless_repair_closes_them(tmp_path):
    v, f = standing_body_mesh()
    path = write_mesh(tmp_path, v, f[1:])
    with pytest.raises(ValueError, match=r"^repair: skin.ply has 3 boundary edges") as err:
        read_skin(path)
    assert "\n" not in str(err.value)
    repaired = read_skin(path, repair=True)
    assert len(repaired.faces) == len(f) and repaired.repaired == ("closed 3 boundary edges",)


def test_inverted_normals_are_refused_naming_repair(tmp_path):
    v, f = standing_body_mesh()
    with pytest.raises(ValueError, match=r"^repair: .* negative volume .* normals point inwards"):
        read_skin(write_mesh(tmp_path, v, f[:, ::-1]))
    assert read_skin(write_mesh(tmp_path, v, f[:, ::-1], "flip.ply"), repair=True).volume > 0.0


def test_a_wrong_unit_or_up_axis_is_refused_naming_the_key(tmp_path):
    v, f = standing_body_mesh(scale=100.0)                                   # a file in cm
    path = write_mesh(tmp_path, v, f)
    with pytest.raises(ValueError, match=r"^units: the body is 170 m tall"):
        read_skin(path)
    assert abs(read_skin(path, units="cm").height - 1.7) < 1e-9
    with pytest.raises(ValueError, match=r"^up: .* lies on its side"):
        read_skin(path, units="cm", up="y")


def test_a_joint_outside_the_mesh_is_refused_naming_rest_positions():
    body = body_ellipsoid()
    mesh = skin_mesh(*ellipsoid_mesh(body, 3))
    rest = {n: body.kinematics.positions(0.0)[n] for n in ("a", "b", "m")}
    rest["b"] = rest["b"] + [0.05, 0.0, 0.0]                                 # 5 cm beyond the tip
    with pytest.raises(ValueError, match=r"^rest_positions: joint 'b' \(given\) lies 0.05\d* m outside"):
        MeshSkin(mesh, body, rest_positions=rest)


def test_query_agrees_with_the_analytic_ellipsoid_within_the_chord_error():
    """Vertices on the ellipsoid: the triangulated surface lies inside it by at most the sagitta of the largest
    triangle, rho^2 kappa / 2 (rho the largest circumradius, kappa = r_max / r_min^2 the largest curvature)."""
    body = body_ellipsoid()
    vertices, faces = ellipsoid_mesh(body)
    skin = MeshSkin(skin_mesh(vertices, faces), body)
    e = body.pose(0.0)["s"]
    p = vertices[faces]
    a, b, c = (np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in ((1, 2), (2, 0), (0, 1)))
    double_area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    rho = (a * b * c / (2.0 * double_area)).max()
    bound = rho ** 2 * (e.radii.max() / e.radii.min() ** 2) / 2.0
    rng = np.random.default_rng(1)
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    x = e.to_global(u * e.radii) + rng.uniform(-0.01, 0.02, (2000, 1)) * u
    q = skin.query(x, 0.5)
    _, gap, normal = e.closest_point(x)
    assert bound < 1.5e-3
    assert np.all(q.gap - gap >= -1e-12) and np.abs(q.gap - gap).max() <= bound
    S = igl.signed_distance(x, vertices, np.asarray(faces, dtype=np.int64), igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
    assert np.abs(q.gap - S).max() < 1e-12                                  # libigl's pseudonormal sign
    assert np.allclose(np.linalg.norm(q.normal, axis=1), 1.0) and np.all(np.sum(q.normal * normal, axis=1) > 0.99)
    assert np.allclose(q.weights, 1.0) and np.abs(q.foot - x).max() < 0.03


def test_the_arm_skin_poses_by_elbow_flexion_and_a_reused_tree_stays_within_its_bound():
    body = default_arm(elbow_flexion())
    skin = ellipsoid_skin(body, spacing=0.01)
    t1 = body.kinematics.time_range[1]
    k = skin.segment_names.index("forearm")
    e0, e = body.pose(0.0)["forearm"], body.pose(t1)["forearm"]
    v0 = skin.mesh.vertices
    rigid = (skin.weights[:, k] == 1.0) & (np.abs((v0 - e0.center) @ e0.rotation[:, 0]) < 0.05)
    expected = (v0[rigid] - e0.center) @ e0.rotation @ e.rotation.T + e.center
    assert rigid.sum() > 20 and np.abs(skin.surface(t1)[0][rigid] - expected).max() < 1e-12
    reused = MeshSkin(skin.mesh, body, tree_tolerance=2e-3, joint_tolerance=0.02)
    x = skin.surface(0.5)[0][::7] + 0.004
    for t in np.linspace(0.5, 0.52, 5):      # libigl's tree of `posed`, reused within its tolerance
        assert np.abs(reused.posed(t).closest(x)[0] - skin.query(x, t).gap).max() <= 2 * 2e-3
    assert reused.tree_builds < 5


def test_pressure_on_the_skin_keeps_the_total_force_and_is_written(tmp_path):
    body = body_ellipsoid()
    skin = MeshSkin(skin_mesh(*ellipsoid_mesh(body, 3)), body)
    rng = np.random.default_rng(2)
    x = skin.surface(0.0)[0][rng.integers(0, len(skin.mesh.vertices), 300)] * 1.001
    force = rng.uniform(0.0, 0.1, 300)
    p = skin_pressure(skin, 0.0, x, force)
    assert np.all(p >= 0.0) and abs(p @ vertex_areas(*skin.surface(0.0)) - force.sum()) < 1e-12
    writer = SkinPressureWriter(tmp_path, "skin_pressure", skin)
    for t in (0.0, 0.5):
        assert np.allclose(writer.write(t, x, force), p)
    writer.close()
    assert (tmp_path / "skin_pressure.xdmf").is_file() and (tmp_path / "skin_pressure_00001.vtp").is_file()


def brute_force(skin: MeshSkin, x: np.ndarray, t: float) -> tuple[np.ndarray, ...]:
    """(gap, foot, normal, weights) of the points x on the skin at t by libigl's AABB tree of all the posed
    triangles, every point searched (`PosedSurface.closest`, a new tree), the weights interpolated in numpy."""
    gap, tri, bary, foot, normal = PosedSurface(skin.surface(t)[0], skin.topology).closest(x)
    return gap, foot, normal, skin.foot_weights(tri, bary)


def assert_same_answers(q, reference, where) -> None:
    """The compiled query's answers equal the brute force's: gaps and feet to 1e-12 m, and away from the surface
    (|gap| > 1 um, where the normal is the unit offset) normals and weights to 1e-9."""
    gap, foot, normal, weights = reference
    away = np.abs(gap) > 1e-6
    assert np.abs(q.gap - gap).max() < 1e-12 and np.abs(q.foot - foot).max() < 1e-12, where
    assert np.abs(q.normal - normal)[away].max() < 1e-9 and np.abs(q.weights - weights)[away].max() < 1e-9, where
    assert np.allclose(q.weights.sum(axis=1), 1.0), where


def skin_points(skin: MeshSkin, t: float, n: int, seed: int, spread: float) -> np.ndarray:
    """n points about the skin posed at t: vertices and triangle centres moved by up to `spread` [m] each way."""
    rng = np.random.default_rng(seed)
    vertices, faces = skin.surface(t)
    around = np.concatenate([vertices, vertices[faces].mean(axis=1)])
    return around[rng.integers(0, len(around), n)] + rng.uniform(-spread, spread, (n, 3))


@pytest.mark.parametrize("growth", [1.0, 0.8])
def test_the_compiled_query_answers_as_libigl_on_all_points_of_the_flexed_arm(growth):
    """The compiled query (the tree built once and refitted per pose, rigid parts searched in their segment's
    frame; growth != 1: maps that are not rotations, every box refitted) against libigl's tree of all the posed
    triangles on every point, at three angles of the elbow flexion; then the active set (margin 5 mm) over a
    sequence of times: every gap at or below the margin is the brute force's, every other point lies farther."""
    body = default_arm(elbow_flexion())
    skin = ellipsoid_skin(body, spacing=0.01)
    if growth != 1.0:
        skin.transverse_scale = lambda t: growth
    t1 = body.kinematics.time_range[1]
    for t in (0.0, 0.4 * t1, t1):
        x = skin_points(skin, t, 3000, 3, 0.01)
        assert_same_answers(skin.query(x, t), brute_force(skin, x, t), t)
    active = MeshSkin(skin.mesh, body, margin=5e-3, joint_tolerance=0.02)
    active.transverse_scale = skin.transverse_scale
    x = skin_points(skin, 0.5 * t1, 1500, 4, 0.02)
    rng = np.random.default_rng(5)
    searched = []
    for k, t in enumerate(np.linspace(0.5 * t1, 0.5 * t1 + 0.05, 6)):
        x = x + rng.uniform(-1e-3, 1e-3, x.shape)
        before = active.exact_points
        q, (gap, foot, normal, weights) = active.query(x, t), brute_force(skin, x, t)
        searched.append(active.exact_points - before)
        near = np.isfinite(q.gap)
        assert np.all(gap[~near] > 5e-3) and np.all(near[gap <= 5e-3]), t
        assert np.abs(q.gap[near] - gap[near]).max() < 1e-12 and np.abs(q.foot[near] - foot[near]).max() < 1e-12
        away = near & (np.abs(gap) > 1e-6)
        assert np.abs(q.normal - normal)[away].max() < 1e-9 and np.abs(q.weights - weights)[away].max() < 1e-9
        assert np.all(q.foot[~near] == x[~near])
    assert searched[0] == len(x) and max(searched[1:]) < len(x)        # the active set skips far points


@needs_human
def test_the_compiled_query_answers_as_libigl_on_the_walking_human():
    mesh = read_skin(HUMAN_PATH, **HUMAN_KEYS)
    body = lower_body(HUMAN_DIMENSIONS, winter_walking(HUMAN_DIMENSIONS))
    skin = MeshSkin(mesh, body, rest_positions=human_rest())
    for t in (0.3, 0.8):
        x = skin_points(skin, t, 4000, 6, 0.015)
        assert_same_answers(skin.query(x, t), brute_force(skin, x, t), t)


def test_a_non_finite_point_is_refused():
    skin = MeshSkin(skin_mesh(*ellipsoid_mesh(body_ellipsoid(), 2)), body_ellipsoid())
    with pytest.raises(ValueError, match="x must be finite"):
        skin.query(np.array([[0.2, 0.0, 1.0], [np.nan, 0.0, 1.0]]), 0.0)


@pytest.mark.mpi
def test_the_sleeve_on_a_mesh_skin_is_the_same_on_one_and_two_ranks():
    """The tube sleeve (10x13, mu = 0.1) flexed to 4 degrees on the arm's triangulated blend (`ellipsoid_skin`,
    1 cm, active set margin 0): the elbow torque, peak pressure and contact force histories on COMM_WORLD (2 ranks
    under mpirun) equal the serial ones (COMM_SELF) within 1e-6 of their largest values."""
    config = SleeveConfig.of(n_around=10, n_along=13, final_angle=4.0)

    def history(comm) -> np.ndarray:
        run = tube_flexion_run("mesh skin", config.fabric, config.tube, config.arm, config.motion, config.contact,
                               config.route, comm, skin=sleeve_skin(config, 0.01, 0.0))
        h = run.run()
        run.destroy()
        return np.array([[s.torques["elbow"], s.peak_pressure, s.contact_force] for s in h.steps])

    parallel, serial = history(MPI.COMM_WORLD), history(MPI.COMM_SELF)
    scale = np.max(np.abs(serial), axis=0)
    assert serial[-1, 0] > 0.0 and scale[1] > 0.0                     # the forearm touches the sleeve
    assert np.all(np.abs(parallel - serial) <= 1e-6 * scale + 1e-15), ((parallel - serial) / scale, serial)
