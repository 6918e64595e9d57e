"""The accuracy commands' options as a user gives them: `run --accuracy ... --out DIR`
writes into DIR, and `plan` without a quantity lists the quantities the scene accepts."""
import json
import tomllib
from pathlib import Path

import pytest
from toml_text import dumps

from fabricfem import cli

ROOT = Path(__file__).resolve().parents[1]


def _strip(tmp_path: Path, quantity: str | None = "probe_ux_m") -> Path:
    """The rolled strip of scenes/rollup.toml on 8 x 4 cells, one load step, its [output] dir tmp_path/scene_dir."""
    data = tomllib.loads((ROOT / "scenes" / "rollup.toml").read_text())
    data["mesh"].update(nx=8, ny=4)
    data["solver"] = {"targets": [1.0], "initial_step": 0.05}
    data["output"].update(dir=str(tmp_path / "scene_dir"), render=False)
    data["accuracy"] = {"finer_levels": 1, **({"quantity": quantity} if quantity else {})}
    path = tmp_path / "strip.toml"
    path.write_text(dumps(data))
    return path


def test_run_with_accuracy_writes_into_out(tmp_path):
    """`run --accuracy 5% --out DIR`: the pilots under DIR/accuracy/, the chosen level's outputs, its summary.json
    (with the plan's entries) and accuracy_plan.csv in DIR; nothing in the scene's [output] dir."""
    path, out = _strip(tmp_path), tmp_path / "chosen"
    assert cli.main(["run", str(path), "--accuracy", "5%", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["accuracy_target"] == 0.05
    assert (out / "accuracy_plan.csv").is_file() and (out / "history.csv").is_file()
    assert sorted(p.name for p in (out / "accuracy").iterdir())[:3] == ["level+0", "level-1", "level-2"]
    assert not (tmp_path / "scene_dir").exists()


@pytest.mark.parametrize("args", [["--accuracy", "5%"], []])
def test_plan_without_a_quantity_lists_the_accepted_ones(args, tmp_path, capsys, no_meshing):
    """`plan` without --quantity and without [accuracy] quantity (with or without a target): exit 2, one line
    naming accuracy.quantity and listing the quantities this scene accepts (a static probe's three components),
    before anything is meshed."""
    code = cli.main(["plan", str(_strip(tmp_path, quantity=None)), *args])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1, err
    assert "accuracy.quantity" in err[0] and "probe_ux_m, probe_uy_m, probe_uz_m" in err[0], err[0]


def test_plan_of_a_wear_scene_lists_its_torque_quantities(tmp_path, capsys, no_meshing):
    """The sleeve: its monitors' peak and final torques, the pressures and the strain."""
    code = cli.main(["plan", str(ROOT / "scenes" / "sleeve.toml"), "--accuracy", "10%"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "torque_elbow_peak_Nm" in err and "pressure_peak_Pa" in err and "max_strain" in err, err
