"""Several tube garments worn one over the other, meshed as one fabric surface with one connected part each.

Each layer is an open circular cylinder along +x from x = 0 to x = its length [m], of its radius [m], built as
fabricfem.meshes.tube builds one tube (the circle at x = 0 split into k arcs, extruded along +x; second-order nodes
on the circle), all in one gmsh model, so that one FabricMesh (one shell, one self-contact, one body contact) holds
them all. The layers share no node: each is its own connected part of the mesh, which the cloth-cloth contact
(fabricfem.contact.self_contact) treats as different garments.

Tags: edges "<name>.end0" (x = 0) and "<name>.end1" (x = length) of each layer; cells tagged with the layer's index
+ 1 (`FabricMesh.cell_tags`, the order of the layers, inside out). Material frame as the tube's: warp +x, normal the
outward radial direction.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

from mpi4py import MPI

from . import _validate, directions
from .gmsh_io import FabricMesh, mesh_from_gmsh
from .sector_partition import by_sectors
from .tube import _n_arcs


@dataclass(frozen=True)
class TubeLayer:
    """One tube of a layered garment stack: its name (the prefix of its edge tags), length and radius [m], Q
    cells around and along."""

    name: str
    length: float
    radius: float
    n_around: int
    n_along: int


def _add_tube(model: Any, layer: TubeLayer, cell: str) -> tuple[list[int], list[int], list[int]]:
    """The geometry of one tube in `model` (not synchronized): (arcs at x = 0, arcs at x = length, surfaces)."""
    geo = model.geo
    k = _n_arcs(layer.n_around)
    centre = geo.addPoint(0.0, 0.0, 0.0)
    angles = [2.0 * math.pi * i / k for i in range(k)]
    points = [geo.addPoint(0.0, layer.radius * math.cos(a), layer.radius * math.sin(a)) for a in angles]
    arcs = [geo.addCircleArc(points[i], centre, points[(i + 1) % k]) for i in range(k)]
    for arc in arcs:
        geo.mesh.setTransfiniteCurve(arc, layer.n_around // k + 1)
    out = geo.extrude([(1, a) for a in arcs], layer.length, 0.0, 0.0, numElements=[layer.n_along],
                      recombine=(cell == "quadrilateral"))
    geo.remove([(0, centre)])
    return arcs, [tag for _, tag in out[0::4]], [tag for _, tag in out[1::4]]


def _build(model: Any, layers: Sequence[TubeLayer], cell: str, order: int) -> None:
    """Every layer's geometry, its edge and cell groups, and the mesh of all of them."""
    parts = [_add_tube(model, layer, cell) for layer in layers]
    model.geo.synchronize()
    for index, (layer, (arcs, tops, surfaces)) in enumerate(zip(layers, parts)):
        model.setPhysicalName(1, model.addPhysicalGroup(1, arcs), f"{layer.name}.end0")
        model.setPhysicalName(1, model.addPhysicalGroup(1, tops), f"{layer.name}.end1")
        model.setPhysicalName(2, model.addPhysicalGroup(2, surfaces, tag=index + 1), layer.name)
    model.mesh.generate(2)
    if order > 1:
        model.mesh.setOrder(order)


def concentric_tubes(layers: Sequence[TubeLayer], cell: str = "quadrilateral", order: int = 2,
                     comm: MPI.Comm = MPI.COMM_WORLD) -> FabricMesh:
    """One FabricMesh of the tube `layers` (module docstring), each a connected part, its cells split among the
    ranks by angle about +x (fabricfem.meshes.sector_partition) when every layer has 2 cells around per rank, else
    by the graph partitioner; ValueError naming a refused value (sizes positive,
    at least 3 cells around, unique names)."""
    checked = []
    for layer in layers:
        checked.append(TubeLayer(str(layer.name), _validate.positive_length("length", layer.length),
                                 _validate.positive_length("radius", layer.radius),
                                 _validate.count("n_around", layer.n_around, minimum=3),
                                 _validate.count("n_along", layer.n_along)))
    names = [layer.name for layer in checked]
    if not checked or len(set(names)) != len(names):
        raise ValueError(f"layers: one or more layers with unique names, got {names}")
    cell = _validate.choice("cell", cell, _validate.CELLS)
    order = _validate.choice("order", _validate.count("order", order), (1, 2))
    return mesh_from_gmsh(lambda model: _build(model, checked, cell, order), (1.0, 0.0, 0.0),
                          directions.radial_from_x_axis(), comm, name="layers",
                          partition="sectors" if by_sectors(comm.size, min(c.n_around for c in checked)) else "graph")
