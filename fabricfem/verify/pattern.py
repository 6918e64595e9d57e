"""Sewing patterns: the meshed trousers of [Korosteleva2021] against their exact outlines and seams."""
from __future__ import annotations

import copy
from pathlib import Path

import ufl
from dolfinx import fem
from mpi4py import MPI

from fabricfem.meshes.pattern import (
    STITCH_LENGTH_TOLERANCE,
    Pattern,
    check_pattern,
    edge_length,
    outline_area,
    read_garmentcode,
)
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.patterns import pattern_path
from fabricfem.verify import Timer, case, result

TROUSERS = pattern_path("pants_straight_sides")
# (order, h [m]): order-2 geometry puts the mid-edge nodes on the Bezier edges (area error ~1e-6 at h = 5 cm);
# order 1 needs h = 1 cm to bring the chord error of the curved edges below 1e-4
MESHES = ((2, 0.05), (1, 0.01))


def panel_areas(garment) -> dict[str, float]:
    """Area [m^2] of each panel's cells: 1 dx assembled over its cell tag, summed over the ranks."""
    mesh = garment.fabric.mesh
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=garment.fabric.cell_tags)
    one = fem.Constant(mesh, 1.0)
    return {name: mesh.comm.allreduce(fem.assemble_scalar(fem.form(one * dx(tag))), op=MPI.SUM)
            for name, tag in garment.panel_tags.items()}


def stretched(pattern: Pattern, panel: str, factor: float) -> Pattern:
    """A copy of ``pattern`` with ``panel`` scaled by ``factor`` about its first vertex (its edges longer)."""
    bad = copy.deepcopy(pattern)
    v = bad.panels[panel].vertices
    bad.panels[panel].vertices = v[0] + factor * (v - v[0])
    return bad


@case("pattern-mesh", mpi=True)
def pattern_mesh(path: Path = TROUSERS) -> list:
    """The four-panel trousers [Korosteleva2021] meshed with quadrilaterals: each panel's meshed area (1 dx over
    its cells, all ranks) against the exact outline area (polygon + closed-form parabolic segments), within
    1e-4 relative, for order 2 at h = 5 cm and order 1 at h = 1 cm; each stitch pairs as many nodes on both
    sides (tolerance 0); each stitch's exact edge lengths differ by less than the stitch tolerance (value: the
    relative difference); and a pattern whose right back panel is stretched by 10 % is refused before meshing,
    naming both panels and both edges of a seam (refused = 1)."""
    out = []
    pattern = read_garmentcode(path)
    for order, h in MESHES:
        with Timer() as timer:
            garment = mesh_pattern(pattern, h, order=order)
            areas = panel_areas(garment)
        ndofs = garment.fabric.mesh.geometry.index_map().size_global
        for name, area in areas.items():
            out.append(result("pattern-mesh", f"order {order}, h = {h} m: area of panel {name} [m^2]", area,
                              outline_area(pattern.panels[name]), 1e-4, ndofs, timer.elapsed))
    for s in garment.stitches:
        out.append(result("pattern-mesh", f"stitch {s.name}: nodes on side b (reference: side a)",
                          len(s.points_b), len(s.points_a), 0.0, ndofs, 0.0))
    for s in pattern.stitches:
        la, lb = (edge_length(pattern.panels[p], e) for p, e in (s.a, s.b))
        out.append(result("pattern-mesh", f"stitch {s.name}: |L_a - L_b| / max (L_a = {la:.6f} m)",
                          abs(la - lb) / max(la, lb), 0.0, STITCH_LENGTH_TOLERANCE, 0, 0.0, scale=1.0))
    with Timer() as timer:
        bad = stretched(pattern, "Rback", 1.1)
        try:
            mesh_pattern(bad, 0.05)
            refused = 0.0
        except ValueError as error:
            message = str(error)
            named = all(item in message for item in ("'Rfront'", "'Rback'", "edge"))
            refused = 1.0 if named else 0.5
            check_pattern(pattern)   # the original passes the same check
    out.append(result("pattern-mesh", "Rback stretched 10 %: refused naming both panels and edges (1 = yes)",
                      refused, 1.0, 0.0, 0, timer.elapsed))
    return out
