"""Scene files: validation before meshing (errors name the key) and a complete small run."""
import csv
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from toml_text import dumps

from fabricfem import scenes as scene_module
from fabricfem.cli import main
from fabricfem.scenes.run import build_model, run_scene
from fabricfem.scenes.schema import SceneError

ROOT = Path(__file__).resolve().parents[1]


def rollup_data() -> dict:
    return tomllib.loads((ROOT / "scenes" / "rollup.toml").read_text())


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["fabric"].update(E_1=1.0), r"unknown key 'E_1' \(did you mean 'E1'\?\)"),
    (lambda d: d.pop("fabric"), r"missing section \[fabric\]"),
    (lambda d: d.update(meshh={}), r"unknown section \[meshh\] .*\(did you mean 'mesh'\?\)"),
    (lambda d: d["mesh"].update(nx="sixty"), r"mesh.nx: expected int"),
    (lambda d: d["mesh"].pop("lx"), r"a plate needs \['lx'\]"),
    (lambda d: d["load"][0].update(type="moment"), r"unknown load 'moment'"),
    (lambda d: d["fabric"].pop("thickness"), r"missing required key 'thickness'"),
    (lambda d: d["support"][0].update(point=[0, 0, 0]), r"support\[0\]: give exactly one of 'edge'"),
    (lambda d: d["support"][0].pop("edge"), r"support\[0\]: give exactly one of 'edge'"),
    (lambda d: d["support"][0].pop("edge") and d["support"][0].update(point=[0, 0]),
     r"support\[0\].point: expected a list of 3 numbers"),
])
def test_bad_scene_is_refused_before_meshing(mutate, message):
    data = rollup_data()
    mutate(data)
    with pytest.raises(SceneError, match=message):
        scene_module.validate(data)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["fabric"].update(E1=-5e6), r"fabric: E1 must be a positive"),
    (lambda d: d["fabric"].update(nu12=0.9, E1=1e6, E2=3e6), r"nu12"),
    (lambda d: d["support"][0].update(edge="shoulder"), r"support\[0\].edge: a plate has no edge 'shoulder'"),
    (lambda d: d["support"][0].update(u=[0, 0]), r"support\[0\].u: expected 3 components"),
    (lambda d: d["support"][0].pop("edge") and d["support"][0].update(point=[0.0011, 0.0, 0.0]),
     r"support\[0\].point: point .* is not a mesh node"),
])
def test_bad_values_name_the_key(mutate, message):
    data = rollup_data()
    mutate(data)
    with pytest.raises(SceneError, match=message):
        build_model(scene_module.validate(data))


def test_cli_run_reports_scene_error(tmp_path, capsys):
    path = tmp_path / "typo.toml"
    path.write_text((ROOT / "scenes" / "rollup.toml").read_text().replace("thickness", "thicknes"))
    assert main(["run", str(path)]) == 2
    assert "thicknes" in capsys.readouterr().err


def test_run_small_rollup_scene(tmp_path):
    """The roll-up scene on a coarser mesh: the probe (tip) ends on the clamp after a full turn
    (|tip - clamp| < 1% L, the verify tolerance) and the outputs exist."""
    data = rollup_data()
    data["mesh"].update(nx=20, ny=1)
    data["output"].update(dir=str(tmp_path), render=False)
    outcome = run_scene(scene_module.validate(data))
    history = outcome.result
    assert outcome.status == "completed" and outcome.exit_code == 0
    assert history[-1].load_factor == pytest.approx(1.0)
    rows = list(csv.reader(open(tmp_path / "history.csv")))
    tip = np.array([0.3, 0.0, 0.0]) + np.array([float(v) for v in rows[-1][2:5]])
    assert np.linalg.norm(tip - [0.0, tip[1], 0.0]) < 0.01 * 0.3
    assert (tmp_path / "solution.xdmf").exists() and (tmp_path / "solution.h5").exists()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["load_steps"] == len(history) and summary["status"] == "completed"
    assert set(summary["outputs"]) >= {"solution.xdmf", "solution.h5", "history.csv"}
    assert 50.0 < summary["peak_memory_mib"] < 1.0e5  # MiB (max over ranks of ru_maxrss)


def test_point_support_clamps_a_node(tmp_path):
    """A support at a node (point = [x, y, z]) holds that node only: the strip pinned at its two left corners
    (u and theta) under the end moment still turns, and the pinned corner does not move."""
    data = rollup_data()
    data["mesh"].update(nx=20, ny=1)
    data["solver"]["targets"] = [0.05]
    data["support"] = [{"point": [0.0, y, 0.0], "u": [0, 0, 0], "theta": [0, 0]} for y in (0.0, 0.03)]
    data["output"].update(dir=str(tmp_path), render=False)
    scene = scene_module.validate(data)
    model = build_model(scene)
    assert len(model.bcs) == 10  # 2 nodes x (3 displacements + 2 rotations)
    run_scene(scene)
    rows = list(csv.reader(open(tmp_path / "history.csv")))
    assert abs(float(rows[-1][4])) > 1e-3  # the tip moved (m)


def test_scene_reference_is_generated_from_the_section_dataclasses():
    """docs/scenes.md is the output of `fabricfem scenes --markdown` (regenerate it after changing a section), and
    every key of every section's schema appears in it."""
    text = scene_module.schema.reference_markdown()
    assert (ROOT / "docs" / "scenes.md").read_text() == text + "\n"
    for kind, sections in scene_module.schema.SCHEMA.items():        # kind -> section -> key -> (types, required)
        for section, keys in sections.items():
            for key in keys:
                assert f"| {key} |" in text, (kind, section, key)


def test_rerun_into_the_same_folder_leaves_no_stale_output(tmp_path):
    """A first run renders final.png; a rerun of a changed scene (fewer steps, no render) into the same folder
    removes the first run's outputs before it starts, so nothing of the first run passes for the second's; its
    summary names the scene (hash) and lists only its own files."""
    data = rollup_data()
    data["mesh"].update(nx=10, ny=1)
    data["solver"]["targets"] = [0.1, 0.2]
    data["output"].update(dir=str(tmp_path), render=True)
    first = run_scene(scene_module.validate(data))
    assert (tmp_path / "final.png").exists() and first.exit_code == 0
    first_hash = json.loads((tmp_path / "summary.json").read_text())["scene_sha256"]
    data["solver"]["targets"] = [0.1]
    data["output"]["render"] = False
    second = run_scene(scene_module.validate(data))
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert not (tmp_path / "final.png").exists()
    assert "final.png" not in summary["outputs"] and summary["status"] == "completed"
    assert summary["scene_sha256"] != first_hash and len(summary["scene_sha256"]) == 64
    assert len(list(csv.reader(open(tmp_path / "history.csv")))) == 1 + len(second.result)


def test_a_run_that_stops_early_exits_1_and_says_so(tmp_path, capsys):
    """A static scene whose load cannot be carried within the step limits (two Newton iterations allowed, no
    step below the full load): exit code 1, one line on stderr saying why, and summary.json's status "failed"."""
    data = rollup_data()
    data["mesh"].update(nx=10, ny=1)
    data["solver"].update(targets=[1.0], initial_step=1.0, min_step=1.0, petsc_options={"snes_max_it": 2})
    data["output"].update(dir=str(tmp_path), render=False)
    path = tmp_path / "stops.toml"
    path.write_text(dumps(data))
    assert main(["run", str(path)]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("fabricfem run: stopped:"), err
    assert json.loads((tmp_path / "summary.json").read_text())["status"].startswith("failed:")
