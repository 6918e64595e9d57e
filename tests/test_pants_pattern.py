"""The shipped pants (fabricfem.wear.pants, fabricfem/patterns/pants_four_panel.json) are worn as trousers: each
leg's centre line lies on the leg's axis when placed, and after the donning of scenes/pants_walk.toml each leg of
the trousers goes round a leg of the body and the waistband is at the waist (checked on the written cloth.xdmf, an
independent look at the state: the angles of the cloth's nodes round each leg). Before 2026-11-28 the lower legs
of the trousers lay beside the shanks (docs/findings/2026-11-28-pants-placement.md)."""
import json
import math
import tomllib
from pathlib import Path

import meshio
import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial.transform import Rotation
from toml_text import dumps

from fabricfem import cli
from fabricfem.body.lower_body import DEFAULT_LOWER_BODY
from fabricfem.patterns import pattern_path
from fabricfem.scenes import load
from fabricfem.scenes.wear import garment_mesh
from fabricfem.verify.pants import quick_pants_data
from fabricfem.wear.pants import CM, PANTS_BODY, PantsEase, pants_garmentcode, pants_sizes

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "pants_walk.toml"
LEG_AXIS = 0.5 * tomllib.loads(SCENE.read_text())["body"]["hip_spacing"]     # m: the scene's body, 0.11


def test_the_shipped_pattern_is_the_builders():
    """pants_four_panel.json is what write_pants_pattern writes, for the scene's own body (the three cannot drift
    apart)."""
    shipped = json.loads(pattern_path("pants_four_panel").read_text())
    assert shipped == json.loads(json.dumps(pants_garmentcode()))
    assert 0.5 * PANTS_BODY.hip_joint_spacing == LEG_AXIS


def test_each_legs_centre_line_is_on_the_legs_axis():
    """In GarmentCode's frame (x left, cm) the midpoint of every panel's hem and of its width at the crotch level
    (vertices v3, v4 and v2, v5, turned by the panel's rotation about y (0 or 180 deg) and translated) lies at
    x = +-11 cm, and the hem ends hem_clearance above the
    ankle when the waistband is at the waist (closed form of the module docstring; round-off 1e-9 cm)."""
    panels = json.loads(pattern_path("pants_four_panel").read_text())["pattern"]["panels"]
    sizes, ease = pants_sizes(), PantsEase()
    for name, panel in panels.items():
        turn = math.cos(math.radians(panel["rotation"][1]))             # +1 front, -1 back (turned about y)
        v = np.array(panel["vertices"]) * [turn, 1.0] + np.array(panel["translation"][:2])
        side = 1.0 if name.startswith("L") else -1.0
        assert math.isclose(0.5 * (v[3, 0] + v[4, 0]), side * LEG_AXIS * CM, abs_tol=1e-9)
        assert math.isclose(0.5 * (v[2, 0] + v[5, 0]), side * LEG_AXIS * CM, abs_tol=1e-9)
        assert math.isclose(abs(v[3, 0] - v[4, 0]), sizes["hem"] * CM, abs_tol=1e-9)
        hem_below_waist = -(panel["vertices"][3][1]) / CM
        expected = DEFAULT_LOWER_BODY.waist_height - DEFAULT_LOWER_BODY.ankle_height - ease.hem_clearance
        assert math.isclose(hem_below_waist, expected, abs_tol=1e-9)



def test_each_panels_hem_is_placed_near_the_leg():
    """Placed by its Euler angles (R = Rz Ry Rx, scipy's extrinsic "xyz") and translation, every panel's waistband
    lies ease.depth off the pelvis (its front-back semi-axis, 0.1514 m, which the builder takes rounded to the mm:
    0.05 cm) and its hem's midpoint ease.hem_depth in front of or behind the leg's axis (x = 0 of the standing
    body), the right panels layer_gap farther out (closed form of the module docstring; round-off 1e-6 cm)."""
    panels = json.loads(pattern_path("pants_four_panel").read_text())["pattern"]["panels"]
    ease, pelvis_depth = PantsEase(), DEFAULT_LOWER_BODY.pelvis_radii[1]
    for name, panel in panels.items():
        rotation = Rotation.from_euler("xyz", panel["rotation"], degrees=True).as_matrix()
        v = np.column_stack([np.array(panel["vertices"]), np.zeros(6)]) @ rotation.T + panel["translation"]
        gap = ease.layer_gap if name.startswith("R") else 0.0
        front = 1.0 if name.endswith("front") else -1.0
        assert np.allclose(v[[0, 1], 2], front * (pelvis_depth + ease.depth + gap) * CM, atol=0.05)
        assert math.isclose(0.5 * (v[3, 2] + v[4, 2]), front * (ease.hem_depth + gap) * CM, abs_tol=1e-6)

def _largest_angle_gap(points: np.ndarray, axis_y: float) -> float:
    """Largest gap [deg] between the angles of `points` (n, 3) round the vertical line x = 0, y = axis_y."""
    angles = np.sort(np.degrees(np.arctan2(points[:, 1] - axis_y, points[:, 0])))
    return float(np.max(np.diff(np.concatenate([angles, angles[:1] + 360.0]))))


def test_the_donned_pants_go_round_the_legs_and_stay_at_the_waist(tmp_path):
    """The shipped scene's donning (sewing, pull, growth with the feet regrowing, belt, 0.1 s standing) on h = 0.1 m
    (fabricfem.verify.pants.quick_pants_data). At the last record, at mid-thigh (z = 0.65 m) and mid-shank
    (z = 0.28 m), the cloth's nodes within 3 cm of that height surround each leg: the largest gap between their
    angles round the leg's axis is below 120 deg (a tube round the leg: measured 27-29 deg on this mesh; a trouser
    leg beside the leg leaves a gap above 180 deg). The waistband's nodes are on average within 3 cm of the waist
    height (measured +0.9 cm: the belt sits on the pelvis' upper slope; before the grip held it while the body grew it
    ended 18 cm lower, at the hips)."""
    data = quick_pants_data()
    data["output"] = {"dir": str(tmp_path / "out"), "render": False}
    scene = tmp_path / "pants.toml"
    scene.write_text(dumps(data))
    assert cli.main(["run", str(scene)]) in (0, 3)
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "out" / "cloth.xdmf")) as reader:
        reference, _ = reader.read_points_cells()
        _, point_data, _ = reader.read_data(reader.num_steps - 1)
    x = reference + point_data["displacement"][:, :3]
    for height in (0.65, 0.28):
        band = x[np.abs(x[:, 2] - height) < 0.03]
        for axis_y in (LEG_AXIS, -LEG_AXIS):
            leg = band[band[:, 1] * np.sign(axis_y) > 0.0]          # this leg's side of the midline
            assert len(leg) >= 6
            assert _largest_angle_gap(leg, axis_y) < 120.0, (height, axis_y)
    top = reference[:, 2] > reference[:, 2].max() - 1e-9
    assert abs(x[top, 2].mean() - DEFAULT_LOWER_BODY.waist_height) < 0.03


def test_the_crotch_is_as_long_as_the_bodys():
    """The front and back crotch seams of the shipped scene's mesh (SeamSpec lengths) together reach from the front
    waist to the back waist round the pelvis: at least the arc length of the pelvis ellipsoid's midline section
    between the two waist points (0.596 m, summed numerically on 20001 points), with at most 5 % of ease (measured
    0.607 m; the pattern before 2026-11-28 had 0.482 m)."""
    scene = load(SCENE)
    _, seams, _, _ = garment_mesh(scene.parsed, scene.path, MPI.COMM_SELF)
    crotch = sum(s.length for s in seams if s.name in ("Rfront.5-Lfront.5", "Rback.5-Lback.5"))
    dims = DEFAULT_LOWER_BODY
    r_v, r_ap, _ = dims.pelvis_radii
    centre = dims.crotch_height + r_v
    start = math.asin((dims.waist_height - centre) / r_v)
    theta = np.linspace(start, -math.pi - start, 20001)
    arc = np.sum(np.hypot(np.diff(r_ap * np.cos(theta)), np.diff(r_v * np.sin(theta))))
    assert arc <= crotch <= 1.05 * arc, (crotch, arc)


def test_a_hem_depth_outside_the_waistbands_is_refused():
    """A hem placed farther from the leg's axis than the waistband (or at or behind it) is refused, naming the key."""
    for depth in (0.0, 0.5):
        with pytest.raises(ValueError, match="hem_depth"):
            pants_garmentcode(ease=PantsEase(hem_depth=depth))
