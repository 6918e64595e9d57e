"""Scene files (TOML): what to mesh, which fabric, supports, loads, solver and outputs.

A scene is validated completely before anything is meshed: an unknown section or key, a missing
required key or a value of the wrong type raises SceneError naming it (with a close match for
typos). Units are SI. Example (scenes/rollup.toml):

    [mesh]
    type = "plate"            # plate | tube
    lx = 0.3
    ly = 0.03
    nx = 60
    ny = 3
    cell = "quadrilateral"

    [fabric]
    E1 = 5e6                  # Pa
    E2 = 3e6
    G12 = 2e5
    nu12 = 0.0
    thickness = 5e-4          # m
    density = 600.0           # kg/m^3

    [[support]]
    edge = "left"
    u = [0, 0, 0]             # m, "free" leaves a component free
    theta = [0, 0]            # rad

    [[load]]
    type = "edge_moment"      # gravity | body_force | edge_traction | pressure | edge_moment | point
    edge = "right"
    value = [0.0, -1.09e-3]   # N m/m

    [solver]
    targets = [0.25, 0.5, 0.75, 1.0]
    initial_step = 0.05

    [output]
    dir = "results/rollup"
    probe = [0.3, 0.0, 0.0]   # a node whose displacement is reported
"""
from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SCHEMA: dict[str, dict[str, tuple[type | tuple, bool]]] = {
    # section -> key -> (type(s), required)
    "scene": {"name": (str, False), "description": (str, False)},
    "mesh": {"type": (str, True), "lx": ((int, float), False), "ly": ((int, float), False),
             "nx": (int, False), "ny": (int, False), "cell": (str, False), "structured": (bool, False),
             "length": ((int, float), False), "radius": ((int, float), False), "n_around": (int, False),
             "n_along": (int, False), "order": (int, False)},
    "fabric": {"name": (str, False), "E1": ((int, float), True), "E2": ((int, float), True),
               "G12": ((int, float), True), "nu12": ((int, float), True), "thickness": ((int, float), True),
               "density": ((int, float), False), "G13": ((int, float), False),
               "bending_rigidity": (list, False), "bending_law": (str, False),
               "kawabata_coefficients": (list, False), "B0": ((int, float), False),
               "kappa0": ((int, float), False)},
    "model": {"kind": (str, False), "rebase": (bool, False)},
    "support": {"edge": (str, True), "u": (list, False), "theta": (list, False)},
    "load": {"type": (str, True), "edge": (str, False), "value": ((list, int, float), False),
             "point": (list, False)},
    "solver": {"targets": ((list, int, float), True), "initial_step": ((int, float), False),
               "min_step": ((int, float), False), "petsc_options": (dict, False)},
    "output": {"dir": (str, False), "probe": (list, False), "render": (bool, False)},
}
LIST_SECTIONS = {"support", "load"}
REQUIRED_SECTIONS = {"mesh", "fabric", "solver"}
MESH_KEYS = {"plate": {"lx", "ly", "nx", "ny"}, "tube": {"length", "radius", "n_around", "n_along"}}
LOAD_TYPES = {"gravity", "body_force", "edge_traction", "pressure", "edge_moment", "point"}


class SceneError(ValueError):
    """A scene file that cannot be run; the message names the offending key."""


def _suggest(name: str, options) -> str:
    close = difflib.get_close_matches(name, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _check_table(section: str, table: dict, where: str):
    schema = SCHEMA[section]
    for key, value in table.items():
        if key not in schema:
            raise SceneError(f"{where}: unknown key {key!r}{_suggest(key, schema)}; allowed: {sorted(schema)}")
        types, _ = schema[key]
        if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)):
            raise SceneError(f"{where}.{key}: expected {types}, got a boolean")
        if not isinstance(value, types):
            raise SceneError(f"{where}.{key}: expected {getattr(types, '__name__', types)}, got {value!r}")
    for key, (_, required) in schema.items():
        if required and key not in table:
            raise SceneError(f"{where}: missing required key {key!r}")


@dataclass
class Scene:
    data: dict[str, Any]
    path: Path | None = None

    def __getitem__(self, key):
        return self.data[key]

    def get(self, key, default=None):
        return self.data.get(key, default)


def validate(data: dict, source: str = "scene") -> Scene:
    """Check sections, keys, types and cross-references; raise SceneError naming the problem."""
    for section in data:
        if section not in SCHEMA:
            raise SceneError(f"{source}: unknown section [{section}]{_suggest(section, SCHEMA)}; "
                             f"allowed: {sorted(SCHEMA)}")
    for section in REQUIRED_SECTIONS:
        if section not in data:
            raise SceneError(f"{source}: missing section [{section}]")
    for section, content in data.items():
        if section in LIST_SECTIONS:
            if not isinstance(content, list):
                raise SceneError(f"{source}: [{section}] must be an array of tables: write [[{section}]]")
            for i, table in enumerate(content):
                _check_table(section, table, f"{section}[{i}]")
        else:
            if not isinstance(content, dict):
                raise SceneError(f"{source}: [{section}] must be a table")
            _check_table(section, content, section)
    mesh = data["mesh"]
    if mesh["type"] not in MESH_KEYS:
        raise SceneError(f"mesh.type: unknown mesh {mesh['type']!r}{_suggest(mesh['type'], MESH_KEYS)}; "
                         f"allowed: {sorted(MESH_KEYS)}")
    missing = MESH_KEYS[mesh["type"]] - set(mesh)
    if missing:
        raise SceneError(f"mesh: a {mesh['type']} needs {sorted(missing)}")
    for i, load in enumerate(data.get("load", [])):
        if load["type"] not in LOAD_TYPES:
            raise SceneError(f"load[{i}].type: unknown load {load['type']!r}{_suggest(load['type'], LOAD_TYPES)}")
    return Scene(data)


def load(path: str | Path) -> Scene:
    path = Path(path)
    if not path.exists():
        raise SceneError(f"scene file {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None
    scene = validate(data, str(path))
    scene.path = path
    return scene
