"""Mesh a sewing pattern (:mod:`fabricfem.meshes.pattern`) and place its panels in 3-D.

Each panel is meshed by gmsh (built-in kernel, rank 0) in its own flat plane: straight edges as lines, curved
edges as quadratic Bezier curves, quadrilaterals by default (Frontal-Delaunay triangles recombined by the
Blossom full-quad algorithm) or triangles, geometry order 1 or 2 (the mid-edge nodes of order 2 lie on the
Bezier curves), target size ``h`` [m]. Every edge is a transfinite curve with n_seg = max(2, ceil(L / h))
segments (L its exact length), rounded up to an even number for quadrilaterals (the full-quad algorithm halves
and re-splits the boundary; gmsh 4.8 aborts on an odd count); the edges of a stitch (and of chains of
stitches) get the same count, the largest of the group, so their nodes pair one to one.

Placement maps the flat panel, the stress-free reference, isometrically to its 3-D start geometry, which is
the geometry of the mesh the solver gets (the shell's reference configuration):

* :class:`RigidPlacement` (the default, from the panel's translation and XYZ Euler rotation): the reference is
  the flat panel moved rigidly, free of strain and of curvature.
* :func:`wrap_on_cylinder`: the panel rolled onto a cylinder (panel x -> arc length around the axis, panel y
  -> along the axis). Lengths and areas on the surface are those of the flat panel (isometric, no membrane
  strain), but the reference is the wrapped shape: its curvature 1/radius across the axis is the shell's
  stress-free reference curvature, so bending is measured relative to the wrapped shape, not to the flat panel.

Each panel's cells carry its own cell tag (physical surface named like the panel, id = 1 + its position in
``pattern.panels``); each edge a facet tag named ``f"{panel}.{edge}"``. The warp direction of a panel is its
grain mapped by the placement's tangent map; the normal is the placement's image of the panel plane's +z,
turned over for a clockwise outline, so it agrees with the cells' orientation (GarmentCode outlines run
counter-clockwise seen from outside [Korosteleva2021], so it points outwards). Since points of different
panels may coincide in 3-D, the per-panel fields are given as ``FabricMesh.panel_directions`` (cell tag ->
fields), which ``FabricMesh.directions_at`` applies panel by panel; ``FabricMesh.warp`` / ``normal`` take the
panel of the nearest mesh node (ambiguous only where panels touch).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from dolfinx.mesh import GhostMode
from mpi4py import MPI
from scipy.spatial import cKDTree

from . import _validate
from .fabric_mesh import DirectionField, FabricMesh
from .gmsh_io import gmsh_to_dolfinx
from .pattern import STITCH_LENGTH_TOLERANCE, Panel, Pattern, check_pattern, edge_control_points, edge_length

__all__ = ["CylinderWrap", "GarmentMesh", "RigidPlacement", "SeamPairs", "mesh_pattern", "wrap_on_cylinder"]

_QUAD_OPTIONS = {"Mesh.Algorithm": 6, "Mesh.RecombinationAlgorithm": 3}   # as fabricfem.meshes.plate
_PANEL_GAP = 1.0   # [m] panel i is meshed flat in the plane z = i * _PANEL_GAP (no two panels share a point)


class Placement(Protocol):
    """An isometric map of a flat panel (x, y) [m] into 3-D."""

    def map(self, xy: np.ndarray) -> np.ndarray: ...

    def fields(self, grain: np.ndarray, side: float) -> tuple[DirectionField, DirectionField]: ...


@dataclass(frozen=True)
class RigidPlacement:
    """x = R (x_panel, y_panel, 0) + translation: rotation matrix R (3, 3), translation (3,) [m]."""

    rotation: np.ndarray
    translation: np.ndarray

    @classmethod
    def of(cls, panel: Panel) -> RigidPlacement:
        """The panel's own placement (its translation and extrinsic XYZ Euler rotation)."""
        return cls(panel.rotation_matrix(), panel.translation.copy())

    def map(self, xy: np.ndarray) -> np.ndarray:
        """Placed points (n, 3) [m] of the panel points ``xy`` (n, 2) [m]."""
        return xy @ self.rotation[:, :2].T + self.translation

    def fields(self, grain: np.ndarray, side: float) -> tuple[DirectionField, DirectionField]:
        """Constant warp R (grain, 0) and normal ``side`` R e_z, as fields x (3, N) -> (3, N)."""
        warp = self.rotation[:, :2] @ grain
        normal = side * self.rotation[:, 2]
        return _constant(warp), _constant(normal)


@dataclass(frozen=True)
class CylinderWrap:
    """The panel rolled onto the cylinder of ``radius`` [m] about the axis through ``axis_point`` along the unit
    ``axis``: (x, y) -> axis_point + y a + r (cos t e_r + sin t e_t), t = angle0 + x / r, with e_r the unit
    ``zero_direction`` (perpendicular to a) and e_t = a x e_r. The panel's +z becomes the outward radial."""

    axis_point: np.ndarray
    axis: np.ndarray
    radius: float
    zero_direction: np.ndarray
    angle0: float = 0.0

    def _frame(self, x3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outward radial and circumferential unit vectors (N, 3) at placed points (N, 3)."""
        d = x3 - self.axis_point
        radial = d - np.outer(d @ self.axis, self.axis)
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        return radial, np.cross(self.axis, radial)

    def map(self, xy: np.ndarray) -> np.ndarray:
        t = self.angle0 + xy[:, 0] / self.radius
        e_t = np.cross(self.axis, self.zero_direction)
        return (self.axis_point + np.outer(xy[:, 1], self.axis)
                + self.radius * (np.outer(np.cos(t), self.zero_direction) + np.outer(np.sin(t), e_t)))

    def fields(self, grain: np.ndarray, side: float) -> tuple[DirectionField, DirectionField]:
        """Warp g_x e_t + g_y a and normal ``side`` e_r at the placed points."""
        def warp(x: np.ndarray) -> np.ndarray:
            _, e_t = self._frame(np.asarray(x, dtype=float).T)
            return (grain[0] * e_t + grain[1] * self.axis).T

        def normal(x: np.ndarray) -> np.ndarray:
            radial, _ = self._frame(np.asarray(x, dtype=float).T)
            return side * radial.T

        return warp, normal


def wrap_on_cylinder(axis_point: Sequence[float], axis_dir: Sequence[float], radius: float,
                     zero_direction: Sequence[float] | None = None, angle0: float = 0.0) -> CylinderWrap:
    """Placement rolling a panel onto a cylinder (isometric: panel x -> arc length around, y -> along the axis).

    Args:
        axis_point: a point of the axis [m].
        axis_dir: direction of the axis (normalised).
        radius: cylinder radius [m], > 0.
        zero_direction: radial direction of the panel's x = 0 (projected perpendicular to the axis; default:
            the global axis least aligned with ``axis_dir``, projected).
        angle0: angle [rad] of the panel's x = 0 from ``zero_direction`` about the axis.

    Raises:
        ValueError: naming the argument that is not finite, zero, or (zero_direction) parallel to the axis.
    """
    p = _validate.point3("axis_point", axis_point)
    a = _validate.point3("axis_dir", axis_dir)
    if not np.linalg.norm(a) > 0.0:
        raise ValueError(f"axis_dir: must be a non-zero 3-vector, got {axis_dir!r}")
    a = a / np.linalg.norm(a)
    r = _validate.positive_length("radius", radius)
    z = (np.eye(3)[np.argmin(np.abs(a))] if zero_direction is None
         else _validate.point3("zero_direction", zero_direction))
    z = z - (z @ a) * a
    if not np.linalg.norm(z) > 1e-12:
        raise ValueError(f"zero_direction: must not be parallel to axis_dir, got {zero_direction!r}")
    if not math.isfinite(angle0):
        raise ValueError(f"angle0: must be finite, got {angle0!r}")
    return CylinderWrap(p, a, r, z / np.linalg.norm(z), float(angle0))


def _constant(v: np.ndarray) -> DirectionField:
    v = np.asarray(v, dtype=float).reshape(3, 1)

    def field(x: np.ndarray) -> np.ndarray:
        return np.repeat(v, np.shape(x)[1], axis=1)

    return field


@dataclass
class SeamPairs:
    """The node pairs of one stitch: ``points_a[i]`` (on edge a, from its start) is sewn to ``points_b[i]``
    (on edge b, from its end: the edges are joined in opposite directions). Coordinates (n, 3) [m] are the placed
    3-D positions of the mesh nodes on the two edges, vertices and (order 2) mid-edge nodes in order along the
    edge; ``panel_tag_a/b`` are the panels' cell tag ids (so (tag, point) finds the node among coincident ones);
    ``lengths`` the exact flat lengths [m] of edge a and edge b."""

    name: str
    panels: tuple[str, str]
    edges: tuple[int, int]
    points_a: np.ndarray
    points_b: np.ndarray
    panel_tag_a: int
    panel_tag_b: int
    lengths: tuple[float, float]


@dataclass
class GarmentMesh:
    """A meshed, placed pattern: ``fabric`` (the FabricMesh; cell tag per panel, facet tag per edge),
    ``pattern``, ``stitches`` (one SeamPairs per stitch, in the pattern's order), ``panel_tags`` (panel name ->
    cell tag id) and ``placements`` (panel name -> the placement used)."""

    fabric: FabricMesh
    pattern: Pattern
    stitches: list[SeamPairs]
    panel_tags: dict[str, int]
    placements: dict[str, Placement]
    _edges: dict[tuple[str, int], np.ndarray] = field(repr=False, default_factory=dict)

    def edge_points(self, panel: str, edge: int) -> np.ndarray:
        """Placed coordinates (n, 3) [m] of the mesh nodes on ``edge`` of ``panel``, from its start to its end
        (vertices and, for order 2, mid-edge nodes); the same on every rank."""
        try:
            return self._edges[(panel, int(edge))].copy()
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"edge_points: no edge {edge!r} of panel {panel!r}") from None


def _segment_counts(pattern: Pattern, h: float, even: bool) -> dict[tuple[str, int], int]:
    """Segments per edge: max(2, ceil(L / h)) (even for quads), equal within each group of stitched edges."""
    keys = [(name, k) for name, p in pattern.panels.items() for k in range(len(p.edges))]
    parent = {key: key for key in keys}

    def root(key):
        while parent[key] != key:
            key = parent[key]
        return key

    for s in pattern.stitches:
        parent[root((s.a[0], int(s.a[1])))] = root((s.b[0], int(s.b[1])))
    counts = {key: max(2, math.ceil(edge_length(pattern.panels[key[0]], key[1]) / h - 1e-9)) for key in keys}
    if even:
        counts = {key: n + n % 2 for key, n in counts.items()}
    group: dict[tuple[str, int], int] = {}
    for key, n in counts.items():
        group[root(key)] = max(group.get(root(key), 0), n)
    return {key: group[root(key)] for key in keys}


def _build(model, pattern: Pattern, counts: Mapping[tuple[str, int], int], cell: str, order: int,
           collected: dict) -> None:
    """Flat geometry of every panel (panel i at z = i * _PANEL_GAP), tags, mesh; the nodes along each edge
    (flat coordinates, in order from its start) go to ``collected``."""
    geo = model.geo
    curves = {}
    for i, (name, panel) in enumerate(pattern.panels.items()):
        z = i * _PANEL_GAP
        points = {v: geo.addPoint(*panel.vertices[v], z) for v in {e.start for e in panel.edges}}
        loop = []
        for k, e in enumerate(panel.edges):
            ctrl = edge_control_points(panel, k)
            if len(ctrl) == 2:
                c = geo.addLine(points[e.start], points[e.end])
            else:
                c = geo.addBezier([points[e.start], geo.addPoint(*ctrl[1], z), points[e.end]])
            geo.mesh.setTransfiniteCurve(c, counts[(name, k)] + 1)
            curves[(name, k)] = c
            loop.append(c)
        surface = geo.addPlaneSurface([geo.addCurveLoop(loop)])
        if cell == "quadrilateral":
            geo.mesh.setRecombine(2, surface)
        curves[name] = surface
    geo.synchronize()
    for i, name in enumerate(pattern.panels):
        model.setPhysicalName(2, model.addPhysicalGroup(2, [curves[name]], i + 1), name)
        for k in range(len(pattern.panels[name].edges)):
            model.setPhysicalName(1, model.addPhysicalGroup(1, [curves[(name, k)]]), f"{name}.{k}")
    model.mesh.generate(2)
    if order > 1:
        model.mesh.setOrder(order)
    tags, coords, _ = model.mesh.getNodes()
    tags, coords = np.asarray(tags, np.int64), np.asarray(coords, float).reshape(-1, 3)
    sorter = np.argsort(tags)
    for key, c in curves.items():
        if isinstance(key, str):
            continue
        _, _, nodes = model.mesh.getElements(1, c)
        nodes = np.asarray(nodes[0], np.int64).reshape(counts[key], -1)   # (segments, 2 or 3): ends, then mid
        if not np.array_equal(nodes[1:, 0], nodes[:-1, 1]):
            raise RuntimeError(f"edge {key[0]}.{key[1]}: gmsh's edge elements are not chained in order")
        chain = np.concatenate([nodes[:, [0, 2]].ravel() if order > 1 else nodes[:, 0], nodes[-1:, 1]])
        xy = coords[sorter[np.searchsorted(tags, chain, sorter=sorter)], :2]
        panel = pattern.panels[key[0]]
        if not np.allclose(xy[0], panel.vertices[panel.edges[key[1]].start], rtol=0, atol=1e-9):
            xy = xy[::-1]   # gmsh ran the curve the other way
        collected[key] = xy


def mesh_pattern(pattern: Pattern, h: float, order: int = 2, cell: str = "quadrilateral",
                 placements: Mapping[str, Placement] | None = None,
                 stitch_length_tolerance: float = STITCH_LENGTH_TOLERANCE, comm: MPI.Comm = MPI.COMM_WORLD, *,
                 ghost_mode: GhostMode = GhostMode.shared_facet) -> GarmentMesh:
    """Mesh every panel of ``pattern`` flat, place it in 3-D, and pair the nodes of stitched edges.

    Collective on ``comm`` (gmsh runs on its rank 0). The pattern is checked first (:func:`check_pattern`, a
    twisted stitch judged where ``placements`` put its edges); nothing is meshed if it is refused.

    Args:
        pattern: the panels and stitches (metres).
        h: target element size [m], > 0 (edges get max(2, ceil(L / h)) segments, see the module docstring).
        order: geometry order, 1 or 2 (9-node quadrilaterals / 6-node triangles, mid-edge nodes on the curves).
        cell: ``"quadrilateral"`` (default) or ``"triangle"``.
        placements: panel name -> placement (:class:`RigidPlacement`, :func:`wrap_on_cylinder`); panels not
            named keep their own rigid placement (translation, XYZ Euler rotation).
        stitch_length_tolerance: largest relative length difference of stitched edges.
        comm: communicator of the mesh.
        ghost_mode: dolfinx ghost mode.

    Returns:
        GarmentMesh: the FabricMesh (placed geometry, per-panel directions), the stitches' node pairs.

    Raises:
        ValueError: on every rank, naming the item, if the pattern is refused or an argument is invalid.
    """
    h = _validate.positive_length("h", h)
    order = _validate.choice("order", _validate.count("order", order), (1, 2))
    cell = _validate.choice("cell", cell, _validate.CELLS)
    placements = dict(placements or {})
    unknown = set(placements) - set(pattern.panels)
    if unknown:
        raise ValueError(f"placements: no panel named {sorted(unknown)}; panels: {sorted(pattern.panels)}")
    places = {name: placements.get(name) or RigidPlacement.of(p) for name, p in pattern.panels.items()}
    check_pattern(pattern, stitch_length_tolerance, {name: place.map for name, place in places.items()})
    counts = _segment_counts(pattern, h, even=cell == "quadrilateral")
    collected: dict = {}
    mesh, cell_tags, facet_tags, names = gmsh_to_dolfinx(
        lambda model: _build(model, pattern, counts, cell, order, collected), comm, 0, gdim=3, name="pattern",
        options=_QUAD_OPTIONS if cell == "quadrilateral" else {}, ghost_mode=ghost_mode)
    collected = comm.bcast(collected, root=0)

    panel_tags = {name: i + 1 for i, name in enumerate(pattern.panels)}
    x = mesh.geometry.x
    index = np.rint(x[:, 2] / _PANEL_GAP).astype(np.int64)
    for i, name in enumerate(pattern.panels):
        mask = index == i
        x[mask] = places[name].map(x[mask, :2])
    edges = {key: places[key[0]].map(xy) for key, xy in collected.items()}

    fields = {panel_tags[name]: places[name].fields(p.grain, math.copysign(1.0, p.signed_area()))
              for name, p in pattern.panels.items()}
    warp, normal = _nearest_panel_fields(x, index + 1, fields)
    fabric = FabricMesh(mesh=mesh, facet_tags=facet_tags, tags=names, warp=warp, normal=normal,
                        cell_tags=cell_tags, panel_directions=fields)
    seams = []
    for s in pattern.stitches:
        (pa, ea), (pb, eb) = (s.a[0], int(s.a[1])), (s.b[0], int(s.b[1]))
        seams.append(SeamPairs(s.name, (pa, pb), (ea, eb), edges[(pa, ea)].copy(), edges[(pb, eb)][::-1].copy(),
                               panel_tags[pa], panel_tags[pb],
                               (edge_length(pattern.panels[pa], ea), edge_length(pattern.panels[pb], eb))))
    return GarmentMesh(fabric, pattern, seams, panel_tags, places, edges)


def _nearest_panel_fields(x: np.ndarray, node_tag: np.ndarray,
                          fields: Mapping[int, tuple[DirectionField, DirectionField]]
                          ) -> tuple[DirectionField, DirectionField]:
    """Fields of x only: each point takes the panel of the nearest (rank-local) mesh node. Where panels touch
    this is ambiguous; the shell uses FabricMesh.directions_at, which is not."""
    tree = cKDTree(x) if len(x) else None

    def which(slot: int) -> Callable[[np.ndarray], np.ndarray]:
        def field_(points: np.ndarray) -> np.ndarray:
            points = np.asarray(points, dtype=float)
            out = np.zeros((3, points.shape[1]))
            if tree is None or points.shape[1] == 0:
                return out
            tag = node_tag[tree.query(points.T)[1]]
            for t, pair in fields.items():
                sel = tag == t
                if sel.any():
                    out[:, sel] = pair[slot](points[:, sel])
            return out
        return field_

    return which(0), which(1)
