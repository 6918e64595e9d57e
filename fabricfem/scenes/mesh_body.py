"""A wear scene's body from a surface mesh (`[body] type = "mesh"`): the keys checked, the skin read and rigged.

Keys (fabricfem.scenes.wear_sections.WearBodySection): `file` (a mesh trimesh reads, relative to the scene file, or
"human" for the Debian assimp-testmodels human, `fabricfem.body.human.HUMAN_PATH`, read with its own units and up
axis, `HUMAN_KEYS`), `units`, `up`, `repair`, `components` (fabricfem.body.mesh_skin.read_skin), `skeleton`
(lower_body or arm: the segments the skin is rigged to, with that preset's dimension keys and motions), `skinning`
(linear or implicit, fabricfem.body.mesh_skin) and
`rest_positions` (the skeleton's joints and markers in the mesh [m], a table or "human"; default the skeleton's
first pose). `check_mesh_keys` makes the checks that need no file (with `check_wear`, before anything is built);
`scene_skin` reads the file and rigs it in `fabricfem.scenes.wear.plan`, before the garment is meshed: every refusal
is one SceneError line naming the key, e.g. "body.units: the body is 170 m tall ...". The contact searches the
skin with the active set (margin 0, fabricfem.body.mesh_skin.MeshSkin.query) in compiled code, exactly (a tree
refitted to each pose, fabricfem.body.mesh_query); the quick trousers scene on the walking human costs 0.60 ms of
contact per step against 0.37 ms on the blended ellipsoids of its dimensions
(docs/findings/2026-11-27-mesh-skin-cost.md).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fabricfem.body.conventions import LENGTH_UNITS
from fabricfem.body.human import HUMAN_KEYS, HUMAN_PATH, human_rest
from fabricfem.body.mesh_skin import COMPONENTS, HEIGHT_RANGE, SKINNING, MeshSkin, read_skin
from fabricfem.scenes.errors import SceneError

SKELETONS = ("lower_body", "arm")
HUMAN = "human"                   # file and rest_positions: the Debian human and its measured joints
CONTACT_MARGIN = 0.0              # m: the active set's margin of the scene's skin (MeshSkin.query)
SKIN_KEYS = ("units", "up", "repair", "components")


def check_mesh_keys(body: dict) -> None:
    """The checks of a mesh body's keys that read no file (SceneError naming body.<key>)."""
    if body.get("skeleton") not in SKELETONS:
        raise SceneError(f"body.skeleton: a mesh body is rigged to the segments of {list(SKELETONS)}, got "
                         f"{body.get('skeleton')!r}")
    if not body.get("file"):
        raise SceneError("body.file: a mesh body needs its surface mesh file (or \"human\")")
    if body.get("up", "z") not in ("y", "z"):
        raise SceneError(f"body.up: the file's up axis must be \"y\" or \"z\", got {body['up']!r}")
    if body.get("skinning", "linear") not in SKINNING:
        raise SceneError(f"body.skinning: one of {list(SKINNING)}, got {body['skinning']!r}")
    if body.get("components", "largest") not in COMPONENTS:
        raise SceneError(f"body.components: one of {list(COMPONENTS)}, got {body['components']!r}")
    units = body.get("units", "m")
    if isinstance(units, str) and units.strip().lower() not in LENGTH_UNITS:
        raise SceneError(f"body.units: unknown unit {units!r}; a name {sorted(LENGTH_UNITS)} or a number of metres "
                         "per file unit")
    if not isinstance(units, str) and not (math.isfinite(units) and units > 0):
        raise SceneError(f"body.units: metres per file unit must be a positive number, got {units!r}")
    rest = body.get("rest_positions")
    if isinstance(rest, str) and rest != HUMAN:
        raise SceneError(f"body.rest_positions: a table of joint/marker name -> [x, y, z] [m] or \"{HUMAN}\", "
                         f"got {rest!r}")
    if isinstance(rest, str) and body["skeleton"] != "lower_body":
        raise SceneError(f"body.rest_positions: \"{HUMAN}\" gives the lower body's joints; this skeleton is "
                         f"{body['skeleton']!r}")
    for name, point in (rest.items() if isinstance(rest, dict) else ()):
        if not (isinstance(point, list) and len(point) == 3 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in point)):
            raise SceneError(f"body.rest_positions.{name}: expected [x, y, z] [m], got {point!r}")


def mesh_path(file: str, scene_path: Path | None) -> Path:
    """The mesh file of body.file: "human" (the Debian human), or a path relative to the scene file."""
    if file == HUMAN:
        return HUMAN_PATH
    path = Path(file)
    if not path.is_absolute() and scene_path is not None:
        path = Path(scene_path).parent / path
    return path


def scene_skin(body_section, body, scene_path: Path | None) -> MeshSkin:
    """The MeshSkin of [body] (a WearBodySection of type mesh) rigged to `body` (its segments and motion):
    SceneError naming body.<key> for a missing or unreadable file, a wrong unit or up axis, holes or inverted
    normals, a joint outside the mesh or missing from rest_positions."""
    section = body_section
    path = mesh_path(section.file, scene_path)
    if not path.is_file():
        hint = " (the Debian package assimp-testmodels is not installed)" if section.file == HUMAN else ""
        raise SceneError(f"body.file: no mesh file {path}{hint}")
    keys = {"units": section.units, "up": section.up, "repair": section.repair, "components": section.components}
    if section.file == HUMAN:
        keys.update(HUMAN_KEYS)
    rest = section.rest_positions
    if rest == HUMAN:
        rest = human_rest()
    elif isinstance(rest, dict):
        rest = {name: np.asarray(p, dtype=float) for name, p in rest.items()}
    try:
        mesh = read_skin(path, height_range=None if section.skeleton == "arm" else HEIGHT_RANGE, **keys)
        return MeshSkin(mesh, body, rest_positions=rest, margin=CONTACT_MARGIN, skinning=section.skinning,
                        blend_width=section.blend_width)
    except ValueError as exc:
        key, _, rest_of = str(exc).partition(":")
        key = "file" if key == "path" else key
        raise SceneError(f"body.{key}:{rest_of}" if key in (*SKIN_KEYS, "rest_positions", "file") else
                         f"body.file: {exc}") from None
