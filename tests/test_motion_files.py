"""Motion files in wear scenes ([motion] type = "file"): units as metres per file unit, placement of the motion in
the garment (motion.place) and the check that the garment meets the body, the TOML form of averaged and offset
points in motion.mapping, and the collinear-marker refusal naming the segment, marker and joints."""
import math
import re
from pathlib import Path

import numpy as np
import pytest
from shipped_scenes import scene_data
from toml_text import dumps

from fabricfem import cli
from fabricfem.body import JointTrajectory
from fabricfem.body.lower_body import standing
from fabricfem.body.mocap import write_trc
from fabricfem.body.pose import Segment
from fabricfem.scenes import build as scene_build
from fabricfem.scenes import wear
from fabricfem.verify.mocap import CMU_BVH

ROOT = Path(__file__).resolve().parents[1]
TIMES = np.array([0.0, 0.1, 0.2])


def _scene(name: str) -> dict:
    return scene_data(name)


def _standing_file(tmp_path: Path, shift=(0.0, 0.0, 0.0), name: str = "stand.trc") -> dict[str, np.ndarray]:
    """A TRC file (mm, Z up) of the standing lower body moved by `shift` [m]; returns its points [m] at t = 0."""
    base = standing(duration=0.2)
    points = {n: np.array([base.positions(t)[n] + np.asarray(shift) for t in TIMES]) for n in base.names}
    write_trc(tmp_path / name, JointTrajectory(TIMES, points), units="mm")
    return {n: p[0] for n, p in points.items()}


def _trousers_on_file(tmp_path: Path, **motion) -> dict:
    data = _scene("trousers_standing.toml")
    data["output"] = {"dir": str(tmp_path / "out")}
    data["motion"] = {"type": "file", "path": "stand.trc", "record_time": 0.02, **motion}
    return data


def _plan(tmp_path: Path, data: dict) -> wear.WearPlan:
    path = tmp_path / "scene.toml"
    path.write_text(dumps(data))
    scene = scene_build.load(path)
    return wear.plan(scene.parsed, wear.wear_fabric(scene.parsed, scene_build.build_fabric), path)


def _refused(tmp_path: Path, data: dict, capsys) -> str:
    """The one line of a scene refused (exit 2) before meshing."""
    path = tmp_path / "bad.toml"
    path.write_text(dumps(data))
    code = cli.main(["run", str(path)])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert "Traceback" not in lines[0]
    return lines[0]


def _centroid(posed) -> np.ndarray:
    """Centre of volume [m] of posed ellipsoids (each weighted by r1 r2 r3)."""
    volumes = np.array([np.prod(e.radii) for e in posed.values()])
    return volumes @ np.array([e.center for e in posed.values()]) / volumes.sum()


# ------------------------------------------------------------------------------------------ units
def test_units_accept_metres_per_file_unit(tmp_path):
    """units = 0.001 (a number: metres per unit) reads the mm file as units = "mm" does; 0.002 doubles it."""
    points = _standing_file(tmp_path)
    for units, factor in ((0.001, 1.0), (0.002, 2.0)):
        plan = _plan(tmp_path, _trousers_on_file(tmp_path, units=units))
        got = plan.body.kinematics.positions(0.0)
        for name in ("hip_l", "ankle_r", "waist"):
            np.testing.assert_allclose(got[name], factor * points[name], atol=1e-6)


@pytest.mark.parametrize("units, words", [(0.0, "positive"), (-0.0254, "positive"), (math.inf, "finite"),
                                          (math.nan, "finite"), ("0.0564444", "without quotes"),
                                          ("furlong", "furlong")])
def test_bad_units_refused_naming_motion_units(tmp_path, capsys, no_meshing, units, words):
    _standing_file(tmp_path)
    line = _refused(tmp_path, _trousers_on_file(tmp_path, units=units), capsys)
    assert "motion.units:" in line and words in line, line


# ------------------------------------------------------------------------------------------ placement
def test_a_motion_far_from_the_garment_is_refused_with_the_distance(tmp_path, capsys, no_meshing):
    """The standing body recorded 0.65 m in front of the trousers: the garment never meets it."""
    _standing_file(tmp_path, shift=(0.65, 0.0, 0.0))
    line = _refused(tmp_path, _trousers_on_file(tmp_path), capsys)
    assert "motion.place:" in line and "place = \"garment\"" in line, line
    distance = float(re.search(r"([0-9.]+) m from the garment", line).group(1))
    assert 0.2 < distance < 0.65, line


def test_place_garment_moves_the_first_pose_into_the_garment(tmp_path):
    """place = "garment" translates the motion horizontally so that the first pose's centre of volume is at the
    centre of the garment's reference box; the heights stay. The same body recorded at another place ends up in
    the same pose, and that pose is within 2.5 cm of the standing preset the shipped scene put the trousers on
    (measured: 2.04 cm forward)."""
    file_points = _standing_file(tmp_path, shift=(0.65, 0.3, 0.0))
    plan = _plan(tmp_path, _trousers_on_file(tmp_path, place="garment"))
    placed = plan.body.kinematics.positions(0.0)
    lower, upper = wear.garment_box(_plan_scene(tmp_path), tmp_path / "scene.toml")
    np.testing.assert_allclose(_centroid(plan.body.pose(0.0))[:2], (0.5 * (lower + upper))[:2], atol=1e-12)
    for name, p in file_points.items():
        assert placed[name][2] == pytest.approx(p[2], abs=1e-6)
    _standing_file(tmp_path)
    at_origin = _plan(tmp_path, _trousers_on_file(tmp_path, place="garment")).body.kinematics.positions(0.0)
    preset = standing().positions(0.0)
    for name in placed:
        np.testing.assert_allclose(placed[name], at_origin[name], atol=1e-6)
        assert np.linalg.norm(placed[name] - preset[name]) < 0.025, name


def _plan_scene(tmp_path: Path):
    return scene_build.load(tmp_path / "scene.toml").parsed


def test_place_keeps_the_height_and_refuses_a_garment_out_of_reach(tmp_path, capsys, no_meshing):
    """Trousers lifted 3 m: placing the body keeps its feet on the floor, so it still never meets them."""
    _standing_file(tmp_path)
    data = _trousers_on_file(tmp_path, place="garment")
    data["garment"]["translate"] = [0.0, 0.0, 4.0]
    line = _refused(tmp_path, data, capsys)
    assert "motion.place:" in line and " m " in line and "height" in line, line


def test_place_centres_the_arm_in_the_tube(tmp_path):
    """An arm (no floor: placed in 3D) held still in the tube sleeve: its centre of volume goes to the tube's centre
    (length / 2, 0, 0)."""
    data = _scene("sleeve.toml")
    data["motion"] = {"type": "still", "duration": 0.1, "place": "garment"}
    plan = _plan(tmp_path, data)
    np.testing.assert_allclose(_centroid(plan.body.pose(0.0)), [0.25, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d["motion"].update(place="body"), "'body'"),
    (lambda d: (d["route"].update(solver="quasistatic"), d["contact"].update(method="penalty")), "explicit"),
])
def test_bad_place_refused(tmp_path, capsys, no_meshing, mutate, words):
    data = _scene("sleeve.toml")
    data["output"] = {"dir": str(tmp_path / "out")}
    data["motion"]["place"] = "garment"
    mutate(data)
    line = _refused(tmp_path, data, capsys)
    assert "motion.place:" in line and words in line, line


# ------------------------------------------------------------------------------------------ mapping
def test_mapping_tables_give_means_and_offsets(tmp_path):
    """mapping = {name = "marker" | {marker = M} | {mean = [A, B, ...]}, optional offset = [dx, dy, dz] [m]};
    body points the mapping leaves out keep their own names."""
    points = _standing_file(tmp_path)
    mapping = {"knee_r": {"mean": ["hip_r", "ankle_r"]}, "thigh_marker_l": {"marker": "thigh_marker_l",
                                                                            "offset": [0.0, 0.05, 0.0]},
               "waist": {"mean": ["hip_l", "hip_r"], "offset": [0.0, 0.0, 0.156]}, "toe_l": "toe_l"}
    got = _plan(tmp_path, _trousers_on_file(tmp_path, mapping=mapping)).body.kinematics.positions(0.0)
    np.testing.assert_allclose(got["knee_r"], 0.5 * (points["hip_r"] + points["ankle_r"]), atol=1e-6)
    np.testing.assert_allclose(got["thigh_marker_l"], points["thigh_marker_l"] + [0.0, 0.05, 0.0], atol=1e-6)
    np.testing.assert_allclose(got["waist"], 0.5 * (points["hip_l"] + points["hip_r"]) + [0, 0, 0.156], atol=1e-6)
    np.testing.assert_allclose(got["ankle_l"], points["ankle_l"], atol=1e-6)


@pytest.mark.parametrize("source, words", [
    ({"marker": "knee_r", "mean": ["hip_r", "ankle_r"]}, "marker or mean"),
    ({"mean": []}, "mean"),
    ({"marker": "knee_r", "offset": [0.0, 0.1]}, "offset"),
    ({"marker": "knee_r", "ofset": [0.0, 0.0, 0.1]}, "ofset"),
    ({"offset": [0.0, 0.0, 0.1]}, "marker or mean"),
    (3, "3"),
])
def test_bad_mapping_forms_refused_naming_the_point(tmp_path, capsys, no_meshing, source, words):
    _standing_file(tmp_path)
    line = _refused(tmp_path, _trousers_on_file(tmp_path, mapping={"knee_r": source}), capsys)
    assert "motion.mapping.knee_r:" in line and words in line, line


def test_a_mapping_key_that_is_no_body_point_is_refused(tmp_path, capsys, no_meshing):
    _standing_file(tmp_path)
    line = _refused(tmp_path, _trousers_on_file(tmp_path, mapping={"kne_r": "knee_r"}), capsys)
    assert "motion.mapping.kne_r:" in line and "knee_r" in line, line


def test_collinear_marker_refused_naming_segment_marker_and_joints(tmp_path, capsys, no_meshing):
    """A thigh marker mapped to the midpoint of hip and knee lies on the thigh's long axis: refused before
    meshing, naming the segment, the marker, the joints and the frame."""
    _standing_file(tmp_path)
    data = _trousers_on_file(tmp_path, mapping={"thigh_marker_l": {"mean": ["hip_l", "knee_l"]}})
    line = _refused(tmp_path, data, capsys)
    assert "motion.mapping:" in line and "segment 'thigh_l'" in line, line
    assert "marker 'thigh_marker_l' is collinear with the long axis hip_l-knee_l" in line and "frame 0" in line


def test_collinear_marker_message_of_a_posed_segment():
    segment = Segment("shank_r", "knee_r", "ankle_r", "shank_marker_r", (0.2, 0.06, 0.06))
    points = {"knee_r": np.zeros(3), "ankle_r": np.array([0.0, 0.0, -0.4]), "shank_marker_r": [0.0, 0.0, -0.1]}
    with pytest.raises(ValueError, match="segment 'shank_r': marker 'shank_marker_r' is collinear with the long axis "
                                         "knee_r-ankle_r"):
        segment.pose(points)


# ------------------------------------------------------------------------------------------ CMU BVH
def _cmu_mapping() -> dict:
    """The lower body from the CMU skeleton in TOML form: leg joints by name, the pelvis and trunk points offsets
    of the hips' midpoint, the segment markers offsets of joint midpoints (as fabricfem.verify.mocap)."""
    hips = ["LeftUpLeg", "RightUpLeg"]
    mapping = {"waist": {"mean": hips, "offset": [0.0, 0.0, 0.156]}, "crotch": {"mean": hips, "offset": [0, 0, -0.054]},
               "chest": {"mean": hips, "offset": [0.0, 0.0, 0.366]},
               "trunk_marker": {"mean": hips, "offset": [0.15, 0.0, 0.156]},
               "pelvis_marker": {"mean": hips, "offset": [0.15, 0.0, 0.097]}}
    for s, side, y in (("l", "Left", 0.15), ("r", "Right", -0.15)):
        joints = {"hip": f"{side}UpLeg", "knee": f"{side}Leg", "ankle": f"{side}Foot", "toe": f"{side}ToeBase"}
        mapping.update({f"{j}_{s}": name for j, name in joints.items()})
        mapping[f"thigh_marker_{s}"] = {"mean": [joints["hip"], joints["knee"]], "offset": [0.0, y, 0.0]}
        mapping[f"shank_marker_{s}"] = {"mean": [joints["knee"], joints["ankle"]], "offset": [0.0, y, 0.0]}
        mapping[f"foot_marker_{s}"] = {"mean": [joints["ankle"], joints["toe"]], "offset": [0.0, 0.0, 0.15]}
    return mapping


def test_cmu_bvh_in_the_trousers(tmp_path, capsys, no_meshing):
    """The CMU recording (units = 0.0254 / 0.45 m per unit as a number, the TOML mapping of means and offsets):
    where the file recorded it the body is refused (the garment never meets it); placed, it is in the trousers."""
    if not CMU_BVH.exists():
        pytest.skip(f"{CMU_BVH} absent: install the Debian package assimp-testmodels")
    data = _trousers_on_file(tmp_path, units=0.0564444, up="y", mapping=_cmu_mapping(), duration=1.0)
    data["motion"]["path"] = str(CMU_BVH)
    line = _refused(tmp_path, data, capsys)
    assert "motion.place:" in line and re.search(r"[0-9.]+ m from the garment", line), line
    data["motion"]["place"] = "garment"
    plan = _plan(tmp_path, data)
    lower, upper = wear.garment_box(_plan_scene(tmp_path), tmp_path / "scene.toml")
    np.testing.assert_allclose(_centroid(plan.body.pose(0.0))[:2], (0.5 * (lower + upper))[:2], atol=1e-12)
    assert plan.timeline.motion_time == pytest.approx(1.0)
