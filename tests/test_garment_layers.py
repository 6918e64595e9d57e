"""Several garments in one wear scene ([[garment]], fabricfem.scenes.garments): the shipped two-garment scene reads
and builds, a quick version (a few degrees of flexion) runs with 0 intersecting triangle pairs at every record and
a positive pressure of the sleeve on the base layer, the layer pressure equals the load on two pressed concentric
tubes (fabricfem.verify.layers), and the bad inputs exit 2 with one line naming the key, before any meshing."""
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from toml_text import dumps, refused_in_one_line

from fabricfem import cli
from fabricfem.meshes.layers import TubeLayer, concentric_tubes
from fabricfem.scenes import build
from fabricfem.verify.layers import pressed_tubes

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "sleeve_layers.toml"


def _data() -> dict:
    return tomllib.loads(SCENE.read_text())


def test_the_scene_reads_and_parses_both_garments_inside_out():
    scene = build.load(SCENE)
    parsed = scene.parsed
    assert parsed.layered and [g.name for g in parsed.garments] == ["base", "sleeve"]
    assert parsed.garment.name == "base" and parsed.garments[1].radius > parsed.garments[0].radius
    assert parsed.contact.self_contact


def test_one_garment_as_an_array_of_tables_is_the_one_garment_scene():
    data = tomllib.loads((ROOT / "scenes" / "sleeve.toml").read_text())
    data["garment"] = [data["garment"]]
    parsed = build.validate(data, "one").parsed
    assert not parsed.layered and parsed.garment.radius == 0.06


def test_concentric_tubes_are_one_mesh_with_one_part_and_tag_per_layer():
    fmesh = concentric_tubes([TubeLayer("a", 0.2, 0.05, 6, 2), TubeLayer("b", 0.15, 0.06, 8, 2)], comm=MPI.COMM_SELF)
    assert sorted(fmesh.tags) == ["a.end0", "a.end1", "b.end0", "b.end1"]
    values, counts = np.unique(fmesh.cell_tags.values, return_counts=True)
    assert values.tolist() == [1, 2] and counts.tolist() == [12, 16]
    r = np.hypot(*fmesh.mesh.geometry.x[:, 1:].T)
    assert np.allclose(np.unique(np.round(r, 9)), [0.05, 0.06])


def test_quick_two_garment_flexion_keeps_the_layers_apart_and_pressed(tmp_path):
    """2 degrees after 0.1 s of rest on the shipped meshes (20 x 26, 20 x 23): 0 crossing triangle pairs at every
    record, the sleeve's weight on the base layer (a positive load), the base layer on the skin, none of the sleeve
    on the skin; the CSV has the per-garment columns and summary.json their peaks."""
    data = _data()
    data["motion"].update(final_angle=2.0, settle_time=0.1)
    data["output"] = {"dir": str(tmp_path / "out"), "render_at": []}
    path = tmp_path / "quick.toml"
    path.write_text(dumps(data))
    assert cli.main(["run", str(path)]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["max_intersecting_pairs"] == 0
    layers = summary["layers"]
    assert layers["sleeve_on_base_force_N"]["peak"] > 0.0 and layers["sleeve_on_base_peak_Pa"]["peak"] > 0.0
    assert layers["base_skin_peak_Pa"]["peak"] > 0.0 and layers["sleeve_skin_peak_Pa"]["peak"] == 0.0
    header = (tmp_path / "out" / "torque.csv").read_text().splitlines()[0]
    assert "sleeve_on_base_force_N" in header and "base_skin_mean_Pa" in header


def test_layer_pressure_equals_the_load_on_pressed_concentric_tubes():
    """The outer tube pressed by 100 Pa onto the held inner one: the monitor's load of the outer on the inner equals
    p sum A within 1 % (hoop share 0.35 %, fabricfem.verify.layers), its mean pressure p within 3 %."""
    out = pressed_tubes(comm=MPI.COMM_SELF)
    assert out["contact"] == pytest.approx(out["load"], rel=0.01)
    assert out["mean_Pa"] == pytest.approx(100.0, rel=0.03)


def _second(**values):
    return lambda d: d["garment"][1].update(values)


BAD = [  # (mutation, text the one-line error must contain)
    (_second(radius=0.055), "garment[1].radius"),                          # the outer garment inside
    (_second(radius=0.0605), "garment[1].radius"),                         # closer than the contact distance
    (lambda d: d["contact"].update(self_contact_distance=0.0), "contact.self_contact_distance"),
    (lambda d: d["contact"].update(self_contact_distance=0.05), "contact.self_contact_distance"),
    (lambda d: d["contact"].update(self_contact=False), "contact.self_contact"),
    (_second(fabric="plain-weave-ti-contact"), "garment[1].fabric"),
    (_second(builder="pattern", pattern="tshirt"), "garment[1].builder"),
    (_second(name="base"), "garment[1].name"),
    (_second(order=1), "garment[1].order"),
    (_second(hold=["wrist"]), "garment[1].hold"),
    (lambda d: d["route"].update(solver="quasistatic"), "route.solver"),
    (lambda d: d["garment"][1].pop("radius"), "garment[1]"),
]


@pytest.mark.parametrize("mutate, key", BAD, ids=[key + f"-{i}" for i, (_, key) in enumerate(BAD)])
def test_bad_layers_exit_2_with_one_line_naming_the_key(mutate, key, tmp_path, capsys, no_meshing, monkeypatch):
    def trap(*args, **kwargs):
        raise AssertionError("meshed before refusing the scene")
    monkeypatch.setattr("fabricfem.scenes.garments.concentric_tubes", trap)
    data = _data()
    data["output"]["dir"] = str(tmp_path / "out")
    mutate(data)
    refused_in_one_line(tmp_path / "bad.toml", data, key, capsys)
