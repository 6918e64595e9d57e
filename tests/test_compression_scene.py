"""The shipped compression sleeve scene (scenes/compression_sleeve.toml, a wear scene on the explicit engine): it
describes the demo's sleeve (demos/demo_compression_sleeve.py) and satisfies compression_run's conditions before
anything is meshed, and `fabricfem run` of a coarse copy writes the compression report."""
import importlib.util
import tomllib
from pathlib import Path

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.cli import main
from fabricfem.wear.compression import check_limb_on_axis

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "compression_sleeve.toml"


def scene() -> dict:
    return tomllib.loads(SCENE.read_text())


def demo():
    path = ROOT / "demos" / "demo_compression_sleeve.py"
    spec = importlib.util.spec_from_file_location("demo_compression_sleeve", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_scene_is_the_demo_on_the_explicit_engine():
    """Route, donning by growth, settling and frictionless contact of the scene equal the demo's constants."""
    data, d = scene(), demo()
    assert data["route"]["solver"] == "explicit" and data["donning"]["method"] == "grow"
    assert data["motion"]["type"] == "still" and data["contact"]["friction"] == 0.0
    assert data["body"]["type"] == "limb"
    assert np.allclose(data["body"]["center"], d.FOREARM.center) and np.allclose(data["body"]["radii"], d.FOREARM.radii)
    assert (data["garment"]["length"], data["garment"]["radius"]) == (d.LENGTH, d.RELAXED_RADIUS)
    assert (data["donning"]["start"], data["donning"]["time"], data["motion"]["duration"],
            data["motion"]["record_time"]) == (d.START, d.DONNING_TIME, d.SETTLE_TIME, d.RECORD_TIME)
    fabric = {k: data["fabric"][k] for k in ("E1", "E2", "G12", "nu12", "thickness", "density")}
    assert fabric == {k: getattr(d.KNIT, k) for k in fabric}


def test_scene_limb_fits_compression_run():
    """The limb lies on the tube's axis (check_limb_on_axis) and fits inside the relaxed tube at the start."""
    data = scene()
    limb = Ellipsoid(np.array(data["body"]["center"]), np.eye(3), np.array(data["body"]["radii"]))
    check_limb_on_axis(limb)
    assert data["donning"]["start"] * max(limb.radii[1:]) < data["garment"]["radius"]


def test_run_coarse_compression_scene(tmp_path, capsys):
    """`fabricfem run` of the scene on a 16 x 8 tube writes the compression report and prints the summary."""
    text = (SCENE.read_text().replace("n_around = 32", "n_around = 16").replace("n_along = 16", "n_along = 8")
            .replace('dir = "results/compression_sleeve"', f'dir = "{tmp_path}"\nrender = false'))
    path = tmp_path / "scene.toml"
    path.write_text(text)
    assert main(["run", str(path)]) == 0
    assert "pressure" in capsys.readouterr().out
    for name in ("sleeve.xdmf", "pressure_profile.csv", "pressure_profile.png"):
        assert (tmp_path / name).exists(), name
