"""Open circular cylinder (a sleeve) as a fabric surface.

Axis along +x from x = 0 (``end0``, shoulder) to x = length (``end1``,
wrist), radius ``radius`` (metres), with ``n_around`` elements around the
circumference and ``n_along`` along the axis; the thesis meshes 10x13,
15x20, 20x26 and 30x39 are ``n_around x n_along``.

Construction (gmsh built-in kernel, rank 0): the circle x = 0 is split into
k arcs, k the smallest divisor of ``n_around`` that is >= 3 (each arc is then
shorter than pi, as gmsh requires, and gets ``n_around / k`` equal segments);
all arcs are extruded together along +x with ``n_along`` layers.  Adjacent
patches share their lateral edges, so the mesh is conforming all around,
including where the angle wraps.  All first-order nodes lie on the circle, at
angles 2 pi j / n_around; second-order nodes are placed on the circle too.
Quadrilaterals come from recombined layers; triangles split each layer quad
into two.

Material frame: warp ``E1 = +x`` (along the sleeve, first material
direction), normal ``N`` = outward radial ``(0, y, z) / r`` (the cells are
oriented so that ``ufl.CellNormal`` points outwards), weft
``E2 = N x E1`` (circumferential; at (0, 0, R) it is +y).
"""
from __future__ import annotations

import inspect

import numpy as np
from dolfinx.mesh import GhostMode
from mpi4py import MPI

from . import _validate, directions
from .gmsh_io import FabricMesh, mesh_from_gmsh
from .sector_partition import by_sectors


def _n_arcs(n_around: int) -> int:
    """Smallest divisor of ``n_around`` that is at least 3."""
    return next(k for k in range(3, n_around + 1) if n_around % k == 0)


def _build(model, length: float, radius: float, n_around: int, n_along: int,
           cell: str, order: int, sector: tuple[float, float] | None = None) -> None:
    """Geometry, physical groups and mesh of the tube (``sector`` None) or of the cylindrical panel between
    the angles ``sector`` = (a0, a1) [rad] about +x, measured from +y towards +z, in ``model``."""
    geo = model.geo
    k = _n_arcs(n_around)
    centre = geo.addPoint(0.0, 0.0, 0.0)
    a0, a1 = (0.0, 2.0 * np.pi) if sector is None else sector
    angles = a0 + (a1 - a0) * np.arange(k + (sector is not None)) / k
    points = [geo.addPoint(0.0, radius * np.cos(a), radius * np.sin(a)) for a in angles]
    # arcs run with increasing angle about +x (the tube closes on its first point)
    arcs = [geo.addCircleArc(points[i], centre, points[(i + 1) % len(points)]) for i in range(k)]
    for arc in arcs:
        geo.mesh.setTransfiniteCurve(arc, n_around // k + 1)
    out = geo.extrude([(1, a) for a in arcs], length, 0.0, 0.0, numElements=[n_along],
                      recombine=(cell == "quadrilateral"))
    # per extruded curve: (1, top curve), (2, surface), (1, lateral line), (1, lateral line)
    tops = [tag for dim, tag in out[0::4]]
    surfaces = [tag for dim, tag in out[1::4]]
    geo.remove([(0, centre)])
    geo.synchronize()
    model.setPhysicalName(1, model.addPhysicalGroup(1, arcs), "end0")
    model.setPhysicalName(1, model.addPhysicalGroup(1, tops), "end1")
    if sector is not None:     # the straight edges: the lateral lines extruded from the sector's end points
        laterals = {tag for dim, tag in out if dim == 1} - set(tops)
        for name, start in (("side0", points[0]), ("side1", points[-1])):
            side = [c for c in laterals if start in {abs(p) for _, p in model.getBoundary([(1, c)], oriented=False)}]
            model.setPhysicalName(1, model.addPhysicalGroup(1, side), name)
    model.setPhysicalName(2, model.addPhysicalGroup(2, surfaces), "fabric")
    model.mesh.generate(2)
    if order > 1:
        model.mesh.setOrder(order)


def tube(length: float, radius: float, n_around: int, n_along: int, cell: str = "quadrilateral",
         comm: MPI.Comm = MPI.COMM_WORLD, order: int = 1, *,
         ghost_mode: GhostMode = GhostMode.shared_facet) -> FabricMesh:
    """Mesh of the open cylinder ``0 <= x <= length``, ``y^2 + z^2 = radius^2``.

    Args:
        length: Axial length (m), > 0.
        radius: Radius (m), > 0.
        n_around: Elements around the circumference (>= 3).
        n_along: Elements along the axis (>= 1).
        cell: ``"quadrilateral"`` or ``"triangle"`` (2 per quadrilateral).
        comm: Communicator; gmsh runs on its rank 0 only; the cells are split among the ranks by their angle
            about +x (fabricfem.meshes.sector_partition: on 2 ranks, z < 0 and z >= 0) when there are at least 2
            cells around per rank, else by the graph partitioner.
        order: Geometry order, 1 or 2 (6-node triangles / 9-node quads).
        ghost_mode: dolfinx ghost mode of the distributed mesh.

    Returns:
        FabricMesh with warp +x, outward radial normal, edge tags
        ``end0`` (x = 0) and ``end1`` (x = length).
    """
    return _cylinder(length, radius, n_around, n_along, cell, comm, order, ghost_mode, None, "tube")


def cylindrical_panel(length: float, radius: float, angle: float, n_around: int, n_along: int,
                      cell: str = "quadrilateral", comm: MPI.Comm = MPI.COMM_WORLD, order: int = 2, *,
                      start: float | None = None, ghost_mode: GhostMode = GhostMode.shared_facet) -> FabricMesh:
    """Mesh of the open cylindrical panel ``0 <= x <= length``, ``y^2 + z^2 = radius^2``, spanning ``angle``
    [rad] (< 2 pi) about +x from the angle ``start`` [rad] (measured about +x from +y towards +z) to
    start + angle; by default (``start`` None) symmetrically about the +z axis, start = pi/2 - angle/2 (a
    roof: its crown at (x, 0, radius)). A quarter of the cylinder y, z >= 0: angle = pi/2, start = 0.

    Same construction, material frame and arguments as :func:`tube` (``n_around`` elements across the
    panel, at least 3); edge tags ``end0`` (x = 0), ``end1`` (x = length), ``side0`` (the straight edge
    at the angle ``start``; by default y > 0) and ``side1`` (at start + angle; by default y < 0).
    """
    if not (isinstance(angle, (int, float)) and 0.0 < angle < 2.0 * np.pi):
        raise ValueError(f"angle: must lie in (0, 2 pi) radians, got {angle!r}")
    a0 = 0.5 * np.pi - 0.5 * angle if start is None else _validate.finite("start", start)
    sector = (a0, a0 + angle)
    return _cylinder(length, radius, n_around, n_along, cell, comm, order, ghost_mode, sector, "cylindrical_panel")


def _cylinder(length: float, radius: float, n_around: int, n_along: int, cell: str, comm: MPI.Comm, order: int,
              ghost_mode: GhostMode, sector: tuple[float, float] | None, name: str) -> FabricMesh:
    """Validated arguments -> the FabricMesh of the tube (sector None) or panel built by `_build`."""
    length = _validate.positive_length("length", length)
    radius = _validate.positive_length("radius", radius)
    n_around = _validate.count("n_around", n_around, minimum=3)
    n_along = _validate.count("n_along", n_along)
    cell = _validate.choice("cell", cell, _validate.CELLS)
    order = _validate.choice("order", _validate.count("order", order), (1, 2))
    # a whole tube is split among the ranks by angle (each rank one side of the plane z = 0 on 2 ranks: the sleeve's
    # mirror plane, so both halves carry the same contact) while each rank gets at least 2 cells around; a panel,
    # or a tube on more ranks, by the graph partitioner
    by_angle = sector is None and by_sectors(comm.size, n_around)
    key = repr((inspect.getsource(_build), inspect.getsource(_n_arcs), length, radius, n_around, n_along, cell,
                order, sector))
    return mesh_from_gmsh(lambda model: _build(model, length, radius, n_around, n_along, cell, order, sector),
                          (1.0, 0.0, 0.0), directions.radial_from_x_axis(), comm, name=name, ghost_mode=ghost_mode,
                          partition="sectors" if by_angle else "graph", cache_key=key)
