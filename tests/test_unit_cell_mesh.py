"""Tests of the plain-weave unit-cell meshes (meshes/unit_cell.py, meshes/yarn_geometry.py).

Serial:  python -m pytest -q tests/test_unit_cell_mesh.py
MPI:     mpirun -n 2 python -m pytest -q -p no:cacheprovider -m mpi tests/test_unit_cell_mesh.py
"""
from __future__ import annotations

import math

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from scipy import special
from scipy.spatial import cKDTree

from fabricfem.meshes.unit_cell import REFINEMENTS, MeshResolution, section_mesh, unit_cell
from fabricfem.meshes.yarn_geometry import (
    PlainWeave,
    YarnFamily,
    amplitude_from_crimp,
    check_weave,
    sinusoid_arc_length,
)

COMM = MPI.COMM_WORLD
serial_only = pytest.mark.skipif(COMM.size > 1, reason="serial check of process-local data")
ROUNDOFF = 1e-12  # relative: identities that hold exactly up to floating-point round-off


@pytest.fixture(scope="module")
def quarter_coarse():
    return unit_cell(PlainWeave(), "quarter", "coarse", COMM)


@pytest.fixture(scope="module")
def quarter_fine():
    return unit_cell(PlainWeave(), "quarter", "fine", COMM)


@pytest.fixture(scope="module")
def full_coarse():
    return unit_cell(PlainWeave(), "full", "coarse", COMM)


def polygon_area(family: YarnFamily, res: MeshResolution) -> float:
    """Area of the n-gon inscribed in the ellipse at equal parametric angles: (n/2) a b sin(2 pi/n)."""
    n = res.polygon_vertices
    return 0.5 * n * family.semi_width * family.semi_height * math.sin(2.0 * math.pi / n)


def integrate(uc, expr, measure) -> float:
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * measure))
    return uc.mesh.comm.allreduce(local, op=MPI.SUM)


def tag_area(uc, name: str) -> float:
    """Global area of the facets tagged ``name``.

    The selection is re-tagged as 1, so every call uses the same form (one JIT compilation).
    """
    fdim = uc.mesh.topology.dim - 1
    facets = uc.facets(name)
    marker = dolfinx.mesh.meshtags(uc.mesh, fdim, facets, np.ones(facets.size, dtype=np.int32))
    ds = ufl.Measure("ds", domain=uc.mesh, subdomain_data=marker)
    return integrate(uc, 1.0, ds(1))


def owned_cells(uc, name: str) -> np.ndarray:
    cells = uc.cells(name)
    return cells[cells < uc.mesh.topology.index_map(3).size_local]


def facet_vertex_coordinates(uc, name: str) -> np.ndarray:
    """Unique coordinates (n, 3) of the vertices of the local facets tagged ``name``."""
    mesh = uc.mesh
    fdim = mesh.topology.dim - 1
    geometry = dolfinx.cpp.mesh.entities_to_geometry(mesh._mesh, fdim, uc.facets(name), False)
    return mesh.geometry.x[np.unique(geometry.ravel())]


# ------------------------------------------------------------------ geometry (pure numpy)

def test_arc_length_matches_elliptic_integral():
    # Independent closed form: over a half period, L = (2p/pi) sqrt(1+k^2) E(k^2/(1+k^2)), k = pi A/p
    p, amplitude = 1.0e-3, 0.3e-3
    k = math.pi * amplitude / p
    reference = 2.0 * p / math.pi * math.sqrt(1.0 + k * k) * special.ellipe(k * k / (1.0 + k * k))
    # quad with epsrel 1e-13 on a smooth periodic integrand: round-off level agreement expected
    assert sinusoid_arc_length(p, amplitude, 0.0, p) == pytest.approx(reference, rel=1e-12)


def test_amplitude_from_crimp_both_models():
    p, crimp = 1.0e-3, 0.1
    # Kawabata's straight segments [Man2006, eq. 4.1]: sqrt(4 h^2 + y0^2) = (1 + c) y0
    h = amplitude_from_crimp(p, crimp, "kawabata")
    assert math.sqrt(4.0 * h * h + p * p) == pytest.approx((1.0 + crimp) * p, rel=1e-14)
    # sinusoid: the yarn length from the elliptic integral is (1 + c) p (brentq xtol 1e-15 p)
    a = amplitude_from_crimp(p, crimp)
    k = math.pi * a / p
    length = 2.0 * p / math.pi * math.sqrt(1.0 + k * k) * special.ellipe(k * k / (1.0 + k * k))
    assert length == pytest.approx((1.0 + crimp) * p, rel=1e-12)
    assert amplitude_from_crimp(p, 0.0) == 0.0


def test_balanced_weave_volume_fraction():
    # [Man2006, sec. 4.3.5]: balanced weave, radius ratio 1.5, phi = 0.4
    weave = PlainWeave.balanced(1.0e-3, crimp=0.08, volume_fraction=0.4, aspect_ratio=1.5)
    assert weave.warp == weave.weft
    assert weave.warp.aspect_ratio == pytest.approx(1.5, rel=1e-14)
    # brentq solved the width to xtol 1e-15 p; phi is smooth in the width
    assert weave.volume_fraction("quarter") == pytest.approx(0.4, rel=1e-10)
    assert weave.volume_fraction("full") == pytest.approx(0.4, rel=1e-10)
    check_weave(weave)


def test_level_function_on_the_tube():
    # the implicit function is 0 on the centreline and 1 on the surface built from (T, B, N)
    weave = PlainWeave()
    for yarn in weave.yarns("full"):
        s = np.linspace(yarn.start, yarn.end, 37)
        assert np.allclose(yarn.level(yarn.centre(s)), 0.0, atol=1e-20)
        surface = yarn.surface_points(37, 16)
        assert np.allclose(yarn.level(surface), 1.0, rtol=0.0, atol=1e-10)
        outside = yarn.centre(s) + 1.01 * yarn.family.semi_height * yarn.normal(s)
        assert np.all(yarn.level(outside) > 1.0)


def test_default_weave_is_accepted():
    weave = PlainWeave()
    assert check_weave(weave) > 1.0
    # 2 (A + b) is the thickness; crossing gap A_w + A_f - b_w - b_f > 0
    assert weave.warp.amplitude + weave.weft.amplitude > weave.warp.semi_height + weave.weft.semi_height


@pytest.mark.parametrize("factor, accepted", [(1.02, True), (0.98, False)])
def test_crossing_contact_threshold(factor, accepted):
    # Narrow yarns (b/a^2 >> A pi^2/p^2): the tubes first touch at the crossing point, where the
    # centrelines are A_w + A_f apart and the sections b_w + b_f thick: closed-form threshold
    # A = b for a balanced weave.  +-2 % is 30x the sampling error of the check there.
    width = 0.2e-3
    b = 0.5 * width / 1.5
    yarn = YarnFamily(1.0e-3, factor * b, width, width / 1.5)
    weave = PlainWeave(yarn, yarn)
    if accepted:
        assert check_weave(weave) > 1.0
    else:
        with pytest.raises(ValueError, match="amplitude"):
            check_weave(weave)


@pytest.mark.parametrize("factor, accepted", [(0.97, True), (1.03, False)])
def test_curvature_threshold(factor, accepted):
    # A tube of half height b around z = A cos(pi s/p) overlaps itself once b A pi^2 / p^2 >= 1
    width, p = 0.2e-3, 1.0e-3
    b = 0.5 * width / 1.5
    yarn = YarnFamily(p, factor * p * p / (math.pi ** 2 * b), width, width / 1.5)
    weave = PlainWeave(yarn, yarn)
    if accepted:
        check_weave(weave)
    else:
        with pytest.raises(ValueError, match="warp.amplitude"):
            check_weave(weave)


def test_over_crimped_weave_is_rejected():
    # wide yarns (0.8 of the spacing) with crimp 0.2: the steep flanks cut into the crossing yarn
    yarn = YarnFamily.from_crimp(1.0e-3, 0.2, 0.8e-3, aspect_ratio=1.5)
    with pytest.raises(ValueError, match="amplitude.*too large"):
        check_weave(PlainWeave(yarn, yarn))
    with pytest.raises(ValueError, match="amplitude"):
        unit_cell(PlainWeave(yarn, yarn), "quarter", "coarse", COMM)


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match="aspect_ratio"):
        YarnFamily.from_crimp(1e-3, 0.1, 0.5e-3, aspect_ratio=0.0)
    with pytest.raises(ValueError, match="aspect_ratio"):
        PlainWeave.balanced(aspect_ratio=-1.5)
    for name in ("half_period", "width", "height"):
        with pytest.raises(ValueError, match=name):
            YarnFamily(**{name: 0.0})
    with pytest.raises(ValueError, match="amplitude"):
        YarnFamily(amplitude=-1e-4)
    with pytest.raises(ValueError, match="crimp"):
        amplitude_from_crimp(1e-3, -0.1)
    for phi in (0.0, 1.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="volume_fraction"):
            PlainWeave.balanced(volume_fraction=phi)
    with pytest.raises(ValueError, match="volume_fraction"):
        PlainWeave.balanced(volume_fraction=0.95)  # not reachable with yarns narrower than the spacing
    with pytest.raises(ValueError, match="warp.width"):
        check_weave(PlainWeave(YarnFamily(width=1.0e-3, height=0.5e-3), YarnFamily()))
    with pytest.raises(ValueError, match="option"):
        unit_cell(PlainWeave(), "half", "coarse", COMM)
    with pytest.raises(ValueError, match="refinement"):
        unit_cell(PlainWeave(), "quarter", "medium", COMM)
    with pytest.raises(ValueError, match="refinement.core"):
        MeshResolution(along=8, core=0, ring=1)


def test_section_mesh_is_an_inscribed_polygon():
    res = REFINEMENTS["coarse"]
    points, quads, rim = section_mesh(res)
    # positive orientation of every quadrilateral (tensor order v0, v1, v2)
    e1 = points[quads[:, 1]] - points[quads[:, 0]]
    e2 = points[quads[:, 2]] - points[quads[:, 0]]
    assert np.all(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0.0)
    assert np.allclose(np.hypot(*points[rim].T), 1.0, atol=1e-15)
    # bilinear quads tile the regular 4m-gon: total area (n/2) sin(2 pi / n) (unit disc)
    p0, p1, p2, p3 = (points[quads[:, i]] for i in range(4))
    area = 0.5 * np.sum(np.cross(p3 - p0, p2 - p1))  # area of a planar quad from its diagonals
    n = res.polygon_vertices
    assert area == pytest.approx(0.5 * n * math.sin(2.0 * math.pi / n), rel=ROUNDOFF)


# ------------------------------------------------------------------ meshes

@pytest.mark.mpi
def test_tags_present(quarter_coarse, full_coarse):
    for uc, names in ((quarter_coarse, ["warp0", "weft0"]),
                      (full_coarse, ["warp0", "warp1", "weft0", "weft1"])):
        assert sorted(uc.yarn_ids) == sorted(names)
        assert uc.mesh.topology.dim == 3 and uc.mesh.geometry.dim == 3
        for name in names:
            for part in ("start", "end", "surface"):
                assert tag_area(uc, f"{name}_{part}") > 0.0
        counts = [COMM.allreduce(owned_cells(uc, name).size, op=MPI.SUM) for name in names]
        assert len(set(counts)) == 1  # all yarns of a cell are meshed alike


@serial_only
def test_tags_cover_the_whole_boundary(quarter_coarse):
    uc = quarter_coarse
    fdim = uc.mesh.topology.dim - 1
    uc.mesh.topology.create_connectivity(fdim, fdim + 1)
    boundary = dolfinx.mesh.exterior_facet_indices(uc.mesh.topology)
    assert np.array_equal(np.sort(boundary), np.sort(uc.facet_tags.indices))


@pytest.mark.mpi
def test_volume_equals_discrete_identity(quarter_coarse, full_coarse):
    # Exact identity for trilinear hexahedra between planar sections (polygon P, centroid on the
    # centreline) perpendicular to a planar curve: V = area(P) * sum_i (c_{i+1} - c_i).(T_i + T_{i+1})/2.
    # The reference is computed from the analytic centreline only.
    for uc in (quarter_coarse, full_coarse):
        res = uc.resolution
        for yarn in uc.yarns:
            n_seg = res.along * round((yarn.end - yarn.start) / yarn.family.half_period)
            s = np.linspace(yarn.start, yarn.end, n_seg + 1)
            c, t = yarn.centre(s), yarn.tangent(s)
            sweep = np.sum(np.einsum("ij,ij->i", np.diff(c, axis=0), 0.5 * (t[1:] + t[:-1])))
            reference = polygon_area(yarn.family, res) * sweep
            assert uc.yarn_volumes[yarn.name] == pytest.approx(reference, rel=ROUNDOFF)


@pytest.mark.mpi
@pytest.mark.parametrize("refinement", ["coarse", "fine"])
def test_volume_vs_analytic(refinement, quarter_coarse, quarter_fine):
    # Reference: exact tube volume pi a b x arc length (arc length by scipy quad).
    # Discretisation error, both parts make the mesh smaller:
    #  - section: inscribed 4m-gon, relative deficit 1 - sin(2 pi/n)/(2 pi/n) (exact);
    #  - sweep: a segment of arc length h and turning angle kappa h contributes R sin(kappa h)
    #    instead of R kappa h, a relative deficit <= (kappa_max h_max)^2 / 6 (+ O((kappa h)^4)).
    uc = quarter_coarse if refinement == "coarse" else quarter_fine
    res = uc.resolution
    for yarn in uc.yarns:
        fam = yarn.family
        n = res.polygon_vertices
        section_deficit = 1.0 - math.sin(2.0 * math.pi / n) / (2.0 * math.pi / n)
        ds = fam.half_period / res.along
        h_max = ds * math.sqrt(1.0 + (fam.amplitude * math.pi / fam.half_period) ** 2)
        sweep_deficit = (fam.max_curvature * h_max) ** 2 / 6.0
        exact = yarn.volume()
        measured = uc.yarn_volumes[yarn.name]
        print(f"{refinement} {yarn.name}: V_mesh = {measured:.6e}, V_exact = {exact:.6e}, "
              f"rel {measured / exact - 1:+.3e}, bound -{section_deficit + sweep_deficit:.3e}")
        assert measured < exact
        assert exact - measured <= (section_deficit + sweep_deficit) * exact


def test_volume_converges_second_order(quarter_coarse, quarter_fine):
    # fine halves the station spacing and doubles the polygon vertices: both O(h^2) deficits
    # drop by 4 asymptotically; 3 leaves room for pre-asymptotic terms.
    exact = PlainWeave().yarn_volume("quarter")
    e_coarse = exact - quarter_coarse.yarn_volume
    e_fine = exact - quarter_fine.yarn_volume
    assert e_coarse / e_fine > 3.0


@pytest.mark.mpi
def test_end_face_area_is_the_section_polygon(quarter_coarse):
    # every end face is the planar inscribed polygon: area (n/2) a b sin(2 pi/n) exactly
    uc = quarter_coarse
    for yarn in uc.yarns:
        reference = polygon_area(yarn.family, uc.resolution)
        for part in ("start", "end"):
            assert tag_area(uc, f"{yarn.name}_{part}") == pytest.approx(reference, rel=ROUNDOFF)


def test_lateral_area_vs_analytic(quarter_fine):
    # Tube surface of a planar centreline and a section symmetric about the normal:
    # area = ellipse perimeter 4 a E(1 - b^2/a^2) x arc length.  The mesh (inscribed polygon,
    # ruled faces) is smaller by the perimeter deficit of the polygon (computed exactly) plus the
    # sweep deficit (kappa_max h_max)^2 / 6 as for the volume.
    uc = quarter_fine
    res = uc.resolution
    for yarn in uc.yarns:
        fam = yarn.family
        a, b = fam.semi_width, fam.semi_height
        perimeter = 4.0 * a * special.ellipe(1.0 - (b / a) ** 2)
        theta = 2.0 * math.pi * np.arange(res.polygon_vertices + 1) / res.polygon_vertices
        polygon = np.sum(np.hypot(np.diff(a * np.cos(theta)), np.diff(b * np.sin(theta))))
        h_max = fam.half_period / res.along * math.sqrt(1.0 + (fam.amplitude * math.pi / fam.half_period) ** 2)
        sweep_deficit = (fam.max_curvature * h_max) ** 2 / 6.0
        exact = perimeter * yarn.arc_length()
        measured = tag_area(uc, f"{yarn.name}_surface")
        bound = (1.0 - polygon / perimeter) + sweep_deficit
        print(f"{yarn.name}_surface: {measured:.6e} vs {exact:.6e}, rel {measured / exact - 1:+.3e}, bound {bound:.3e}")
        assert abs(measured - exact) <= bound * exact


@serial_only
@pytest.mark.parametrize("option", ["quarter", "full"])
def test_end_faces_match_under_periodicity(option, quarter_coarse, full_coarse):
    uc = quarter_coarse if option == "quarter" else full_coarse
    scale = float(np.max(uc.cell_box))
    for yarn in uc.yarns:
        start = facet_vertex_coordinates(uc, f"{yarn.name}_start")
        end = facet_vertex_coordinates(uc, f"{yarn.name}_end")
        assert start.shape == end.shape and start.shape[0] > 0
        mapped = uc.periodic_relation(yarn.name)(end.T).T
        distance, index = cKDTree(start).query(mapped)
        assert np.max(distance) < ROUNDOFF * scale
        assert np.unique(index).size == start.shape[0]  # one-to-one
        # same transverse in-plane coordinate on both faces
        assert np.allclose(np.sort(start[:, 1 - yarn.axis]), np.sort(end[:, 1 - yarn.axis]),
                           rtol=0.0, atol=ROUNDOFF * scale)
    if option == "full":  # full cell: pure translation, z unchanged
        x = np.array([[0.0], [0.0], [1.0e-4]])
        assert uc.periodic_relation("warp0")(x)[2, 0] == 1.0e-4


def test_yarns_do_not_share_nodes_and_stay_apart(full_coarse):
    # every mesh node lies inside or on its own yarn and outside all the others (level >= 1)
    uc = full_coarse
    x = uc.mesh.geometry.x
    dofmap = uc.mesh.geometry.dofmap.array.reshape(-1, 8)
    for yarn in uc.yarns:
        cells = uc.cells(yarn.name)
        nodes = x[np.unique(dofmap[cells].ravel())]
        assert np.all(yarn.level(nodes) <= 1.0 + 1e-9)
        for other in uc.yarns:
            if other.name != yarn.name:
                assert np.all(other.level(nodes) > 1.0)


def test_yarn_axis(quarter_coarse):
    # Independent estimate of the tangent: the mean direction of the 4 hexahedron edges along the
    # sweep, which equals the tangent at the mid-station up to O((kappa h)^2); the DG0 axis is the
    # tangent at the foot point of the cell midpoint.  Allowed angle: (kappa_max h_max)^2.
    uc = quarter_coarse
    axis = uc.yarn_axis.x.array.reshape(-1, 3)
    dof = uc.yarn_axis.function_space.dofmap.list.array.reshape(-1)
    x = uc.mesh.geometry.x
    nodes = uc.mesh.geometry.dofmap.array.reshape(-1, 8)
    for yarn in uc.yarns:
        cells = uc.cells(yarn.name)
        a = axis[dof[cells]]
        assert np.allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-14)
        assert np.allclose(a[:, 1 - yarn.axis], 0.0, atol=1e-14)
        hx = x[nodes[cells]]
        edge = hx[:, 4:].mean(axis=1) - hx[:, :4].mean(axis=1)
        edge /= np.linalg.norm(edge, axis=1)[:, None]
        fam = yarn.family
        h_max = fam.half_period / uc.resolution.along * math.sqrt(
            1.0 + (fam.amplitude * math.pi / fam.half_period) ** 2)
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", a, edge), -1.0, 1.0))
        print(f"{yarn.name}: max angle axis vs mesh edges {angle.max():.3e} rad")
        assert np.max(angle) <= (fam.max_curvature * h_max) ** 2
        # callable form agrees with the field at the cell midpoints
        mid = dolfinx.mesh.compute_midpoints(uc.mesh, 3, cells)
        assert np.allclose(uc.axis_at(mid.T, yarn.name).T, a, atol=1e-12)


@pytest.mark.mpi
def test_coarse_vs_fine_cell_counts(quarter_coarse, quarter_fine, full_coarse):
    def n_cells(uc):
        return uc.mesh.topology.index_map(3).size_global
    for uc in (quarter_coarse, quarter_fine, full_coarse):
        res = uc.resolution
        half_waves = 2 if uc.option == "quarter" else 8  # 2 yarns x 1, 4 yarns x 2 half periods
        assert n_cells(uc) == half_waves * res.along * res.section_cells
    assert n_cells(quarter_coarse) == 512 and n_cells(quarter_fine) == 5120
    assert n_cells(full_coarse) == 4 * n_cells(quarter_coarse)


def test_cell_box_and_volume_fraction(quarter_coarse, full_coarse):
    w = PlainWeave()
    h = max(w.warp.amplitude + w.warp.semi_height, w.weft.amplitude + w.weft.semi_height)
    assert np.allclose(quarter_coarse.cell_box, [w.warp.half_period, w.weft.half_period, 2 * h], rtol=1e-15)
    assert np.allclose(full_coarse.cell_box, [2 * w.warp.half_period, 2 * w.weft.half_period, 2 * h], rtol=1e-15)
    # the yarn nodes lie within the box except where the tilted end sections stick out in the yarn
    # direction, by at most b sin(alpha_max)
    for uc in (quarter_coarse, full_coarse):
        x = uc.mesh.geometry.x
        assert np.all(x[:, 2] >= uc.box_lower[2] - 1e-15) and np.all(x[:, 2] <= uc.box_upper[2] + 1e-15)
        assert 0.0 < uc.volume_fraction < 1.0
    # same fraction for both cells (the full cell is four quarter cells)
    assert full_coarse.volume_fraction == pytest.approx(quarter_coarse.volume_fraction, rel=ROUNDOFF)


@pytest.mark.mpi
def test_distributed_volume_and_areas_identical():
    # The same mesh built on COMM_WORLD (distributed when run under mpirun -n 2) and on COMM_SELF
    # (whole mesh on each rank) must give the same yarn volumes and tag areas up to the
    # round-off of summing in a different order.
    weave = PlainWeave()
    distributed = unit_cell(weave, "full", "coarse", COMM)
    local = unit_cell(weave, "full", "coarse", MPI.COMM_SELF)
    owned = distributed.mesh.topology.index_map(3).size_local
    if COMM.size > 1:
        assert COMM.allreduce(int(owned > 0), op=MPI.SUM) == COMM.size  # really partitioned
    for name, volume in local.yarn_volumes.items():
        assert distributed.yarn_volumes[name] == pytest.approx(volume, rel=ROUNDOFF)
    for name in local.tags:
        assert tag_area(distributed, name) == pytest.approx(tag_area(local, name), rel=ROUNDOFF)
    # axis field: volume integral of each component over each yarn (one form, selection tagged 1)
    for name in local.yarn_ids:
        for i in range(3):
            values = [axis_integral(uc, name, i) for uc in (distributed, local)]
            assert values[0] == pytest.approx(values[1], rel=ROUNDOFF, abs=ROUNDOFF * local.yarn_volumes[name])


def axis_integral(uc, name: str, component: int) -> float:
    """Integral of yarn_axis . e_component over yarn ``name``."""
    cells = uc.cells(name)
    marker = dolfinx.mesh.meshtags(uc.mesh, 3, cells, np.ones(cells.size, dtype=np.int32))
    direction = dolfinx.fem.Constant(uc.mesh, np.eye(3)[component])
    dx = ufl.Measure("dx", domain=uc.mesh, subdomain_data=marker)
    return integrate(uc, ufl.dot(uc.yarn_axis, direction), dx(1))
