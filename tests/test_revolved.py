"""annulus and spherical_cap: areas against the exact ones, tagged edges of the exact length, the same mesh
on 1 and 2 ranks; the exported mesh_from_gmsh on a slit plate, whose two sides are read separately."""
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fabricfem.materials import Fabric
from fabricfem.meshes import annulus, mesh_from_gmsh, spherical_cap
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path

R_IN, R_OUT, SECTOR = 0.1, 0.3, np.pi / 3
R, OPENING, HOLE = 0.2, np.pi / 2, 0.3
BUILDERS = {   # name -> (builder, exact area [m^2], exact edge lengths [m])
    "annulus": (lambda comm: annulus(R_IN, R_OUT, comm=comm), np.pi * (R_OUT ** 2 - R_IN ** 2),
                {"inner": 2 * np.pi * R_IN, "outer": 2 * np.pi * R_OUT}),
    "annular sector, triangles": (lambda comm: annulus(R_IN, R_OUT, SECTOR, cell="triangle", comm=comm),
                                  SECTOR / 2 * (R_OUT ** 2 - R_IN ** 2),
                                  {"inner": SECTOR * R_IN, "outer": SECTOR * R_OUT, "side0": R_OUT - R_IN,
                                   "side1": R_OUT - R_IN}),
    "hemisphere with a hole": (lambda comm: spherical_cap(R, OPENING, HOLE, comm=comm),
                               2 * np.pi * R ** 2 * (np.cos(HOLE) - np.cos(OPENING)),
                               {"hole": 2 * np.pi * R * np.sin(HOLE), "rim": 2 * np.pi * R}),
    "cap past the equator, triangles": (lambda comm: spherical_cap(R, 2.0, HOLE, cell="triangle", comm=comm),
                                        2 * np.pi * R ** 2 * (np.cos(HOLE) - np.cos(2.0)),
                                        {"hole": 2 * np.pi * R * np.sin(HOLE), "rim": 2 * np.pi * R * np.sin(2.0)}),
}


def measures(fm) -> dict:
    """Area, tagged edge lengths and the number of cells, summed over the ranks of the mesh."""
    ds = ufl.Measure("ds", domain=fm.mesh, subdomain_data=fm.facet_tags)
    total = lambda form: fm.mesh.comm.allreduce(fem.assemble_scalar(fem.form(form)), op=MPI.SUM)  # noqa: E731
    out = {"area": total(1.0 * ufl.dx(domain=fm.mesh)),
           "cells": fm.mesh.topology.index_map(2).size_global}
    out.update({name: total(1.0 * ds(fm.tag(name))) for name in fm.tags})
    return out


@pytest.mark.parametrize("name", list(BUILDERS))
def test_area_and_edges_against_exact(name):
    """Default resolution, second-order geometry: area within 1e-4 relative of the exact one (measured
    <= 2.5e-6), each tagged edge of its exact length within 1e-4; warp tangent and of unit length."""
    build, area, lengths = BUILDERS[name]
    fm = build(MPI.COMM_WORLD)
    got = measures(fm)
    assert got["area"] == pytest.approx(area, rel=1e-4)
    assert set(fm.tags) == set(lengths)
    for tag, length in lengths.items():
        assert got[tag] == pytest.approx(length, rel=1e-4), tag
    x = fm.mesh.geometry.x.T
    assert np.allclose(np.sum(fm.warp(x) * fm.normal(x), axis=0), 0.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(fm.warp(x), axis=0), 1.0)


@pytest.mark.mpi
@pytest.mark.parametrize("name", list(BUILDERS))
def test_same_mesh_on_one_and_two_ranks(name):
    """Under mpirun -n 2: the distributed mesh has the cells, area and edge lengths of the serial one
    (1e-12 relative: the same nodes, summed in another order)."""
    build = BUILDERS[name][0]
    serial, parallel = measures(build(MPI.COMM_SELF)), measures(build(MPI.COMM_WORLD))
    assert serial.keys() == parallel.keys()
    for key in serial:
        assert parallel[key] == pytest.approx(serial[key], rel=1e-12), key


@pytest.mark.parametrize("name, call", [
    ("r_out", lambda: annulus(0.3, 0.1)), ("angle", lambda: annulus(0.1, 0.3, angle=7.0)),
    ("hole_angle", lambda: spherical_cap(1.0, 1.0, 0.0)),
    ("opening_angle", lambda: spherical_cap(1.0, 0.2, 0.3)), ("warp", lambda: annulus(0.1, 0.3, warp=(0, 0, 1))),
    ("angle", lambda: spherical_cap(1.0, 1.0, 0.2, angle=7.0)),
    ("start", lambda: spherical_cap(1.0, 1.0, 0.2, angle=1.0, start=float("nan")))])
def test_bad_arguments_name_the_parameter(name, call):
    with pytest.raises(ValueError, match=name):
        call()


def _slit_plate(model):
    """Unit square with a slit from (0, 0.5) to (0.5, 0.5): two rectangles sharing only x >= 0.5 of y = 0.5;
    the slit's two sides are separate curves on separate (coincident) points."""
    geo = model.geo
    p = {key: geo.addPoint(*xy, 0.0, 0.1) for key, xy in {
        "a": (0, 0), "b": (1, 0), "c": (1, 0.5), "m": (0.5, 0.5), "l_low": (0, 0.5), "l_up": (0, 0.5),
        "d": (1, 1), "e": (0, 1)}.items()}
    line = geo.addLine
    bottom, right_low, shared = line(p["a"], p["b"]), line(p["b"], p["c"]), line(p["c"], p["m"])
    slit_low, left_low = line(p["m"], p["l_low"]), line(p["l_low"], p["a"])
    right_up, top, left_up, slit_up = line(p["c"], p["d"]), line(p["d"], p["e"]), line(p["e"], p["l_up"]), \
        line(p["l_up"], p["m"])
    low = geo.addPlaneSurface([geo.addCurveLoop([bottom, right_low, shared, slit_low, left_low])])
    up = geo.addPlaneSurface([geo.addCurveLoop([-shared, right_up, top, left_up, slit_up])])
    geo.synchronize()
    for name, curves in {"bottom": [bottom], "top": [top], "slit_lower": [slit_low], "slit_upper": [slit_up]}.items():
        model.setPhysicalName(1, model.addPhysicalGroup(1, curves), name)
    model.addPhysicalGroup(2, [low, up])
    model.mesh.generate(2)


@pytest.mark.mpi
def test_slit_sides_are_read_separately():
    """A membrane square with a slit, held at the bottom and pulled up at the top: at (0.25, 0.5) the node of
    the upper side moves up more than the lower side's (the slit opens); the point without `side` is
    refused as ambiguous, and an unslit point needs no side."""
    fm = mesh_from_gmsh(_slit_plate, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), options={"Geometry.AutoCoherence": 0})
    model = ShellModel(fm, Fabric.isotropic(1e6, 0.0, 1e-3), model="membrane")
    model.clamp("bottom").constrain(lambda x: np.full(x.shape[1], True), u=(None, None, 0.0))
    model.add_edge_traction("top", (0.0, 10.0, 0.0))
    solve_load_path(model, 1.0, initial_step=1.0)
    point = (0.25, 0.5, 0.0)
    upper, lower = model.node_value(point, side="slit_upper"), model.node_value(point, side="slit_lower")
    assert upper[1] > lower[1] + 1e-3 > 1e-3
    with pytest.raises(ValueError, match="side"):
        model.node_value(point)
    assert np.all(np.isfinite(model.node_value((1.0, 0.5, 0.0))))


@pytest.mark.parametrize("gap", [5e-5, 1e-8])
def test_annulus_keeps_a_narrow_slit(gap):
    """An angle short of 2 pi by a gap below np.isclose's 6e-5 rad is a slit ring, not a closed one: the edges
    side0 and side1 (each r_out - r_in long) exist, the area is angle / (2 pi) of the closed ring's at the same
    resolution (to 1e-6: its segments are shorter by gap / n_around), and the slit's nodes are doubled (n_radial order + 1 more nodes than the closed ring)."""
    angle = 2.0 * np.pi - gap
    fm = annulus(R_IN, R_OUT, angle, n_radial=2, n_around=12, comm=MPI.COMM_SELF)
    ring = annulus(R_IN, R_OUT, n_radial=2, n_around=12, comm=MPI.COMM_SELF)
    got = measures(fm)
    assert set(fm.tags) == {"inner", "outer", "side0", "side1"}
    assert got["side0"] == pytest.approx(R_OUT - R_IN, rel=1e-12)
    assert got["side1"] == pytest.approx(R_OUT - R_IN, rel=1e-12)
    assert got["area"] == pytest.approx(angle / (2.0 * np.pi) * measures(ring)["area"], rel=1e-6)
    assert len(fm.mesh.geometry.x) == len(ring.mesh.geometry.x) + 2 * 2 + 1


@pytest.mark.parametrize("start", [0.0, np.pi / 2])
def test_quarter_of_a_hemisphere_from_an_azimuth_range(start):
    """spherical_cap(angle=pi/2, start=a0): the quarter of the hemisphere with a hole between the azimuths a0 and
    a0 + pi/2 (the octant x, y, z >= 0 for a0 = 0; x <= 0 <= y for a0 = pi/2): every node on the sphere and
    inside the quarter, side0 in the meridian plane of a0 and side1 in that of a0 + pi/2 (each a meridian arc
    R (opening - hole) long), a quarter of the area; the normal outward and the warp along the meridian."""
    fm = spherical_cap(R, OPENING, HOLE, n_polar=4, n_around=6, angle=np.pi / 2, start=start, comm=MPI.COMM_SELF)
    x = fm.mesh.geometry.x
    assert np.allclose(np.linalg.norm(x, axis=1), R, rtol=0, atol=1e-12)
    azimuth = np.mod(np.arctan2(x[:, 1], x[:, 0]) - start + 1e-9, 2.0 * np.pi) - 1e-9
    assert azimuth.min() >= -1e-9 and azimuth.max() <= np.pi / 2 + 1e-9
    assert x[:, 2].min() >= -1e-12
    got = measures(fm)
    assert got["area"] == pytest.approx(np.pi / 2 * R ** 2 * (np.cos(HOLE) - np.cos(OPENING)), rel=1e-4)
    assert set(fm.tags) == {"hole", "rim", "side0", "side1"}
    for tag, a in (("side0", start), ("side1", start + np.pi / 2)):
        assert got[tag] == pytest.approx(R * (OPENING - HOLE), rel=1e-4)
        mid = dolfinx.mesh.compute_midpoints(fm.mesh, 1, fm.facets(tag))
        assert np.allclose(mid[:, 0] * np.sin(a) - mid[:, 1] * np.cos(a), 0.0, atol=1e-12)     # in the plane
        assert np.all(mid[:, 0] * np.cos(a) + mid[:, 1] * np.sin(a) > 0.0)                     # on its half
    xt = x.T
    assert np.allclose(np.sum(fm.normal(xt) * xt, axis=0), R)
    assert np.allclose(fm.warp(xt)[2], -np.sin(np.arccos(x[:, 2] / R)))
