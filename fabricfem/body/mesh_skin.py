"""A body's skin from a closed triangulated surface: read, checked, rigged to the segments and posed (a `Skin`).

Reading (`read_skin`): any format trimesh reads (OBJ, PLY, STL, glTF/GLB, COLLADA .dae and zipped .zae through
pycollada; the scene's node transforms applied, all parts concatenated, vertices merged), scaled to metres by
`units` (the file's length unit: "m", "cm", "mm", "in" or metres per file unit, `fabricfem.body.conventions`) and
turned z-up by `up` (the file's up axis, "z" or "y": x_body = z_file, y_body = x_file, z_body = y_file for "y",
the mapping of the motion files). Every check is made before the rigging's linear solve and refused with one
ValueError line naming the key to change:

* `up`: the body's height (z extent) is less than half its largest horizontal extent (lying on its side);
* `units`: the body's height is outside `height_range` (0.5 to 2.5 m): "units: the body is 170 m tall; ...";
* `components`: policy for a file of several connected parts. "largest" (default) keeps the part of largest
  area and drops the others (eyes, teeth, accessories; their face counts in `SkinMesh.dropped`); "all" keeps them
  all (each must then be closed);
* `repair`: a kept surface with boundary edges (holes) or enclosing a negative volume (inverted normals) is refused
  unless repair = True, which closes holes with trimesh's fill_holes (refused still if some stay open) and flips
  an inside-out surface.

The Debian asset assimp-testmodels `models/Collada/human.zae` (`fabricfem.body.human`) has 5 parts: the body
(26756 triangles, closed, 0.0549 m^3) and four open eye shells (80 boundary edges): it loads with the default
policy ("largest", no repair).

Rigging and posing (`MeshSkin`): linear blend skinning with bone heat weights (`fabricfem.body.skinning`); the
rest pose is given by the joints' and markers' positions in the mesh (`rest_positions`, default the body's own
pose at the first time of its kinematics), each joint inside the mesh (a joint farther than `joint_tolerance`
outside is refused naming `rest_positions`). Queries (`MeshSkin.query`, the Skin contract of fabricfem.body.skin):
compiled (`fabricfem.body.mesh_query.CompiledSkin`): the segments' maps, the posed vertices, a bounding-box tree
built once and refitted to each pose, the closest point, the pseudonormal sign and normal of
`fabricfem.body.mesh_distance.signed_closest`, the weights interpolated barycentrically at the foot; the maps and
posed vertices of the last few times are cached. The body's segment schedule (segments switched off) is not applied
to a mesh skin: its surface stays whole.

Skinning (`skinning`): "linear" (the default: linear blend skinning, every vertex a convex combination of its
segments' rigid maps) or "implicit" ([Vaillant2013], [Vaillant2014], fabricfem.body.implicit_skinning): the
vertices of more than one segment and those within `skinning_reach` of a shared joint are kept on the level of the
body's blended ellipsoids (fabricfem.body.blended) they had at rest, so a triangulation of the blended body poses as
the blended body; the contract's segment weights at a foot are then the blended ellipsoids' own (`field_at`), as on
the analytic skin, instead of the interpolated bone heat weights.

`ellipsoid_skin` triangulates a body's own segments (the blended ellipsoids by default, or any implicit function)
by marching cubes and rigs it: the default triangulated skin and the tests' reference.
"""
from __future__ import annotations

import copy
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping

import numpy as np

from fabricfem.body.blend_kernel import implicit_values, segment_weights
from fabricfem.body.blended import BLEND_WIDTH, BlendedEllipsoids, stacked, triangulate
from fabricfem.body.conventions import to_body, unit_scale, up_rotation
from fabricfem.body.ellipsoid import _as_points
from fabricfem.body.implicit_skinning import KEY_INTERVAL, SKINNING_REACH, ImplicitSkinning
from fabricfem.body.mesh_distance import PosedSurface, Topology
from fabricfem.body.mesh_query import CompiledSkin, Pose, QueryState

if TYPE_CHECKING:
    import trimesh
from fabricfem.body.skin import SkinQuery
from fabricfem.body.skinning import (
                                     HEAT,
                                     WEIGHT_CUTOFF,
                                     bone_heat_weights,
                                     bones,
                                     check_rest_positions,
                                     frames,
)

HEIGHT_RANGE = (0.5, 2.5)     # m: a body's height outside this is taken for a wrong `units`
COMPONENTS = ("largest", "all")
SKINNING = ("linear", "implicit")
CACHE_SIZE = 4                # posed surfaces kept (an explicit step asks the same time several times)


@dataclass(frozen=True, eq=False)
class SkinMesh:
    """A closed, outward-oriented triangulation in the body frame: vertices (V, 3) [m], faces (F, 3) int64;
    `source` (file or origin), `dropped` (face counts of the parts left out), `repaired` (what repair changed)."""

    vertices: np.ndarray
    faces: np.ndarray
    source: str = "arrays"
    dropped: tuple[int, ...] = ()
    repaired: tuple[str, ...] = ()

    @property
    def height(self) -> float:
        """z extent [m]."""
        return float(np.ptp(self.vertices[:, 2]))

    @property
    def volume(self) -> float:
        """Enclosed volume [m^3] (positive for outward normals)."""
        trimesh = _trimesh()
        return float(trimesh.Trimesh(self.vertices, self.faces, process=False).volume)


def _cleaned(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh with coincident vertices merged and degenerate and duplicate faces removed (nothing re-oriented)."""
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    return mesh


def _trimesh():
    """trimesh, imported at first use: 0.2-0.3 s of imports that a run on ellipsoids does not need."""
    import trimesh  # loaded at first use: a run on ellipsoids does not need it
    return trimesh


def _boundary_edges(mesh: trimesh.Trimesh) -> int:
    return len(_trimesh().grouping.group_rows(mesh.edges_sorted, require_count=1))


def _closed(mesh: trimesh.Trimesh, source: str, repair: bool) -> tuple[trimesh.Trimesh, tuple[str, ...]]:
    """The mesh closed and outward (module docstring, `repair`), with what repair did; ValueError naming
    `repair`."""
    done = []
    holes = _boundary_edges(mesh)
    if holes:
        if not repair:
            raise ValueError(f"repair: {source} has {holes} boundary edges (holes); give repair = true to close "
                             "them (trimesh fill_holes) or close the surface")
        _trimesh().repair.fill_holes(mesh)
        left = _boundary_edges(mesh)
        if left:
            raise ValueError(f"repair: {source} keeps {left} of its {holes} boundary edges open after fill_holes; "
                             "close the surface before reading it")
        done.append(f"closed {holes} boundary edges")
    volume = float(mesh.volume)
    if volume < 0.0:
        if not repair:
            raise ValueError(f"repair: {source} encloses a negative volume ({volume:.4g} m^3): its normals point "
                             "inwards; give repair = true to flip them")
        mesh.invert()
        done.append("flipped the inverted normals")
    return mesh, tuple(done)


def _components(mesh: trimesh.Trimesh, components: str) -> tuple[trimesh.Trimesh, tuple[int, ...]]:
    """The kept part(s) and the face counts of the dropped ones (`components` policy)."""
    if components not in COMPONENTS:
        raise ValueError(f"components must be one of {COMPONENTS}, got {components!r}")
    parts = mesh.split(only_watertight=False)
    if components == "all" or len(parts) <= 1:
        return mesh, ()
    keep = int(np.argmax([p.area for p in parts]))
    return parts[keep], tuple(len(p.faces) for k, p in enumerate(parts) if k != keep)


def _check_size(vertices: np.ndarray, source: str, units, up: str, height_range) -> None:
    """ValueError naming `up` (lying body) or `units` (height outside height_range)."""
    extent = np.ptp(vertices, axis=0)
    if extent[2] < 0.5 * extent[:2].max():
        raise ValueError(f"up: {source} read with up = {up!r} is {extent[2]:.3g} high and {extent[:2].max():.3g} "
                         "long: it lies on its side; give the file's up axis (\"y\" or \"z\")")
    if height_range is not None and not (height_range[0] <= extent[2] <= height_range[1]):
        raise ValueError(f"units: the body is {extent[2]:.4g} m tall with units = {units!r} (expected "
                         f"{height_range[0]} to {height_range[1]} m); give the file's length unit")


def skin_mesh(vertices: np.ndarray, faces: np.ndarray, source: str = "arrays", repair: bool = False
              ) -> SkinMesh:
    """A `SkinMesh` of arrays in the body frame [m] (cleaned, and closed and outward or refused naming `repair`)."""
    mesh = _cleaned(_trimesh().Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64),
                                    process=False))
    mesh, done = _closed(mesh, source, repair)
    return SkinMesh(np.ascontiguousarray(mesh.vertices, dtype=float),
                    np.ascontiguousarray(mesh.faces, dtype=np.int64), source, (), done)


def read_skin(path: str | Path, units: str | float = "m", up: str = "z", components: str = "largest",
              repair: bool = False, height_range: tuple[float, float] | None = HEIGHT_RANGE) -> SkinMesh:
    """Read a closed triangulated skin into the body frame (metres, z up) and check it (module docstring).

    Args:
        path: a mesh file trimesh reads (OBJ, PLY, STL, glTF/GLB, COLLADA .dae/.zae).
        units: the file's length unit (a name or metres per unit).
        up: the file's up axis, "z" or "y".
        components: "largest" (keep the part of largest area) or "all".
        repair: close holes (trimesh fill_holes) and flip inverted normals instead of refusing.
        height_range: (low, high) [m] of a plausible body height (None: not checked, e.g. a limb).

    Raises:
        ValueError (one line) naming `path`, `units`, `up`, `components` or `repair`.
    """
    trimesh = _trimesh()
    scale, _ = unit_scale(units), up_rotation(up)
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path: no mesh file {path}")
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - any reader failure is reported as the file's fault
        raise ValueError(f"path: trimesh cannot read {path}: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError(f"path: {path} holds no triangles")
    mesh = _cleaned(trimesh.Trimesh(to_body(loaded.vertices, scale, up), loaded.faces, process=False))
    mesh, dropped = _components(mesh, components)
    _check_size(mesh.vertices, path.name, units, up, height_range)
    mesh, done = _closed(mesh, path.name, repair)
    return SkinMesh(np.ascontiguousarray(mesh.vertices, dtype=float),
                    np.ascontiguousarray(mesh.faces, dtype=np.int64), str(path), dropped, done)


class MeshSkin:
    """The Skin (fabricfem.body.skin) of a triangulated surface rigged to a Body (module docstring).

    Args:
        mesh: the closed skin in the rest pose [m] (`read_skin`, `skin_mesh`).
        body: the segments and their kinematics.
        rest_positions: joint and marker positions [m] in the mesh's rest pose (name -> (3,)); default: the body's
            pose at the first time of its kinematics.
        joint_tolerance: how far [m] a joint may lie outside the mesh (0: inside or on it).
        tree_tolerance: `posed` (libigl's tree of all triangles, for a caller's own searches) reuses the tree of an
            earlier pose while no vertex moved more than this [m] since its build (0: a new tree for every pose);
            a gap is then at most 2 tree_tolerance above the exact one (`PosedSurface`). The queries are exact
            whatever it is (a refitted tree, `fabricfem.body.mesh_query`).
        heat, cutoff: the bone heat constant and weight cut (`fabricfem.body.skinning.bone_heat_weights`).
        skinning: "linear" (linear blend skinning) or "implicit" (then each vertex of more than one segment is moved
            back onto the level of the body's blended ellipsoids it had at rest, [Vaillant2013]; module docstring).
        blend_width: the width w [m] of those blended ellipsoids (`fabricfem.body.blended.BlendedEllipsoids`).
        skinning_interval: the implicit skinning's key interval [s] (`fabricfem.body.implicit_skinning`).
        skinning_reach: the implicit skinning moves the vertices of more than one segment and those within this
            distance [m] of a joint two segments share.
        margin: None: every query searches every point; a length [m]: the contact's active set (`query`), the
            points whose gap is certainly above it are not searched (gap = +inf).
    `transverse_scale` (None or t -> g) grows the skin across the segments' axes as the donning grows the body
    (`transforms`).

    Raises:
        ValueError naming `rest_positions` (missing names, a joint outside the mesh) or `skinning`.
    """

    def __init__(self, mesh: SkinMesh, body, rest_positions: Mapping[str, np.ndarray] | None = None,
                 joint_tolerance: float = 0.0, tree_tolerance: float = 0.0, heat: float = HEAT,
                 cutoff: float = WEIGHT_CUTOFF, margin: float | None = None, skinning: str = "linear",
                 blend_width: float = BLEND_WIDTH, skinning_interval: float = KEY_INTERVAL,
                 skinning_reach: float = SKINNING_REACH):
        if skinning not in SKINNING:
            raise ValueError(f"skinning: one of {list(SKINNING)}, got {skinning!r}")
        self.mesh, self.body = mesh, body
        self.segment_names = tuple(body.segments)
        t0 = float(body.kinematics.time_range[0])
        origin = "given" if rest_positions is not None else f"the body's pose at t = {t0:g} s"
        rest = check_rest_positions(body, rest_positions if rest_positions is not None
                                    else body.kinematics.positions(t0))
        self.topology = Topology.of(mesh.faces)
        self.rest = PosedSurface(mesh.vertices, self.topology)
        joints = list(body.joints)
        gap = self.rest.closest(np.array([rest[n] for n in joints]))[0]
        worst = int(np.argmax(gap))
        if gap[worst] > joint_tolerance:
            raise ValueError(f"rest_positions: joint {joints[worst]!r} ({origin}) lies {gap[worst]:.4g} m outside "
                             f"the skin {Path(mesh.source).name}; give the joints' positions in the mesh's rest pose")
        self.rest_positions = rest
        self.rest_centers, self.rest_rotations = frames(body, rest)
        self.weights = bone_heat_weights(mesh.vertices, mesh.faces, *bones(body, rest), heat, cutoff)
        if not (np.isfinite(tree_tolerance) and tree_tolerance >= 0.0):
            raise ValueError(f"tree_tolerance must be a length >= 0 [m], got {tree_tolerance!r}")
        self.tree_tolerance = float(tree_tolerance)
        self.tree_builds = 0
        self._tree = None
        self._posed: OrderedDict[float, PosedSurface] = OrderedDict()
        self._maps: OrderedDict[float, list] = OrderedDict()
        segments = list(body.segments.values())
        self._point_names = [getattr(g, end) for end in ("proximal", "distal", "marker") for g in segments]
        self._fraction = np.array([g.center_fraction for g in segments], dtype=float)
        if margin is not None and not (np.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin must be a length >= 0 [m] or None, got {margin!r}")
        self.margin = None if margin is None else float(margin)
        self.transverse_scale: Callable[[float], float] | None = None
        self.exact_points = 0
        self._travel, self._last_maps = 0.0, None
        self._active: dict[int, QueryState] = {}
        on = self.weights > 0.0
        low = np.array([mesh.vertices[c].min(axis=0) for c in on.T])
        high = np.array([mesh.vertices[c].max(axis=0) for c in on.T])
        self._sphere_center = 0.5 * (low + high)
        self._sphere_radius = np.array([np.linalg.norm(mesh.vertices[c] - m, axis=1).max()
                                        for c, m in zip(on.T, self._sphere_center)])
        self.skinning = skinning
        self.field = BlendedEllipsoids(body, blend_width) if skinning == "implicit" else None
        shifted = self._near_joints(on, rest, skinning_reach) if self.field is not None else np.zeros(0, dtype=np.int64)
        self._shifted, self._skinning_interval = shifted, skinning_interval
        self._levels = self._rest_levels(rest) if self.field is not None else np.zeros(0)
        self._field_at = None
        self.implicit = self._tracker()
        self.compiled = CompiledSkin(mesh.vertices, self.topology, self.weights, self._fraction, self.rest_centers,
                                     self.rest_rotations, self._sphere_center, self._sphere_radius, shifted)

    def _near_joints(self, on: np.ndarray, rest: Mapping[str, np.ndarray], reach: float) -> np.ndarray:
        """The vertices the implicit skinning moves: those of more than one segment and those within `reach` [m] of
        a joint two segments share (at rest)."""
        if not (np.isfinite(reach) and reach >= 0.0):
            raise ValueError(f"skinning_reach must be a length >= 0 [m], got {reach!r}")
        ends = [n for g in self.body.segments.values() for n in (g.proximal, g.distal)]
        shared = np.array([rest[n] for n in dict.fromkeys(ends) if ends.count(n) > 1], dtype=float).reshape(-1, 3)
        near = np.zeros(len(on), dtype=bool)
        for joint in shared:
            near |= np.linalg.norm(self.mesh.vertices - joint, axis=1) <= reach
        return np.flatnonzero(near | (on.sum(axis=1) > 1))

    def _rest_levels(self, rest: Mapping[str, np.ndarray]) -> np.ndarray:
        """phi [m] of the blended ellipsoids posed at the rest positions at the vertices the implicit skinning
        moves (the levels they are kept on)."""
        centers, rotations, radii = stacked([g.pose(rest) for g in self.body.segments.values()])
        return implicit_values(self.mesh.vertices[self._shifted], centers, rotations, radii, self.field.widths)

    def _tracker(self) -> ImplicitSkinning | None:
        """The implicit skinning of this skin's body (None for linear blend skinning)."""
        if self.field is None:
            return None

        def linear(t: float):
            points, g = self._frame_points(t)
            pose = self.compiled.pose_at(points, g)
            return pose.A, pose.b

        return ImplicitSkinning(self.mesh.vertices, self.mesh.faces, self.weights, self._shifted, self._levels,
                                linear, self.field_at, float(self.body.kinematics.time_range[0]),
                                self._skinning_interval)

    def _frame_points(self, t: float) -> tuple[np.ndarray, float]:
        """The segments' joints and markers (3K, 3) [m] at time t [s] and the donning's growth g."""
        positions = self.body.kinematics.positions(t)
        return np.array([positions[n] for n in self._point_names], dtype=float), self.growth(t)

    def growth(self, t: float) -> float:
        """The donning's transverse growth g at time t [s] (`transverse_scale`; 1 without one)."""
        return 1.0 if self.transverse_scale is None else float(self.transverse_scale(t))

    @property
    def blended_triangles(self) -> int:
        """The number of triangles with a corner of weight below 1 (moving with more than one segment)."""
        return int(((self.weights > 0.0).sum(axis=1) > 1)[self.mesh.faces].any(axis=1).sum())

    def transforms(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The segments' maps rest -> pose at time t [s], (A (K, 3, 3), b (K, 3) [m]) (`maps`)."""
        pose = self.maps(t)
        return pose.A, pose.b

    def maps(self, t: float) -> Pose:
        """The skin's `Pose` at time t [s]: A_k = R_k (R_k^0)^T, b_k = c_k - A_k c_k^0 [m]
        (`fabricfem.body.skinning.blend_transforms`) with the frames (c_k, R_k) of the joints and markers at t (the
        formulas of fabricfem.body.pose.segment_frame, without its checks: the first pose, at the rigging, went
        through them), compiled (`CompiledSkin.pose_at`); with a `transverse_scale` g(t) (the donning's growth)
        A_k = R_k diag(1, g, g) (R_k^0)^T: each segment's part of the skin scaled by g across the segment's axis
        (its local e1), as the contact grows the segments' radii. The last `CACHE_SIZE` times are cached."""
        key = float(t)
        if key in self._maps:
            self._maps.move_to_end(key)
            return self._maps[key]
        out = self._maps[key] = self.compiled.pose_at(*self._frame_points(key))
        if self.implicit is not None:
            out.set_shift(self.implicit.shift(key))
        if len(self._maps) > CACHE_SIZE:
            self._maps.popitem(last=False)
        return out

    def vertices(self, t: float) -> np.ndarray:
        """The posed vertices (V, 3) [m] at time t [s] (linear blend skinning, compiled; cached with `maps`)."""
        return self.compiled.pose(self.maps(t))

    def with_body(self, body) -> MeshSkin:
        """This skin (mesh, weights, rest frames, compiled tree shared) moved by another Body of the same segments,
        e.g. the garment run's body on the run's clock (fabricfem.wear.garment); no cached poses."""
        if tuple(body.segments) != self.segment_names:
            raise ValueError(f"skin: its segments {list(self.segment_names)} are not the body's {list(body.segments)}")
        twin = copy.copy(self)
        twin.body = body
        if self.field is not None:
            twin.field = BlendedEllipsoids(body, self.field.width)
            twin._field_at, twin.implicit = None, twin._tracker()
        twin._posed, twin._maps, twin._active, twin._tree = OrderedDict(), OrderedDict(), {}, None
        twin._travel, twin._last_maps = 0.0, None
        return twin

    def posed(self, t: float) -> PosedSurface:
        """The posed surface at time t [s] with libigl's AABB tree of all its triangles (cached for the last
        `CACHE_SIZE` times, reused within `tree_tolerance`; the queries use the compiled tree instead)."""
        key = float(t)
        if key in self._posed:
            self._posed.move_to_end(key)
            return self._posed[key]
        vertices = self.vertices(key)
        tree = self._tree
        if tree is not None and not (np.linalg.norm(vertices - tree[1], axis=1).max() <= self.tree_tolerance):
            tree = None
        surface = PosedSurface(vertices, self.topology, tree)
        if tree is None:
            self.tree_builds += 1
            self._tree = (surface.tree, surface.built_on)
        self._posed[key] = surface
        if len(self._posed) > CACHE_SIZE:
            self._posed.popitem(last=False)
        return surface

    def closest(self, x, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(gap (N,) [m], triangle (N,), barycentric coordinates (N, 3), foot (N, 3) [m], normal (N, 3)) of the
        points x (N, 3) [m] on the skin posed at time t [s] (`CompiledSkin.query`, every point searched: the sign
        and normal of `fabricfem.body.mesh_distance.signed_closest`)."""
        pts = _points(x)
        state = QueryState(self.compiled.ffi, len(pts), len(self.segment_names))
        self.exact_points += self.compiled.query(self.maps(t), pts, state)
        return state.gap, state.triangle, state.bary, state.foot, state.normal

    def foot_weights(self, triangle: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(N, K) segment weights at feet given by triangle and barycentric coordinates (interpolated linearly)."""
        b = np.clip(bary, 0.0, 1.0)
        b /= b.sum(axis=1, keepdims=True)
        return np.einsum("nj,njk->nk", b, self.weights[self.mesh.faces[triangle]])

    def travel(self, t: float) -> float:
        """The skin's travel [m] up to time t [s]: the sum over the successive times asked of a bound on the largest
        vertex displacement between them, max_k (|A_k - A'_k|_F R_k + |(A_k - A'_k) c_k + b_k - b'_k|) over the
        segments' bounding spheres (c_k, R_k) of their weighted rest vertices (a vertex moves by a convex combination
        of its segments' displacements; `CompiledSkin.travel`), plus the largest change of an implicit skinning's
        shift between them."""
        pose = self.maps(t)
        if self._last_maps is not None and self._last_maps is not pose:
            self._travel += self.compiled.travel(pose, self._last_maps) + shift_change(pose, self._last_maps)
        self._last_maps = pose
        return self._travel

    def query(self, x, t: float) -> SkinQuery:
        """The Skin contract (fabricfem.body.skin) at time t [s] for the points x (N, 3) [m].

        With a `margin` [m] only the points that may lie within it are searched: a point last searched at x0 with
        gap g0 and skin travel s0 has now a gap >= g0 - |x - x0| - (travel(t) - s0) (the gap is 1-Lipschitz in x,
        and moves by at most the skin's displacement); where that bound exceeds the margin the point is not searched
        and gets gap = +inf, foot = x, and its last normal and weights. Every gap below the margin is exact, so
        contact (gap < 0) is decided exactly. The state is kept per number of points (the contact asks all its
        nodes each time). Without a margin every point is searched."""
        pts = _points(x)
        n = len(pts)
        if self.margin is None:
            state = QueryState(self.compiled.ffi, n, len(self.segment_names))
            self.exact_points += self.compiled.query(self.maps(t), pts, state)
        else:
            travel = self.travel(t)
            state = self._active.get(n)
            if state is None:
                state = self._active[n] = QueryState(self.compiled.ffi, n, len(self.segment_names))
            self.exact_points += self.compiled.query(self.maps(t), pts, state, travel, self.margin)
        weights = state.weights.copy()
        if self.field is not None:
            near = np.flatnonzero(np.isfinite(state.gap))
            weights[near] = segment_weights(state.foot[near], *self.field_at(t))
        return SkinQuery(state.gap.copy(), state.foot.copy(), state.normal.copy(), weights)

    def field_at(self, t: float) -> tuple[np.ndarray, ...]:
        """The implicit skinning's blended ellipsoids at time t [s], grown by the donning: centres (K, 3) [m],
        rotations (K, 3, 3), radii (K, 3) [m], widths (K, K) [m] (the last time asked is kept)."""
        key = float(t)
        if self._field_at is None or self._field_at[0] != key:
            centers, rotations, radii = self.field.posed(key)
            g = self.growth(key)
            self._field_at = (key, (centers, rotations, radii * np.array([1.0, g, g]), self.field.widths))
        return self._field_at[1]

    def surface(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The posed skin at time t [s]: vertices (V, 3) [m], triangles (F, 3), outward oriented."""
        return self.vertices(t), self.mesh.faces


def shift_change(pose: Pose, before: Pose) -> float:
    """The largest change [m] of a vertex's implicit-skinning shift from `before` to `pose` (0 without shifts)."""
    if pose.shift is None and before.shift is None:
        return 0.0
    if pose.shift is None or before.shift is None:
        return max(pose.shift_bound, before.shift_bound)
    return float(np.sqrt(((pose.shift - before.shift) ** 2).sum(axis=1).max())) if len(pose.shift) else 0.0


def _points(x) -> np.ndarray:
    """x as a C-contiguous (N, 3) float array (a (3,) point as (1, 3); ValueError naming x for another shape; the
    compiled query refuses non-finite points)."""
    pts = np.ascontiguousarray(x, dtype=float)
    return pts if pts.ndim == 2 and pts.shape[1] == 3 else np.ascontiguousarray(_as_points(x)[0])


def union_implicit(body, t: float) -> Callable[[np.ndarray], np.ndarray]:
    """phi(x) = min_k d_k(x) [m], the exact signed distance to the union of the body's segments posed at time t
    [s] (`Ellipsoid.closest_point`, [Eberly2013]): negative inside."""
    posed = list(body.pose(t).values())

    def phi(x: np.ndarray) -> np.ndarray:
        return np.min([e.closest_point(x)[1] for e in posed], axis=0)   # the few segments, vectorised over x
    return phi


def ellipsoid_skin(body, t: float | None = None, spacing: float = 0.01,
                   implicit: Callable[[np.ndarray], np.ndarray] | None = None, **rig) -> MeshSkin:
    """A triangulated skin of the body's own segments, rigged to them with the body's pose at t as rest pose.

    Args:
        body: the Body; t: the rest time [s] (default: the first time of its kinematics).
        spacing: marching-cubes grid spacing [m] ([Lewiner2003], skimage.measure.marching_cubes): the vertices lie
            on the surface to the grid interpolation's error, the chords cut the surface by at most
            spacing^2 / (8 R) for a radius of curvature R. The grid spans `BlendedEllipsoids.bounds` (the box of
            the segments' ellipsoids grown by the blend's rounding w / 4).
        implicit: phi(x) (N, 3) -> (N,) [m], negative inside (its zero set inside that box); default the blended
            ellipsoids (`BlendedEllipsoids.implicit` at t); `union_implicit(body, t)` gives the plain union.
        rig: keywords of `MeshSkin` (joint_tolerance defaults to 2 spacing: the joints at the segments' tips lie
            on the surface, and the chords cut the tips).
    """
    t = float(body.kinematics.time_range[0]) if t is None else float(t)
    if not (np.isfinite(spacing) and spacing > 0.0):
        raise ValueError(f"spacing must be a positive length [m], got {spacing!r}")
    blended = BlendedEllipsoids(body)
    phi = implicit if implicit is not None else (lambda x: blended.implicit(x, t))
    vertices, faces = triangulate(phi, blended.bounds(t), spacing)
    mesh = skin_mesh(vertices, faces, source=f"ellipsoid skin at t = {t:g} s, spacing {spacing:g} m")
    rig.setdefault("joint_tolerance", 2.0 * spacing)
    return MeshSkin(mesh, body, rest_positions=body.kinematics.positions(t), **rig)
