"""The accuracy target of wear scenes (fabricfem.scenes.accuracy, WearLevels in its docstring): the garment's mesh
as the levels, a quantity of the wear run's summary.json, the pilots cut to a window of body time; the plan of a
small sleeve (observed order or NOT ASYMPTOTIC, a choice or a refusal), `run --accuracy` delivering the whole
scene, the compression sleeve on a cylinder against Laplace's law, and bad input refused before meshing."""
import json
import tomllib
from pathlib import Path

import pytest
from toml_text import dumps

from fabricfem import cli
from fabricfem.materials import Fabric
from fabricfem.scenes.accuracy import plan
from fabricfem.scenes.build import load as load_scene
from fabricfem.scenes.errors import SceneError
from fabricfem.wear.compression import laplace_pressure

ROOT = Path(__file__).resolve().parents[1]
WINDOW = 0.45       # s: the sleeve settles for 0.4 s, then 0.05 s (2.25 degrees) of the flexion


def _sleeve(tmp_path: Path, **accuracy) -> Path:
    """The sleeve on a coarse 8 x 10 tube, levels x 1.3 (5x6, 6x8, 8x10), the pilots on the first WINDOW s."""
    data = tomllib.loads((ROOT / "scenes" / "sleeve.toml").read_text())
    data["garment"].update(n_around=8, n_along=10)
    data["output"] = {"dir": str(tmp_path / "sleeve"), "render": False}
    data["accuracy"] = {"quantity": "torque_elbow_peak_Nm", "window": WINDOW, "ratio": 1.3, "finer_levels": 1,
                        **accuracy}
    path = tmp_path / "sleeve.toml"
    path.write_text(dumps(data))
    return path


CYLINDER_RADIUS = 0.04      # m: the limb, 20 m long along x, is a cylinder over the tube's 0.24 m


def _compression(tmp_path: Path) -> Path:
    """The compression sleeve (relaxed radius 34 mm; an explicit wear scene: the limb grown into the tube, then held
    still while the sleeve settles) on a cylinder of 40 mm: Laplace's law holds along the tube."""
    data = tomllib.loads((ROOT / "scenes" / "compression_sleeve.toml").read_text())
    data["garment"].update(n_around=16, n_along=8)
    data["body"]["radii"] = [20.0, CYLINDER_RADIUS, CYLINDER_RADIUS]
    data["output"] = {"dir": str(tmp_path / "compression"), "render": False}
    data["accuracy"] = {"quantity": "pressure_mean_Pa", "finer_levels": 1}
    path = tmp_path / "compression.toml"
    path.write_text(dumps(data))
    return path


def test_sleeve_plan_table_then_run_delivers_the_whole_scene(tmp_path, capsys):
    """The plan of the sleeve's window: three pilots of decreasing cell size, the table with its steps (the
    critical step follows the mesh), an observed order or NOT ASYMPTOTIC with conservative estimates, the window
    said; then run --accuracy (a loose target that a pilot meets) runs the chosen level over the whole flexion
    and writes the estimate into summary.json."""
    path = _sleeve(tmp_path)
    result = plan(load_scene(path), 0.5)
    out = capsys.readouterr().out
    pilots = [lv for lv in result.levels if lv.value is not None]
    assert [lv.scene["garment"]["n_around"] for lv in pilots] == [5, 6, 8]
    assert pilots[0].step > pilots[-1].step and pilots[0].dofs < pilots[-1].dofs
    assert "accuracy plan: torque_elbow_peak_Nm" in out and "window: the pilots ran the first 0.45 s" in out
    assert ("observed order p =" in out) == result.asymptotic and ("NOT ASYMPTOTIC" in out) != result.asymptotic
    if not result.asymptotic:   # conservative: only the solved levels can be chosen
        assert result.levels[-1].error is None and (result.chosen is None or result.chosen.value is not None)
    chosen = result.require()
    assert chosen.error <= 0.5 and "<- chosen" in out
    assert cli.main(["run", str(path), "--accuracy", "50%"]) == 0
    out = capsys.readouterr().out
    assert out.count("read back") == 3 and "accuracy: chose level" in out
    summary = json.loads((tmp_path / "sleeve" / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["accuracy_window_s"] == WINDOW
    assert summary["accuracy_level"] == chosen.k and summary["accuracy_estimated_error"] <= 0.5
    assert summary["torque_elbow"]["final_at"] == pytest.approx(57.0)        # the whole flexion, not the window
    assert (tmp_path / "sleeve" / "accuracy_plan.csv").is_file()


def test_compression_mean_pressure_meets_the_target_against_laplace(tmp_path, capsys):
    """The compression sleeve on a cylinder, the mean contact pressure over the still phase: the level chosen for
    0.1% is delivered, and its true error against Laplace's law p = T / r (St. Venant-Kirchhoff hoop tension, the
    axial force free) is below the target, as is its estimate; at 1e-4 every pilot's estimate bounds its true
    error."""
    path = _compression(tmp_path)
    assert cli.main(["run", str(path), "--accuracy", "0.1%"]) == 0
    summary = json.loads((tmp_path / "compression" / "summary.json").read_text())
    fabric = Fabric(E1=0.8e6, E2=0.5e6, G12=0.1e6, nu12=0.3, thickness=7e-4, density=400.0)
    exact = laplace_pressure(fabric, 0.034, CYLINDER_RADIUS, axial="free").pressure
    true = abs(summary["pressure"]["mean_Pa"] - exact) / exact
    assert summary["accuracy_quantity"] == "pressure_mean_Pa" and summary["accuracy_window_s"] is None
    assert true <= summary["accuracy_target"] == 0.001 and summary["accuracy_estimated_error"] <= 0.001
    assert "<- chosen" in capsys.readouterr().out
    # 1e-4: the pilots read back. On the explicit engine the pilots' values need not converge monotonically at this
    # level (measured: -7.7e-2, +5.7e-5, -1.4e-6 relative to Laplace on 6x3, 10x5, 16x8), and the planner then gives
    # conservative estimates: each pilot's estimate bounds its true error against Laplace, and a level it chooses is
    # finer than the coarsest pilot and meets 1e-4 against Laplace
    tight = plan(load_scene(path), 1e-4)
    pilots = [lv for lv in tight.levels if lv.value is not None]
    assert len(pilots) == 3
    for lv in pilots:
        assert abs(lv.value - exact) / exact <= lv.error, (lv.k, lv.value, lv.error)
    if tight.chosen is not None:
        assert tight.chosen.k > -2 and abs(tight.chosen.value - exact) / exact <= 1e-4


def _refused(path: Path, capsys, *args) -> str:
    code = cli.main(["plan", str(path), *args])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("change, text", [
    ({"quantity": "elbow_torque"}, "accuracy.quantity: 'elbow_torque' is not a monitored output"),
    ({"window": 0.0}, "accuracy.window: must be a positive body time"),
    ({"window": -1.0}, "accuracy.window: must be a positive body time"),
    ({"window": 5.0}, "accuracy.window: 5 s is longer than the scene (1.66"),
    ({"ratio": 1.0}, "accuracy.ratio: a refinement ratio in (1, 4]"),
    ({"target": 1.5}, "accuracy.target")])
def test_bad_wear_accuracy_refused_before_meshing(change, text, tmp_path, capsys, no_meshing):
    """Each bad [accuracy] key is refused in one line naming it, before anything is meshed or run; an unknown
    quantity lists the valid ones."""
    message = _refused(_sleeve(tmp_path, **change), capsys, "--accuracy", "10%")
    assert text in message
    if "quantity" in change:
        assert "torque_elbow_final_Nm" in message and "pressure_peak_Pa" in message and "max_strain" in message


def test_bad_wear_accuracy_requests(tmp_path, capsys, no_meshing):
    """--quantity unknown on the command line, a window on a quasi-static route (the sleeve's Newton route:
    an accuracy target runs on the explicit engine only), --window too long or negative, and a sleeve on a tube too
    coarse for two coarser pilots: refused naming the key, nothing meshed."""
    message = _refused(_sleeve(tmp_path), capsys, "--accuracy", "1%", "--quantity", "peak_torque")
    assert "accuracy.quantity" in message and "torque_elbow_final_Nm" in message
    data = tomllib.loads((ROOT / "tests" / "data" / "sleeve_quasistatic.toml").read_text())
    data["accuracy"] = {"quantity": "torque_elbow_peak_Nm", "window": 0.1}
    data["output"] = {"dir": str(tmp_path / "window"), "render": False}
    (tmp_path / "window.toml").write_text(dumps(data))
    assert "accuracy: an accuracy target runs a wear scene on the explicit engine" in _refused(
        tmp_path / "window.toml", capsys, "--accuracy", "1%")
    assert "accuracy.window: 9 s is longer" in _refused(_sleeve(tmp_path), capsys, "--accuracy", "1%", "--window", "9")
    assert "accuracy.window: must be a positive body time" in _refused(_sleeve(tmp_path), capsys, "--accuracy", "1%",
                                                               "--window", "-0.1")
    coarse = tomllib.loads(_sleeve(tmp_path).read_text())
    coarse["garment"].update(n_around=6, n_along=8)
    del coarse["accuracy"]["ratio"]
    (tmp_path / "coarse.toml").write_text(dumps(coarse))
    assert "garment.n_around: 6 cells around" in _refused(tmp_path / "coarse.toml", capsys, "--accuracy", "10%")


def test_end_time_cuts_the_phases():
    """route.end_time (the window) cuts the phases as scheduled: whole record intervals up to it."""
    from fabricfem.wear.garment import Timeline
    t = Timeline(record_time=0.1, donning_time=0.2, grow_from=0.8, settle_time=0.3, end_time=0.4)
    assert t.phase_records(1.0) == {"sew": 0, "pull": 0, "don": 2, "belt": 0, "settle": 2, "motion": 0}
    assert sum(Timeline(record_time=0.1, settle_time=0.3).phase_records(1.0).values()) == 13
    with pytest.raises(ValueError, match="end_time"):
        Timeline(end_time=0.0)
    with pytest.raises(SceneError, match="route.end_time: stops a run of the explicit engine"):
        from fabricfem.scenes.schema import validate
        data = tomllib.loads((ROOT / "tests" / "data" / "sleeve_quasistatic.toml").read_text())
        validate({**data, "route": {**data["route"], "end_time": 0.1}})
