"""[garment.wrap]: pattern panels rolled onto cylinders in the scene's frame (fabricfem.scenes.panel_placement), the
pants' wraps round their own legs (fabricfem.wear.pants.pants_wraps), and the setup's refusal of a self-contact run
whose seams are sewn through another panel (fabricfem.contact.sewing_lines). Checked against the geometry itself:
the distance of the placed nodes from the axis, the stitched edges' lengths, the side of the midline."""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from toml_text import refused_in_one_line

from fabricfem.meshes.pattern import edge_length
from fabricfem.scenes.build import load
from fabricfem.scenes.panel_placement import check_wrap, panel_placements
from fabricfem.scenes.schema import SceneError
from fabricfem.scenes.wear import garment_mesh, read_pattern
from fabricfem.wear.pants import PANTS_BODY, pants_sizes, pants_wraps

ROOT = Path(__file__).resolve().parents[1]
SELF_SCENE = ROOT / "scenes" / "pants_walk_self.toml"
GOOD = {"axis_point": [0.0, 0.1, 0.9], "axis": [0.0, 0.0, 1.0], "radius": 0.12, "zero_direction": [0.0, 1.0, 0.0]}


@pytest.mark.parametrize("table, key", [
    ({**GOOD, "radius": 0.0}, "garment.wrap.P.radius"),
    ({**GOOD, "radius": True}, "garment.wrap.P.radius"),
    ({**GOOD, "angle0": float("nan")}, "garment.wrap.P.angle0"),
    ({**GOOD, "axis": [0.0, 0.0]}, "garment.wrap.P.axis"),
    ({**GOOD, "axis": [0.0, 0.0, 0.0]}, "garment.wrap.P.axis_dir"),
    ({**GOOD, "zero_direction": [0.0, 0.0, 2.0]}, "garment.wrap.P.zero_direction"),
    ({**GOOD, "centre": [0.0, 0.0, 0.0]}, "unknown key(s) ['centre']"),
    ({k: v for k, v in GOOD.items() if k != "radius"}, "missing ['radius']"),
    ([1, 2], "garment.wrap.P"),
])
def test_a_bad_wrap_is_refused_naming_the_key(table, key):
    with pytest.raises(SceneError) as info:
        check_wrap({"wrap": {"P": table}})
    assert key in str(info.value), str(info.value)


def test_the_pants_scene_carries_the_wraps_of_pants_wraps():
    """The numbers in scenes/pants_walk_self.toml are those of the function (rounded to 1e-6 as written)."""
    wrap = tomllib.loads(SELF_SCENE.read_text())["garment"]["wrap"]
    expected = pants_wraps()
    assert set(wrap) == set(expected)
    for name, table in expected.items():
        for key, value in table.items():
            np.testing.assert_allclose(wrap[name][key], value, atol=1e-6, err_msg=f"{name}.{key}")


def test_the_wrapped_pants_lie_on_their_cylinders_each_leg_on_its_own_side():
    """Meshed as the run meshes them (h = 0.07, Q2): every node of a panel at the wrap's radius from its axis (the
    roll is exact at the nodes; 1e-12 m); the left panels at y >= +inseam_clearance, the right at <= -clearance
    (the inseam ends are the panels' nearest points to the midline); each stitched edge as long on the cylinder as
    in the flat pattern (the roll is isometric; the polyline through the nodes of a curved edge is shorter by the
    chord error, below 0.1 % here)."""
    scene = load(SELF_SCENE)
    fabric, _, _, garment = garment_mesh(scene.parsed, scene.path, MPI.COMM_SELF)
    x = fabric.mesh.geometry.x
    tags = np.zeros(len(x), dtype=np.int64)
    dofs = fabric.mesh.geometry.dofmap.array.reshape(fabric.mesh.topology.index_map(2).size_local, 9)
    tags[dofs[fabric.cell_tags.indices].ravel()] = np.repeat(fabric.cell_tags.values, 9)
    for name, table in scene.parsed.garment.wrap.items():
        p = x[tags == garment.panel_tags[name]]
        axis_point = np.asarray(table["axis_point"])
        radial = (p - axis_point)[:, :2]                    # the axis is vertical
        np.testing.assert_allclose(np.linalg.norm(radial, axis=1), table["radius"], atol=1e-12)
        side = 1.0 if name.startswith("L") else -1.0
        assert np.min(side * p[:, 1]) >= 0.005 - 1e-9, name
    pattern = garment.pattern
    for stitch in garment.stitches:
        for panel, edge in zip(stitch.panels, stitch.edges):
            points = garment.edge_points(panel, edge)
            placed = np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))
            assert placed == pytest.approx(edge_length(pattern.panels[panel], edge), rel=1e-3), (panel, edge)


def test_pants_wraps_refuse_a_radius_too_small_to_cover_the_panel():
    T = pants_sizes(PANTS_BODY)["thigh"]
    with pytest.raises(ValueError, match="radius"):
        pants_wraps(radius=0.99 * T / math.pi)
    with pytest.raises(ValueError, match="inseam_clearance"):
        pants_wraps(inseam_clearance=0.0)


def test_a_wrap_on_a_panel_the_pattern_lacks_is_refused():
    scene = load(SELF_SCENE)
    garment = dataclasses.replace(scene.parsed.garment, wrap={**scene.parsed.garment.wrap, "Cfront": GOOD})
    with pytest.raises(SceneError, match="garment.wrap: no panel named \\['Cfront'\\]"):
        panel_placements(garment, read_pattern(scene.parsed, scene.path))


def test_a_self_contact_run_with_a_seam_sewn_through_a_panel_is_refused_at_setup(tmp_path, capsys):
    """The self-contact scene with the rigid flat panels of scenes/pants_walk.toml (no wrap): the right inseam
    is sewn through the left leg (tests/test_sewing_paths.py); `fabricfem run` exits 2 naming it, before the
    time loop."""
    data = tomllib.loads(SELF_SCENE.read_text())
    plain = tomllib.loads((ROOT / "scenes" / "pants_walk.toml").read_text())["garment"]
    data["garment"] = plain
    data["output"]["dir"] = str(tmp_path / "out")
    line = refused_in_one_line(tmp_path / "sewn_through.toml", data, "Rfront.4-Rback.0 (21 of 21)", capsys)
    assert "contact.self_contact" in line and not (tmp_path / "out" / "torque.csv").exists()


def test_a_wrap_on_a_tube_is_refused(tmp_path, capsys, no_meshing):
    """[garment.wrap] places pattern panels; on a tube garment it would be ignored, so the scene is refused."""
    data = tomllib.loads((ROOT / "scenes" / "sleeve_layers.toml").read_text())
    garment = data["garment"][0] if isinstance(data["garment"], list) else data["garment"]
    garment["wrap"] = {"P": GOOD}
    data["output"]["dir"] = str(tmp_path / "out")
    refused_in_one_line(tmp_path / "tube_wrap.toml", data, "garment.wrap", capsys)
