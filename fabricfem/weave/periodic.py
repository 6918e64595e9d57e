"""The periodic pairs of a unit cell ([Man2006, sec. 4.3.2-4.3.3]; fabricfem.weave.homogenize, module docstring):
`PeriodicPair`, the geometry of the paired faces, the slave -> master point maps with their component signs
chained at edges and corners (`SlaveFaces`), the pin vertex, and the dolfinx_mpc constraint built from them
(`periodic_constraint`). Lengths in m.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import dolfinx.cpp as _cpp
import dolfinx.fem as fem
import dolfinx.mesh as dmesh
import dolfinx_mpc
import numpy as np
from mpi4py import MPI

__all__ = ["GEOMETRIC_TOLERANCE", "Locator", "PeriodicPair", "SlaveFaces", "allreduce", "bounding_box",
           "periodic_constraint", "pin_point"]

Locator = Callable[[np.ndarray], np.ndarray]

GEOMETRIC_TOLERANCE = 1e-8  # relative to the cell diagonal: points closer than this coincide


@dataclass(frozen=True)
class PeriodicPair:
    """Two opposite faces with u*_i(x) = s_i u*_i(m(x)) for x on the slave face, where the master
    point is m(x) = x - translation or m(x) = relation(x), and s = component_scale.

    `slave` and `master` are facet-tag values (with `facet_tags` given to the problem) or,
    for geometric pairs, `slave` is a locator x (3, n) -> bool (n,) and `translation` or
    `relation` is required. `translation` [m] is the vector from the master face to the slave face;
    with tags it defaults to the difference of the faces' vertex centroids (exact for meshes whose
    opposite faces match, which dolfinx_mpc does not otherwise require). `relation` x (3, n) ->
    (3, n) [m] is a general point map from the slave face onto the master face (e.g.
    UnitCellMesh.periodic_relation(name) of the quarter cell: half-period shift and z -> -z);
    give either `relation` or `translation`. `component_scale` (s_x, s_y, s_z), non-zero and
    dimensionless, is (1, 1, -1) for the anti-symmetric quarter cell [Man2006, sec. 4.3.3].
    `components` lists the displacement components (0, 1, 2) that are coupled; the others are left
    free by this pair (e.g. u*_z when it is prescribed on both faces by `fixed_facets`, the thesis'
    end-face condition of sec. 4.3.5.3).
    """

    slave: int | Locator
    master: int | None = None
    translation: Sequence[float] | None = None
    relation: Callable[[np.ndarray], np.ndarray] | None = None
    component_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    components: tuple[int, ...] = (0, 1, 2)


def _facet_vertex_coordinates(mesh: dmesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """Coordinates (n, 3) of the vertices of the given facets, gathered from all ranks, each vertex
    once (by global index), so that every rank sees the same complete face."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, 0)
    f2v = mesh.topology.connectivity(tdim - 1, 0)
    per_facet = f2v.offsets[1] - f2v.offsets[0]  # one facet type per mesh
    verts = np.unique(f2v.array.reshape(-1, per_facet)[facets].ravel()).astype(np.int32)
    nodes = _cpp.mesh.entities_to_geometry(mesh._mesh, 0, verts, False).ravel()
    global_ids = mesh.topology.index_map(0).local_to_global(verts)
    ids = np.concatenate(mesh.comm.allgather(np.asarray(global_ids, dtype=np.int64)))
    x = np.concatenate(mesh.comm.allgather(mesh.geometry.x[nodes]))
    return x[np.unique(ids, return_index=True)[1]]


@dataclass(frozen=True)
class _Face:
    """A planar face: centroid c, unit normal n and bounding box, for geometric membership tests."""

    centroid: np.ndarray
    normal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tolerance: float

    def contains(self, x: np.ndarray) -> np.ndarray:
        """Whether the points x (3, n) [m] lie on the face (within the tolerance), (n,)."""
        on_plane = np.abs(self.normal @ (x - self.centroid[:, None])) <= self.tolerance
        inside = np.all((x >= self.lower[:, None] - self.tolerance) & (x <= self.upper[:, None] + self.tolerance),
                        axis=0)
        return on_plane & inside


def _tagged_face(mesh: dmesh.Mesh, facet_tags, tag: int, tolerance: float) -> _Face:
    """Fit the plane of the facets tagged `tag` (same result on all ranks); ValueError if missing or
    not planar."""
    x = _facet_vertex_coordinates(mesh, facet_tags.indices[facet_tags.values == tag])
    if len(x) < 3:
        raise ValueError(f"periodic_pairs: facet tag {tag} marks no face of the mesh (found {len(x)} vertices)")
    centroid = x.mean(axis=0)
    d = x - centroid
    normal = np.linalg.eigh(d.T @ d)[1][:, 0]  # direction of least spread
    offplane = float(np.abs(d @ normal).max())
    if offplane > tolerance:
        raise ValueError(f"periodic_pairs: the face with facet tag {tag} is not planar "
                         f"(vertices up to {offplane:.3g} m off its mean plane)")
    return _Face(centroid, normal, x.min(axis=0), x.max(axis=0), tolerance)


def allreduce(comm: MPI.Comm, a: np.ndarray, op: MPI.Op) -> np.ndarray:
    """Element-wise reduction of a float array over `comm` (the pickle path cannot MIN/MAX arrays)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty_like(a)
    comm.Allreduce(a, out, op=op)
    return out


def bounding_box(mesh: dmesh.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners [m] of the axis-aligned bounding box of the mesh on all ranks."""
    x = mesh.geometry.x
    lower = x.min(axis=0) if len(x) else np.full(3, np.inf)
    upper = x.max(axis=0) if len(x) else np.full(3, -np.inf)
    return allreduce(mesh.comm, lower, MPI.MIN), allreduce(mesh.comm, upper, MPI.MAX)


def pin_point(mesh: dmesh.Mesh, excluded: Callable[[np.ndarray], np.ndarray], target: np.ndarray) -> np.ndarray:
    """The mesh vertex nearest `target` that no slave face contains (same choice on every rank)."""
    nv = mesh.topology.index_map(0).size_local
    nodes = _cpp.mesh.entities_to_geometry(mesh._mesh, 0, np.arange(nv, dtype=np.int32), False).ravel()
    x = mesh.geometry.x[nodes]
    x = x[~excluded(x.T)] if len(x) else x
    if len(x):
        dist = np.linalg.norm(x - target, axis=1)
        # ties broken by coordinates so that every partition picks the same vertex
        best = x[np.lexsort((x[:, 2], x[:, 1], x[:, 0], np.round(dist, 12)))[0]]
        candidate = (round(float(np.linalg.norm(best - target)), 12), *best.tolist())
    else:
        candidate = (np.inf, 0.0, 0.0, 0.0)
    winner = min(mesh.comm.allgather(candidate))
    if not np.isfinite(winner[0]):
        raise ValueError("periodic_pairs: every vertex lies on a slave face; no point left to pin")
    return np.array(winner[1:])


class SlaveFaces:
    """The slave faces of the periodic pairs with their slave -> master point maps and component signs s.

    Built from PeriodicPairs (all by facet tag, with facet_tags, or all by locator; ValueError otherwise or on a
    bad translation [m], relation, component_scale or components); tol [m]: face membership and the smallest
    translation. Attributes: faces (locators x (3, n) -> bool (n,)), maps (x (3, n) -> (3, n) [m]), scales
    ((3,) each) and coupled (the sorted coupled components of each pair)."""

    def __init__(self, mesh: dmesh.Mesh, pairs: Sequence[PeriodicPair], facet_tags, tol: float):
        if not pairs:
            raise ValueError("periodic_pairs must contain at least one PeriodicPair")
        by_tag = [isinstance(p.slave, (int, np.integer)) for p in pairs]
        if any(by_tag) and not all(by_tag):
            raise ValueError("periodic_pairs must be all by facet tag or all by locator, not mixed")
        faces, maps, scales = [], [], []
        for p in pairs:
            if p.relation is not None and p.translation is not None:
                raise ValueError("periodic_pairs: give either a relation or a translation, not both")
            if p.relation is not None and not callable(p.relation):
                raise ValueError(f"periodic_pairs: relation must be a callable x (3, n) -> (3, n), got {p.relation!r}")
            scale = np.asarray(p.component_scale, dtype=float)
            if scale.shape != (3,) or not np.all(np.isfinite(scale)) or np.any(scale == 0.0):
                raise ValueError(f"periodic_pairs: component_scale must be three finite non-zero numbers, "
                                 f"got {p.component_scale!r}")
            if by_tag[0]:
                if facet_tags is None:
                    raise ValueError("facet_tags are required for periodic_pairs given by tag")
                slave = _tagged_face(mesh, facet_tags, int(p.slave), tol)
                if p.translation is None and p.relation is None:
                    if p.master is None:
                        raise ValueError(f"periodic_pairs: pair with slave tag {p.slave} needs a master tag, "
                                         "a translation or a relation")
                    master = _tagged_face(mesh, facet_tags, int(p.master), tol)
                    t = slave.centroid - master.centroid
                else:
                    t = None if p.translation is None else np.asarray(p.translation, dtype=float)
                faces.append(slave.contains)
            else:
                if not callable(p.slave) or (p.translation is None and p.relation is None):
                    raise ValueError("periodic_pairs: a pair given by locator needs a callable slave and a "
                                     "translation or a relation")
                faces.append(p.slave)
                t = None if p.translation is None else np.asarray(p.translation, dtype=float)
            if p.relation is not None:
                maps.append(lambda x, r=p.relation: np.asarray(r(x), dtype=np.float64).reshape(3, -1))
            else:
                if t.shape != (3,) or not np.all(np.isfinite(t)) or np.linalg.norm(t) <= tol:
                    raise ValueError(f"periodic_pairs: translation must be a non-zero finite 3-vector, got {t!r}")
                maps.append(lambda x, t=t: x - t[:, None])
            scales.append(scale)

        self.faces, self.maps, self.scales = faces, maps, scales
        self.coupled = [tuple(sorted(set(int(c) for c in p.components))) for p in pairs]
        for comps in self.coupled:
            if not comps or any(c not in (0, 1, 2) for c in comps):
                raise ValueError(f"periodic_pairs: components must be a non-empty subset of (0, 1, 2), got {comps!r}")

    def contains(self, x: np.ndarray) -> np.ndarray:
        """Whether the points x (3, n) [m] lie on any slave face, (n,)."""
        hit = np.zeros(x.shape[1], dtype=bool)
        for face in self.faces:
            hit |= face(x)
        return hit

    def chain(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Master points (3, n) [m] of the points x (3, n) and their component signs (3, n).

        A point on several slave faces (edge, corner) is mapped by each pair in turn, until it lies on no slave
        face (no chained constraints); its sign is the product of the pairs'. ValueError on a cycle."""
        out, sign = np.array(x, dtype=np.float64, copy=True), np.ones((3, x.shape[1]))
        for _ in range(2 * len(self.faces) + 1):
            moved = False
            for face, point_map, s in zip(self.faces, self.maps, self.scales):
                hit = face(out)
                if np.any(hit):
                    out[:, hit] = point_map(out[:, hit])
                    sign[:, hit] *= s[:, None]
                    moved = True
            if not moved:
                return out, sign
        raise ValueError("periodic_pairs: the maps send slave points back onto slave faces (cycle); "
                         "each pair must map its slave face onto a master face")


def periodic_constraint(V: fem.FunctionSpace, faces: SlaveFaces, pairs: Sequence[PeriodicPair], facet_tags,
                        bcs: list) -> dolfinx_mpc.MultiPointConstraint:
    """The finalized dolfinx_mpc constraint u*_i(x) = s_i u*_i(master(x)) on the slave faces (Dirichlet `bcs`
    kept): one periodic constraint of all components when every pair couples all of them with s = 1 (by
    topology for tagged pairs), else one per component c and per sign s occurring at the slave points
    (products over the pairs meeting at an edge or corner)."""
    mpc = dolfinx_mpc.MultiPointConstraint(V)
    if all(np.all(s == 1.0) for s in faces.scales) and all(c == (0, 1, 2) for c in faces.coupled):
        def to_master(x: np.ndarray) -> np.ndarray:
            return faces.chain(x)[0]
        if isinstance(pairs[0].slave, (int, np.integer)):
            mesh = V.mesh
            slave_facets = np.unique(np.concatenate(
                [facet_tags.indices[facet_tags.values == p.slave] for p in pairs]))
            all_slaves = dmesh.meshtags(mesh, mesh.topology.dim - 1, slave_facets.astype(np.int32), 1)
            mpc.create_periodic_constraint_topological(V, all_slaves, 1, to_master, bcs)
        else:
            mpc.create_periodic_constraint_geometrical(V, faces.contains, to_master, bcs)
        mpc.finalize()
        return mpc
    signs = {1.0}
    for s in faces.scales:
        signs |= {round(float(a * b), 12) for a in signs for b in s}
    for c in range(3):
        faces_c = [face for face, comps in zip(faces.faces, faces.coupled) if c in comps]
        if not faces_c:
            continue

        def on_slave_face_c(x: np.ndarray, faces_c=faces_c) -> np.ndarray:
            hit = np.zeros(x.shape[1], dtype=bool)
            for face in faces_c:
                hit |= face(x)
            return hit
        for value in sorted(signs):
            def indicator(x: np.ndarray, c: int = c, value: float = value,
                          on_face: Locator = on_slave_face_c) -> np.ndarray:
                hit = on_face(x)
                sign = np.zeros(x.shape[1])
                if np.any(hit):
                    sign[hit] = faces.chain(x[:, hit])[1][c]
                return hit & np.isclose(sign, value, rtol=0, atol=1e-12)
            mpc.create_periodic_constraint_geometrical(V.sub(c), indicator, lambda x: faces.chain(x)[0],
                                                       bcs, scale=value)
    mpc.finalize()
    return mpc
