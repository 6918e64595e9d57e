"""Where a wear scene's pattern panels start in 3-D: each panel's own rigid placement (its GarmentCode translation
and Euler rotation) turned by `[garment] rotate` and moved by `translate`, or, for the panels named in
`[garment.wrap]`, rolled onto a cylinder given in the scene's frame (fabricfem.meshes.pattern_mesh.CylinderWrap;
`rotate` and `translate` do not apply to them). A wrap table:

    axis_point = [x, y, z]       m: a point of the cylinder's axis; the panel's y = 0 lies at its height along the axis
    axis = [x, y, z]             the axis direction (normalised), the panel's +y
    radius = r                   m
    zero_direction = [x, y, z]   the radial direction of the panel's x = 0 (projected perpendicular to the axis)
    angle0 = t0                  deg (default 0): the panel's x maps to the angle t0 + x / r about the axis from
                                 zero_direction, turning towards axis x zero_direction

The roll is isometric (no membrane strain at the start); its curvature is the shell's stress-free reference
curvature. SI units.
"""
from __future__ import annotations

import math

import numpy as np

from fabricfem.meshes.pattern import Panel, Pattern
from fabricfem.meshes.pattern_mesh import Placement, RigidPlacement, wrap_on_cylinder
from fabricfem.scenes.errors import SceneError, finite_vector
from fabricfem.scenes.wear_sections import GarmentSection

WRAP_KEYS = {"axis_point": True, "axis": True, "radius": True, "zero_direction": True, "angle0": False}


def garment_frame(garment: GarmentSection) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3, 3), shift (3,) [m]) of garment.rotate and garment.translate, applied to a pattern's rigidly
    placed panels: x = rotation x_panel + shift."""
    rotation = np.eye(3)
    if garment.rotate is not None:
        rotation = Panel("frame", np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), rotation=tuple(garment.rotate)
                         ).rotation_matrix()
    return rotation, np.zeros(3) if garment.translate is None else np.asarray(garment.translate, dtype=float)


def check_wrap(garment: dict) -> None:
    """[garment.wrap] of the garment table before any meshing: on a pattern garment only, a table of panel name ->
    wrap table (module docstring) with known keys, 3-vectors, a positive radius, a non-zero axis and a
    zero_direction not along it (SceneError naming the key)."""
    wrap = garment.get("wrap")
    if wrap is None:
        return
    if garment.get("builder", "pattern") == "tube":
        raise SceneError("garment.wrap: rolls the panels of a pattern; this garment is a tube")
    if not isinstance(wrap, dict):
        raise SceneError(f"garment.wrap: a table of panel name -> cylinder, got {wrap!r}")
    for name, table in wrap.items():
        where = f"garment.wrap.{name}"
        if not isinstance(table, dict):
            raise SceneError(f"{where}: a table with keys {sorted(WRAP_KEYS)}, got {table!r}")
        unknown = sorted(set(table) - set(WRAP_KEYS))
        missing = sorted(k for k, required in WRAP_KEYS.items() if required and k not in table)
        if unknown or missing:
            raise SceneError(f"{where}: " + (f"unknown key(s) {unknown}; " if unknown else "")
                             + (f"missing {missing}; " if missing else "") + f"allowed: {sorted(WRAP_KEYS)}")
        vectors = {k: finite_vector(f"{where}.{k}", table[k]) for k in ("axis_point", "axis", "zero_direction")}
        for key, value, kind in (("radius", table["radius"], "positive length [m]"),
                                 ("angle0", table.get("angle0", 0.0), "finite angle [deg]")):
            if (isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
                    or (key == "radius" and value <= 0.0)):
                raise SceneError(f"{where}.{key}: expected a {kind}, got {value!r}")
        try:
            wrap_on_cylinder(vectors["axis_point"], vectors["axis"], table["radius"], vectors["zero_direction"],
                             math.radians(table.get("angle0", 0.0)))
        except ValueError as exc:
            raise SceneError(f"{where}.{exc}") from None


def panel_placements(garment: GarmentSection, pattern: Pattern) -> dict[str, Placement]:
    """Panel name -> its placement in the scene's frame (module docstring); a wrapped panel the pattern lacks is
    refused (SceneError naming garment.wrap and the pattern's panels)."""
    wrap = garment.wrap or {}
    unknown = sorted(set(wrap) - set(pattern.panels))
    if unknown:
        raise SceneError(f"garment.wrap: no panel named {unknown} in the pattern; panels {sorted(pattern.panels)}")
    rotation, shift = garment_frame(garment)
    placements: dict[str, Placement] = {}
    for name, panel in pattern.panels.items():
        if name in wrap:
            w = wrap[name]
            placements[name] = wrap_on_cylinder(w["axis_point"], w["axis"], w["radius"], w["zero_direction"],
                                                math.radians(w.get("angle0", 0.0)))
        else:
            own = RigidPlacement.of(panel)
            placements[name] = RigidPlacement(rotation @ own.rotation, rotation @ own.translation + shift)
    return placements
