"""Hexahedral volume meshes of plain-weave unit cells ([Man2006, sec. 4.3.3], Fig. 19).

Each yarn is a separate body (no shared nodes; the yarns interact by
contact only): a structured mesh of first-order hexahedra obtained by
sweeping an O-grid of its elliptic cross-section (a square core and
``ring`` layers of quadrilaterals out to the ellipse) along the sinusoidal
centreline, one section plane perpendicular to the tangent at each of the
equally spaced stations s_i.  All boundary nodes lie on the exact elliptic
tube (see :mod:`.yarn_geometry`).  Both end faces of a yarn carry the same
section mesh, so their nodes match one to one under the cell's periodicity
(:meth:`UnitCellMesh.periodic_relation`), which periodic constraints need.

The mesh is generated with numpy on rank 0 and handed to
``dolfinx.mesh.create_mesh``, which partitions and distributes it; cell and
facet tags follow with ``distribute_entity_data`` (as in :mod:`.gmsh_io`).
gmsh is not needed: the structured sweep gives matching end faces by
construction.  Units: metres.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.cpp
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from dolfinx.mesh import GhostMode, Mesh, MeshTagsMetaClass
from mpi4py import MPI

from .gmsh_io import entity_tags
from .yarn_geometry import PlainWeave, YarnPath, _option, check_weave

__all__ = ["MeshResolution", "REFINEMENTS", "UnitCellMesh", "section_mesh", "unit_cell"]


@dataclass(frozen=True)
class MeshResolution:
    """Divisions of the structured yarn meshes.

    Attributes:
        along: hexahedra per half period along the centreline (>= 2).
        core: divisions of each side of the square core of the O-grid
            (>= 1); the section polygon has 4 * core vertices on the ellipse.
        ring: layers of quadrilaterals between the core and the ellipse (>= 1).
        core_size: half side of the core square in the unit disc, in (0, 1/sqrt(2)).
    """

    along: int
    core: int
    ring: int
    core_size: float = 0.55

    def __post_init__(self) -> None:
        for name, minimum in (("along", 2), ("core", 1), ("ring", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
                raise ValueError(f"refinement.{name}: must be an integer >= {minimum}, got {value!r}")
        if not (0.0 < float(self.core_size) < 1.0 / math.sqrt(2.0)):
            raise ValueError(f"refinement.core_size: must be in (0, 1/sqrt(2)), got {self.core_size!r}")

    @property
    def section_cells(self) -> int:
        """Quadrilaterals per cross-section."""
        return self.core ** 2 + 4 * self.core * self.ring

    @property
    def polygon_vertices(self) -> int:
        """Vertices of the section polygon inscribed in the ellipse."""
        return 4 * self.core


REFINEMENTS: dict[str, MeshResolution] = {
    "coarse": MeshResolution(along=8, core=4, ring=1),
    "fine": MeshResolution(along=16, core=8, ring=3),
}


def section_mesh(res: MeshResolution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """O-grid quadrilateral mesh of the unit disc.

    Returns:
        ``(points, quads, rim)``: points (n, 2); quads (m, 4) in dolfinx
        tensor-product order (v0, v1, v2, v3 = (0,0), (1,0), (0,1), (1,1))
        with positive orientation (v1 - v0) x (v2 - v0) > 0; rim (4 core,)
        indices of the points on the unit circle, counter-clockwise, at the
        equally spaced angles -pi/4 + 2 pi k / (4 core).
    """
    m, r, c = res.core, res.ring, float(res.core_size)
    grid = np.linspace(-c, c, m + 1)
    core_x, core_y = np.meshgrid(grid, grid, indexing="xy")  # node (i, j) at index i + (m+1) j
    core_points = np.column_stack([core_x.ravel(), core_y.ravel()])
    ij = np.arange(m)
    i, j = np.meshgrid(ij, ij, indexing="xy")
    n0 = (i + (m + 1) * j).ravel()
    core_quads = np.column_stack([n0, n0 + 1, n0 + m + 1, n0 + m + 2])

    # core boundary, counter-clockwise from corner (c, -c): right, top, left, bottom sides
    k = np.arange(m)
    boundary = np.concatenate([m + (m + 1) * k,                 # i = m, j = 0..m-1
                               (m - k) + (m + 1) * m,           # j = m, i = m..1
                               (m + 1) * (m - k),               # i = 0, j = m..1
                               k])                              # j = 0, i = 0..m-1
    n_rim = 4 * m
    angle = -0.25 * np.pi + 2.0 * np.pi * np.arange(n_rim) / n_rim
    circle = np.column_stack([np.cos(angle), np.sin(angle)])
    inner = core_points[boundary]
    layers = [core_points]
    for level in range(1, r + 1):
        w = level / r
        layers.append((1.0 - w) * inner + w * circle)
    points = np.concatenate(layers)

    rings = [boundary]
    start = core_points.shape[0]
    for level in range(r):
        rings.append(start + level * n_rim + np.arange(n_rim))
    ring_quads = []
    for level in range(r):
        lo, hi = rings[level], rings[level + 1]
        lo_next, hi_next = np.roll(lo, -1), np.roll(hi, -1)
        # tensor order: xi along the rim (k -> k+1), eta outwards
        ring_quads.append(np.column_stack([lo, lo_next, hi, hi_next]))
    quads = np.concatenate([core_quads] + ring_quads)
    e1 = points[quads[:, 1]] - points[quads[:, 0]]
    e2 = points[quads[:, 2]] - points[quads[:, 0]]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0.0
    quads[flip] = quads[flip][:, [0, 2, 1, 3]]
    return points, quads.astype(np.int64), rings[-1].astype(np.int64)


def _yarn_block(yarn: YarnPath, res: MeshResolution, node_offset: int
                ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Nodes (n, 3), hexahedra (m, 8) and facets {start, end, surface} of one yarn."""
    fam = yarn.family
    n_half = int(round((yarn.end - yarn.start) / fam.half_period))
    n_seg = res.along * n_half
    s = np.linspace(yarn.start, yarn.end, n_seg + 1)
    disc, quads, rim = section_mesh(res)
    n_disc = disc.shape[0]
    u = fam.semi_width * disc[:, 0]
    v = fam.semi_height * disc[:, 1]
    nodes = (yarn.centre(s)[:, None, :] + u[None, :, None] * yarn.binormal[None, None, :]
             + v[None, :, None] * yarn.normal(s)[:, None, :]).reshape(-1, 3)
    # (B, N, T) is right-handed, so positive quads in (u, v) sweep to positive hexahedra
    station = node_offset + n_disc * np.arange(n_seg)[:, None, None]
    bottom = station + quads[None, :, :]
    hexes = np.concatenate([bottom, bottom + n_disc], axis=2).reshape(-1, 8)
    edge = np.column_stack([rim, np.roll(rim, -1)])
    lateral_bottom = station + edge[None, :, :]
    lateral = np.concatenate([lateral_bottom, lateral_bottom + n_disc], axis=2).reshape(-1, 4)
    facets = {"start": node_offset + quads,
              "end": node_offset + n_seg * n_disc + quads,
              "surface": lateral}
    return nodes, hexes, facets


@dataclass
class UnitCellMesh:
    """A distributed hexahedral mesh of a plain-weave unit cell.

    Attributes:
        mesh: dolfinx mesh (tdim = gdim = 3, metres).
        cell_tags: yarn id per cell (``yarn_ids``).
        facet_tags: boundary facets: per yarn ``<yarn>_start`` / ``<yarn>_end``
            (end faces at s = start / end) and ``<yarn>_surface`` (lateral,
            contact surface).
        tags: facet tag name -> id.
        yarn_ids: yarn name (``warp0``, ``weft0``, ...) -> cell tag id.
        yarn_axis: DG0 vector Function, the unit centreline tangent of the
            yarn of each cell (the material direction A of [Man2006, eq. 4.68]).
        weave: the geometry.
        option: ``"quarter"`` (thesis option B) or ``"full"`` (option A).
        yarns: the yarn pieces, in the order of ``yarn_ids``.
        box_lower, box_upper: corners of the cell bounding box (m) that
            defines |Y| in the volume fraction [Man2006, eq. 4.65].
        yarn_volumes: measured volume of each yarn of the mesh (m^3).
        resolution: the divisions used.
    """

    mesh: Mesh
    cell_tags: MeshTagsMetaClass
    facet_tags: MeshTagsMetaClass
    tags: dict[str, int]
    yarn_ids: dict[str, int]
    yarn_axis: dolfinx.fem.Function
    weave: PlainWeave
    option: str
    yarns: tuple[YarnPath, ...]
    box_lower: np.ndarray
    box_upper: np.ndarray
    yarn_volumes: dict[str, float]
    resolution: MeshResolution

    @property
    def yarn_volume(self) -> float:
        """Total yarn volume |Y_s| of the mesh (m^3)."""
        return float(sum(self.yarn_volumes.values()))

    @property
    def cell_box(self) -> np.ndarray:
        """Period lengths / box sides (lx, ly, lz) (m); lx, ly are the in-plane periods."""
        return self.box_upper - self.box_lower

    @property
    def periods(self) -> np.ndarray:
        """In-plane repeat lengths (lx, ly) (m); the quarter cell repeats with z -> -z."""
        return self.cell_box[:2].copy()

    @property
    def volume_fraction(self) -> float:
        """phi = |Y_s| / |Y| of the mesh [Man2006, eq. 4.65]."""
        return self.yarn_volume / float(np.prod(self.cell_box))

    def tag(self, name: str) -> int:
        """Facet tag id of ``name``."""
        try:
            return self.tags[name]
        except KeyError:
            raise ValueError(f"name: unknown facet tag {name!r}; available: {sorted(self.tags)}") from None

    def facets(self, name: str) -> np.ndarray:
        """Local facet indices tagged ``name``."""
        return self.facet_tags.indices[self.facet_tags.values == self.tag(name)]

    def yarn(self, name: str) -> YarnPath:
        """The yarn piece called ``name``."""
        for y in self.yarns:
            if y.name == name:
                return y
        raise ValueError(f"yarn: unknown yarn {name!r}; available: {[y.name for y in self.yarns]}")

    def cells(self, name: str) -> np.ndarray:
        """Local cell indices of yarn ``name``."""
        self.yarn(name)
        return self.cell_tags.indices[self.cell_tags.values == self.yarn_ids[name]]

    def axis_at(self, x: np.ndarray, name: str) -> np.ndarray:
        """Unit centreline tangent (3, n) of yarn ``name`` at points ``x`` (3, n) inside it."""
        return _axis(self.yarn(name))(x)

    def periodic_relation(self, name: str) -> Callable[[np.ndarray], np.ndarray]:
        """Map x (3, n) on the ``<name>_end`` face to the matching point of ``<name>_start``.

        Full cell: translation by minus the period along the yarn.  Quarter
        cell (anti-symmetric repetition, [Man2006, sec. 4.3.3]): translation by
        minus the half period and reflection z -> -z (so a periodic
        displacement constraint must also flip u_z).
        """
        y = self.yarn(name)
        length = y.end - y.start
        reflect = self.option == "quarter"

        def relation(x: np.ndarray) -> np.ndarray:
            out = np.array(x, dtype=np.float64, copy=True)
            out[y.axis] -= length
            if reflect:
                out[2] = -out[2]
            return out
        return relation


def _axis(yarn: YarnPath) -> Callable[[np.ndarray], np.ndarray]:
    """x (3, n) -> unit tangent (3, n) at the foot point of x on the centreline."""
    def axis(x: np.ndarray) -> np.ndarray:
        pts = np.asarray(x, dtype=np.float64)[:3].T
        s, _, _ = yarn.section_coordinates(pts)
        s = np.where(np.isnan(s), pts[:, yarn.axis], s)  # outside the tube: the nearest station
        return yarn.tangent(s).T.copy()
    return axis


def _resolution(refinement: str | MeshResolution) -> MeshResolution:
    if isinstance(refinement, MeshResolution):
        return refinement
    if isinstance(refinement, str) and refinement in REFINEMENTS:
        return REFINEMENTS[refinement]
    raise ValueError(f"refinement: expected one of {list(REFINEMENTS)} or a MeshResolution, got {refinement!r}")


def unit_cell(geometry: PlainWeave | None = None, option: str = "quarter",
              refinement: str | MeshResolution = "coarse", comm: MPI.Comm = MPI.COMM_WORLD,
              *, ghost_mode: GhostMode = GhostMode.shared_facet) -> UnitCellMesh:
    """Hexahedral mesh of a plain-weave unit cell, built on rank 0 and distributed.

    Args:
        geometry: the weave (default ``PlainWeave()``); checked with
            :func:`check_weave` (ValueError if yarns would overlap).
        option: ``"quarter"``: thesis option B, the half waves of warp0 and
            weft0 crossing at the origin; ``"full"``: option A, warp0, warp1,
            weft0, weft1 over one period each.
        refinement: ``"coarse"``, ``"fine"`` or a :class:`MeshResolution`.
        comm: communicator of the mesh (collective).
        ghost_mode: dolfinx ghost mode.

    Returns:
        UnitCellMesh with cell tags (one per yarn), named facet tags, the
        yarn-axis field and the measured yarn volumes.
    """
    weave = PlainWeave() if geometry is None else geometry
    if not isinstance(weave, PlainWeave):
        raise ValueError(f"geometry: must be a PlainWeave, got {weave!r}")
    _option(option)
    res = _resolution(refinement)
    check_weave(weave)  # deterministic: raises identically on every rank
    yarns = weave.yarns(option)
    yarn_ids = {y.name: k + 1 for k, y in enumerate(yarns)}
    tags: dict[str, int] = {}
    for k, y in enumerate(yarns):
        for j, part in enumerate(("start", "end", "surface")):
            tags[f"{y.name}_{part}"] = 10 * (k + 1) + j + 1

    if comm.rank == 0:
        nodes, cells, cell_values, facets, facet_values = [], [], [], [], []
        offset = 0
        for y in yarns:
            x, hexes, parts = _yarn_block(y, res, offset)
            offset += x.shape[0]
            nodes.append(x)
            cells.append(hexes)
            cell_values.append(np.full(hexes.shape[0], yarn_ids[y.name], np.int32))
            for part, quads in parts.items():
                facets.append(quads)
                facet_values.append(np.full(quads.shape[0], tags[f"{y.name}_{part}"], np.int32))
        x_all = np.concatenate(nodes)
        cells_all = np.concatenate(cells)
        cell_values_all = np.concatenate(cell_values)
        facets_all = np.concatenate(facets)
        facet_values_all = np.concatenate(facet_values)
    else:
        x_all = np.empty((0, 3), np.float64)
        cells_all = np.empty((0, 8), np.int64)
        cell_values_all = np.empty(0, np.int32)
        facets_all = np.empty((0, 4), np.int64)
        facet_values_all = np.empty(0, np.int32)

    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.Cell("hexahedron", geometric_dimension=3), 1))
    mesh = dolfinx.mesh.create_mesh(comm, cells_all, np.ascontiguousarray(x_all), domain,
                                    ghost_mode=ghost_mode,
                                    partitioner=dolfinx.mesh.create_cell_partitioner())
    tdim = mesh.topology.dim
    cell_tags = entity_tags(mesh, tdim, cells_all, cell_values_all)
    cell_tags.name = "yarns"
    mesh.topology.create_entities(tdim - 1)
    facet_tags = entity_tags(mesh, tdim - 1, facets_all, facet_values_all)
    facet_tags.name = "facet_tags"

    V = dolfinx.fem.VectorFunctionSpace(mesh, ("DG", 0))
    yarn_axis = dolfinx.fem.Function(V, name="yarn_axis")
    for y in yarns:
        yarn_axis.interpolate(_axis(y), cells=cell_tags.indices[cell_tags.values == yarn_ids[y.name]])
    yarn_axis.x.scatter_forward()

    volumes = _yarn_volumes(mesh, cell_tags, yarn_ids)
    lower, upper = weave.cell_bounds(option)
    return UnitCellMesh(mesh=mesh, cell_tags=cell_tags, facet_tags=facet_tags, tags=tags,
                        yarn_ids=yarn_ids, yarn_axis=yarn_axis, weave=weave, option=option,
                        yarns=yarns, box_lower=lower, box_upper=upper, yarn_volumes=volumes,
                        resolution=res)


def _yarn_volumes(mesh: Mesh, cell_tags: MeshTagsMetaClass, yarn_ids: dict[str, int]) -> dict[str, float]:
    """Global volume of each yarn (m^3): cell volumes from a DG0 assembly, summed per tag."""
    Q = dolfinx.fem.FunctionSpace(mesh, ("DG", 0))
    cell_volume = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(ufl.TestFunction(Q) * ufl.dx))
    values = cell_volume.array  # owned dofs = owned cells (DG0)
    n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    dof_of_cell = Q.dofmap.list.array.reshape(-1)
    owned = cell_tags.indices < n_owned
    cells, ids = cell_tags.indices[owned], cell_tags.values[owned]
    out = {}
    for name, k in yarn_ids.items():
        local = float(np.sum(values[dof_of_cell[cells[ids == k]]]))
        out[name] = mesh.comm.allreduce(local, op=MPI.SUM)
    cell_volume.destroy()
    return out
