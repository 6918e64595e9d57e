"""Sewing patterns: flat panels with straight and quadratic Bezier edges, and the stitches between them.

The data model (SI units, metres) and its readers; meshing and placement live in
:mod:`fabricfem.meshes.pattern_mesh`.

* :class:`Panel`: an outline in the panel's own plane, ``vertices`` (n, 2) [m] and ``edges`` in loop order
  (edge k ends where edge k+1 starts, the last ends where the first starts); an edge is straight or a
  quadratic Bezier whose control point is given in the edge's own frame (``curvature = (u, v)``: the edge
  runs from (0, 0) to (1, 0), and v is along the edge direction turned by +90 degrees, the convention of the
  GarmentCode / Garment-Pattern-Generator files [Korosteleva2021]); the rigid placement ``translation`` [m]
  and ``rotation`` (extrinsic XYZ Euler angles [deg]: ``R = Rz Ry Rx``, as ``scipy Rotation.from_euler('xyz',
  degrees=True)``); the ``grain`` (warp) direction, a unit 2-vector in the panel plane.
* :class:`Stitch`: two (panel, edge index) sewn together end to end in opposite directions (the start of
  one edge meets the end of the other); ``twisted`` marks a stitch whose edges are meant to be placed running
  the same way (a twisted seam), which :func:`check_pattern` refuses otherwise.
* :class:`Pattern`: panels by name and stitches. Constructing one checks its structure (ValueError naming
  the item); :func:`check_pattern` adds the geometric checks (self-intersecting outlines, stitched edges of
  different lengths, twisted stitches) that the mesher runs before meshing; :func:`check_held_stitches` refuses
  held edges that a stitch would have to pull together.

Readers: :func:`read_garmentcode` (JSON of [Korosteleva2021]), :func:`pattern_from_dict` and
:func:`read_pattern_toml` (a declaration in plain SI metres), :func:`pattern_to_toml` (its inverse).

Exact geometry: :func:`outline_area` (polygon plus the closed-form areas of the quadratic Bezier segments)
and :func:`edge_length` (closed form of the quadratic Bezier arc length).
"""
from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "STITCH_LENGTH_TOLERANCE",
    "Edge",
    "Panel",
    "Pattern",
    "Stitch",
    "bezier_length",
    "check_held_stitches",
    "check_pattern",
    "edge_control_points",
    "edge_length",
    "outline_area",
    "outline_polyline",
    "pattern_from_dict",
    "pattern_to_dict",
    "pattern_to_toml",
    "read_garmentcode",
    "read_pattern_toml",
]

STITCH_LENGTH_TOLERANCE = 0.02   # default relative length difference allowed between stitched edges
TWIST_COSINE = -0.5   # a stitch whose edges, as it runs them, have a mean direction cosine below this is twisted
PlaceMap = Callable[[np.ndarray], np.ndarray]   # panel points (n, 2) [m] -> placed points (n, 3) [m]
_GAUSS_T, _GAUSS_W = np.polynomial.legendre.leggauss(48)
_GAUSS_T, _GAUSS_W = 0.5 * (_GAUSS_T + 1.0), 0.5 * _GAUSS_W     # on [0, 1]


@dataclass(frozen=True)
class Edge:
    """An outline edge from vertex ``start`` to vertex ``end`` (indices into the panel's vertices).

    ``curvature``: None (straight) or (u, v), the control point of a quadratic Bezier in the edge frame
    (start (0, 0), end (1, 0), v along the edge direction turned by +90 degrees) [Korosteleva2021].
    """

    start: int
    end: int
    curvature: tuple[float, float] | None = None


@dataclass
class Panel:
    """A flat panel: outline in its own plane [m], rigid placement, grain (warp) direction.

    Attributes:
        name: the panel's name (the cell tag name of its mesh).
        vertices: (n, 2) outline vertices [m], n >= 3, finite.
        edges: the outline in loop order (see the module docstring); default: the closed polygon
            0 -> 1 -> ... -> n-1 -> 0.
        translation: (3,) [m] of the rigid placement x = R (x_panel, y_panel, 0) + translation.
        rotation: (3,) extrinsic XYZ Euler angles [deg] of R = Rz Ry Rx.
        grain: unit 2-vector in the panel plane, the warp direction (default (0, 1): the panel's vertical).
    """

    name: str
    vertices: np.ndarray
    edges: list[Edge] = field(default_factory=list)
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    grain: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0]))

    def __post_init__(self) -> None:
        item = f"panel {self.name!r}"
        try:
            v = np.asarray(self.vertices, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{item}: vertices must be (n, 2) numbers, got {self.vertices!r}") from None
        if v.ndim != 2 or v.shape[1] != 2:
            raise ValueError(f"{item}: vertices must have shape (n, 2), got {v.shape}")
        if len(v) < 3:
            raise ValueError(f"{item}: needs at least 3 vertices, got {len(v)}")
        bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
        if bad.size:
            raise ValueError(f"{item}: vertex {int(bad[0])} is not finite: {v[bad[0]].tolist()}")
        self.vertices = v
        if not self.edges:
            self.edges = [Edge(k, (k + 1) % len(v)) for k in range(len(v))]
        self.edges = [e if isinstance(e, Edge) else Edge(*e) for e in self.edges]
        for k, e in enumerate(self.edges):
            if not (0 <= e.start < len(v) and 0 <= e.end < len(v)):
                raise ValueError(f"{item}: edge {k} names vertex indices {(e.start, e.end)} outside 0..{len(v) - 1}")
            if e.curvature is not None and (len(e.curvature) != 2 or not np.all(np.isfinite(e.curvature))):
                raise ValueError(f"{item}: edge {k} curvature must be 2 finite numbers (u, v), got {e.curvature!r}")
            if np.array_equal(v[e.start], v[e.end]):
                raise ValueError(f"{item}: edge {k} has zero length (vertices {e.start} and {e.end} coincide)")
            following = self.edges[(k + 1) % len(self.edges)]
            if e.end != following.start:
                raise ValueError(f"{item}: edge {k} ends at vertex {e.end} but edge {(k + 1) % len(self.edges)} "
                                 f"starts at vertex {following.start}; edges must form one closed loop in order")
        for key, shape in (("translation", (3,)), ("rotation", (3,)), ("grain", (2,))):
            value = np.asarray(getattr(self, key), dtype=np.float64)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ValueError(f"{item}: {key} must be {shape[0]} finite numbers, got {getattr(self, key)!r}")
            setattr(self, key, value)
        norm = np.linalg.norm(self.grain)
        if not norm > 0.0:
            raise ValueError(f"{item}: grain must be a non-zero 2-vector, got {self.grain.tolist()}")
        self.grain = self.grain / norm

    def rotation_matrix(self) -> np.ndarray:
        """R = Rz(c) Ry(b) Rx(a) for ``rotation = (a, b, c)`` [deg]: extrinsic XYZ (GarmentCode's Maya convention,
        scipy ``Rotation.from_euler('xyz', rotation, degrees=True).as_matrix()``)."""
        a, b, c = np.deg2rad(self.rotation)
        rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
        ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
        rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
        return rz @ ry @ rx

    def signed_area(self) -> float:
        """Signed area of the outline [m^2]: > 0 when it runs counter-clockwise in the panel plane."""
        return outline_area(self, signed=True)


@dataclass(frozen=True)
class Stitch:
    """Edge ``a = (panel, edge index)`` sewn to edge ``b`` end to end in opposite directions; ``twisted``: the
    edges are meant to be placed running the same way (else :func:`check_pattern` refuses such a stitch)."""

    a: tuple[str, int]
    b: tuple[str, int]
    twisted: bool = False

    @property
    def name(self) -> str:
        return f"{self.a[0]}.{self.a[1]}-{self.b[0]}.{self.b[1]}"


@dataclass
class Pattern:
    """Panels by name and the stitches between their edges; construction checks that every stitch names an
    existing panel and an edge index in range (ValueError naming the stitch)."""

    panels: dict[str, Panel]
    stitches: list[Stitch] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.panels:
            raise ValueError("panels: a pattern needs at least one panel")
        self.stitches = [s if isinstance(s, Stitch) else Stitch(tuple(s[0]), tuple(s[1])) for s in self.stitches]
        for k, s in enumerate(self.stitches):
            for side in (s.a, s.b):
                panel, edge = side
                if panel not in self.panels:
                    raise ValueError(f"stitch {k} ({s.name}): panel {panel!r} does not exist; "
                                     f"panels: {sorted(self.panels)}")
                n = len(self.panels[panel].edges)
                if isinstance(edge, bool) or not isinstance(edge, (int, np.integer)) or not 0 <= edge < n:
                    raise ValueError(f"stitch {k} ({s.name}): edge {edge!r} of panel {panel!r} is out of range "
                                     f"0..{n - 1}")


# ---------------------------------------------------------------- exact geometry

def edge_control_points(panel: Panel, k: int) -> np.ndarray:
    """Bezier control points of edge ``k`` [m]: (2, 2) for a straight edge (start, end), (3, 2) for a
    quadratic one (start, control, end). Control = start + u d + v J d with d = end - start and J d the
    edge direction turned by +90 degrees, (-d_y, d_x) [Korosteleva2021]."""
    e = panel.edges[k]
    p0, p1 = panel.vertices[e.start], panel.vertices[e.end]
    if e.curvature is None:
        return np.array([p0, p1])
    d = p1 - p0
    u, v = e.curvature
    return np.array([p0, p0 + u * d + v * np.array([-d[1], d[0]]), p1])


def bezier_length(points: np.ndarray) -> float:
    """Arc length [m] of a quadratic Bezier (3, 2) or a segment (2, 2), exact to round-off.

    B'(t) = 2 (A + t B), A = C - P0, B = P1 - 2 C + P0, so |B'| = 2 sqrt(a) sqrt(s^2 + k) with
    a = B.B, s = t + A.B / a, k = |A x B|^2 / a^2, and L = sqrt(a) [s sqrt(s^2 + k) + k asinh(s / sqrt k)] over
    s in [s0, s0 + 1]. Where that closed form cancels (|s| > 50: a nearly straight parametrisation), the
    integrand is analytic far around [0, 1] and 48-point Gauss-Legendre quadrature is exact to round-off.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 2:
        return float(np.linalg.norm(pts[1] - pts[0]))
    A, B = pts[1] - pts[0], pts[2] - 2.0 * pts[1] + pts[0]
    a = float(B @ B)
    s0 = float(A @ B) / a if a > 0.0 else math.inf
    if a == 0.0 or abs(s0) > 50.0 or abs(s0 + 1.0) > 50.0:
        speed = 2.0 * np.linalg.norm(A[None, :] + _GAUSS_T[:, None] * B[None, :], axis=1)
        return float(_GAUSS_W @ speed)
    k = float(A[0] * B[1] - A[1] * B[0]) ** 2 / a ** 2

    def primitive(s: float) -> float:
        root = math.sqrt(s * s + k)
        return s * root + (k * math.asinh(s / math.sqrt(k)) if k > 0.0 else 0.0)

    return math.sqrt(a) * (primitive(s0 + 1.0) - primitive(s0))


def edge_length(panel: Panel, k: int) -> float:
    """Exact length [m] of edge ``k`` of ``panel`` (:func:`bezier_length`)."""
    return bezier_length(edge_control_points(panel, k))


def outline_area(panel: Panel, signed: bool = False) -> float:
    """Exact area [m^2] enclosed by the outline: 1/2 of the loop integral of x dy - y dx, which is
    P0 x P1 / 2 for a segment and (2 P0 x C + 2 C x P1 + P0 x P1) / 6 for a quadratic Bezier (the segment's
    term plus 2/3 of the triangle P0 C P1, Archimedes' parabolic segment). Positive for a counter-clockwise
    outline when ``signed``."""
    def cross(p, q):
        return p[0] * q[1] - p[1] * q[0]
    total = 0.0
    for k in range(len(panel.edges)):
        pts = edge_control_points(panel, k)
        if len(pts) == 2:
            total += 0.5 * cross(pts[0], pts[1])
        else:
            total += (2.0 * cross(pts[0], pts[1]) + 2.0 * cross(pts[1], pts[2]) + cross(pts[0], pts[2])) / 6.0
    return float(total if signed else abs(total))


def _bezier_points(pts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Points (len(t), 2) of the Bezier with control points ``pts`` (2 or 3 rows) at parameters ``t``."""
    t = t[:, None]
    if len(pts) == 2:
        return (1.0 - t) * pts[0] + t * pts[1]
    return (1.0 - t) ** 2 * pts[0] + 2.0 * t * (1.0 - t) * pts[1] + t ** 2 * pts[2]


def outline_polyline(panel: Panel, n_curved: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """The outline as a closed polyline: points (m, 2) [m] (the first not repeated at the end) and, per
    segment i (points i -> i+1 mod m), the edge index it belongs to. Curved edges get ``n_curved`` segments."""
    points, owner = [], []
    for k in range(len(panel.edges)):
        pts = edge_control_points(panel, k)
        n = 1 if len(pts) == 2 else n_curved
        points.append(_bezier_points(pts, np.linspace(0.0, 1.0, n + 1)[:-1]))
        owner.append(np.full(n, k))
    return np.concatenate(points), np.concatenate(owner)


# ---------------------------------------------------------------- geometric checks

def _self_intersection(panel: Panel) -> tuple[int, int] | None:
    """The first pair of edges (i, j) whose polylines cross or touch away from their shared vertices, or None.

    All pairs of non-adjacent segments at once (vectorised orientation tests; touching counts, with a
    tolerance of 1e-12 of the outline's size)."""
    p, owner = outline_polyline(panel)
    q = np.roll(p, -1, axis=0)
    m = len(p)
    scale = max(float(np.ptp(p, axis=0).max()), 1e-300)
    tol = 1e-12 * scale * scale

    def orient(a, b, c):   # (b - a) x (c - a) for all pairs: a, b of shape (m, 1, 2), c of shape (1, m, 2)
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])

    P, Q = p[:, None, :], q[:, None, :]
    R, S = p[None, :, :], q[None, :, :]
    o1, o2 = orient(P, Q, R), orient(P, Q, S)
    o3, o4 = orient(R, S, P), orient(R, S, Q)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)

    def on_segment(o, a, b, c):   # c collinear with segment a-b and within its bounding box
        lo, hi = np.minimum(a, b) - 1e-12 * scale, np.maximum(a, b) + 1e-12 * scale
        return (np.abs(o) <= tol) & np.all((c >= lo) & (c <= hi), axis=-1)

    touch = (on_segment(o1, P, Q, R) | on_segment(o2, P, Q, S) | on_segment(o3, R, S, P) | on_segment(o4, R, S, Q))
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    apart = (j > i + 1) & ~((i == 0) & (j == m - 1))
    hit = np.argwhere((proper | touch) & apart)
    if hit.size == 0:
        return None
    a, b = hit[0]
    return int(owner[a]), int(owner[b])


def check_pattern(pattern: Pattern, stitch_length_tolerance: float = STITCH_LENGTH_TOLERANCE,
                  placements: Mapping[str, PlaceMap] | None = None) -> None:
    """Refuse a pattern that cannot be meshed and sewn (ValueError naming the item).

    Checks, beyond those of construction: no panel outline intersects itself (segment-segment tests on a
    fine polyline of the outline, 64 segments per curved edge), the two edges of each stitch have exact
    lengths L_a, L_b with |L_a - L_b| <= ``stitch_length_tolerance`` max(L_a, L_b), and no stitch is twisted
    unless marked so (:func:`stitch_alignment` below TWIST_COSINE = -0.5: its edges, placed by ``placements``
    (panel name -> map of panel points (n, 2) to 3-D (n, 3) [m]; default each panel's rigid placement), run
    the same way, so joining them in opposite directions would cross the seam over).
    """
    tol = float(stitch_length_tolerance)
    if not (math.isfinite(tol) and tol >= 0.0):
        raise ValueError(f"stitch_length_tolerance: must be a finite number >= 0, got {stitch_length_tolerance!r}")
    for name, panel in pattern.panels.items():
        crossing = _self_intersection(panel)
        if crossing is not None:
            raise ValueError(f"panel {name!r}: the outline intersects itself (edges {crossing[0]} and {crossing[1]})")
    for s in pattern.stitches:
        la, lb = (edge_length(pattern.panels[p], e) for p, e in (s.a, s.b))
        if abs(la - lb) > tol * max(la, lb):
            raise ValueError(f"stitch {s.name}: edge {s.a[1]} of panel {s.a[0]!r} is {la:.6g} m long and edge "
                             f"{s.b[1]} of panel {s.b[0]!r} {lb:.6g} m; they differ by "
                             f"{abs(la - lb) / max(la, lb):.3g} relative, more than stitch_length_tolerance = {tol:g}")
        cosine = stitch_alignment(pattern, s, placements)
        if cosine < TWIST_COSINE and not s.twisted:
            raise ValueError(
                f"stitch {s.name}: edge {s.a[1]} of panel {s.a[0]!r} and edge {s.b[1]} of panel {s.b[0]!r} run the "
                f"same way where they are placed (mean direction cosine {-cosine:.2f}), but a stitch joins its "
                f"edges in opposite directions (the start of one meets the end of the other), so this seam is "
                f"twisted; stitch the other edge, turn a panel over, or, if the twist is meant, mark the stitch (TOML "
                f"pattern): "
                f'["{s.a[0]}", {s.a[1]}, "{s.b[0]}", {s.b[1]}, {{twisted = true}}]')


def _placed_edge(pattern: Pattern, side: tuple[str, int], placements: Mapping[str, PlaceMap] | None,
                 n: int = 17) -> np.ndarray:
    """Points (n, 3) [m] of edge ``side`` at n equal steps of its Bezier parameter, from its start, placed by
    ``placements[panel]`` or else by the panel's rigid placement x = R (x, y, 0) + translation."""
    panel = pattern.panels[side[0]]
    xy = _bezier_points(edge_control_points(panel, int(side[1])), np.linspace(0.0, 1.0, n))
    place = (placements or {}).get(side[0])
    if place is not None:
        return np.asarray(place(xy), dtype=np.float64)
    return xy @ panel.rotation_matrix()[:, :2].T + panel.translation


def stitch_alignment(pattern: Pattern, stitch: Stitch, placements: Mapping[str, PlaceMap] | None = None) -> float:
    """How the two edges of ``stitch`` run where they are placed, as the stitch runs them (a from its start, b
    from its end): sum_i t_a,i . t_b,i / sum_i |t_a,i| |t_b,i| over the chords t of 16 equal parameter steps,
    in [-1, 1]. +1: the edges run opposite ways and the stitch joins them straight (the start of a at the end of
    b); -1: they run the same way and the stitch crosses the seam over (twisted); near 0: placed across each
    other. ``placements`` as in :func:`check_pattern`."""
    ta = np.diff(_placed_edge(pattern, stitch.a, placements), axis=0)
    tb = np.diff(_placed_edge(pattern, stitch.b, placements)[::-1], axis=0)
    weight = float(np.sum(np.linalg.norm(ta, axis=1) * np.linalg.norm(tb, axis=1)))
    return float(np.sum(ta * tb)) / max(weight, 1e-300)


def check_held_stitches(pattern: Pattern, held: Iterable[tuple[str, int]],
                        stitch_length_tolerance: float = STITCH_LENGTH_TOLERANCE,
                        placements: Mapping[str, PlaceMap] | None = None) -> None:
    """Refuse held edges that a stitch would have to pull together (ValueError naming the stitch and the distance).

    A node on a held edge does not move; a stitch ties the nodes of its edges pairwise (the start of a to the end
    of b, and so on). Where both nodes of a pair are held (their edge is held, or it ends at a vertex of a held
    edge of its panel) at placed positions farther apart than ``stitch_length_tolerance`` max(L_a, L_b) [m], the
    seam cannot close. Checked at the edges' ends and, where both stitched edges are held, at 17 points along
    them. ``held``: (panel, edge index) pairs; ``placements`` as in :func:`check_pattern`.
    """
    held = {(p, int(e)) for p, e in held}
    vertices = {(p, v) for p, e in held for v in (pattern.panels[p].edges[e].start, pattern.panels[p].edges[e].end)}
    for s in pattern.stitches:
        sides, masks = [], []
        for side, first in ((s.a, "start"), (s.b, "end")):
            edge = pattern.panels[side[0]].edges[int(side[1])]
            points = _placed_edge(pattern, side, placements)
            mask = np.full(len(points), (side[0], int(side[1])) in held)
            mask[[0, -1]] |= [(side[0], edge.start) in vertices, (side[0], edge.end) in vertices]
            sides.append(points if first == "start" else points[::-1])
            masks.append(mask if first == "start" else mask[::-1])
        both = masks[0] & masks[1]
        if not both.any():
            continue
        gap = np.where(both, np.linalg.norm(sides[0] - sides[1], axis=1), 0.0)
        worst = int(np.argmax(gap))
        limit = float(stitch_length_tolerance) * max(edge_length(pattern.panels[p], e) for p, e in (s.a, s.b))
        if gap[worst] > limit:
            where = {0: f"the start of edge {s.a[1]} of panel {s.a[0]!r}",
                     len(gap) - 1: f"the end of edge {s.a[1]} of panel {s.a[0]!r}"}.get(worst, "along its edges")
            raise ValueError(f"stitch {s.name}: held nodes that it sews together are {gap[worst]:.3g} m apart (at "
                             f"{where}); held nodes do not move, so the seam cannot close (allowed: the stitch "
                             f"length tolerance x the edge length = {limit:.3g} m); hold one side only, or "
                             f"place the held edges where they meet")


# ---------------------------------------------------------------- readers

def _curvature(raw: Any, where: str) -> tuple[float, float] | None:
    """GarmentCode curvature: [u, v] or {"type": "quadratic", "params": [[u, v]]}."""
    if raw is None:
        return None
    if isinstance(raw, Mapping):
        if raw.get("type") != "quadratic":
            raise ValueError(f"{where}: curvature type {raw.get('type')!r} is not supported (only quadratic)")
        raw = raw["params"][0]
    try:
        u, v = (float(c) for c in raw)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: curvature must be [u, v], got {raw!r}") from None
    return (u, v)


def read_garmentcode(path: str | Path) -> Pattern:
    """Read a GarmentCode / Garment-Pattern-Generator JSON pattern [Korosteleva2021] into SI metres.

    Vertices and translations are divided by ``properties.units_in_meter`` (100: centimetres); curvature is
    kept as the relative (u, v) of the file (``properties.curvature_coords`` must be ``relative``); rotation
    is the file's XYZ Euler angles [deg]; grain is the default (0, 1). Stitches: the first two
    ``{"panel", "edge"}`` entries of each item.

    Raises:
        ValueError: naming the file and the item if it is malformed.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        spec, props = data["pattern"], data.get("properties", {})
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a GarmentCode pattern ({error})") from None
    units = props.get("units_in_meter", 100)
    if not (isinstance(units, (int, float)) and units > 0):
        raise ValueError(f"{path}: properties.units_in_meter must be > 0, got {units!r}")
    if props.get("curvature_coords", "relative") != "relative":
        raise ValueError(f"{path}: properties.curvature_coords {props['curvature_coords']!r} is not supported "
                         "(only relative)")
    scale = 1.0 / float(units)
    panels = {}
    for name, raw in spec.get("panels", {}).items():
        try:
            edges = [Edge(int(e["endpoints"][0]), int(e["endpoints"][1]),
                          _curvature(e.get("curvature"), f"{path}: panel {name!r} edge {k}"))
                     for k, e in enumerate(raw["edges"])]
            panels[name] = Panel(name, scale * np.asarray(raw["vertices"], dtype=np.float64), edges,
                                 scale * np.asarray(raw.get("translation", (0, 0, 0)), dtype=np.float64),
                                 np.asarray(raw.get("rotation", (0, 0, 0)), dtype=np.float64))
        except (KeyError, TypeError, IndexError) as error:
            raise ValueError(f"{path}: panel {name!r} is malformed ({error!r})") from None
    stitches = []
    for k, item in enumerate(spec.get("stitches", [])):
        sides = [s for s in item if isinstance(s, Mapping)][:2]
        if len(sides) != 2 or not all("panel" in s and "edge" in s for s in sides):
            raise ValueError(f"{path}: stitch {k} must hold two {{panel, edge}} entries, got {item!r}")
        stitches.append(Stitch((sides[0]["panel"], sides[0]["edge"]), (sides[1]["panel"], sides[1]["edge"])))
    return Pattern(panels, stitches)


def pattern_from_dict(d: Mapping[str, Any]) -> Pattern:
    """A pattern from its declaration in plain SI metres (the TOML layout)::

        stitches = [["front", 1, "back", 3]]         # panel a, edge a, panel b, edge b[, {twisted = true}]
        [panels.front]
        vertices = [[0.0, 0.0], [0.3, 0.0], [0.3, 0.6], [0.0, 0.6]]        # m
        edges = [[0, 1], [1, 2, {curvature = [0.5, 0.1]}], [2, 3], [3, 0]] # optional: default closed polygon
        translation = [0.0, 0.0, 0.1]                # m, default 0
        rotation = [0.0, 180.0, 0.0]                 # extrinsic XYZ Euler angles [deg], default 0
        grain = [0.0, 1.0]                           # warp direction in the panel plane, default (0, 1)

    Raises:
        ValueError: naming the panel, key or stitch that is malformed.
    """
    unknown = set(d) - {"panels", "stitches"}
    if unknown:
        raise ValueError(f"pattern: unknown keys {sorted(unknown)}; expected panels, stitches")
    panels = {}
    for name, raw in dict(d.get("panels", {})).items():
        extra = set(raw) - {"vertices", "edges", "translation", "rotation", "grain"}
        if extra:
            raise ValueError(f"panel {name!r}: unknown keys {sorted(extra)}")
        if "vertices" not in raw:
            raise ValueError(f"panel {name!r}: vertices missing")
        edges = []
        for k, e in enumerate(raw.get("edges", [])):
            options = e[2] if len(e) > 2 and isinstance(e[2], Mapping) else {}
            if len(e) not in (2, 3) or set(options) - {"curvature"}:
                raise ValueError(f"panel {name!r}: edge {k} must be [start, end] or [start, end, {{curvature = "
                                 f"[u, v]}}], got {e!r}")
            edges.append(Edge(int(e[0]), int(e[1]), _curvature(options.get("curvature"), f"panel {name!r} edge {k}")))
        panels[name] = Panel(name, np.asarray(raw["vertices"], dtype=np.float64), edges,
                             raw.get("translation", np.zeros(3)), raw.get("rotation", np.zeros(3)),
                             raw.get("grain", np.array([0.0, 1.0])))
    stitches = []
    for k, s in enumerate(d.get("stitches", [])):
        options = s[4] if len(s) == 5 and isinstance(s[4], Mapping) else {}
        if len(s) not in (4, 5) or (len(s) == 5 and (set(options) != {"twisted"}
                                                     or not isinstance(options["twisted"], bool))):
            raise ValueError(f"stitch {k}: must be [panel_a, edge_a, panel_b, edge_b] or [panel_a, edge_a, panel_b, "
                             f"edge_b, {{twisted = true}}], got {s!r}")
        stitches.append(Stitch((str(s[0]), s[1]), (str(s[2]), s[3]), bool(options.get("twisted", False))))
    return Pattern(panels, stitches)


def read_pattern_toml(path: str | Path) -> Pattern:
    """:func:`pattern_from_dict` of a TOML file (ValueError naming the file if it is not valid TOML)."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise ValueError(f"{path}: {error}") from None
    return pattern_from_dict(data)


def pattern_to_dict(pattern: Pattern) -> dict[str, Any]:
    """The declaration of :func:`pattern_from_dict` (plain lists and floats, metres)."""
    panels = {}
    for name, p in pattern.panels.items():
        edges = [[e.start, e.end] + ([{"curvature": [float(c) for c in e.curvature]}] if e.curvature else [])
                 for e in p.edges]
        panels[name] = {"vertices": p.vertices.tolist(), "edges": edges, "translation": p.translation.tolist(),
                        "rotation": p.rotation.tolist(), "grain": p.grain.tolist()}
    stitches = [[s.a[0], int(s.a[1]), s.b[0], int(s.b[1])] + ([{"twisted": True}] if s.twisted else [])
                for s in pattern.stitches]
    return {"stitches": stitches, "panels": panels}


def _toml_value(v: Any) -> str:
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)   # ints, and floats with round-trip precision


def pattern_to_toml(pattern: Pattern) -> str:
    """The pattern as TOML text that :func:`read_pattern_toml` reads back to the same pattern (bit for bit)."""
    d = pattern_to_dict(pattern)
    lines = [f"stitches = {_toml_value(d['stitches'])}"]
    for name, p in d["panels"].items():
        lines.append(f"\n[panels.{json.dumps(name)}]")
        lines += [f"{key} = {_toml_value(value)}" for key, value in p.items()]
    return "\n".join(lines) + "\n"
