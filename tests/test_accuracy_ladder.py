"""An accuracy target on a wear scene's windowed statistic uses the mesh ladder (fabricfem.studies.accuracy_ladder):
the coarsest ladder level within the target of the finest is chosen, run into the scene's folder, and its measured
difference reported in summary.json; a target no level below the finest meets is refused naming accuracy.target.
Quick path: a 6 x 8 sleeve flexed to 6 degrees, levels x 1.3 (6x8, 8x10, 10x14), about 1 s a level."""
import csv
import json
import tomllib
from pathlib import Path

import pytest
from toml_text import dumps

from fabricfem import cli
from fabricfem.scenes.build import load as load_scene
from fabricfem.scenes.errors import SceneError
from fabricfem.studies.accuracy_ladder import ladder_plan, quantity_name, uses_ladder

ROOT = Path(__file__).resolve().parents[1]
QUANTITY = "torque_elbow_window_mean_Nm"


def _sleeve(tmp_path: Path, **accuracy) -> Path:
    """scenes/sleeve.toml on a 6 x 8 tube to 6 degrees in records of 1 degree after 0.1 s of rest; the ladder
    x 1.3 with two finer levels."""
    data = tomllib.loads((ROOT / "scenes" / "sleeve.toml").read_text())
    data["garment"].update(n_around=6, n_along=8)
    data["motion"].update(final_angle=6.0, output_angle_step=1.0, settle_time=0.1)
    data["output"] = {"dir": str(tmp_path / "sleeve"), "render": False}
    data["accuracy"] = {"ratio": 1.3, "finer_levels": 2, **accuracy}
    path = tmp_path / "sleeve.toml"
    path.write_text(dumps(data))
    return path


def test_the_ladder_chooses_the_coarsest_level_within_the_target_and_delivers_it(tmp_path, capsys):
    """The plan's differences are those of the levels' summaries; a target just above the smaller difference of
    the two coarser levels chooses the coarsest level that meets it; run --accuracy reads the ladder back, runs that
    level into the scene's folder and reports its measured difference (the same run: equal to the ladder's)."""
    path = _sleeve(tmp_path)
    scene = load_scene(path)
    assert uses_ladder(scene, "torque_elbow.window_mean_Nm") and not uses_ladder(scene, "torque_elbow_peak_Nm")
    assert quantity_name(scene, "torque_elbow.window_mean_Nm") == QUANTITY
    plan = ladder_plan(scene, 0.5, QUANTITY)
    assert [d["garment"]["n_around"] for d in plan.datas] == [6, 8, 10]
    finest = json.loads((plan.folders[-1] / "summary.json").read_text())["torque_elbow"]["window_mean_Nm"]
    for folder, value, difference in zip(plan.folders, plan.values, plan.differences):
        mean = json.loads((folder / "summary.json").read_text())["torque_elbow"]["window_mean_Nm"]
        assert value == mean and difference == pytest.approx(abs(mean - finest) / abs(finest), rel=1e-12)
    target = 1.01 * min(plan.differences[:-1])
    expected = next(k for k, d in enumerate(plan.differences[:-1]) if d <= target)
    capsys.readouterr()
    assert cli.main(["run", str(path), "--accuracy", f"{target:.6f}", "--quantity",
                     "torque_elbow.window_mean_Nm"]) == 0
    out = capsys.readouterr().out
    assert out.count("read back") == 3 and "<- chosen" in out and "measured difference" in out
    summary = json.loads((tmp_path / "sleeve" / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["accuracy_method"] == "mesh ladder"
    assert summary["accuracy_level"] == expected and summary["accuracy_reference_mesh"] == "10x14"
    assert summary["accuracy_measured_difference"] <= target
    assert summary["accuracy_measured_difference"] == pytest.approx(plan.differences[expected], rel=1e-9)
    assert summary["torque_elbow"]["window_mean_Nm"] == pytest.approx(plan.values[expected], rel=1e-12)
    rows = list(csv.DictReader(open(tmp_path / "sleeve" / "accuracy_plan.csv")))
    assert [r["chosen"] for r in rows] == [str(k == expected) for k in range(3)]


def test_a_target_no_coarser_level_meets_is_refused(tmp_path, capsys):
    """Below every coarser level's difference: refused in one line naming accuracy.target with the measured
    differences (exit 2), the ladder kept for a rerun; a --window is refused naming accuracy.window."""
    path = _sleeve(tmp_path)
    plan = ladder_plan(load_scene(path), 0.5, QUANTITY)
    capsys.readouterr()
    tight = 0.5 * min(plan.differences[:-1])
    assert cli.main(["plan", str(path), "--accuracy", f"{tight:.3e}", "--quantity", QUANTITY]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "accuracy.target: no ladder level below the finest (10x14)" in err[0]
    assert "6x8" in err[0] and "8x10" in err[0]
    assert cli.main(["plan", str(path), "--accuracy", "5%", "--quantity", QUANTITY, "--window", "0.2"]) == 2
    assert "accuracy.window: a windowed statistic" in capsys.readouterr().err
    with pytest.raises(SceneError, match="accuracy.finer_levels"):
        ladder_plan(load_scene(_sleeve(tmp_path, finer_levels=0)), 0.05, QUANTITY)
