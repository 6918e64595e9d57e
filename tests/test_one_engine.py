"""One engine and one scene contract: the sleeve study, the sleeve demo and the shipped sleeve scene run the same
program (the garment engine) and give the same torque history; scenes name their kind; the older sleeve and
compression layouts are refused with every moved key in one message."""
import importlib.util
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import scene_data
from toml_text import dumps

from fabricfem import cli
from fabricfem import scenes as scene_module
from fabricfem.scenes.run import run_scene
from fabricfem.studies.sleeve import run_study

ROOT = Path(__file__).resolve().parents[1]
QUICK = {"final_angle": 6.0, "output_angle_step": 3.0, "angle_steps": 2}   # the study's and the demo's quick flexion


def test_the_second_programs_are_gone():
    found = subprocess.run(["grep", "-rn", r"class ExplicitSleeve\|def run_compression_scene\|def sleeve_data\|"
                            r"def compression_data", str(ROOT / "fabricfem")], capture_output=True, text=True)
    assert found.stdout == ""


def test_study_demo_and_scene_give_the_same_torque_history(tmp_path):
    """Mesh I (10 x 13), mu = 0.1, to 6 degrees in records of 3 degrees after the 0.4 s rest: the same program,
    so the same numbers (tolerance 1e-12 N m: bit-identical expected; the bound allows nothing a second program
    could hide, the torque is 2.5e-2 to 5e-2 N m)."""
    study = run_study(tmp_path / "study", quick=True, only=("mesh_mu0.1",), mesh_frictions=(0.1,),
                      comm=MPI.COMM_SELF)
    angle, torque = next(iter(study["mesh_mu0.1"].values())).motion_curve("elbow")
    spec = importlib.util.spec_from_file_location("demo_sleeve", ROOT / "demos" / "demo_sleeve.py")
    demo_module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo_module)
    demo = demo_module.main(tmp_path / "demo", quick=True, comm=MPI.COMM_SELF)
    data = scene_data("sleeve.toml")
    data["motion"].update(QUICK)
    data["output"] = {"dir": str(tmp_path / "scene"), "render": False}
    scene = run_scene(scene_module.validate(data), MPI.COMM_SELF).result
    assert np.allclose(angle, [0.0, 3.0, 6.0], rtol=0.0, atol=1e-9)
    for other in (demo, scene):
        other_angle, other_torque = other.motion_curve("elbow")
        assert np.array_equal(other_angle, angle)
        assert np.max(np.abs(other_torque - torque)) <= 1e-12


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(dumps(data))
    return path


def test_a_scene_without_kind_exits_2_naming_kind(tmp_path, capsys):
    data = tomllib.loads((ROOT / "scenes" / "rollup.toml").read_text())
    del data["scene"]["kind"]
    assert cli.main(["run", str(_write(tmp_path, data))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[scene] kind" in err[0]


def test_an_old_sleeve_layout_lists_every_moved_key_in_one_message(tmp_path, capsys):
    data = tomllib.loads((ROOT / "tests" / "data" / "sleeve_kind.toml").read_text())
    data["motion"]["solver"] = data["route"].pop("solver")
    data["motion"]["mass_damping"] = data["route"].pop("mass_damping")
    assert cli.main(["run", str(_write(tmp_path, data))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    for moved in ("scene.kind = 'sleeve' -> scene.kind = \"wear\"", "mesh.length -> garment.length",
                  "mesh.radius -> garment.radius", "mesh.n_around -> garment.n_around", "mesh.type -> garment.builder",
                  "body.type -> body.type = \"arm\"", "motion.solver -> route.solver",
                  "motion.mass_damping -> route.mass_damping", "output.render_angles -> output.render_at"):
        assert moved in err[0], moved


def test_an_old_compression_layout_is_refused_with_its_moved_keys():
    data = {"scene": {"kind": "compression"}, "mesh": {"type": "tube", "length": 0.24, "radius": 0.034,
            "n_around": 16, "n_along": 8}, "fabric": {"E1": 1e6}, "limb": {"center": [0.12, 0, 0],
            "radii": [0.3, 0.04, 0.04]}, "donning": {"start": 0.7, "steps": 4}}
    with pytest.raises(scene_module.SceneError) as err:
        scene_module.validate(data)
    for moved in ("limb.center -> body.center", "limb.radii -> body.radii", "donning.steps -> donning.time",
                  "mesh.n_along -> garment.n_along"):
        assert moved in str(err.value)


@pytest.mark.parametrize("path", sorted((ROOT / "scenes").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_scene_parses_once_into_its_kinds_frozen_sections(path):
    import dataclasses

    from fabricfem.scenes.contract import DynamicScene, StaticScene, WearScene
    scene = scene_module.load(path)
    parsed = scene.parsed
    assert type(parsed) is {"static": StaticScene, "dynamic": DynamicScene, "wear": WearScene}[scene.kind]
    assert scene.parsed is parsed                      # parsed once
    with pytest.raises(dataclasses.FrozenInstanceError):
        parsed.scene = None
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.kind = "static"


def test_one_schema_table_for_every_kind():
    from fabricfem.scenes.schema import SCHEMA
    assert set(SCHEMA) == {"static", "dynamic", "wear"}
    assert "garment" in SCHEMA["wear"] and "garment" not in SCHEMA["static"]
    data = scene_data("sleeve.toml")
    data["garment"]["lenght"] = 0.5
    with pytest.raises(scene_module.SceneError, match=r"garment: unknown key 'lenght' \(did you mean 'length'\?\)"):
        scene_module.validate(data)
