"""Container for a fabric mid-surface mesh with its material directions.

A fabric is modelled as a 2D manifold in 3D (topological dimension 2,
geometric dimension 3), also when it is flat.  Coordinates are in metres.

Material frame on the reference (undeformed) surface:

* warp ``E1``: the first material direction, a unit vector tangent to the
  surface (the warp yarns);
* normal ``N``: the unit surface normal, with one consistent orientation
  (it agrees with ``ufl.CellNormal`` of the mesh cells);
* weft ``E2 = N x E1``: the second material direction, tangent to the
  surface and orthogonal to the warp, so that (E1, E2, N) is right-handed.

The direction fields are plain functions of the coordinates in the layout
``dolfinx.fem.Function.interpolate`` uses: ``x`` with shape (3, n_points)
maps to an array with shape (3, n_points).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.mesh
import numpy as np

DirectionField = Callable[[np.ndarray], np.ndarray]


@dataclass
class FabricMesh:
    """A distributed fabric mesh with boundary tags and material directions.

    Attributes:
        mesh: The dolfinx mesh; always geometric dimension 3, topological
            dimension 2 (metres).
        facet_tags: Tags of boundary edges (dimension 1); the values are
            gmsh physical group ids.
        tags: Physical group name -> id for ``facet_tags``.
        warp: ``x (3, N) -> E1 (3, N)``, unit warp direction tangent to the
            reference surface.
        normal: ``x (3, N) -> N (3, N)``, unit reference normal with a
            consistent orientation.
        cell_tags: Cell tags from gmsh physical surfaces, or None.
        panel_directions: optional cell tag value -> (warp, normal) fields, each valid on the cells with
            that tag (a garment's panels: points of different panels may coincide in 3D, where a field of
            x alone is ambiguous). Used by :meth:`directions_at`; None: ``warp`` and ``normal`` everywhere.
    """

    mesh: dolfinx.mesh.Mesh
    facet_tags: dolfinx.mesh.MeshTagsMetaClass
    tags: dict[str, int]
    warp: DirectionField
    normal: DirectionField
    cell_tags: dolfinx.mesh.MeshTagsMetaClass | None = None
    panel_directions: dict[int, tuple[DirectionField, DirectionField]] | None = None

    def __post_init__(self) -> None:
        gdim, tdim = self.mesh.geometry.dim, self.mesh.topology.dim
        if gdim != 3 or tdim != 2:
            raise ValueError(
                f"mesh: a FabricMesh needs a surface in 3D (tdim 2, gdim 3), got tdim {tdim}, gdim {gdim}")
        if self.facet_tags.dim != tdim - 1:
            raise ValueError(f"facet_tags: expected dimension {tdim - 1}, got {self.facet_tags.dim}")
        if self.panel_directions is not None and self.cell_tags is None:
            raise ValueError("panel_directions: needs cell_tags (the fields are given per cell tag value)")

    def tag(self, name: str) -> int:
        """Physical group id of the facet tag ``name``."""
        try:
            return self.tags[name]
        except KeyError:
            raise ValueError(
                f"tag: unknown facet tag {name!r}; available tags: {sorted(self.tags)}") from None

    def facets(self, name: str) -> np.ndarray:
        """Local (process) indices of the facets (edges) tagged ``name``."""
        value = self.tag(name)
        return self.facet_tags.indices[self.facet_tags.values == value]

    def weft(self, x: np.ndarray) -> np.ndarray:
        """Weft direction ``E2 = N x E1`` at points ``x`` (3, N); unit, tangent."""
        return np.cross(self.normal(x), self.warp(x), axis=0)

    def directions_at(self, V) -> tuple[np.ndarray, np.ndarray]:
        """Warp E1 and normal N, each (3, n), at the n nodes of the Lagrange space ``V`` (the rows of
        ``V.tabulate_dof_coordinates()``, one per node also for a vector space).

        Without ``panel_directions``: ``warp`` and ``normal`` at the node coordinates. With them: the nodes of
        the cells tagged t take the fields of t (a node shared by cells of two tags takes the later tag's;
        panels of a garment share no node), the other nodes ``warp`` and ``normal``.
        """
        x = V.tabulate_dof_coordinates().T
        warp = np.array(self.warp(x), dtype=float)
        normal = np.array(self.normal(x), dtype=float)
        if self.panel_directions:
            dofs = V.dofmap.list.array.reshape(V.dofmap.list.num_nodes, -1)   # (cells, nodes per cell)
            for value, (w, n) in self.panel_directions.items():
                nodes = np.unique(dofs[self.cell_tags.indices[self.cell_tags.values == value]])
                warp[:, nodes] = w(x[:, nodes])
                normal[:, nodes] = n(x[:, nodes])
        return warp, normal
