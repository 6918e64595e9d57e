"""The verdict of a run: plausibility checks with their values and bounds in summary.json, one line per failed
check, status "completed with warnings" and exit code 3 (fabricfem.wear.verdict, fabricfem.scenes.dynamic)."""
import json
from pathlib import Path

import pytest
from shipped_scenes import scene_data
from toml_text import dumps

from fabricfem import cli
from fabricfem.scenes.dynamic import dynamic_checks
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.verdict import Bounds, wear_checks

ROOT = Path(__file__).resolve().parents[1]


def _sleeve(tmp_path: Path, **changes) -> Path:
    """scenes/sleeve.toml to 3 degrees in records of 1.5 degrees after 0.1 s of rest, no renders, with `changes`
    ({section: {key: value}})."""
    data = scene_data("sleeve.toml")
    data["motion"].update(final_angle=3.0, output_angle_step=1.5, settle_time=0.1)
    data["output"] = {"dir": str(tmp_path / "out"), "render": False}
    for section, values in changes.items():
        data.setdefault(section, {}).update(values)
    path = tmp_path / "scene.toml"
    path.write_text(dumps(data))
    return path


def _summary(tmp_path: Path) -> dict:
    return json.loads((tmp_path / "out" / "summary.json").read_text())


def test_a_plausible_sleeve_completes_with_every_check_passed(tmp_path, capsys):
    assert cli.main(["run", str(_sleeve(tmp_path))]) == 0
    summary = _summary(tmp_path)
    assert summary["status"] == "completed" and summary["verdict"]["status"] == "plausible"
    names = {c["name"] for c in summary["verdict"]["checks"]}
    assert names == {"penetration", "seam gap", "fabric strain", "skin pressure", "kinetic energy", "start distance",
                     "contact", "intersecting triangle pairs", "local strain"}
    local = next(c for c in summary["verdict"]["checks"] if c["name"] == "local strain")
    # the quadrature-point maximum is at least the largest vertex (patch) average (an average never exceeds its max)
    assert summary["max_local_strain"] == local["value"] >= summary["max_strain"] > 0.0
    assert summary["max_intersecting_pairs"] == 0 and summary["self_contact"] is False
    assert "CHECK FAILED" not in capsys.readouterr().out


def _step(**values) -> WearStep:
    base = dict(phase="motion", time=1.0, torques={"knee": 0.1}, peak_pressure=2e3, peak_segment="shank",
                peak_position=(0.0, 0.0, 0.0), mean_pressure=1e3, max_penetration=1e-5, contact_force=1.0,
                seam_gap=1e-4, seam_forces={}, max_strain=0.05, time_steps=10, kinetic_energy=1e-4,
                strain_energy=1e-2, wall=0.0)
    return WearStep(**{**base, **values})


@pytest.mark.parametrize("values, failed", [
    ({}, set()),
    ({"peak_pressure": 2.9e6}, {"skin pressure"}),        # the two-stride pants' 2943 kPa record
    ({"max_strain": 4.47}, {"fabric strain"}),            # and its Green strain
    ({"seam_gap": 0.14}, {"seam gap"}),                   # seam corners held 0.14 m apart
    ({"max_penetration": 5e-3}, {"penetration"}),
    ({"kinetic_energy": 1e-2}, {"kinetic energy"}),
    ({"contact_force": 0.0}, {"contact"}),
])
def test_each_check_compares_its_record_values_with_its_bound(values, failed):
    history = WearHistory("pants", steps=[_step(phase="settle"), _step(**values)], initial_gap=0.01)
    checks = wear_checks(history, Bounds(), failure_strain=0.3)
    assert {c.name for c in checks if not c.passed} == failed
    assert all(c.line().startswith(f"CHECK FAILED {c.name}") for c in checks if not c.passed)


def test_the_kinetic_check_takes_the_energy_relative_to_the_body_where_a_record_has_it():
    """A record whose ground-frame kinetic energy equals its strain energy (ratio 1, above the bound 0.5) passes when
    its energy relative to the body (fabricfem.wear.relative_motion) is a tenth of it, and fails without that
    measurement (nan)."""
    def check(step):
        history = WearHistory("walk", steps=[_step(phase="settle"), step], initial_gap=0.01)
        return {c.name: c for c in wear_checks(history, Bounds(), failure_strain=0.3)}["kinetic energy"]
    relative = check(_step(kinetic_energy=1e-2, relative_kinetic_energy=1e-3))
    assert relative.passed and relative.value == 0.1
    ground = check(_step(kinetic_energy=1e-2))
    assert not ground.passed and ground.value == 1.0


def test_the_local_strain_is_reported_and_never_fails():
    """The records' largest quadrature-point strain is information: its check passes above the failure strain, it
    is in the summary, and records that did not measure it (nan) leave both out."""
    history = WearHistory("pants", steps=[_step(phase="settle"), _step(max_local_strain=5.45)], initial_gap=0.01)
    check = {c.name: c for c in wear_checks(history, Bounds(), failure_strain=0.3)}["local strain"]
    assert check.passed and check.value == 5.45 and check.bound == 0.3
    assert history.summary()["max_local_strain"] == 5.45
    unmeasured = WearHistory("pants", steps=[_step()], initial_gap=0.01)
    assert "local strain" not in {c.name for c in wear_checks(unmeasured)}
    assert "max_local_strain" not in unmeasured.summary()


@pytest.mark.parametrize("self_contact, counts, failed", [
    (True, [0, 0], False), (True, [0, 3], True), (False, [0, 3], False), (False, [None, None], None)])
def test_intersecting_triangle_pairs_fail_only_with_self_contact_on(self_contact, counts, failed):
    """The records' largest count of intersecting triangle pairs is a failed check above 0 with self-contact on,
    information (passed, its value kept) with it off, and no check when no record counted."""
    history = WearHistory("sleeve", steps=[_step(intersecting_pairs=c) for c in counts], initial_gap=0.01,
                          self_contact=self_contact)
    check = {c.name: c for c in wear_checks(history, Bounds())}.get("intersecting triangle pairs")
    if failed is None:
        assert check is None and "max_intersecting_pairs" not in history.summary()
        return
    assert check.passed is not failed and check.value == max(counts)
    assert history.summary()["max_intersecting_pairs"] == max(counts)


@pytest.mark.parametrize("values, words", [
    ({"self_contact": True, "self_contact_distance": 0.0}, "contact.self_contact_distance: must be a positive"),
    ({"self_contact": True, "self_contact_distance": 0.05}, "contact.self_contact_distance: 0.05 m exceeds the mesh"),
    ({"self_contact": True, "self_friction": -0.1}, "self_friction must be a number >= 0"),
])
def test_bad_self_contact_keys_exit_2_with_one_line_naming_them(tmp_path, capsys, values, words):
    """A zero contact distance, one beyond the mesh size (10 x 13: 0.049 m) and a negative friction are refused
    before any meshing: exit 2, one line naming the key."""
    assert cli.main(["run", str(_sleeve(tmp_path, contact=values))]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1


def test_the_energy_balance_of_a_dynamic_run():
    """The strain-limited corner-pinned cloth closes its balance to 2e-4 (scenes/corner_pinned.toml); a run that
    gains 6 % of its work from nowhere fails (tolerance 5 %)."""
    good = {"kinetic_J": 0.041388, "strain_J": 0.000446, "dissipated_J": 0.008979, "external_work_J": 0.050821,
            "max_strain_recorded": 0.01}
    assert all(c.passed for c in dynamic_checks(good, 0.3))
    bad = {**good, "kinetic_J": good["kinetic_J"] + 0.06 * good["external_work_J"]}
    assert [c.name for c in dynamic_checks(bad, 0.3) if not c.passed] == ["energy balance"]


def test_the_renders_colour_range_ends_at_a_high_percentile():
    """One 2.9 MPa outlier among 1-3 kPa pressures: the colour range ends near 3 kPa, the true maximum is kept."""
    import numpy as np

    from fabricfem.wear.recorder import colour_top
    frames = [np.linspace(1e3, 3e3, 500), np.concatenate([np.zeros(100), np.linspace(1e3, 3e3, 499), [2.9e6]])]
    top, largest = colour_top(frames)
    assert 2.9e3 < top < 3.1e3 and largest == 2.9e6


def test_a_garment_sewn_around_the_body_is_not_judged_by_its_start_distance():
    """Pattern panels start apart around the body (the pants: 0.11 m) and are sewn on: no start-distance check."""
    sewn = WearHistory("pants", steps=[_step(phase="sew"), _step()], initial_gap=0.11)
    assert "start distance" not in {c.name for c in wear_checks(sewn)}
    worn = WearHistory("sleeve", steps=[_step(phase="settle"), _step()], initial_gap=0.11)
    assert [c.name for c in wear_checks(worn) if not c.passed] == ["start distance"]


@pytest.mark.parametrize("section, values, words", [
    ("checks", {"max_skin_pressure": -1.0}, "checks: max_skin_pressure must be a positive finite bound"),
    ("checks", {"max_penetration": float("inf")}, "checks: max_penetration must be a positive finite bound"),
    ("fabric", {"failure_strain": 0.0}, "fabric.failure_strain: must be > 0"),
    ("output", {"windows": [[57.0, 20.0]]}, r"output.windows\[0\]: a window \[a, b\] needs a < b"),
    ("output", {"windows": [[20.0]]}, r"output.windows\[0\]: expected a list of 2 numbers"),
    ("output", {"sensor_diameter": 0.0}, "output.sensor_diameter: must be > 0"),
    ("output", {"sensor_diameter": float("nan")}, "output.sensor_diameter: must be finite"),
    ("output", {"sensor_diameter": "3 cm"}, "output.sensor_diameter: expected"),
])
def test_bad_verdict_and_window_keys_are_refused_naming_them(tmp_path, section, values, words):
    import re

    from fabricfem import scenes as scene_module
    data = scene_data("sleeve.toml")
    data.setdefault(section, {}).update(values)
    with pytest.raises(scene_module.SceneError, match=words if "\\" in words else re.escape(words)):
        scene_module.validate(data)
