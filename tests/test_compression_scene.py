"""Compression scenes ([limb], [donning]): validation before meshing (errors name the key) and a small run
through `fabricfem run`."""
import tomllib
from pathlib import Path

import pytest

from fabricfem import scenes as scene_module
from fabricfem.cli import main
from fabricfem.scenes.schema import SceneError

ROOT = Path(__file__).resolve().parents[1]


def compression_data() -> dict:
    return tomllib.loads((ROOT / "tests" / "data" / "compression_kind.toml").read_text())


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["limb"].update(radius=[0.1, 0.04, 0.04]), r"unknown key 'radius' \(did you mean 'radii'\?\)"),
    (lambda d: d.pop("limb"), r"missing section \[limb\]"),
    (lambda d: d.update(solver={"targets": [1.0]}), r"compression scene"),
    (lambda d: d["mesh"].update(n_around=30), r"mesh.n_around: must be a multiple of 4"),
    (lambda d: d["mesh"].update(type="plate", lx=1.0, ly=1.0, nx=2, ny=2), r"mesh.type: a compression scene"),
    (lambda d: d["limb"].update(center=[0.12, 0.01, 0.0]), r"limb.center: the limb must lie on the tube axis"),
    (lambda d: d["limb"].update(radii=[0.3, -0.04, 0.03]), r"limb.radii: must be positive"),
    (lambda d: d["limb"].update(radii=[0.3, 0.04]), r"limb.radii: expected a list of 3 numbers"),
    (lambda d: d["donning"].update(start=0.9), r"donning.start: the limb at 0.9 .* does not fit inside"),
    (lambda d: d["donning"].update(start=-0.5), r"donning.start: .* must lie in \(0, 1\]"),
    (lambda d: d["donning"].update(steps=0), r"donning.steps: must be positive"),
])
def test_bad_compression_scene_is_refused_before_meshing(mutate, message):
    data = compression_data()
    mutate(data)
    with pytest.raises(SceneError, match=message):
        scene_module.validate(data)


def test_default_start_leaves_the_limb_inside():
    data = compression_data()
    data["donning"].pop("start")
    scene_module.validate(data)
    assert scene_module.donning_start(data) * 0.044 == pytest.approx(0.95 * 0.034)


def test_run_small_compression_scene(tmp_path, capsys):
    """`fabricfem run` of a coarse compression scene writes its outputs and prints the summary. (16 x 4 cells
    were too coarse: Newton stalled at 0.948 of the limb's size after 4 cuts; 16 x 8 runs in ~8 s.)"""
    text = (ROOT / "tests" / "data" / "compression_kind.toml").read_text()
    text = (text.replace("n_around = 32", "n_around = 16").replace("n_along = 16", "n_along = 8")
            .replace("steps = 12", "steps = 4").replace('dir = "results/compression_kind"', f'dir = "{tmp_path}"'))
    path = tmp_path / "scene.toml"
    path.write_text(text)
    assert main(["run", str(path)]) == 0
    assert "pressure on the skin" in capsys.readouterr().out
    for name in ("sleeve.xdmf", "pressure.png", "pressure_profile.csv", "pressure_profile.png"):
        assert (tmp_path / name).exists(), name
