"""The older sleeve and compression scene layouts, refused with every moved key in one message.

Before the one engine, an arm in a tube was a scene of kind "sleeve" ([mesh] type = "tube", [body] type =
"default_arm", [motion], [contact], [route]) and a compression sleeve one of kind "compression" ([mesh], [limb],
[donning], quasi-static growth). Both are wear scenes now ([scene] kind = "wear", [garment] builder = "tube").
A file in an older layout is refused before anything is read further, with one line that lists each key it uses
at its new section and name, so that a user rewrites it once (not one run per key).
"""
from __future__ import annotations

OLD_KINDS = ("sleeve", "compression")
TUBE_KEYS = ("length", "radius", "n_around", "n_along", "order", "quadrature", "hold_rotations")
# old "section.key" -> new "section.key" (or a note where the key has no one-to-one successor)
MOVED = {
    **{f"mesh.{k}": f"garment.{k}" for k in TUBE_KEYS},
    "mesh.type": "garment.builder = \"tube\"",
    "mesh.cell": "(dropped: wear tubes are Q2 quadrilaterals)",
    "body.type": "body.type = \"arm\" (for \"default_arm\")",
    "motion.steps": "motion.angle_steps",
    "motion.solver": "route.solver",
    "motion.mass_damping": "route.mass_damping",
    "motion.rotary_inertia_scale": "route.rotary_inertia_scale",
    "motion.dynamic_similarity": "route.dynamic_similarity",
    "contact.gravity": "route.gravity",
    "output.render_angles": "output.render_at",
    "limb.center": "body.center (with body.type = \"limb\")",
    "limb.radii": "body.radii (with body.type = \"limb\")",
    "donning.steps": "donning.time (growth time [s] on the explicit engine, with donning.method = \"grow\")",
    "donning.tolerance": "(dropped: the explicit contact holds the gap)",
    "donning.start": "donning.start (with donning.method = \"grow\")",
}
# sections whose presence beside [mesh] marks an older wear layout
OLD_SECTIONS = ("body", "motion", "contact", "route", "limb", "donning")


def is_old_layout(data: dict) -> bool:
    """True for a scene in the older sleeve or compression layout (its kind, or [mesh] beside a wearer's section)."""
    kind = data.get("scene", {}).get("kind") if isinstance(data.get("scene"), dict) else None
    return kind in OLD_KINDS or ("mesh" in data and "garment" not in data
                                 and any(name in data for name in OLD_SECTIONS))


def old_layout_message(data: dict, source: str = "scene") -> str:
    """One line: the file is in an older layout, and each key it uses -> its new section and name."""
    moves = []
    kind = data.get("scene", {}).get("kind")
    if kind is not None:
        moves.append(f"scene.kind = {kind!r} -> scene.kind = \"wear\"")
    for section, table in data.items():
        if not isinstance(table, dict):
            continue
        for key in table:
            new = MOVED.get(f"{section}.{key}")
            if new is not None:
                moves.append(f"{section}.{key} -> {new}")
    if "limb" in data and "motion" not in data:
        moves.append("(new) motion.type = \"still\"")
    layout = "compression" if ("limb" in data or kind == "compression") else "sleeve"
    return (f"{source}: the older {layout} layout is no longer read; a garment on a wearer is a wear scene. Moved "
            f"keys (old -> new): " + "; ".join(moves) + " (docs/scenes.md, scenes/sleeve.toml and "
            "scenes/compression_sleeve.toml show the layout)")
