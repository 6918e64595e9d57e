"""The shipped trousers on the Debian human (scenes/trousers_human.toml, a `[body] type = "mesh"` scene): run in
the tests' quick mode, and a mesh body's keys refused with one line naming the key before anything is meshed."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import meshio
import numpy as np
import pytest
import toml_text

from fabricfem.body.human import HUMAN_PATH
from fabricfem.scenes import build as scene_build
from fabricfem.scenes.errors import SceneError
from fabricfem.scenes.run import run_scene

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "trousers_human.toml"
needs_human = pytest.mark.skipif(not HUMAN_PATH.is_file(), reason=f"{HUMAN_PATH} absent: the Debian package "
                                 "assimp-testmodels (the human surface) is not installed")
# quick mode: a coarser garment, shorter sewing, growth and settling, and the run cut 0.1 s into the walk
QUICK = {"garment": {"h": 0.08, "sewing_time": 0.1}, "donning": {"time": 0.1}, "motion": {"settle_time": 0.05},
         "route": {"end_time": 0.35}, "output": {"render": False}}


def _scene(tmp_path: Path, changes: dict) -> Path:
    data = tomllib.loads(SCENE.read_text())
    for section, values in changes.items():
        data.setdefault(section, {}).update(values)
    path = tmp_path / "scene.toml"
    path.write_text(toml_text.dumps(data))
    return path


@needs_human
def test_trousers_on_the_human_run_in_quick_mode_and_write_the_skin_pressure(tmp_path):
    out = tmp_path / "run"
    outcome = run_scene(scene_build.load(_scene(tmp_path, QUICK)), out=out)
    assert outcome.status.startswith("completed"), outcome.status
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("completed")
    assert (out / "skin_pressure.xdmf").is_file() and sorted(out.glob("skin_pressure_*.vtp"))
    with meshio.xdmf.TimeSeriesReader(str(out / "skin_pressure.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        _, data, _ = reader.read_data(reader.num_steps - 1)
    assert len(cells[0].data) == 26756 and data["pressure"].shape == (len(points),)
    assert np.all(data["pressure"] >= 0.0) and data["pressure"].max() > 0.0     # the trousers touch the skin


@needs_human
@pytest.mark.parametrize("changes, key", [
    ({"body": {"file": str(HUMAN_PATH), "up": "y", "units": "cm"}}, "body.units"),   # a 1.7 cm body
    ({"body": {"file": str(HUMAN_PATH), "up": "z"}}, "body.up"),                     # lying on its side
    ({"body": {"file": "no_such_body.obj"}}, "body.file"),
    ({"body": {"skeleton": "torso"}}, "body.skeleton"),
    ({"body": {"up": "x"}}, "body.up"),
    ({"body": {"skinning": "dual_quaternion"}}, "body.skinning"),
    ({"body": {"components": "all"}}, "body.repair"),                          # the open eye shells kept
    ({"body": {"rest_positions": {"waist": [0.0, 0.0, 3.0]}}}, "body.rest_positions"),
    ({"motion": {"type": "elbow_flexion"}}, "motion.type"),
])
def test_a_mesh_body_is_refused_naming_the_key(tmp_path, changes, key):
    with pytest.raises(SceneError) as err:
        scene_build.load(_scene(tmp_path, changes))
    line = str(err.value)
    assert key in line and "\n" not in line, line
