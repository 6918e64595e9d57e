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

A sleeve scene (scenes/sleeve.toml, run by fabricfem.sleeve) has a tube [mesh], a [fabric], no
[solver] and no [[support]] (the shoulder end end0 is held), and three more sections:

    [body]
    type = "default_arm"          # upper arm + forearm ellipsoids (fabricfem.body.default_arm)
    upper_arm_girth = 0.35        # m, optional (also forearm_girth, upper_arm_length, forearm_length);
                                  # girth / (2 pi) must stay below mesh.radius
    [motion]
    type = "elbow_flexion"
    final_angle = 57.0            # deg, in (0, 180)
    angular_velocity = 45.0       # deg/s
    steps = 19                    # quasi-static angle steps
    [contact]
    method = "penalty"            # penalty | augmented
    friction = 0.1                # Coulomb mu >= 0
    penalty = 1e7                 # Pa/m, optional (default 10 E t / h^2)
    stabilization = 0.01          # viscous regularisation c / (E t / R^2), optional
    gravity = false               # sleeve weight along -y

[output] may add render_angles = [19.0, 38.0, 57.0] (deg) and body_samples (points per ellipsoid ring).
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
    "output": {"dir": (str, False), "probe": (list, False), "render": (bool, False),
               "render_angles": (list, False), "body_samples": (int, False)},
    # sleeve scenes (fabricfem.sleeve): the wearer, its motion and the contact
    "body": {"type": (str, True), "upper_arm_length": ((int, float), False), "forearm_length": ((int, float), False),
             "upper_arm_girth": ((int, float), False), "forearm_girth": ((int, float), False)},
    "motion": {"type": (str, True), "final_angle": ((int, float), False), "angular_velocity": ((int, float), False),
               "steps": (int, False)},
    "contact": {"method": (str, False), "friction": ((int, float), False), "penalty": ((int, float), False),
                "stabilization": ((int, float), False), "gravity": (bool, False)},
}
LIST_SECTIONS = {"support", "load"}
REQUIRED_SECTIONS = {"mesh", "fabric", "solver"}
SLEEVE_SECTIONS = {"body", "motion", "contact"}     # a scene with any of them is a sleeve scene
BODY_TYPES = {"default_arm"}
MOTION_TYPES = {"elbow_flexion"}
CONTACT_METHODS = {"penalty", "augmented"}
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
    sleeve = bool(SLEEVE_SECTIONS & set(data))
    required = (REQUIRED_SECTIONS - {"solver"}) | SLEEVE_SECTIONS if sleeve else REQUIRED_SECTIONS
    for section in sorted(required):
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
    if sleeve:
        _check_sleeve(data)
    return Scene(data)


def _positive(where: str, value) -> None:
    if not value > 0:
        raise SceneError(f"{where}: must be positive, got {value!r}")


def _check_sleeve(data: dict) -> None:
    """Sleeve scenes: a tube, a known body and motion, non-negative friction, and an arm that fits inside
    the sleeve (largest segment radius girth / (2 pi) below mesh.radius)."""
    import math
    mesh, body, motion, contact = data["mesh"], data["body"], data["motion"], data["contact"]
    if mesh["type"] != "tube":
        raise SceneError(f"mesh.type: a sleeve scene needs a 'tube' mesh, got {mesh['type']!r}")
    if body["type"] not in BODY_TYPES:
        raise SceneError(f"body.type: unknown body {body['type']!r}{_suggest(body['type'], BODY_TYPES)}; "
                         f"allowed: {sorted(BODY_TYPES)}")
    if motion["type"] not in MOTION_TYPES:
        raise SceneError(f"motion.type: unknown motion {motion['type']!r}{_suggest(motion['type'], MOTION_TYPES)}; "
                         f"allowed: {sorted(MOTION_TYPES)}")
    method = contact.get("method", "penalty")
    if method not in CONTACT_METHODS:
        raise SceneError(f"contact.method: unknown method {method!r}{_suggest(method, CONTACT_METHODS)}; "
                         f"allowed: {sorted(CONTACT_METHODS)}")
    friction = contact.get("friction", 0.1)
    if not (math.isfinite(friction) and friction >= 0.0):
        raise SceneError(f"contact.friction: the Coulomb coefficient must be >= 0, got {friction!r}")
    for key in ("penalty", "stabilization"):
        if key in contact:
            _positive(f"contact.{key}", contact[key])
    for key in ("length", "radius"):
        _positive(f"mesh.{key}", mesh[key])
    for key in ("upper_arm_length", "forearm_length", "upper_arm_girth", "forearm_girth"):
        if key in body:
            _positive(f"body.{key}", body[key])
    if "final_angle" in motion and not 0 < motion["final_angle"] < 180:
        raise SceneError(f"motion.final_angle: must lie in (0, 180) degrees, got {motion['final_angle']!r}")
    for key in ("angular_velocity", "steps"):
        if key in motion:
            _positive(f"motion.{key}", motion[key])
    from fabricfem.body.arm import DEFAULT_ARM
    for key in ("upper_arm_girth", "forearm_girth"):
        girth = body.get(key, getattr(DEFAULT_ARM, key))
        if girth / (2.0 * math.pi) >= mesh["radius"]:
            raise SceneError(f"body.{key}: an arm of girth {girth} m (radius {girth / (2 * math.pi):.4f} m) does not "
                             f"fit inside a sleeve of mesh.radius {mesh['radius']} m; the arm must start inside "
                             f"the sleeve without penetration")


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
