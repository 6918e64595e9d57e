"""Motion readers and writers (C3D, BVH, TRC), unit/axis mapping, resampling, refusals; the lower-body
preset, segment schedule and joint/segment checks."""
import math

import numpy as np
import pytest

from fabricfem.body import (
    DEFAULT_LOWER_BODY,
    BvhSkeleton,
    JointTrajectory,
    LowerBodyDimensions,
    Mean,
    Offset,
    SegmentSchedule,
    forward_kinematics,
    load_motion,
    lower_body,
    map_points,
    read_bvh,
    read_c3d,
    read_trc,
    segment_points,
    standing,
    winter_walking,
    write_bvh,
    write_c3d,
    write_trc,
)
from fabricfem.body.conventions import UP_ROTATIONS
from fabricfem.verify.mocap import CMU_BVH, CMU_UNITS


def _motion() -> JointTrajectory:
    t = 0.01 * np.arange(5)
    a = np.column_stack([0.1 + t, 0.2 + 0 * t, 0.9 + 0 * t])
    return JointTrajectory(t, {"A": a, "B": a + [0.0, 0.0, -0.4], "C": a + [0.1, 0.05, -0.2]})


@pytest.mark.parametrize("fmt", ["c3d", "trc"])
@pytest.mark.parametrize("up", ["z", "y"])
def test_marker_file_round_trip_with_units_and_axes(tmp_path, fmt, up):
    motion = _motion()
    write, read = {"c3d": (write_c3d, read_c3d), "trc": (write_trc, read_trc)}[fmt]
    path = tmp_path / f"m.{fmt}"
    write(path, motion, units="cm", up=up)
    back = read(path, up=up)
    np.testing.assert_allclose(back.times, motion.times, atol=1e-12)
    for name in motion.names:
        np.testing.assert_allclose(back.samples()[name], motion.samples()[name], atol=1e-6)
    # the explicit units override the file's, and reading with the other up axis rotates by R_y
    raw = read(path, units="m", up="z")
    expected = 100.0 * motion.samples()["A"] @ (UP_ROTATIONS[up] if up == "y" else np.eye(3))
    np.testing.assert_allclose(raw.samples()["A"], expected, atol=1e-4)


def test_axis_rotation_is_the_documented_cyclic_permutation():
    R = UP_ROTATIONS["y"]
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_array_equal(R @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])   # file y (up) -> body z
    np.testing.assert_array_equal(R @ [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])   # file z (forward) -> body x


def test_trc_inches_and_resampling(tmp_path):
    path = tmp_path / "m.trc"
    write_trc(path, _motion(), units="in")
    back = read_trc(path)
    np.testing.assert_allclose(back.samples()["B"], _motion().samples()["B"], atol=1e-9)
    fine = back.resampled(np.linspace(0.0, 0.04, 9))
    np.testing.assert_allclose(fine.samples()["A"][:, 0], 0.1 + np.linspace(0.0, 0.04, 9), atol=1e-9)
    with pytest.raises(ValueError, match="time range"):
        back.resampled([0.0, 0.05])


def _chain() -> tuple[BvhSkeleton, np.ndarray]:
    skeleton = BvhSkeleton(("root", "knee", "ankle", "ankle_end"), (-1, 0, 1, 2),
                           np.array([[0.0, 0.0, 0.0], [0.0, -40.0, 0.0], [0.0, -42.0, 0.0], [0.0, 0.0, 20.0]]),
                           (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
                            ("Zrotation", "Xrotation", "Yrotation"), ("Xrotation",), ()))
    t = np.linspace(0.0, 1.0, 11)
    zero = 0 * t
    motion = np.column_stack([10 * t, 90 + zero, zero, 20 * t, -30 * t, 15 * t, zero, 60 * t, -10 * t, -20 * t])
    return skeleton, motion


def test_bvh_forward_kinematics_and_round_trip(tmp_path):
    """FK of an analytic chain against hand-composed rotations; write -> read gives the same positions
    within the printed precision (6 decimals)."""
    skeleton, motion = _chain()
    fk = forward_kinematics(skeleton, motion)

    def rot(axis, deg):
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        return {"X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
                "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]
    m = motion[-1]
    r0 = rot("Z", m[3]) @ rot("X", m[4]) @ rot("Y", m[5])
    r1 = r0 @ rot("Z", m[6]) @ rot("X", m[7]) @ rot("Y", m[8])
    knee = m[:3] + r0 @ [0.0, -40.0, 0.0]
    ankle = knee + r1 @ [0.0, -42.0, 0.0]
    toe = ankle + r1 @ rot("X", m[9]) @ [0.0, 0.0, 20.0]
    np.testing.assert_allclose(fk[-1], [m[:3], knee, ankle, toe], atol=1e-12)
    path = tmp_path / "chain.bvh"
    write_bvh(path, skeleton, motion, 0.1)
    back = read_bvh(path, units="cm", up="y")
    assert back.names == skeleton.names
    expected = 0.01 * fk @ UP_ROTATIONS["y"].T
    for k, name in enumerate(skeleton.names):
        np.testing.assert_allclose(back.samples()[name], expected[:, k], atol=1e-8)
    np.testing.assert_allclose(back.times, 0.1 * np.arange(11), atol=1e-12)


def test_mapping_with_virtual_points_and_segment_sources():
    motion = _motion()
    mapped = map_points(motion, {"hip": "A", "mid": Mean(("A", "B")), "lat": Offset(Mean(("A", "B")), (0, 0.1, 0))})
    np.testing.assert_allclose(mapped.samples()["mid"], 0.5 * (motion.samples()["A"] + motion.samples()["B"]))
    np.testing.assert_allclose(mapped.samples()["lat"] - mapped.samples()["mid"], [[0, 0.1, 0]] * 5)
    segments = DEFAULT_LOWER_BODY.segments()
    points = segment_points(segments, {"thigh_l": ("A", "B", "C"), "shank_l": ("B", "D", "E")})
    assert points["knee_l"] == "B"
    with pytest.raises(ValueError, match="knee_l"):
        segment_points(segments, {"thigh_l": ("A", "B", "C"), "shank_l": ("X", "D", "E")})
    with pytest.raises(ValueError, match="arm"):
        segment_points(segments, {"arm": ("A", "B", "C")})


# --- refusals -----------------------------------------------------------------------------------
def test_missing_marker_is_refused_naming_it_and_listing_the_available(tmp_path):
    path = tmp_path / "m.c3d"
    write_c3d(path, _motion())
    with pytest.raises(ValueError, match=r"'KNEE'.*available: \['A', 'B', 'C'\]"):
        load_motion(path, {"knee": "KNEE", "hip": "A"})


def test_non_increasing_times_refused_with_the_frame(tmp_path):
    path = tmp_path / "m.trc"
    write_trc(path, _motion())
    lines = path.read_text().splitlines()
    lines[8] = lines[8].replace("\t0.02\t", "\t0.01\t")     # frame 2 repeats the time of frame 1
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="frame 2"):
        read_trc(path)


@pytest.mark.parametrize("gap", ["nan", "zeros"])
def test_c3d_gaps_refused_or_filled(tmp_path, gap):
    import ezc3d
    path = tmp_path / "m.c3d"
    write_c3d(path, _motion())
    c3d = ezc3d.c3d(str(path))
    points = c3d["data"]["points"]
    points[:3, 1, 2] = math.nan if gap == "nan" else 0.0
    c3d["data"]["points"] = points
    c3d.write(str(path))
    with pytest.raises(ValueError, match=r"marker 'B'.*frame 2"):
        read_c3d(path)
    filled = read_c3d(path, fill_gaps=True)
    np.testing.assert_allclose(filled.samples()["B"], _motion().samples()["B"], atol=1e-6)


def test_bvh_without_units_and_bad_frame_refused(tmp_path):
    skeleton, motion = _chain()
    path = tmp_path / "chain.bvh"
    write_bvh(path, skeleton, motion, 0.1)
    with pytest.raises(ValueError, match="units"):
        load_motion(path)
    text = path.read_text().splitlines()
    text[-1] = text[-1] + " 1.0"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError, match="frame 10"):
        read_bvh(path, units="cm")


# --- lower body ---------------------------------------------------------------------------------
def test_lower_body_preset_standing_on_the_ground():
    body = lower_body()
    assert list(body.segments) == ["trunk", "pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"]
    posed = body.pose(0.5)
    d = DEFAULT_LOWER_BODY
    assert posed["thigh_l"].radii[0] == pytest.approx(0.5 * 0.408)
    assert posed["shank_r"].radii[1] == pytest.approx(0.392 / (2 * math.pi))
    pos = body.kinematics.positions(0.0)
    assert np.linalg.norm(pos["knee_l"] - pos["hip_l"]) == pytest.approx(0.408)
    assert np.linalg.norm(pos["ankle_r"] - pos["knee_r"]) == pytest.approx(0.418)
    for foot in ("foot_l", "foot_r"):
        e = posed[foot]
        lowest = e.center[2] - np.sqrt(np.sum((e.rotation[2] * e.radii) ** 2))
        assert abs(lowest) < 1e-3
        assert e.center[0] - e.radii[0] == pytest.approx(-d.heel_fraction * d.foot_length)   # heel behind the ankle
    # the pelvis section at waist height has the waist girth, its bottom is at crotch height
    p = posed["pelvis"]
    assert p.center[2] - p.radii[0] == pytest.approx(0.845)
    q = math.sqrt(1 - ((1.055 - p.center[2]) / p.radii[0]) ** 2)
    from fabricfem.body.lower_body import ellipse_perimeter
    assert ellipse_perimeter(q * p.radii[1], q * p.radii[2]) == pytest.approx(0.937, rel=1e-4)


def test_dimensions_are_overridable_and_checked():
    tall = LowerBodyDimensions(thigh_length=0.45, calf_girth=0.40)
    pos = standing(tall).positions(0.0)
    assert np.linalg.norm(pos["knee_l"] - pos["hip_l"]) == pytest.approx(0.45)
    assert lower_body(tall).segment("shank_l").radii[1] == pytest.approx(0.40 / (2 * math.pi))
    with pytest.raises(ValueError, match="calf_girth"):
        LowerBodyDimensions(calf_girth=-1.0)
    with pytest.raises(ValueError, match="waist_girth"):
        LowerBodyDimensions(waist_girth=1.1)


def test_two_leg_gait_is_half_a_cycle_apart():
    gait = winter_walking(strides=1)
    t = np.linspace(0.0, 0.5 * gait.cycle_time, 7)
    np.testing.assert_allclose(gait.angles(t + 0.5 * gait.cycle_time, "l"), gait.angles(t, "r"), atol=1e-12)
    knee = np.degrees(gait.angles(np.linspace(0, gait.cycle_time, 200), "l")[:, 1])
    assert 55.0 < knee.max() < 65.0                              # Winter's swing peak ~60 deg
    pts = gait.points(np.linspace(0, gait.cycle_time, 50))
    np.testing.assert_allclose(np.linalg.norm(pts["knee_r"] - pts["hip_r"], axis=1), 0.408, rtol=1e-12)
    body = lower_body(kinematics=gait)
    assert set(body.pose(0.3)) == set(body.segments)


# --- schedule and checks ------------------------------------------------------------------------
def test_schedule_switches_the_feet_off_and_on():
    schedule = SegmentSchedule({"feet": (["foot_l", "foot_r"], [(1.0, 2.0), (3.0, math.inf)])})
    body = lower_body(kinematics=standing(duration=5.0), schedule=schedule)
    assert "foot_l" in body.active(0.5) and "foot_r" in body.active(2.0)
    assert not {"foot_l", "foot_r"} & set(body.active(1.5))
    assert len(body.active(4.0)) == 6
    toe_tip = np.array([[0.2, 0.0993, 0.05]])
    g_on, _, k_on = body.gap(toe_tip, 0.5)
    g_off, _, k_off = body.gap(toe_tip, 1.5)
    assert g_on[0] < 0.0 and list(body.segments)[k_on[0]] == "foot_l"
    assert g_off[0] > 0.0 and list(body.segments)[k_off[0]] != "foot_l"
    with pytest.raises(ValueError, match="toes"):
        lower_body(schedule=SegmentSchedule({"feet": (["toes"], [(0.0, 1.0)])}))
    with pytest.raises(ValueError, match="overlap"):
        SegmentSchedule({"feet": (["foot_l"], [(0.0, 2.0), (1.0, 3.0)])})


def test_a_returning_segment_regrows_from_a_fifth_of_its_size():
    """regrow_time T_g: g(t) = 0.2 + 0.8 smoothstep((t - t_on) / T_g) after the group comes back at t_on (closed form:
    smoothstep(1/2) = 1/2), 1 for segments of no group and before any return; a negative time is refused."""
    from fabricfem.body.schedule import REGROW_FROM
    schedule = SegmentSchedule({"feet": (["foot_l", "foot_r"], [(0.0, 1.0)])}, regrow_time=0.2)
    names = ["foot_l", "shank_l", "foot_r"]
    np.testing.assert_allclose(schedule.sizes(names, 0.5), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(schedule.sizes(names, 1.0), [REGROW_FROM, 1.0, REGROW_FROM])
    np.testing.assert_allclose(schedule.sizes(names, 1.1), [0.6, 1.0, 0.6], rtol=1e-12)
    np.testing.assert_allclose(schedule.sizes(names, 1.3), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(SegmentSchedule({"feet": (["foot_l"], [(0.0, 1.0)])}).sizes(names, 1.0), 1.0)
    with pytest.raises(ValueError, match="regrow_time"):
        SegmentSchedule({"feet": (["foot_l"], [(0.0, 1.0)])}, regrow_time=-1.0)


def test_check_joint_and_check_segments():
    body = lower_body()
    assert body.check_joint("knee_l") == ["thigh_l", "shank_l"]
    assert body.check_joint("waist") == ["trunk", "pelvis"]
    with pytest.raises(ValueError, match="'hip_l'"):
        body.check_joint("hip_l")
    with pytest.raises(ValueError, match="'elbow'"):
        body.check_joint("elbow")
    with pytest.raises(ValueError, match="empty"):
        body.check_segments([])
    with pytest.raises(ValueError, match="'arm'"):
        body.check_segments(["thigh_l", "arm"])


def test_cmu_bvh_poses_the_lower_body():
    if not CMU_BVH.exists():
        pytest.skip(f"{CMU_BVH} absent: install the Debian package assimp-testmodels")
    joints = {"hip_l": "LeftUpLeg", "knee_l": "LeftLeg", "ankle_l": "LeftFoot"}
    motion = load_motion(CMU_BVH, joints, units=CMU_UNITS, up="y")
    thigh = np.linalg.norm(motion.samples()["knee_l"] - motion.samples()["hip_l"], axis=1)
    assert np.ptp(thigh) < 1e-12 and 0.35 < thigh[0] < 0.45     # constant, and near ANSUR's 0.408 m
    assert np.min(motion.samples()["ankle_l"][:, 2]) > -0.05      # Z up: the feet stay near/above the floor
