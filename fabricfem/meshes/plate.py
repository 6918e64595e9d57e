"""Flat rectangular fabric plate in 3D.

The rectangle ``[x0, x0 + lx] x [y0, y0 + ly]`` in the plane ``z = z0``
(metres), meshed by gmsh on rank 0 and distributed over ``comm``.

Material frame: warp ``E1 = +x`` (first material direction), normal
``N = +z`` (the cells are oriented so that ``ufl.CellNormal`` is +z), and
weft ``E2 = N x E1 = +y``.

Edge tags: ``left`` (x = x0), ``right`` (x = x0 + lx), ``bottom``
(y = y0), ``top`` (y = y0 + ly); the cells carry the tag ``fabric``.
"""
from __future__ import annotations

from collections.abc import Sequence

from dolfinx.mesh import GhostMode
from mpi4py import MPI

from . import _validate
from .gmsh_io import FabricMesh, mesh_from_gmsh

# our name -> gmsh transfinite arrangement
DIAGONALS = {"right": "Right", "left": "Left", "alternate": "AlternateRight"}

# Unstructured quadrilaterals: Frontal-Delaunay triangles recombined by
# "Blossom full-quad" (no triangles left).  Not Mesh.Algorithm 8
# (Frontal-Delaunay for quads): it segfaults in Debian's gmsh 4.8.
_QUAD_OPTIONS = {"Mesh.Algorithm": 6, "Mesh.RecombinationAlgorithm": 3}


def _build(model, p0, lx: float, ly: float, nx: int, ny: int, cell: str,
           structured: bool, diagonal: str) -> None:
    """Geometry, physical groups and mesh of the rectangle in ``model``."""
    x0, y0, z0 = p0
    h = max(lx / nx, ly / ny)
    geo = model.geo
    corners = [geo.addPoint(x0 + dx, y0 + dy, z0, h)
               for dx, dy in ((0, 0), (lx, 0), (lx, ly), (0, ly))]
    # counter-clockwise seen from +z, so the surface (and cell) normal is +z
    bottom, right, top, left = (geo.addLine(corners[i], corners[(i + 1) % 4]) for i in range(4))
    surface = geo.addPlaneSurface([geo.addCurveLoop([bottom, right, top, left])])
    if structured:
        for curve, n in ((bottom, nx), (top, nx), (left, ny), (right, ny)):
            geo.mesh.setTransfiniteCurve(curve, n + 1)
        geo.mesh.setTransfiniteSurface(surface, DIAGONALS[diagonal], corners)
    if cell == "quadrilateral":
        geo.mesh.setRecombine(2, surface)
    geo.synchronize()
    for name, curve in (("bottom", bottom), ("right", right), ("top", top), ("left", left)):
        model.setPhysicalName(1, model.addPhysicalGroup(1, [curve]), name)
    model.setPhysicalName(2, model.addPhysicalGroup(2, [surface]), "fabric")
    model.mesh.generate(2)


def plate(lx: float, ly: float, nx: int, ny: int, cell: str = "triangle", structured: bool = True,
          origin: Sequence[float] = (0.0, 0.0, 0.0), comm: MPI.Comm = MPI.COMM_WORLD,
          diagonal: str = "right", *, ghost_mode: GhostMode = GhostMode.shared_facet) -> FabricMesh:
    """Mesh of the flat rectangle ``[x0, x0+lx] x [y0, y0+ly] x {z0}``.

    Args:
        lx, ly: Side lengths along x and y (m), > 0.
        nx, ny: Divisions along x and y (>= 1).  Structured: exactly
            nx x ny squares (each split into 2 triangles, or one quadrilateral).
            Unstructured: target element size max(lx/nx, ly/ny).
        cell: ``"triangle"`` or ``"quadrilateral"``.
        structured: Transfinite (structured) or unstructured gmsh meshing.
        origin: ``(x0, y0, z0)`` (m).
        comm: Communicator; gmsh runs on its rank 0 only.
        diagonal: Split of the structured squares into triangles, the gmsh
            transfinite arrangement: ``"right"``, ``"left"`` or ``"alternate"``.
            Ignored for quadrilaterals and unstructured meshes.
        ghost_mode: dolfinx ghost mode of the distributed mesh.

    Returns:
        FabricMesh with warp +x, normal +z, edge tags left/right/bottom/top.
    """
    lx = _validate.positive_length("lx", lx)
    ly = _validate.positive_length("ly", ly)
    nx = _validate.count("nx", nx)
    ny = _validate.count("ny", ny)
    cell = _validate.choice("cell", cell, _validate.CELLS)
    diagonal = _validate.choice("diagonal", diagonal, tuple(DIAGONALS))
    p0 = _validate.point3("origin", origin)
    options = _QUAD_OPTIONS if (cell == "quadrilateral" and not structured) else {}
    return mesh_from_gmsh(lambda model: _build(model, p0, lx, ly, nx, ny, cell, bool(structured), diagonal),
                          (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), comm, name="plate", options=options, ghost_mode=ghost_mode)
