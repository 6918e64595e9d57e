"""Several garments in one wear scene: `[[garment]]` entries, listed from the inside out.

Route: the garments are meshed into ONE fabric surface with one connected part per garment
(fabricfem.meshes.layers.concentric_tubes), so that the one engine (fabricfem.wear.garment.GarmentRun), its body
contact and its cloth-cloth contact (fabricfem.contact.self_contact, which treats separate parts as different
garments and so also acts between the layers) run unchanged. Garments are tubes along +x about the same axis (the
sleeve over a base layer); a pattern garment is worn alone.

What one shell allows: the shell's material constants are per model (fabricfem.shell: dolfinx Constants and the
hand-written kernel's packed constants), not per cell, so every garment wears the scene's [fabric] (a garment's
`fabric` naming another stored fabric is refused); one geometry order and one quadrature for all. Per garment: its
sizes, its holds (its edge tags "<name>.end0" / "<name>.end1") and its monitors (fabricfem.wear.layers: the
pressure of each outer layer on the inner one and of each garment on the skin).

Checks, each a SceneError naming the key (one line, exit 2): before meshing, a layer order that puts a garment
inside the one listed before it, and garments whose facets start closer than the contact distance d_c (the outer
tube's chords lie at r cos(pi / (order n_around)) from the axis, its nodes on the circle); after meshing, before
any step, an intersecting triangle pair (fabricfem.contact.intersections) or a vertex of one garment within d_c of
another's triangle in the start state. SI units.
"""
from __future__ import annotations

import math

import numpy as np

from fabricfem.meshes.layers import TubeLayer, concentric_tubes
from fabricfem.scenes.contract import WearScene
from fabricfem.scenes.errors import SceneError
from fabricfem.scenes.wear_sections import GarmentSection, first_garment, garment_tables
from fabricfem.wear.layers import LayerMonitor, layer_labels

TUBE_KEYS = ("length", "radius", "n_around", "n_along")
SHARED_KEYS = ("order", "quadrature")          # one shell: the same for every garment


def garment_name(table: dict, index: int) -> str:
    """The garment's name: its `name`, else "garment<index>"."""
    return str(table.get("name") or f"garment{index}")


def check_layers(data: dict) -> None:
    """The data checks of several garments (module docstring) before meshing; nothing for one garment."""
    tables = garment_tables(data)
    if not tables:
        raise SceneError("garment: [[garment]] needs at least one garment table")
    if len(tables) == 1:
        return
    route, contact = data.get("route", {}), data.get("contact", {})
    if route.get("solver", "explicit") != "explicit":
        raise SceneError(f"route.solver: several garments run on the explicit engine (route.solver = \"explicit\"), "
                         f"not the {route['solver']} route")
    if not contact.get("self_contact"):
        raise SceneError("contact.self_contact: several garments need the cloth-cloth contact that keeps them apart "
                         "(write [contact] self_contact = true)")
    if "accuracy" in data:
        raise SceneError("accuracy: the accuracy levels refine one garment's mesh; a scene of several garments has "
                         "none (leave [accuracy] out)")
    names: dict[str, int] = {}
    for i, table in enumerate(tables):
        _check_layer_table(data, table, i, names)
        if i:
            _check_order(tables[i - 1], table, i, names)


def _check_layer_table(data: dict, table: dict, i: int, names: dict[str, int]) -> None:
    """One garment of several: a tube with positive sizes, a unique name, the scene's fabric, the shared keys of
    garment[0], holds of its own edges."""
    where = f"garment[{i}]"
    if table.get("builder", GarmentSection.builder) != "tube":
        raise SceneError(f"{where}.builder: several garments are tubes about one axis (builder = \"tube\"); a "
                         f"pattern garment is worn alone")
    missing = [k for k in TUBE_KEYS if k not in table]
    if missing:
        raise SceneError(f"{where}: a tube needs {missing}")
    for key in TUBE_KEYS:
        if not table[key] > 0:
            raise SceneError(f"{where}.{key}: must be positive, got {table[key]!r}")
    name = garment_name(table, i)
    if "." in name or not name:
        raise SceneError(f"{where}.name: a name without dots (the prefix of the edge tags), got {name!r}")
    if name in names:
        raise SceneError(f"{where}.name: {name!r} is already the name of garment[{names[name]}]")
    names[name] = i
    first = first_garment(data)
    for key in SHARED_KEYS:
        if table.get(key) != first.get(key):
            raise SceneError(f"{where}.{key}: the garments share one shell, so one {key} for all: garment[0] has "
                             f"{first.get(key)!r}, this one {table.get(key)!r}")
    fabric = table.get("fabric")
    if fabric is not None and fabric != data.get("fabric", {}).get("catalogue"):
        raise SceneError(f"{where}.fabric: {fabric!r} is not the scene's [fabric]; the shell's material constants are "
                         f"per model, not per cell (fabricfem.shell), so every garment wears [fabric]")
    for tag in table.get("hold", []):
        if tag not in ("end0", "end1"):
            raise SceneError(f"{where}.hold: a tube's edges are end0 and end1, got {tag!r}")


def _check_order(inner: dict, outer: dict, i: int, names: dict[str, int]) -> None:
    """The layer order: garment i lies outside garment i - 1 (radius [m] larger)."""
    if outer["radius"] <= inner["radius"]:
        raise SceneError(f"garment[{i}].radius: {outer['radius']:g} m puts {garment_name(outer, i)!r} inside (or on) "
                         f"{garment_name(inner, i - 1)!r} of garment[{i - 1}] ({inner['radius']:g} m); [[garment]] "
                         f"entries go from the inside out, each of a larger radius")


def facet_radius(garment: GarmentSection) -> float:
    """Smallest distance [m] of the tube's surface from its axis: its chords between nodes spaced
    2 pi / (order n_around), at r cos(pi / (order n_around)) (the nodes lie on the circle of radius r)."""
    return garment.radius * math.cos(math.pi / (garment.order * garment.n_around))


def check_layer_gaps(wear: WearScene, thickness: float) -> None:
    """Garments whose facets start within the contact distance d_c [m] (contact.self_contact_distance, default the
    fabric's `thickness` [m]) of the garment inside them are refused naming the outer one's radius (before
    meshing)."""
    d_c = wear.contact.self_contact_distance or thickness
    for i in range(1, len(wear.garments)):
        inner, outer = wear.garments[i - 1], wear.garments[i]
        clearance = facet_radius(outer) - inner.radius
        if clearance <= d_c:
            needed = (inner.radius + d_c) / math.cos(math.pi / (outer.order * outer.n_around))
            raise SceneError(f"garment[{i}].radius: {_name(wear, i)!r} ({outer.radius:g} m) and {_name(wear, i - 1)!r} "
                             f"({inner.radius:g} m) intersect or touch at the start: their surfaces are "
                             f"{clearance:.3g} m apart, not more than the contact distance {d_c:g} m; give a radius "
                             f"above {needed:.4g} m")


def _name(wear: WearScene, i: int) -> str:
    return wear.garments[i].name or f"garment{i}"


def layered_garment_mesh(wear: WearScene, comm) -> tuple:
    """(FabricMesh, seams [], hold tags "<name>.end0", None) of several tube garments (the return of
    fabricfem.scenes.wear.garment_mesh)."""
    layers = [TubeLayer(_name(wear, i), g.length, g.radius, g.n_around, g.n_along) for i, g in enumerate(wear.garments)]
    try:
        fmesh = concentric_tubes(layers, order=wear.garment.order, comm=comm)
    except ValueError as exc:
        raise SceneError(f"garment: {exc}") from None
    holds = [f"{layer.name}.{tag}" for layer, g in zip(layers, wear.garments) for tag in g.hold]
    return fmesh, [], holds, None


def attach_layers(run, wear: WearScene) -> None:
    """Give the run of several garments its per-garment monitors (fabricfem.wear.layers.LayerMonitor) and the
    self-contact its layers, after checking the start state (module docstring; SceneError naming the key)."""
    cloth = run.self_contact
    labels = layer_labels(cloth.surface, run.model.fmesh)
    cloth.layer = labels
    names = tuple(_name(wear, i) for i in range(len(wear.garments)))
    start = cloth.surface.reference
    crossing = run.intersections(np.zeros_like(run.integrator.d.getArray(readonly=True)))
    if crossing:
        raise SceneError(f"garment: the garments intersect at the start: {crossing} pairs of their triangles cross "
                         f"(fabricfem.contact.intersections); list them from the inside out, each of a larger radius")
    pairs = cloth.contact_pairs(start)
    tri = cloth.surface.triangles[pairs.triangle, 0]
    across = labels[pairs.vertex] != labels[tri]
    if across.any():
        k = int(np.argmin(np.where(across, pairs.distance, np.inf)))
        outer = int(max(labels[pairs.vertex[k]], labels[tri[k]]))
        raise SceneError(f"garment[{outer}].radius: {names[outer]!r} starts {pairs.distance[k]:.3g} m from "
                         f"{names[outer - 1]!r}, within the contact distance {cloth.distance:g} m; give it a larger "
                         f"radius")
    run.layers = LayerMonitor(names, labels, cloth)
