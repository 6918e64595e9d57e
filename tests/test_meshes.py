"""Tests of fabricfem.meshes: plate, tube, gmsh conversion, material frame.

Serial:  python -m pytest -q tests/test_meshes.py
MPI:     mpirun -n 2 python -m pytest -q -p no:cacheprovider -m mpi tests/test_meshes.py
"""
from __future__ import annotations

import math

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from fabricfem.meshes import FabricMesh, cylindrical_panel, model_to_mesh, plate, tube
from fabricfem.meshes.gmsh_io import gmsh_to_dolfinx

COMM = MPI.COMM_WORLD
serial_only = pytest.mark.skipif(COMM.size > 1, reason="checks process-local topology")


def integrate(expr, measure) -> float:
    """Global integral of ``expr * measure`` (summed over ranks)."""
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * measure))
    return COMM.allreduce(local, op=MPI.SUM)


def area(fm: FabricMesh) -> float:
    return integrate(1.0, ufl.dx(domain=fm.mesh))


def tag_length(fm: FabricMesh, name: str) -> float:
    ds = ufl.Measure("ds", domain=fm.mesh, subdomain_data=fm.facet_tags)
    return integrate(1.0, ds(fm.tag(name)))


def n_cells(fm: FabricMesh) -> int:
    return fm.mesh.topology.index_map(2).size_global


def n_vertices(fm: FabricMesh) -> int:
    return fm.mesh.topology.index_map(0).size_global


def facet_midpoints(fm: FabricMesh, name: str) -> np.ndarray:
    """Midpoints (n, 3) of the local facets tagged ``name``."""
    facets = fm.facets(name)
    return dolfinx.mesh.compute_midpoints(fm.mesh, 1, facets).reshape(-1, 3)


def tube_area(length: float, radius: float, n_around: int) -> float:
    """Area of the prism inscribed in the cylinder with n_around flat sides."""
    s = math.pi / n_around
    return 2.0 * math.pi * radius * length * math.sin(s) / s


# ---------------------------------------------------------------- plate


@pytest.mark.parametrize("cell, per_square", [("triangle", 2), ("quadrilateral", 1)])
def test_plate_structured_counts_and_area(cell, per_square):
    fm = plate(2.0, 0.5, 8, 3, cell=cell, origin=(1.0, -2.0, 0.3))
    assert fm.mesh.geometry.dim == 3 and fm.mesh.topology.dim == 2
    assert fm.mesh.topology.cell_name() == cell
    assert n_cells(fm) == per_square * 8 * 3
    assert n_vertices(fm) == 9 * 4
    assert area(fm) == pytest.approx(1.0, rel=1e-12)
    assert np.allclose(fm.mesh.geometry.x[:, 2], 0.3)


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_plate_unstructured(cell):
    fm = plate(2.0, 1.0, 8, 4, cell=cell, structured=False)
    assert fm.mesh.topology.cell_name() == cell
    assert area(fm) == pytest.approx(2.0, rel=1e-12)
    assert n_cells(fm) > 8 * 4 / 2
    assert tag_length(fm, "top") == pytest.approx(2.0, rel=1e-12)


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_plate_tags_on_edges(cell):
    x0, y0, lx, ly, nx, ny = -1.0, 2.0, 3.0, 1.5, 6, 3
    fm = plate(lx, ly, nx, ny, cell=cell, origin=(x0, y0, 0.0))
    assert set(fm.tags) == {"left", "right", "bottom", "top"}
    lines = {"left": (0, x0, ny, ly), "right": (0, x0 + lx, ny, ly),
             "bottom": (1, y0, nx, lx), "top": (1, y0 + ly, nx, lx)}
    for name, (axis, value, count, length) in lines.items():
        mid = facet_midpoints(fm, name)
        assert np.allclose(mid[:, axis], value), name
        if COMM.size == 1:
            assert len(mid) == count, name
        assert tag_length(fm, name) == pytest.approx(length, rel=1e-12), name
    if COMM.size == 1:  # every boundary edge is tagged, nothing else is
        boundary = dolfinx.mesh.exterior_facet_indices(fm.mesh.topology)
        assert np.array_equal(np.sort(fm.facet_tags.indices), np.sort(boundary))


@serial_only
@pytest.mark.parametrize("diagonal, shared", [("right", {(0, 0), (1, 1)}), ("left", {(1, 0), (0, 1)})])
def test_plate_diagonal(diagonal, shared):
    fm = plate(1.0, 1.0, 1, 1, diagonal=diagonal)
    cells = fm.mesh.geometry.dofmap.array.reshape(2, 3)
    common = np.intersect1d(cells[0], cells[1])
    assert {tuple(p) for p in np.rint(fm.mesh.geometry.x[common, :2]).astype(int)} == shared


# ---------------------------------------------------------------- tube


@pytest.mark.parametrize("n_around, n_along", [(10, 13), (15, 20)])
@pytest.mark.parametrize("cell, per_quad", [("quadrilateral", 1), ("triangle", 2)])
def test_tube_counts_and_area(n_around, n_along, cell, per_quad):
    length, radius = 0.6, 0.05
    fm = tube(length, radius, n_around, n_along, cell=cell)
    assert fm.mesh.geometry.dim == 3 and fm.mesh.topology.cell_name() == cell
    assert n_cells(fm) == per_quad * n_around * n_along
    assert n_vertices(fm) == n_around * (n_along + 1)  # no duplicated seam nodes
    assert area(fm) == pytest.approx(tube_area(length, radius, n_around), rel=1e-12)
    x = fm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), radius)
    x_min = COMM.allreduce(x[:, 0].min(), op=MPI.MIN)
    x_max = COMM.allreduce(x[:, 0].max(), op=MPI.MAX)
    assert x_min == pytest.approx(0.0, abs=1e-14) and x_max == pytest.approx(length)


@serial_only
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
@pytest.mark.parametrize("n_around", [3, 7, 10])
def test_tube_closed_around(cell, n_around):
    length, n_along = 1.0, 4
    fm = tube(length, 0.2, n_around, n_along, cell=cell)
    topology = fm.mesh.topology
    topology.create_connectivity(1, 2)
    cells_per_edge = np.diff(topology.connectivity(1, 2).offsets)
    assert set(np.unique(cells_per_edge)) == {1, 2}
    boundary = np.flatnonzero(cells_per_edge == 1).astype(np.int32)
    assert len(boundary) == 2 * n_around
    x_mid = dolfinx.mesh.compute_midpoints(fm.mesh, 1, boundary)[:, 0]
    assert np.all(np.isclose(x_mid, 0.0) | np.isclose(x_mid, length))
    # the end tags are exactly the boundary edges, split by end
    for name, x_end in (("end0", 0.0), ("end1", length)):
        mid = facet_midpoints(fm, name)
        assert len(mid) == n_around and np.allclose(mid[:, 0], x_end)
    assert np.array_equal(np.sort(fm.facet_tags.indices), boundary)
    # Euler characteristic of an open cylinder: V - E + F = 0
    n_edges = topology.index_map(1).size_local
    assert n_vertices(fm) - n_edges + n_cells(fm) == 0


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_tube_second_order(cell):
    length, radius, n_around = 1.0, 0.1, 10
    fm = tube(length, radius, n_around, 5, cell=cell, order=2)
    assert fm.mesh.geometry.cmap.degree == 2
    x = fm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), radius)  # mid-side nodes on the circle too
    exact = 2.0 * math.pi * radius * length
    a = area(fm)
    assert abs(a - exact) < 0.01 * abs(tube_area(length, radius, n_around) - exact)
    for name in ("end0", "end1"):
        assert tag_length(fm, name) == pytest.approx(2 * math.pi * radius, rel=1e-3)
    assert n_cells(fm) == (2 if cell == "triangle" else 1) * n_around * 5


def test_tube_tags_on_ends():
    fm = tube(0.5, 0.1, 12, 6)
    assert set(fm.tags) == {"end0", "end1"}
    assert np.allclose(facet_midpoints(fm, "end0")[:, 0], 0.0)
    assert np.allclose(facet_midpoints(fm, "end1")[:, 0], 0.5)
    for name in fm.tags:
        assert tag_length(fm, name) == pytest.approx(12 * 2 * 0.1 * math.sin(math.pi / 12), rel=1e-12)


@pytest.mark.parametrize("n_around", [3, 8])
def test_cylindrical_panel_geometry_and_tags(n_around):
    """The Scordelis-Lo roof: nodes on the cylinder, the 80-degree opening symmetric about +z, straight
    edges side0 (y > 0) and side1 (y < 0) of length L, curved ends of the arc's chord length (order 1)."""
    length, radius, angle = 50.0, 25.0, math.radians(80.0)
    fm = cylindrical_panel(length, radius, angle, n_around, 4, order=1)
    assert set(fm.tags) == {"end0", "end1", "side0", "side1"}
    x = fm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), radius)
    assert COMM.allreduce(x[:, 2].min(), op=MPI.MIN) == pytest.approx(radius * math.cos(angle / 2))
    assert np.allclose(facet_midpoints(fm, "end0")[:, 0], 0.0)
    assert np.allclose(facet_midpoints(fm, "end1")[:, 0], length)
    for side, sign in (("side0", 1.0), ("side1", -1.0)):
        mid = facet_midpoints(fm, side)
        assert np.allclose(mid[:, 1], sign * radius * math.sin(angle / 2))
        assert tag_length(fm, side) == pytest.approx(length, rel=1e-12)
    assert tag_length(fm, "end0") == pytest.approx(2 * n_around * radius * math.sin(angle / (2 * n_around)),
                                                   rel=1e-12)
    assert n_cells(fm) == n_around * 4


@pytest.mark.parametrize("start", [0.0, math.pi])
def test_quarter_cylinder_panel_from_a_start_angle(start):
    """cylindrical_panel(angle=pi/2, start=a0): the quarter of the cylinder between the angles a0 and a0 + pi/2
    about +x from +y towards +z (for a0 = 0 the quarter y, z >= 0, side0 on +y and side1 on +z; for a0 = pi the
    quarter y, z <= 0): every node on the cylinder and inside the quarter, the straight edges where the angles
    say, the normal outward."""
    length, radius = 0.4, 0.1
    fm = cylindrical_panel(length, radius, math.pi / 2, 4, 2, order=2, start=start)
    x = fm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), radius)
    sign = 1.0 if start == 0.0 else -1.0
    assert np.all(sign * x[:, 1] >= -1e-12) and np.all(sign * x[:, 2] >= -1e-12)
    for side, a in (("side0", start), ("side1", start + math.pi / 2)):
        mid = facet_midpoints(fm, side)
        assert np.allclose(mid[:, 1:], radius * np.array([math.cos(a), math.sin(a)]), atol=1e-12), side
        assert tag_length(fm, side) == pytest.approx(length, rel=1e-12)
    xt = x.T
    assert np.allclose(np.sum(fm.normal(xt)[1:] * xt[1:], axis=0), radius)
    assert area(fm) == pytest.approx(math.pi / 2 * radius * length, rel=1e-4)


def test_default_cylindrical_panel_is_centred_on_z():
    """Without `start` the panel stays the roof centred on +z (the former layout)."""
    fm = cylindrical_panel(1.0, 0.5, 1.0, 4, 2)
    assert np.allclose(facet_midpoints(fm, "side0")[:, 1:], 0.5 * np.array([math.sin(0.5), math.cos(0.5)]))


@pytest.mark.parametrize("angle", [0.0, -1.0, 2 * math.pi, float("nan")])
def test_cylindrical_panel_bad_angle(angle):
    with pytest.raises(ValueError, match="^angle:"):
        cylindrical_panel(1.0, 0.1, angle, 4, 2)


# ---------------------------------------------------------------- frame


def frame_meshes():
    return [plate(1.0, 2.0, 3, 4), plate(1.0, 2.0, 3, 4, cell="quadrilateral"),
            tube(1.0, 0.3, 8, 3), tube(1.0, 0.3, 8, 3, cell="triangle")]


@pytest.mark.parametrize("index", range(4))
def test_frame_orthonormal_and_tangent(index):
    fm = frame_meshes()[index]
    x = fm.mesh.geometry.x.T  # (3, N)
    e1, n, e2 = fm.warp(x), fm.normal(x), fm.weft(x)
    for v in (e1, n, e2):
        assert v.shape == x.shape
        assert np.allclose(np.linalg.norm(v, axis=0), 1.0)
    assert np.allclose(np.sum(e1 * n, axis=0), 0.0)
    assert np.allclose(np.sum(e2 * n, axis=0), 0.0)
    assert np.allclose(np.sum(e1 * e2, axis=0), 0.0)
    assert np.allclose(np.linalg.det(np.stack([e1.T, e2.T, n.T], axis=2)), 1.0)  # right-handed
    assert np.allclose(e2, np.cross(n, e1, axis=0))


@pytest.mark.parametrize("index", range(4))
def test_normal_matches_cell_orientation(index):
    """The reference normal agrees with ufl.CellNormal (cells consistently oriented)."""
    fm = frame_meshes()[index]
    V = dolfinx.fem.VectorFunctionSpace(fm.mesh, ("DG", 0))
    n_ref = dolfinx.fem.Function(V)
    n_ref.interpolate(fm.normal)
    a = area(fm)
    agree = integrate(ufl.dot(ufl.CellNormal(fm.mesh), n_ref), ufl.dx(domain=fm.mesh))
    assert agree > a * math.cos(math.pi / 8) - 1e-12  # tube: 8 sides; plate: exactly a
    # warp is tangent to the cells too
    w = dolfinx.fem.Function(V)
    w.interpolate(fm.warp)
    assert abs(integrate(ufl.dot(ufl.CellNormal(fm.mesh), w) ** 2, ufl.dx(domain=fm.mesh))) < 1e-20


@serial_only
def test_tube_weft_is_circumferential():
    fm = tube(1.0, 1.0, 4, 1)
    x = np.array([[0.5, 0.5], [0.0, 1.0], [1.0, 0.0]])  # (0.5,0,1) and (0.5,1,0)
    assert np.allclose(fm.normal(x), [[0, 0], [0, 1], [1, 0]])
    assert np.allclose(fm.weft(x), [[0, 0], [1, 0], [0, -1]])


# ---------------------------------------------------------------- tags API


def test_tag_lookup_and_unknown_tag():
    fm = plate(1.0, 1.0, 2, 2)
    assert fm.tag("left") == fm.tags["left"]
    assert fm.facets("left").dtype == np.int32
    with pytest.raises(ValueError, match=r"tag.*'sleeve'.*\['bottom', 'left', 'right', 'top'\]"):
        fm.tag("sleeve")
    with pytest.raises(ValueError, match="available"):
        fm.facets("wrist")


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("kwargs, param", [
    (dict(lx=0.0), "lx"), (dict(lx=-1.0), "lx"), (dict(ly=float("nan")), "ly"),
    (dict(ly="a"), "ly"), (dict(nx=0), "nx"), (dict(ny=1.5), "ny"), (dict(nx=True), "nx"),
    (dict(cell="hexahedron"), "cell"), (dict(diagonal="up"), "diagonal"),
    (dict(origin=(0.0, 0.0)), "origin"), (dict(origin=(0.0, 0.0, math.inf)), "origin"),
])
def test_plate_bad_input(kwargs, param):
    args = dict(lx=1.0, ly=1.0, nx=2, ny=2) | kwargs
    with pytest.raises(ValueError, match=rf"^{param}:"):
        plate(**args)


@pytest.mark.parametrize("kwargs, param", [
    (dict(length=0.0), "length"), (dict(radius=-0.1), "radius"), (dict(n_around=2), "n_around"),
    (dict(n_along=0), "n_along"), (dict(cell="tetrahedron"), "cell"), (dict(order=3), "order"),
])
def test_tube_bad_input(kwargs, param):
    args = dict(length=1.0, radius=0.1, n_around=6, n_along=2) | kwargs
    with pytest.raises(ValueError, match=rf"^{param}:"):
        tube(**args)


# ---------------------------------------------------------------- gmsh_io


def _disk_with_two_groups(model) -> None:
    """Unit disk split into two half-disk physical surfaces, boundary tagged 'rim' (unnamed cut)."""
    geo = model.geo
    c = geo.addPoint(0, 0, 0, 0.3)
    p = [geo.addPoint(x, y, 0, 0.3) for x, y in ((1, 0), (0, 1), (-1, 0), (0, -1))]
    arcs = [geo.addCircleArc(p[i], c, p[(i + 1) % 4]) for i in range(4)]
    cut = geo.addLine(p[0], p[2])
    upper = geo.addPlaneSurface([geo.addCurveLoop([arcs[0], arcs[1], -cut])])
    lower = geo.addPlaneSurface([geo.addCurveLoop([arcs[2], arcs[3], cut])])
    geo.synchronize()
    model.setPhysicalName(1, model.addPhysicalGroup(1, arcs, 7), "rim")
    model.addPhysicalGroup(1, [cut], 9)
    model.addPhysicalGroup(2, [upper], 1)
    model.addPhysicalGroup(2, [lower], 2)
    model.mesh.generate(2)


@pytest.mark.parametrize("gdim", [2, 3])
def test_model_to_mesh_cell_tags_and_names(gdim):
    mesh, cell_tags, facet_tags, names = gmsh_to_dolfinx(_disk_with_two_groups, COMM, gdim=gdim)
    assert mesh.geometry.dim == gdim
    assert names == {"rim": 7, "9": 9}
    upper = integrate(1.0, ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags)(1))
    total = integrate(1.0, ufl.dx(domain=mesh))
    assert upper == pytest.approx(total / 2, rel=1e-12)
    dS = ufl.Measure("dS", domain=mesh, subdomain_data=facet_tags)
    assert integrate(1.0, dS(9)) == pytest.approx(2.0, rel=1e-12)  # the cut, an interior line
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
    assert integrate(1.0, ds(7)) == pytest.approx(integrate(1.0, ds), rel=1e-12)


def test_model_to_mesh_without_mesh_raises():
    def geometry_only(model):
        model.geo.addPoint(0, 0, 0)
        model.geo.synchronize()
    with pytest.raises(ValueError, match="^model:.*no mesh"):
        gmsh_to_dolfinx(geometry_only, COMM)


def test_model_to_mesh_bad_gdim():
    with pytest.raises(ValueError, match="^gdim:"):
        model_to_mesh(None, COMM, gdim=4)


@serial_only
def test_user_gmsh_session_is_preserved():
    import gmsh

    from fabricfem.meshes._gmsh_session import gmsh_is_initialized
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mine")
        plate(1.0, 1.0, 2, 2)
        tube(1.0, 0.1, 6, 2)
        assert gmsh_is_initialized(gmsh)
        assert gmsh.model.getCurrent() == "mine"
        assert gmsh.model.list() == ["", "mine"]
        assert gmsh.option.getNumber("General.Terminal") == 0
    finally:
        gmsh.finalize()


# ---------------------------------------------------------------- MPI


@pytest.mark.mpi
@pytest.mark.parametrize("make, cells, exact_area, lengths", [
    (lambda: plate(2.0, 1.0, 8, 4), 64, 2.0, {"left": 1.0, "right": 1.0, "bottom": 2.0, "top": 2.0}),
    (lambda: plate(2.0, 1.0, 8, 4, cell="quadrilateral"), 32, 2.0,
     {"left": 1.0, "right": 1.0, "bottom": 2.0, "top": 2.0}),
    (lambda: tube(1.0, 0.1, 10, 13), 130, tube_area(1.0, 0.1, 10),
     {"end0": tube_area(1.0, 0.1, 10), "end1": tube_area(1.0, 0.1, 10)}),
    (lambda: tube(1.0, 0.1, 15, 20, cell="triangle"), 600, tube_area(1.0, 0.1, 15),
     {"end0": tube_area(1.0, 0.1, 15), "end1": tube_area(1.0, 0.1, 15)}),
], ids=["plate-tri", "plate-quad", "tube-quad-10x13", "tube-tri-15x20"])
def test_global_counts_area_and_tag_lengths(make, cells, exact_area, lengths):
    """Same global cell count, area and tagged edge lengths on any number of ranks."""
    fm = make()
    assert n_cells(fm) == cells
    assert area(fm) == pytest.approx(exact_area, rel=1e-12)
    for name, length in lengths.items():  # ds(tag) summed over ranks: no facet lost or doubled
        assert tag_length(fm, name) == pytest.approx(length, rel=1e-12), name
    x = fm.mesh.geometry.x.T
    assert np.allclose(np.sum(fm.warp(x) * fm.normal(x), axis=0), 0.0)


@pytest.mark.mpi
def test_build_error_raised_on_all_ranks():
    def broken(model):
        raise RuntimeError("broken geometry")
    with pytest.raises(RuntimeError, match="broken geometry"):
        gmsh_to_dolfinx(broken, COMM)
