"""Stitches that cannot sew as drawn, refused before meshing: a twisted stitch (its two edges placed running the
same way, so the stitch, which joins them in opposite directions, would cross the seam over) unless marked as
meant, and held edges that a stitch would have to pull together (fabricfem.meshes.pattern, fabricfem.scenes.wear)."""
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from toml_text import dumps

from fabricfem import cli
from fabricfem.meshes.pattern import (
    Panel,
    Pattern,
    Stitch,
    check_held_stitches,
    check_pattern,
    pattern_from_dict,
    pattern_to_dict,
)
from fabricfem.meshes.pattern_mesh import mesh_pattern, wrap_on_cylinder

ROOT = Path(__file__).resolve().parents[1]
RECT = [[-0.1, 0.0], [0.1, 0.0], [0.1, 0.5], [-0.1, 0.5]]     # m: 0.2 wide, 0.5 long; edges 0 bottom, 1 right ...


STRAIGHT = '[["front", 1, "back", 3], ["front", 3, "back", 1]]'
REVERSED = '[["front", 1, "back", 1], ["front", 3, "back", 3]]'


def sleeve_toml(back_rotation: float = 180.0, gap: float = 0.14, stitches: str = STRAIGHT) -> str:
    """A two-panel sleeve as GarmentCode lays it out: the front in the plane z = gap / 2 and the back at -gap / 2
    turned by 180 degrees about y (both outlines counter-clockwise seen from outside), sewn along both long
    sides (front.1 at x = +0.1 to back.3, which the turn puts there). With back_rotation = 0 the back faces the
    same way as the front: its edge 1 lies at x = +0.1 too but runs the same way as front.1, so the REVERSED
    stitches front.1-back.1 and front.3-back.3 (end to end in opposite directions) twist both seams."""
    return f"""stitches = {stitches}
[panels.front]
vertices = {RECT}
translation = [0.0, 0.0, {gap / 2}]
[panels.back]
vertices = {RECT}
translation = [0.0, 0.0, {-gap / 2}]
rotation = [0.0, {back_rotation}, 0.0]
"""


def sleeve(**kw) -> Pattern:
    return pattern_from_dict(tomllib.loads(sleeve_toml(**kw)))


# ------------------------------------------------------------------------------ twisted stitches
def test_untwisted_sleeve_and_the_shipped_patterns_pass():
    check_pattern(sleeve())
    from fabricfem.meshes.pattern import read_garmentcode
    from fabricfem.patterns import pattern_path
    for name in ("pants_straight_sides", "pants_four_panel"):
        check_pattern(read_garmentcode(pattern_path(name)))


def test_reversed_stitch_of_a_sleeve_is_refused_naming_it():
    """The back panel not turned over: its long edges run the same way as the front's, so the stitch front.1-back.1
    would sew the front's bottom corner to the back's top one (the sleeve crumples into a wad)."""
    with pytest.raises(ValueError, match=r"^stitch front\.1-back\.1: .*same way.*twisted = true") as info:
        check_pattern(sleeve(back_rotation=0.0, stitches=REVERSED))
    assert "\n" not in str(info.value)


def test_meant_twist_is_accepted_and_round_trips():
    twisted = '[["front", 1, "back", 1, {twisted = true}], ["front", 3, "back", 3, {twisted = true}]]'
    pattern = sleeve(back_rotation=0.0, stitches=twisted)
    assert all(s.twisted for s in pattern.stitches)
    check_pattern(pattern)
    assert pattern_from_dict(pattern_to_dict(pattern)).stitches == pattern.stitches
    with pytest.raises(ValueError, match=r"^stitch 0: .*twisted"):
        pattern_from_dict(tomllib.loads(sleeve_toml(stitches='[["front", 1, "back", 3, {twist = 1}]]')))


def test_twist_is_judged_where_the_mesher_places_the_panels():
    """Rolled onto a cylinder the sleeve of tests/test_garment.py is sewn straight; stitching edge 1 of one panel
    to edge 1 of the other (both running along +x) is refused by mesh_pattern before anything is meshed."""
    widths = (0.15, 2 * np.pi * 0.06 - 0.15)
    panels = {n: Panel(n, np.array([[0.0, 0.0], [w, 0.0], [w, 0.5], [0.0, 0.5]])) for n, w in zip("ab", widths)}
    places = {n: wrap_on_cylinder((0, 0, 0), (1, 0, 0), 0.06, zero_direction=(0, 1, 0), angle0=a)
              for n, a in (("a", 0.0), ("b", widths[0] / 0.06))}
    with pytest.raises(ValueError, match=r"^stitch a\.1-b\.1: "):
        mesh_pattern(Pattern(panels, [Stitch(("a", 1), ("b", 1))]), 0.1, placements=places, comm=MPI.COMM_SELF)


# ------------------------------------------------------------------------------ held edges
def test_held_edges_a_stitch_must_pull_together_are_refused():
    """Both panels' shoulder edges held (edge 0, y = 0) with the panels 0.14 m apart: the stitches' corners at the
    shoulder stay 0.14 m apart, refused naming the stitch and the distance; one side held, or held corners that
    meet, pass."""
    with pytest.raises(ValueError, match=r"^stitch front\.1-back\.3: .*0\.14 m apart") as info:
        check_held_stitches(sleeve(), [("front", 0), ("back", 0)])
    assert "\n" not in str(info.value)
    check_held_stitches(sleeve(), [("front", 0)])
    check_held_stitches(sleeve(gap=0.0), [("front", 0), ("back", 0)])
    check_held_stitches(sleeve(gap=0.0), [("front", 1), ("back", 3)])         # the stitched edges themselves meet


def test_held_stitched_edges_apart_along_their_length_are_refused():
    """Holding the two stitched edges themselves: they are 0.14 m apart everywhere."""
    with pytest.raises(ValueError, match=r"^stitch front\.1-back\.3: .*0\.14 m apart"):
        check_held_stitches(sleeve(), [("front", 1), ("back", 3)])


# ------------------------------------------------------------------------------ wear scenes
def _scene(tmp_path: Path, pattern_text: str, hold: list[str]) -> Path:
    data = tomllib.loads((ROOT / "scenes" / "trousers_standing.toml").read_text())
    data["garment"].update(pattern="sleeve.toml", hold=hold, scale=1.0)
    del data["garment"]["rotate"]
    data["output"] = {"dir": str(tmp_path / "out")}
    (tmp_path / "sleeve.toml").write_text(pattern_text)
    path = tmp_path / "scene.toml"
    path.write_text(dumps(data))
    return path


@pytest.mark.parametrize("pattern_kw, hold, key", [
    ({"back_rotation": 0.0, "stitches": REVERSED}, [], "garment.pattern: stitch front.1-back.1"),
    ({}, ["front.0", "back.0"], "garment.hold: stitch front.1-back.3"),
    ({}, ["front.9"], "garment.hold: no pattern edge 'front.9'"),
], ids=["twisted", "held-apart", "unknown-edge"])
def test_wear_scene_refuses_them_in_one_line(pattern_kw, hold, key, tmp_path, capsys, monkeypatch):
    def trap(*args, **kwargs):
        raise AssertionError("meshed before refusing the scene")
    monkeypatch.setattr("fabricfem.scenes.wear.mesh_pattern", trap)
    code = cli.main(["run", str(_scene(tmp_path, sleeve_toml(**pattern_kw), hold))])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert key in lines[0] and "Traceback" not in lines[0], lines[0]
    if hold == ["front.0", "back.0"]:
        assert "0.14 m" in lines[0]
