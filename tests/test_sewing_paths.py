"""fabricfem.studies.sewing_paths: the stitches whose sewing line crosses another panel, on a hand-made case whose
answer is known by construction, and on the shipped pants (the right inseam through the left leg's panels)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fabricfem.contact.sewing_lines import crossing_stitches
from fabricfem.studies.sewing_paths import main, sewing_report

ROOT = Path(__file__).resolve().parents[1]


def test_a_stitch_line_through_a_third_panel_is_found():
    """A unit square (two triangles, panel 3) in the plane z = 0; stitches from z = +0.1 to z = -0.1 between panels 1
    and 2: over the square it is crossed, beside it not; the square counted as one of the stitch's own panels, not;
    a stitch whose line ends on the square (its end on the plane) not (the ends are left out)."""
    points = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1, 0], [0.0, 1, 0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    tags = np.array([3, 3])
    a = np.array([[0.3, 0.6, 0.1], [1.5, 0.5, 0.1], [0.4, 0.2, 0.1]])
    b = np.array([[0.3, 0.6, -0.1], [1.5, 0.5, -0.1], [0.4, 0.2, 0.0]])
    np.testing.assert_array_equal(crossing_stitches(a, b, (1, 2), points, triangles, tags), [True, False, False])
    np.testing.assert_array_equal(crossing_stitches(a, b, (1, 3), points, triangles, tags), [False, False, False])


def test_the_pants_right_inseam_is_sewn_through_the_left_leg():
    """scenes/pants_walk.toml: each leg's flat panels overlap the other leg's across the midline, the right leg's
    outside the left's, so every stitch of the right inseam crosses a left-leg panel and no other seam's does
    (docs/findings/2026-11-28-stitched-zones.md)."""
    rows = {row["seam"]: row for row in sewing_report(ROOT / "scenes" / "pants_walk.toml")}
    inseam = rows.pop("Rfront.4-Rback.0")
    assert inseam["pairs"] > 0 and inseam["through_another_panel"] == inseam["pairs"]
    assert inseam["a_y"][0] >= -1e-12 and inseam["a_y"][1] > 0.05      # on the left of the midline
    assert all(row["through_another_panel"] == 0 for row in rows.values())


def test_a_scene_without_a_pattern_or_a_missing_file_is_refused_in_one_line(tmp_path, capsys):
    """A tube garment has no seams to sew, a missing file is no scene: exit 2 with the reason (argparse's error)."""
    for scene, reason in ((ROOT / "scenes" / "sleeve.toml", "is not a pattern"), (tmp_path / "none.toml", "scene:")):
        with pytest.raises(SystemExit) as stop:
            main([str(scene)])
        assert stop.value.code == 2 and reason in capsys.readouterr().err


def test_the_wrapped_pants_sew_no_stitch_through_another_panel():
    """scenes/pants_walk_self.toml: each leg's panels rolled round its own leg (fabricfem.wear.pants.pants_wraps),
    every seam closes in the open."""
    rows = sewing_report(ROOT / "scenes" / "pants_walk_self.toml")
    assert len(rows) == 8 and all(row["through_another_panel"] == 0 for row in rows)


def test_the_panel_triangles_cover_each_flat_panel_once():
    """The 8 triangles per 9-node cell of scenes/pants_walk.toml's flat panels: per panel, their area equals the
    outline's (fabricfem.meshes.pattern.outline_area: the curved crotch edge as a Bezier; the mesh's Q2 edge departs
    from it by the interpolation error, 1e-3 relative allowed) and their normals all point one way (no folded or
    doubled triangle: the split follows dolfinx's node order)."""
    from mpi4py import MPI

    from fabricfem.contact.sewing_lines import panel_triangles
    from fabricfem.meshes.pattern import outline_area
    from fabricfem.scenes.build import load
    from fabricfem.scenes.wear import garment_mesh
    scene = load(ROOT / "scenes" / "pants_walk.toml")
    fabric, _, _, garment = garment_mesh(scene.parsed, scene.path, MPI.COMM_SELF)
    points, triangles, tags = panel_triangles(fabric)
    p = points[triangles]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    for name, tag in garment.panel_tags.items():
        mine = cross[tags == tag]
        assert 0.5 * np.linalg.norm(mine, axis=1).sum() == pytest.approx(outline_area(garment.pattern.panels[name]),
                                                                         rel=1e-3), name
        unit = mine / np.linalg.norm(mine, axis=1, keepdims=True)
        assert np.all(unit @ unit[0] > 0.999), name


@pytest.mark.mpi
def test_sewn_through_on_a_distributed_mesh_agrees_with_the_serial_answer():
    """Under mpirun -n 2 each rank tests its own cells: the OR over the ranks finds every stitch of the right inseam
    of scenes/pants_walk.toml and no other (the serial answer of the test above), the same on every rank."""
    from mpi4py import MPI

    from fabricfem.contact.sewing_lines import sewn_through
    from fabricfem.scenes.build import load
    from fabricfem.scenes.wear import garment_mesh
    scene = load(ROOT / "scenes" / "pants_walk.toml")
    fabric, seams, _, _ = garment_mesh(scene.parsed, scene.path, MPI.COMM_WORLD)
    crossed = {seam.name: c for seam, c in zip(seams, sewn_through(fabric, seams, MPI.COMM_WORLD))}
    assert crossed.pop("Rfront.4-Rback.0").all() and not any(c.any() for c in crossed.values())
