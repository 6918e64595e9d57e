"""Surfaces of revolution about +z: the flat annulus (or annular sector) and the spherical cap with a hole.

Construction (gmsh built-in kernel, rank 0): the surface is cut into k patches at the azimuths
start + j angle / k (k the smallest divisor of ``n_around`` with angle / k < pi, as circle arcs need), each a
transfinite four-sided patch bounded by two circle arcs about the z axis (``inner``/``outer``,
``hole``/``rim``) and two radial lines or meridian arcs; the full revolution (angle = 2 pi exactly) closes on
the first cut, so the mesh is conforming all around. Any angle below 2 pi, however close, keeps its cut: the
edges ``side0`` and ``side1`` are separate curves on separate points even where they coincide to round-off
(gmsh's Geometry.AutoCoherence is off for sectors), so a slit ring is a sector of angle 2 pi - gap. Patches on the sphere are mapped onto it (``In Sphere``): all nodes, the
second-order ones included, lie on the sphere. Loops run counter-clockwise in (radius or polar angle,
azimuth), so cell normals agree with the reference normal.
"""
from __future__ import annotations

import numpy as np
from dolfinx.mesh import GhostMode
from mpi4py import MPI

from . import _validate, directions
from .gmsh_io import FabricMesh, mesh_from_gmsh


def _patches(model, ring, spoke, n_spoke: int, n_around: int, sector: tuple[float, float], cell: str, order: int,
             names: tuple[str, str], sphere_centre: bool) -> None:
    """Mesh k patches between the rings ring(0, a) and ring(1, a) (points at azimuth a [rad]), joined by
    spokes, over the azimuths ``sector`` = (start, angle); tags names = (inner ring, outer ring) and, when
    angle < 2 pi, side0 (a = start) and side1 (a = start + angle)."""
    geo = model.geo
    start, angle = sector
    closed = _is_closed(angle)
    k = next(j for j in range(1, n_around + 1) if n_around % j == 0 and angle / j < np.pi - 1e-9)
    cuts = k if closed else k + 1
    azimuths = start + angle * np.arange(cuts) / k
    points = [[geo.addPoint(*ring(i, a)) for a in azimuths] for i in (0, 1)]
    centres = [geo.addPoint(0.0, 0.0, ring(i, 0.0)[2]) for i in (0, 1)]
    origin = geo.addPoint(0.0, 0.0, 0.0)
    arcs = [[geo.addCircleArc(points[i][j], centres[i], points[i][(j + 1) % cuts]) for j in range(k)]
            for i in (0, 1)]
    spokes = [spoke(geo, points[0][j], points[1][j], origin) for j in range(cuts)]
    for curve in arcs[0] + arcs[1]:
        geo.mesh.setTransfiniteCurve(curve, n_around // k + 1)
    for curve in spokes:
        geo.mesh.setTransfiniteCurve(curve, n_spoke + 1)
    surfaces = []
    for j in range(k):
        loop = geo.addCurveLoop([spokes[j], arcs[1][j], -spokes[(j + 1) % cuts], -arcs[0][j]])
        surface = geo.addSurfaceFilling([loop], sphereCenterTag=origin if sphere_centre else -1)
        geo.mesh.setTransfiniteSurface(surface)
        if cell == "quadrilateral":
            geo.mesh.setRecombine(2, surface)
        surfaces.append(surface)
    geo.synchronize()
    groups = {names[0]: arcs[0], names[1]: arcs[1]}
    if not closed:
        groups.update(side0=[spokes[0]], side1=[spokes[-1]])
    for name, curves in groups.items():
        model.setPhysicalName(1, model.addPhysicalGroup(1, curves), name)
    model.setPhysicalName(2, model.addPhysicalGroup(2, surfaces), "fabric")
    model.mesh.generate(2)
    if order > 1:
        model.mesh.setOrder(order)


def _is_closed(angle: float) -> bool:
    """A full revolution: angle = 2 pi exactly (_angle clips round-off above it), not a sector of a small gap."""
    return angle == 2.0 * np.pi


def _sector_options(angle: float) -> dict[str, float]:
    """gmsh options of a revolved surface: a sector's two cut edges stay separate curves on separate points,
    however close they are (no automatic merging of coincident entities)."""
    return {} if _is_closed(angle) else {"Geometry.AutoCoherence": 0}


def _common(n_radial: int, n_around: int, cell: str, order: int) -> tuple[int, int, str, int]:
    return (_validate.count("n_radial", n_radial), _validate.count("n_around", n_around, minimum=3),
            _validate.choice("cell", cell, _validate.CELLS),
            _validate.choice("order", _validate.count("order", order), (1, 2)))


def annulus(r_in: float, r_out: float, angle: float = 2.0 * np.pi, n_radial: int = 8, n_around: int = 48,
            cell: str = "quadrilateral", comm: MPI.Comm = MPI.COMM_WORLD, order: int = 2, *,
            warp=(1.0, 0.0, 0.0), ghost_mode: GhostMode = GhostMode.shared_facet) -> FabricMesh:
    """Flat annulus r_in <= r <= r_out [m] in the plane z = 0, or the annular sector 0 <= a <= angle [rad]
    (azimuth from +x towards +y); area angle (r_out^2 - r_in^2) / 2.

    Args:
        r_in, r_out: inner and outer radius [m], 0 < r_in < r_out.
        angle: opening of the sector [rad], in (0, 2 pi]: 2 pi the full annulus; anything less a sector with
            the edges side0 and side1, also a slit ring of a gap 2 pi - angle down to round-off.
        n_radial, n_around: elements across and around (n_around >= 3).
        cell: "quadrilateral" or "triangle"; order: geometry order 1 or 2 (curved edges).
        warp: constant warp direction in the plane (a flat cloth cut to shape: straight yarns).

    Returns:
        FabricMesh with normal +z, edge tags ``inner``, ``outer`` and, for a sector, ``side0`` (a = 0) and
        ``side1`` (a = angle).
    """
    r_in = _validate.positive_length("r_in", r_in)
    r_out = _validate.positive_length("r_out", r_out)
    if r_out <= r_in:
        raise ValueError(f"r_out: must exceed r_in = {r_in}, got {r_out!r}")
    angle = _angle("angle", angle, 2.0 * np.pi)
    n_radial, n_around, cell, order = _common(n_radial, n_around, cell, order)
    if np.dot(np.asarray(warp, dtype=float), (0.0, 0.0, 1.0)) != 0.0:
        raise ValueError(f"warp: must lie in the plane z = 0, got {warp!r}")

    def ring(i: int, a: float) -> tuple[float, float, float]:
        r = (r_in, r_out)[i]
        return r * np.cos(a), r * np.sin(a), 0.0

    return mesh_from_gmsh(
        lambda model: _patches(model, ring, lambda geo, p, q, _: geo.addLine(p, q), n_radial, n_around,
                               (0.0, angle), cell, order, ("inner", "outer"), False),
        warp, (0.0, 0.0, 1.0), comm, name="annulus", options=_sector_options(angle), ghost_mode=ghost_mode)


def spherical_cap(R: float, opening_angle: float, hole_angle: float, n_polar: int = 12, n_around: int = 48,
                  cell: str = "quadrilateral", comm: MPI.Comm = MPI.COMM_WORLD, order: int = 2, *,
                  angle: float = 2.0 * np.pi, start: float = 0.0,
                  ghost_mode: GhostMode = GhostMode.shared_facet) -> FabricMesh:
    """The sphere |x| = R [m] between the polar angles hole_angle and opening_angle [rad] from +z (a
    hemisphere with a hole: opening_angle = pi / 2) and the azimuths start <= a <= start + angle [rad] (from +x
    towards +y); area angle R^2 (cos hole_angle - cos opening_angle).

    Args:
        R: radius [m]; opening_angle: polar angle of the rim, in (hole_angle, pi);
        hole_angle: polar angle of the hole's edge, in (0, opening_angle) (the pole itself is not meshed:
            its patches would be three-sided; build a closed cap with mesh_from_gmsh).
        n_polar, n_around: elements from hole to rim and around the azimuth range (n_around >= 3).
        cell, order: as for :func:`annulus`.
        angle: azimuthal range [rad], in (0, 2 pi] (2 pi: the whole cap; pi / 2 with opening_angle = pi / 2: a
            quarter of the hemisphere, the octant model).
        start: azimuth of the range's first meridian [rad] (its orientation about +z), finite.

    Returns:
        FabricMesh with outward normal x / R, warp along the meridian away from the pole, weft along the
        parallels; edge tags ``hole`` and ``rim`` and, for angle < 2 pi, the meridian arcs ``side0`` (azimuth
        start) and ``side1`` (start + angle).
    """
    R = _validate.positive_length("R", R)
    hole_angle = _angle("hole_angle", hole_angle, np.pi)
    opening_angle = _angle("opening_angle", opening_angle, np.pi)
    if not (hole_angle < opening_angle < np.pi):
        raise ValueError(f"opening_angle: must lie in (hole_angle, pi), got {opening_angle!r}")
    n_polar, n_around, cell, order = _common(n_polar, n_around, cell, order)
    angle, start = _angle("angle", angle, 2.0 * np.pi), _validate.finite("start", start)

    def ring(i: int, a: float) -> tuple[float, float, float]:
        p = (hole_angle, opening_angle)[i]
        return R * np.sin(p) * np.cos(a), R * np.sin(p) * np.sin(a), R * np.cos(p)

    return mesh_from_gmsh(
        lambda model: _patches(model, ring, lambda geo, p, q, o: geo.addCircleArc(p, o, q), n_polar, n_around,
                               (start, angle), cell, order, ("hole", "rim"), True),
        _meridian, directions.radial_from_origin(), comm, name="spherical_cap", options=_sector_options(angle),
        ghost_mode=ghost_mode)


def _angle(name: str, value: float, upper: float) -> float:
    v = _validate.positive(name, value, "angle in radians")
    if v > upper + 1e-12:
        raise ValueError(f"{name}: must lie in (0, {upper:.6g}] radians, got {value!r}")
    return min(v, upper)


def _meridian(x: np.ndarray) -> np.ndarray:
    """Unit tangent along the meridian, away from +z: ((n . ez) n - ez) / |...|, n = x / |x|."""
    n = np.asarray(x, dtype=float) / np.linalg.norm(x, axis=0)
    t = n * n[2] - np.array([[0.0], [0.0], [1.0]])
    return t / np.linalg.norm(t, axis=0)
