"""Sewing patterns: readers, exact geometry, refused inputs, placement, meshing (fabricfem.meshes.pattern*)."""
import math

import numpy as np
import pytest
import scipy.integrate
from mpi4py import MPI
from scipy.spatial.transform import Rotation

from fabricfem.meshes.pattern import (
    Edge,
    Panel,
    Pattern,
    Stitch,
    bezier_length,
    check_pattern,
    edge_control_points,
    outline_area,
    pattern_from_dict,
    pattern_to_dict,
    pattern_to_toml,
    read_garmentcode,
    read_pattern_toml,
)
from fabricfem.meshes.pattern_mesh import mesh_pattern, wrap_on_cylinder
from fabricfem.verify.pattern import TROUSERS, panel_areas, stretched


def square(name="a", side=0.2, **kw) -> Panel:
    return Panel(name, np.array([[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]]), **kw)


def two_squares(**kw) -> Pattern:
    return Pattern({"a": square("a"), "b": square("b", translation=(0.3, 0.0, 0.0))},
                   [Stitch(("a", 1), ("b", 3))], **kw)


def test_reader_on_the_trousers():
    p = read_garmentcode(TROUSERS)
    assert sorted(p.panels) == ["Lback", "Lfront", "Rback", "Rfront"]
    assert len(p.stitches) == 8
    front = p.panels["Rfront"]
    assert np.allclose(front.vertices[4], (0.30, -0.60))                 # 30 cm, 60 cm in metres
    assert np.allclose(front.translation, (-0.31, -0.05141943055288254, 0.17110372122518136))
    assert front.edges[5] == Edge(5, 0, (0.25, 0.35))
    # control point: start + u d + v (d turned by +90 degrees), the generator's convention
    assert np.allclose(edge_control_points(front, 5)[1], (0.17, -0.26))
    assert p.stitches[0] == Stitch(("Rfront", 2), ("Rback", 2))
    check_pattern(p)


def test_euler_convention_is_scipy_extrinsic_xyz():
    angles = (30.0, -50.0, 120.0)
    panel = square(rotation=angles)
    assert np.allclose(panel.rotation_matrix(), Rotation.from_euler("xyz", angles, degrees=True).as_matrix(),
                       atol=1e-14)


def test_area_of_a_parabolic_segment_is_two_thirds_base_times_height():
    """Square of side b whose top edge bulges outwards by a quadratic Bezier of control (1/2, v) in the edge
    frame: the apex rises by v b / 2 (half the control point's offset), Archimedes: 2/3 base x height."""
    b, v = 0.4, 0.3
    edges = [Edge(0, 1), Edge(1, 2), Edge(2, 3, (0.5, -v)), Edge(3, 0)]   # top runs right to left: -v is up
    panel = Panel("p", np.array([[0.0, 0.0], [b, 0.0], [b, b], [0.0, b]]), edges)
    height = v * b / 2.0
    assert outline_area(panel) == pytest.approx(b * b + 2.0 / 3.0 * b * height, rel=1e-14)
    assert panel.signed_area() > 0


@pytest.mark.parametrize("control", [(0.25, 0.35), (0.5, 0.0), (0.5, 1e-7), (0.9, -2.0), (3.0, 0.0), (-0.4, 0.2)])
def test_bezier_length_against_quadrature(control):
    p0, p1 = np.array([0.3, -0.3]), np.array([0.2, 0.0])
    d = p1 - p0
    c = p0 + control[0] * d + control[1] * np.array([-d[1], d[0]])
    pts = np.array([p0, c, p1])

    def speed(t):
        return np.linalg.norm(2.0 * ((1.0 - t) * (c - p0) + t * (p1 - c)))
    # split at the speed's minimum (a cusp for collinear controls beyond the ends)
    a, b = c - p0, p1 - 2.0 * c + p0
    tm = min(max(-(a @ b) / (b @ b), 0.0), 1.0) if b @ b > 0 else 0.5
    ref = sum(scipy.integrate.quad(speed, lo, hi, epsabs=1e-15, epsrel=1e-13, limit=200)[0]
              for lo, hi in ((0.0, tm), (tm, 1.0)) if hi > lo)
    assert bezier_length(pts) == pytest.approx(ref, rel=1e-12)


def test_missing_panel_is_refused():
    with pytest.raises(ValueError, match=r"stitch 0 .*panel 'c' does not exist"):
        Pattern({"a": square("a")}, [Stitch(("a", 1), ("c", 3))])


def test_edge_out_of_range_is_refused():
    with pytest.raises(ValueError, match=r"edge 4 of panel 'b' is out of range 0..3"):
        Pattern({"a": square("a"), "b": square("b")}, [Stitch(("a", 1), ("b", 4))])


def test_bow_tie_is_refused():
    bow = Panel("bow", np.array([[0.0, 0.0], [0.2, 0.2], [0.2, 0.0], [0.0, 0.2]]))
    with pytest.raises(ValueError, match=r"panel 'bow': the outline intersects itself \(edges 0 and 2\)"):
        check_pattern(Pattern({"bow": bow}))


def test_curved_edge_crossing_the_outline_is_refused():
    edges = [Edge(0, 1), Edge(1, 2), Edge(2, 3, (0.5, 2.5)), Edge(3, 0)]   # the top edge bows down through the bottom
    panel = Panel("p", np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.2], [0.0, 0.2]]), edges)
    with pytest.raises(ValueError, match=r"panel 'p': the outline intersects itself"):
        check_pattern(Pattern({"p": panel}))


def test_stitch_length_mismatch_is_refused_naming_both_sides():
    p = Pattern({"a": square("a"), "b": square("b", side=0.21)}, [Stitch(("a", 1), ("b", 3))])
    with pytest.raises(ValueError, match=r"stitch a.1-b.3: edge 1 of panel 'a' is 0.2 m long and edge 3 of panel "
                                         r"'b' 0.21 m"):
        check_pattern(p)
    check_pattern(p, stitch_length_tolerance=0.05)
    with pytest.raises(ValueError, match="stitch a.1-b.3"):
        mesh_pattern(p, 0.1)


def test_nan_and_too_few_vertices_are_refused():
    with pytest.raises(ValueError, match=r"panel 'n': vertex 2 is not finite"):
        Panel("n", np.array([[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0]]))
    with pytest.raises(ValueError, match=r"panel 't': needs at least 3 vertices, got 2"):
        Panel("t", np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(ValueError, match=r"panel 'o': edge 0 ends at vertex 1 but edge 1 starts at vertex 2"):
        Panel("o", np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), [Edge(0, 1), Edge(2, 0), Edge(0, 2)])


def test_toml_declaration_round_trip(tmp_path):
    text = """
stitches = [["front", 1, "back", 3]]
[panels.front]
vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]
edges = [[0, 1], [1, 2, {curvature = [0.5, 0.1]}], [2, 3], [3, 0]]
translation = [0.0, 0.0, 0.1]
rotation = [0.0, 0.0, 0.0]
grain = [1.0, 0.0]
[panels.back]
vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]
edges = [[0, 1], [1, 2], [2, 3, {curvature = [0.5, 0.1]}], [3, 0]]
rotation = [0.0, 180.0, 0.0]
"""
    path = tmp_path / "p.toml"
    path.write_text(text)
    p = read_pattern_toml(path)
    assert p.panels["front"].edges[1].curvature == (0.5, 0.1)
    assert np.array_equal(p.panels["front"].grain, (1.0, 0.0)) and np.array_equal(p.panels["back"].grain, (0.0, 1.0))
    assert p.stitches == [Stitch(("front", 1), ("back", 3))]
    again = tmp_path / "again.toml"
    again.write_text(pattern_to_toml(p))
    assert pattern_to_dict(read_pattern_toml(again)) == pattern_to_dict(p)
    trousers = read_garmentcode(TROUSERS)
    assert pattern_to_dict(pattern_from_dict(pattern_to_dict(trousers))) == pattern_to_dict(trousers)
    with pytest.raises(ValueError, match=r"panel 'x': unknown keys \['colour'\]"):
        pattern_from_dict({"panels": {"x": {"vertices": [[0, 0], [1, 0], [0, 1]], "colour": 1}}})


def _edge_lengths_3d(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def test_rigid_placement_is_isometric_and_quads_are_the_default():
    p = read_garmentcode(TROUSERS)
    g = mesh_pattern(p, 0.1, order=1, comm=MPI.COMM_SELF)
    assert g.fabric.mesh.ufl_cell().cellname() == "quadrilateral"
    for name, panel in p.panels.items():
        place = g.placements[name]
        for k in range(len(panel.edges)):
            flat = edge_control_points(panel, k)
            placed = place.map(flat)
            # a rigid map keeps every distance: the Bezier control polygon, hence the curve, is congruent
            assert np.allclose(np.linalg.norm(np.diff(placed, axis=0), axis=1),
                               np.linalg.norm(np.diff(flat, axis=0), axis=1), rtol=0, atol=1e-12)
            pts = g.edge_points(name, k)
            assert np.allclose(pts[[0, -1]], place.map(flat[[0, -1]]), rtol=0, atol=1e-12)
    for s in g.stitches:                           # the side seams face each other: same x and y up to offsets
        assert len(s.points_a) == len(s.points_b)
    seam = next(s for s in g.stitches if s.name == "Rfront.2-Rback.2")
    assert np.allclose(seam.points_a[:, 0], seam.points_b[:, 0], atol=1e-12)


def test_cylinder_wrap_is_isometric():
    """The flat outline rolled onto a cylinder: straight edges along the axis keep their length, edges across
    become circular arcs with the same (arc) length, and the mesh nodes lie on the cylinder."""
    radius = 0.08
    wrap = wrap_on_cylinder((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), radius, zero_direction=(0.0, 0.0, 1.0))
    panel = Panel("sleeve", np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.25], [0.0, 0.25]]))
    g = mesh_pattern(Pattern({"sleeve": panel}), 0.02, order=2, placements={"sleeve": wrap}, comm=MPI.COMM_SELF)
    x = g.fabric.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 0], x[:, 2]), radius, rtol=0, atol=1e-12)
    for k in range(4):
        pts = g.edge_points("sleeve", k)
        start, end = wrap.map(panel.vertices[[panel.edges[k].start, panel.edges[k].end]])
        if k in (0, 2):   # across the axis: a circular arc of length = the flat edge (0.3 m), angle 0.3 / r
            chord = np.linalg.norm(end - start)
            assert chord == pytest.approx(2.0 * radius * math.sin(0.3 / (2.0 * radius)), rel=1e-12)
            # nodes equally spaced in angle: the polyline's length converges to the arc length
            assert _edge_lengths_3d(pts) == pytest.approx(0.3, rel=2e-3)
        else:
            assert _edge_lengths_3d(pts) == pytest.approx(0.25, rel=1e-12)
    # the outward radial normal, the warp along the axis (grain (0, 1) -> panel y -> axis)
    warp, normal = g.fabric.panel_directions[1]
    pts = x.T
    assert np.allclose(normal(pts), np.vstack([x[:, 0], 0 * x[:, 1], x[:, 2]]) / radius, atol=1e-12)
    assert np.allclose(warp(pts), np.array([[0.0], [1.0], [0.0]]), atol=1e-12)


def test_stitched_edges_get_the_same_node_count_and_pairs_run_opposite():
    p = two_squares()
    g = mesh_pattern(p, 0.07, order=2, comm=MPI.COMM_SELF)
    (seam,) = g.stitches
    assert seam.name == "a.1-b.3" and seam.panel_tag_a == 1 and seam.panel_tag_b == 2
    # 0.2 / 0.07 -> 3 segments, even for quads -> 4, order 2 -> 9 nodes
    assert len(seam.points_a) == len(seam.points_b) == 9
    # b is a translated by 0.3 in x: edge a.1 (x = 0.2, upwards) meets b.3 (x = 0.3, downwards) reversed
    assert np.allclose(seam.points_b - seam.points_a, (0.1, 0.0, 0.0), atol=1e-12)
    assert seam.lengths == pytest.approx((0.2, 0.2), rel=1e-15)
    assert set(g.fabric.tags) == {f"{n}.{k}" for n in "ab" for k in range(4)}
    tri = mesh_pattern(p, 0.07, order=1, cell="triangle", comm=MPI.COMM_SELF)
    assert tri.fabric.mesh.ufl_cell().cellname() == "triangle"
    assert len(tri.stitches[0].points_a) == 4   # triangles: 3 segments, not rounded to even


def test_per_panel_directions_at_the_shell_nodes():
    """Two panels placed on top of each other with different grains: directions_at gives each panel's own warp
    at its nodes, although the points coincide in 3-D."""
    from dolfinx import fem
    p = Pattern({"a": square("a", grain=(1.0, 0.0)), "b": square("b", grain=(0.0, 1.0))})
    g = mesh_pattern(p, 0.1, comm=MPI.COMM_SELF)
    V = fem.VectorFunctionSpace(g.fabric.mesh, ("Lagrange", 2), dim=3)
    warp, normal = g.fabric.directions_at(V)
    dofs = V.dofmap.list.array.reshape(V.dofmap.list.num_nodes, -1)
    tags = g.fabric.cell_tags
    nodes_a = np.unique(dofs[tags.indices[tags.values == 1]])
    nodes_b = np.unique(dofs[tags.indices[tags.values == 2]])
    assert np.allclose(warp[:, nodes_a].T, (1.0, 0.0, 0.0)) and np.allclose(warp[:, nodes_b].T, (0.0, 1.0, 0.0))
    assert np.allclose(normal.T, (0.0, 0.0, 1.0))


def test_stretched_trousers_are_refused():
    with pytest.raises(ValueError,
                       match=r"stitch Rfront.2-Rback.2: edge 2 of panel 'Rfront' .* edge 2 of panel 'Rback'"):
        mesh_pattern(stretched(read_garmentcode(TROUSERS), "Rback", 1.1), 0.05)


@pytest.mark.mpi
def test_panel_areas_on_all_ranks():
    """Under mpirun -n 2 too: the panels' areas, summed over the ranks, are the exact outline areas."""
    p = read_garmentcode(TROUSERS)
    g = mesh_pattern(p, 0.08, order=2)
    areas = panel_areas(g)
    for name, panel in p.panels.items():
        assert areas[name] == pytest.approx(outline_area(panel), rel=1e-4)
    counts = MPI.COMM_WORLD.allgather([len(s.points_a) for s in g.stitches])
    assert all(c == counts[0] for c in counts)
