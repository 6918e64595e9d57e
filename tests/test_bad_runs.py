"""Bad runs are flagged: small versions of the implausible runs that used to end "completed" (the two-stride pants
with the crossing in stride 2, a sewn sleeve whose seam corners are held apart, a body that never touches the
garment, a strain beyond the fabric's failure strain) each end "completed with warnings", exit with
EXIT_WARNINGS (3) and print the failing check's line; the check's value and bound are in summary.json
(fabricfem.wear.verdict)."""
import json
from pathlib import Path

import pytest
from shipped_scenes import scene_data
from toml_text import dumps

from fabricfem import cli
from fabricfem.wear.verdict import EXIT_WARNINGS

ROOT = Path(__file__).resolve().parents[1]


def _scene(tmp_path: Path, name: str, **changes) -> dict:
    """scenes/<name> writing into tmp_path/out without renders, with `changes` ({section: {key: value}})."""
    data = scene_data(name)
    data["output"] = {"dir": str(tmp_path / "out"), "render": False}
    for section, values in changes.items():
        data.setdefault(section, {}).update(values)
    return data


def _run(tmp_path: Path, data: dict, capsys) -> tuple[str, dict]:
    """Run the scene data through `fabricfem run`: asserts exit 3 and the status; (stdout, summary.json)."""
    path = tmp_path / "scene.toml"
    path.write_text(dumps(data))
    assert cli.main(["run", str(path)]) == EXIT_WARNINGS
    out, err = capsys.readouterr()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"].startswith("completed with warnings: ") and summary["verdict"]["status"] == "warnings"
    assert f"completed with warnings: {', '.join(summary['verdict']['failed'])}" in err
    return out, summary


def _check(summary: dict, name: str) -> dict:
    return next(c for c in summary["verdict"]["checks"] if c["name"] == name)


def test_two_stride_pants_crossing_in_stride_two(tmp_path, capsys):
    """scenes/pants_walk.toml shortened to two strides with the obstacle crossed in the second, on h = 0.2 m (1940
    dofs, about three cells round a thigh; the shipped h = 0.07 m), one knee monitor, records of 0.04 s (0.02 s
    shipped). Measured on the tilted panels of 2026-11-28 (the shipped mesh's whole walk stays at strain 0.43 and
    33 kPa): Green strain 0.68 (above the fabric's failure strain 0.3) and a peak skin pressure of 2.6 MPa at the
    pelvis at t = 4.52 s, inside the crossing stride: this coarse mesh cannot follow the crossing. Its kinetic /
    strain energy ratio relative to the walking body (fabricfem.wear.relative_motion) is 0.11 and passes its bound
    0.5. The pressure was below the default bound of 100 kPa on earlier
    versions of the scene (a chaotic walk), so this test sets [checks] max_skin_pressure = 5 kPa, which the
    crossing must exceed."""
    from fabricfem.studies.pants import crossing_window
    data = _scene(tmp_path, "pants_walk.toml", garment={"h": 0.2},
                  motion={"strides": 2, "crossing_stride": 2, "record_time": 0.04},
                  checks={"max_skin_pressure": 5e3})
    data["torque"] = data["torque"][:1]
    out, summary = _run(tmp_path, data, capsys)
    assert {"fabric strain", "skin pressure"} <= set(summary["verdict"]["failed"])
    for name in ("fabric strain", "skin pressure"):
        assert f"CHECK FAILED {name}: " in out
    strain, pressure = _check(summary, "fabric strain"), _check(summary, "skin pressure")
    assert strain["bound"] == 0.3 and strain["value"] > 0.5
    assert pressure["bound"] == 5e3 and pressure["value"] > 5e3 and pressure["unit"] == "Pa"
    start, end = crossing_window(data)
    assert start <= summary["pressure"]["peak_time_s"] <= end           # the crossing presses hardest
    assert _check(summary, "seam gap")["passed"] and _check(summary, "penetration")["passed"]


SLEEVE_PANEL = [[-0.1, 0.0], [0.1, 0.0], [0.1, 0.5], [-0.1, 0.5]]     # m: 0.2 wide, 0.5 long; edge 0 the shoulder


def _sleeve_pattern(gap: float) -> str:
    """A two-panel sleeve as GarmentCode lays it out (tests/test_pattern_seams.py): the front at z = gap / 2, the
    back at -gap / 2 turned by 180 degrees about y, sewn along both long sides."""
    return f"""stitches = [["front", 1, "back", 3], ["front", 3, "back", 1]]
[panels.front]
vertices = {SLEEVE_PANEL}
translation = [0.0, 0.0, {gap / 2}]
[panels.back]
vertices = {SLEEVE_PANEL}
translation = [0.0, 0.0, {-gap / 2}]
rotation = [0.0, 180.0, 0.0]
"""


def test_sewn_sleeve_with_its_seam_corners_held_apart(tmp_path, capsys):
    """Both panels' shoulder edges held, their seam corners 8 mm apart, hung beside the standing lower body: the
    sewing closes the seams except at the held corners, which stay 8 mm apart (bound max_seam_gap 2 mm). (Corners
    held farther apart than 2 % of the stitched edge's length, as the 0.14 m of the run that used to end
    "completed", are refused before meshing naming garment.hold: tests/test_pattern_seams.py.) About 4 s."""
    gap = 0.008
    (tmp_path / "sleeve.toml").write_text(_sleeve_pattern(gap))
    data = _scene(tmp_path, "trousers_standing.toml", motion={"duration": 0.2})
    data["garment"].update(pattern=str(tmp_path / "sleeve.toml"), hold=["front.0", "back.0"], scale=1.0,
                           translate=[0.6, 0.0, 1.0])
    for key in ("donning", "torque"):
        data.pop(key)
    del data["garment"]["rotate"]
    out, summary = _run(tmp_path, data, capsys)
    assert "seam gap" in summary["verdict"]["failed"] and "CHECK FAILED seam gap: " in out
    seam = _check(summary, "seam gap")
    assert seam["bound"] == 2e-3 and seam["value"] == pytest.approx(gap, rel=0.05) and seam["unit"] == "m"


def _sleeve(tmp_path: Path, **changes) -> dict:
    """scenes/sleeve.toml to 3 degrees in records of 1.5 degrees after 0.1 s of rest."""
    return _scene(tmp_path, "sleeve.toml", **{"motion": {"final_angle": 3.0, "output_angle_step": 1.5,
                                                          "settle_time": 0.1}, **changes})


def test_a_body_that_never_touches_the_garment(tmp_path, capsys):
    """Without gravity a 0.12 m tube floats around the arm (64 mm away): no contact during the motion, and the
    start distance above its bound (5 cm). About 3 s."""
    out, summary = _run(tmp_path, _sleeve(tmp_path, garment={"radius": 0.12}, route={"gravity": False}), capsys)
    assert "CHECK FAILED contact" in out and "CHECK FAILED start distance" in out
    assert {"contact", "start distance"} <= set(summary["verdict"]["failed"])   # (and KE/SE: no strain)
    start = _check(summary, "start distance")
    assert start["bound"] == 0.05 and start["value"] > 0.06
    assert _check(summary, "contact")["value"] == 0.0


def test_the_strain_check_exceeded(tmp_path, capsys):
    """The sleeve strains its cotton to about 8e-3 (Green): a failure strain of 1e-3 flags it. About 3 s."""
    out, summary = _run(tmp_path, _sleeve(tmp_path, fabric={"failure_strain": 1e-3}), capsys)
    assert "CHECK FAILED fabric strain" in out
    assert summary["status"] == "completed with warnings: fabric strain"
    strain = _check(summary, "fabric strain")
    assert strain["bound"] == 1e-3 and strain["value"] > 1e-3 and not strain["passed"]
