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
    value = [0.0, -1.09e-3, 0.0]   # N m/m, a moment vector (x, y, z)

    [solver]
    targets = [0.25, 0.5, 0.75, 1.0]
    initial_step = 0.05

    [output]
    dir = "results/rollup"
    probe = [0.3, 0.0, 0.0]   # a node whose displacement is reported

Every scene names its kind: `[scene] kind = "static" | "dynamic" | "wear"` (a missing kind is refused naming
it). A wear scene (a garment on a moving wearer, fabricfem.scenes.wear) has its own sections; the older sleeve and
compression layouts are refused with every moved key in one message (fabricfem.scenes.legacy).

A support may name a mesh node instead of an edge: point = [x, y, z] (m, a node within 1e-8 m).

A dynamic scene (scenes/cantilever_vibration.toml, scenes/corner_pinned.toml) has a [dynamics] section
instead of [solver]; it starts from rest in the reference configuration with the loads applied at once
(or ramped linearly over ramp_time) and needs fabric.density > 0:

    [dynamics]
    integrator = "newmark"        # newmark | explicit | generalized-alpha (fabricfem.dynamics.ts)
    dt = 1e-3                     # s, or "auto" (explicit only): dt_fraction x the critical step
    end_time = 0.5                # s; the step is shortened to end_time / ceil(end_time / dt)
    dt_fraction = 0.9             # optional, for dt = "auto", in (0, 1]
    force = false                 # explicit: allow dt above the critical step (refused otherwise)
    beta = 0.25                   # newmark only (default trapezoidal); gamma = 0.5
    rho_inf = 1.0                 # generalized-alpha only: spectral radius at infinite step, in [0, 1]
    lumped = false                # lumped mass (newmark / generalized-alpha; explicit is always lumped)
    rayleigh = [0.0, 0.0]         # C = a M + b K: a [1/s], b [s]
    air_drag = 0.0                # eta [kg/(m^2 s)], drag force -eta v per unit area
    strain_limit = 0.01           # optional: max warp/weft Green strain (fast projection, [Peng2022, sec. 3])
    strain_limit_tol = 1e-4       # optional: projection tolerance [-]
    gravity = [0.0, 0.0, -9.81]   # optional, m/s^2 (same as a [[load]] of type "gravity": give one)
    ramp_time = 0.0               # optional, s: load factor min(t / ramp_time, 1)
    output_every = 10             # record CSV / XDMF every N steps (and at 0 and the end)
    contact_penalty = 1e5         # optional, Pa/m, for the obstacles (default 10 E t / h^2)

    [[dynamics.obstacles]]        # rigid, fixed; penalty contact (fabricfem.contact.obstacles)
    type = "plane"                # plane: point, normal | box: lower, upper, radius (bounds may be
    point = [0.0, 0.0, -0.1]      #   inf) | table: center = [cx, cy], half_x, half_y, height, fillet_radius
    normal = [0.0, 0.0, 1.0]

    [[dynamics.monitors]]         # columns of the CSV (and panels of the PNG)
    name = "tip_w"
    point = [0.2, 0.0, 0.0]       # a mesh node; field = "u" (m) | "theta" (rad), component 0, 1, 2
    field = "u"
    component = 2
    [[dynamics.monitors]]
    name = "warp"
    quantity = "max_warp_strain"  # max_warp_strain | max_weft_strain | mean_warp_strain | mean_weft_strain
                                  # | max_displacement (m)

Besides the user's monitors the CSV has the energies (kinetic, strain, external work, dissipated [J]) and
the max vertex Green strain. For the explicit integrator a numeric dt above the critical time step
(fabricfem.dynamics.stability: estimated from the mesh spacing before meshing, structured meshes) is refused
with both numbers unless force = true.
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fabricfem.parameters import param_doc
from fabricfem.scenes import wear as wear_module
from fabricfem.scenes.contract import LIST_SECTIONS, REQUIRED_OF, SECTIONS_OF, TABLE_OR_LIST, parse
from fabricfem.scenes.errors import SceneError
from fabricfem.scenes.errors import suggest as _suggest
from fabricfem.scenes.legacy import is_old_layout, old_layout_message
from fabricfem.scenes.sections import (
    schema_of,
)
from fabricfem.scenes.wear import check_wear


def section_schema(kind: str, name: str) -> dict[str, tuple[type | tuple, bool]]:
    """{key: (TOML types, required)} of section `name` of a `kind` scene, from its dataclasses (SECTIONS_OF)."""
    schema: dict = {}
    for cls in SECTIONS_OF[kind][name]:
        schema.update({k: v for k, v in schema_of(cls).items() if k not in schema})
    return schema


# kind -> section -> key -> (TOML types, required): the one schema of every scene file
SCHEMA = {kind: {name: section_schema(kind, name) for name in sections} for kind, sections in SECTIONS_OF.items()}


def _section_table(title: str, classes: tuple, typed: str | None = None) -> list[str]:
    """The markdown table of one section: each key of `classes` with its type, default and meaning."""
    lines = [f"## {title}", "", " ".join((classes[0].__doc__ or "").split()), "",
             "| key | type | default | meaning |", "|---|---|---|---|"]
    if typed:
        lines.append(f"| type | str | required | {typed} |")
    seen = set()
    for cls in classes:
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if f.name in seen or f.name.startswith("_"):
                continue
            seen.add(f.name)
            if f.default is not dataclasses.MISSING:
                default = "none" if f.default is None else repr(f.default)
            elif f.default_factory is not dataclasses.MISSING:
                default = repr(f.default_factory())
            else:
                default = "required"
            kind = str(hints[f.name]).replace("typing.", "").replace("<class '", "").replace("'>", "")
            kind = kind.replace(" | None", "").replace("|", "or")
            meaning = param_doc(f).replace("|", "\\|")
            lines.append(f"| {f.name} | {kind} | {default} | {meaning} |")
    return lines + [""]


def reference_markdown() -> str:
    """The scene-file reference (docs/scenes.md): per section, each key with its type, default and meaning, read
    from the section dataclasses; the wear kind's sections (fabricfem.scenes.wear) after the others."""
    lines = ["# Scene files: the reference", "",
             "Generated by `fabricfem scenes --markdown docs/scenes.md` from the section dataclasses "
             "(fabricfem/scenes/sections.py, fabricfem/scenes/wear.py, fabricfem/wear/config.py); SI units, angles "
             "in degrees. A scene names its kind in `[scene] kind`: static ([mesh], [fabric], [[support]], [[load]], "
             "[solver]), dynamic ([dynamics] instead of [solver]), wear ([garment], [fabric], [body], [motion], "
             "optional [donning], [contact], [route], [[torque]], [output]: any garment on any moving wearer; "
             "scenes/sleeve.toml, scenes/compression_sleeve.toml, scenes/trousers_standing.toml; several garments "
             "as [[garment]], inside out: scenes/sleeve_layers.toml). The older "
             "sleeve and compression layouts are refused with every moved key in one message.", ""]
    for kind, sections in SECTIONS_OF.items():
        lines += [f"# {kind.capitalize()} scenes (`kind = \"{kind}\"`)", ""]
        if kind == "wear":
            lines += [" ".join((wear_module.__doc__ or "").split()), ""]
        for name, classes in sections.items():
            title = f"[[{name}]]" if name in LIST_SECTIONS or "." in name else f"[{name}]"
            title = f"[{name}] or [[{name}]]" if name in TABLE_OR_LIST else title
            lines += _section_table(title, classes)
    return "\n".join(lines)


INTEGRATORS = {"newmark", "explicit", "generalized-alpha"}
OBSTACLE_KEYS = {"plane": {"point", "normal"}, "box": {"lower", "upper", "radius"},
                 "table": {"center", "half_x", "half_y", "height", "fillet_radius"}}
MONITOR_QUANTITIES = {"max_warp_strain", "max_weft_strain", "mean_warp_strain", "mean_weft_strain",
                      "max_displacement"}
STANDARD_COLUMNS = {"time", "kinetic", "strain", "external_work", "dissipated", "total", "max_strain",
                    "newton_iterations"}
KINDS = tuple(SECTIONS_OF)
CELLS = ("quadrilateral", "triangle")
EDGES = {"plate": ("left", "right", "bottom", "top"), "tube": ("end0", "end1")}   # edge tags of the builders
ALL_NODES = "all"   # a support on every node (e.g. u = ["free", "free", 0]: an in-plane problem)
MESH_KEYS = {"plate": {"lx", "ly", "nx", "ny"}, "tube": {"length", "radius", "n_around", "n_along"}}
LOAD_TYPES = {"gravity", "body_force", "edge_traction", "pressure", "edge_moment", "point"}


def check_table(kind: str, section: str, table, where: str) -> None:
    """Keys and TOML types of one table of a `kind` scene against SCHEMA (SceneError naming the key)."""
    if not isinstance(table, dict):
        raise SceneError(f"{where}: must be a table")
    schema = SCHEMA[kind][section]
    for key, value in table.items():
        if key not in schema:
            raise SceneError(f"{where}: unknown key {key!r}{_suggest(key, schema)}; allowed: {sorted(schema)}")
        types, _ = schema[key]
        accepted = types if isinstance(types, tuple) else (types,)
        if isinstance(value, bool) and bool not in accepted:
            raise SceneError(f"{where}.{key}: expected {getattr(types, '__name__', types)}, got a boolean")
        if not isinstance(value, types):
            raise SceneError(f"{where}.{key}: expected {getattr(types, '__name__', types)}, got {value!r}")
    for key, (_, required) in schema.items():
        if required and key not in table and not (section == "fabric" and "catalogue" in table):
            raise SceneError(f"{where}: missing required key {key!r}")


def check_sections(data: dict, kind: str, source: str) -> None:
    """The sections of a `kind` scene: known names, the required ones, arrays of tables where declared, and each
    table's keys and types (the one validator of every kind's tables)."""
    sections = {name for name in SECTIONS_OF[kind] if "." not in name}
    for name in data:
        if name not in sections:
            raise SceneError(f"{source}: unknown section [{name}] for a {kind} scene{_suggest(name, sections)}; "
                             f"allowed: {sorted(sections)}")
    for name in REQUIRED_OF[kind]:
        if name not in data:
            raise SceneError(f"{source}: missing section [{name}] of a {kind} scene")
    for name, content in data.items():
        if name in LIST_SECTIONS or (name in TABLE_OR_LIST and isinstance(content, list)):
            if not isinstance(content, list):
                raise SceneError(f"{source}: [{name}] must be an array of tables: write [[{name}]]")
            for i, table in enumerate(content):
                check_table(kind, name, table, f"{name}[{i}]")
        else:
            check_table(kind, name, content, name)
    # the arrays inside a section ([[dynamics.obstacles]]) are checked with their section (_array_of_tables)


@dataclass(frozen=True)
class Scene:
    """A validated scene: its TOML data, the file it came from and its kind (static, dynamic, wear); `parsed` is
    the data parsed once into the kind's frozen dataclass of typed sections (fabricfem.scenes.contract)."""

    data: dict[str, Any]
    path: Path | None = None
    kind: str = "static"

    @functools.cached_property
    def parsed(self):
        return parse(self.data, self.kind)

    def __getitem__(self, key):
        return self.data[key]

    def get(self, key, default=None):
        return self.data.get(key, default)


def scene_kind(data: dict, source: str = "scene") -> str:
    """The kind a scene names in [scene] kind (SceneError naming `[scene] kind` when it is missing or unknown, and
    listing every moved key of a file in the older sleeve or compression layout)."""
    if is_old_layout(data):
        raise SceneError(old_layout_message(data, source))
    table = data.get("scene", {})
    kind = table.get("kind") if isinstance(table, dict) else None
    if kind is None:
        raise SceneError(f"{source}: [scene] kind is missing; every scene names its kind: write [scene] kind = "
                         f"\"static\", \"dynamic\" or \"wear\"")
    if kind not in KINDS:
        raise SceneError(f"scene.kind: unknown kind {kind!r}{_suggest(str(kind), KINDS)}; allowed: {list(KINDS)}")
    return kind


def validate(data: dict, source: str = "scene") -> Scene:
    """Check sections, keys, types and cross-references of a scene by its kind; raise SceneError naming the
    problem."""
    kind = scene_kind(data, source)
    if kind != "wear":
        _check_kind_sections(data, kind, source)
    check_sections(data, kind, source)
    _check_verdict_keys(data)
    if kind == "wear":
        check_wear(data)
        check_accuracy(data, "wear")
        return _parsed(Scene(data, kind="wear"))
    _check_mesh(data["mesh"])
    _check_loads_and_supports(data)
    if data.get("output", {}).get("probe") is not None:
        _numbers("output.probe", data["output"]["probe"], 3)
    for key in ("E1", "E2", "G12", "nu12", "thickness", "density", "G13"):
        if key in data["fabric"]:
            _finite(f"fabric.{key}", data["fabric"][key])
    if kind == "dynamic":
        _check_dynamics(data)
    check_accuracy(data, kind)
    return _parsed(Scene(data, kind=kind))


def _parsed(scene: Scene) -> Scene:
    """The scene with its sections parsed (a value a section's dataclass refuses raises SceneError now)."""
    scene.parsed
    return scene


def _check_kind_sections(data: dict, kind: str, source: str) -> None:
    """A static scene has no [dynamics] and a dynamic one no [solver]: the sections must match the kind."""
    if "dynamics" in data and "solver" in data:
        raise SceneError(f"{source}: [dynamics] and [solver] given: a scene is either dynamic (time integration "
                         f"from rest) or static, not both")
    other = {"static": "dynamics", "dynamic": "solver"}[kind]
    if other in data:
        raise SceneError(f"scene.kind: {kind!r} does not match the sections given: [{other}] belongs to a "
                         f"{'dynamic' if other == 'dynamics' else 'static'} scene")


def _check_mesh(mesh: dict) -> None:
    """A known mesh type with its keys, finite and positive, and a known cell."""
    if mesh["type"] not in MESH_KEYS:
        raise SceneError(f"mesh.type: unknown mesh {mesh['type']!r}{_suggest(mesh['type'], MESH_KEYS)}; "
                         f"allowed: {sorted(MESH_KEYS)}")
    missing = MESH_KEYS[mesh["type"]] - set(mesh)
    if missing:
        raise SceneError(f"mesh: a {mesh['type']} needs {sorted(missing)}")
    for key in sorted(MESH_KEYS[mesh["type"]]):
        _finite(f"mesh.{key}", mesh[key], 0.0)
    if mesh.get("cell", "quadrilateral") not in CELLS:
        raise SceneError(f"mesh.cell: unknown cell {mesh['cell']!r}{_suggest(mesh['cell'], CELLS)}; allowed: {CELLS}")


def _check_loads_and_supports(data: dict) -> None:
    """Load types, values, points and edges; supports by edge or point with their components."""
    mesh = data["mesh"]
    edges = EDGES[mesh["type"]]
    for i, load in enumerate(data.get("load", [])):
        if load["type"] not in LOAD_TYPES:
            raise SceneError(f"load[{i}].type: unknown load {load['type']!r}{_suggest(load['type'], LOAD_TYPES)}")
        if "value" in load:
            value = load["value"]
            _numbers(f"load[{i}].value", value if isinstance(value, list) else [value])
        if "point" in load:
            _numbers(f"load[{i}].point", load["point"], 3)
        if "edge" in load and load["edge"] not in edges:
            raise SceneError(f"load[{i}].edge: a {mesh['type']} has no edge {load['edge']!r}"
                             f"{_suggest(load['edge'], edges)}; edges: {list(edges)}")
    for i, support in enumerate(data.get("support", [])):
        if ("edge" in support) == ("point" in support):
            raise SceneError(f"support[{i}]: give exactly one of 'edge' (an edge name) or 'point' = [x, y, z]")
        if "point" in support:
            _numbers(f"support[{i}].point", support["point"], 3)
        for key, n in (("u", 3), ("theta", 2)):
            if key in support:
                values = support[key]
                if not isinstance(values, list) or len(values) != n:
                    raise SceneError(f"support[{i}].{key}: expected {n} components (numbers or \"free\"), "
                                     f"got {values!r}")
                _numbers(f"support[{i}].{key}", [0.0 if v == "free" else v for v in values], n)
        if "edge" in support and support["edge"] not in (*edges, ALL_NODES):
            raise SceneError(f"support[{i}].edge: a {mesh['type']} has no edge {support['edge']!r}"
                             f"{_suggest(support['edge'], (*edges, ALL_NODES))}; edges: {[*edges, ALL_NODES]}")


ACCURACY_KINDS = ("static", "dynamic", "wear")
WEAR_ONLY_ACCURACY_KEYS = ("window", "ratio")


def check_accuracy(data: dict, kind: str) -> None:
    """The [accuracy] section of a scene of `kind` (target, quantity, finer_levels; a wear scene's window and
    ratio are checked by fabricfem.scenes.wear.check_wear); SceneError naming the key."""
    if "accuracy" not in data:
        return
    if kind not in ACCURACY_KINDS:
        raise SceneError(f"accuracy: an accuracy target is for {', '.join(ACCURACY_KINDS)} scenes, not {kind!r} ones")
    accuracy = data["accuracy"]
    if kind != "wear" and (keys := [k for k in WEAR_ONLY_ACCURACY_KEYS if k in accuracy]):
        raise SceneError(f"accuracy.{keys[0]}: a key of wear scenes' accuracy levels, not of {kind} scenes")
    if "target" in accuracy:
        check_target("accuracy.target", accuracy["target"])
    if "quantity" in accuracy:
        accuracy_summary_key(data, accuracy["quantity"])
    if accuracy.get("finer_levels", 0) < 0:
        raise SceneError(f"accuracy.finer_levels: must be >= 0, got {accuracy['finer_levels']!r}")


def check_target(where: str, target) -> float:
    """A relative error target in (0, 1), or SceneError naming `where`."""
    if isinstance(target, bool) or not isinstance(target, (int, float)) or not 0.0 < target < 1.0:
        raise SceneError(f"{where}: a relative error target must lie in (0, 1) (e.g. 0.02 or 2%), got {target!r}")
    return float(target)


def accuracy_quantities(data: dict) -> dict[str, str]:
    """{quantity name: its summary.json key} that an accuracy target may name (AccuracySection.quantity; a dotted
    key names a nested entry of a wear run's summary, fabricfem.scenes.wear.wear_quantities)."""
    if data.get("scene", {}).get("kind") == "wear":
        return wear_module.wear_quantities(data)
    if "dynamics" in data:
        names = {m["name"]: f"final_{m['name']}" for m in data["dynamics"].get("monitors", [])}
        return {**names, **{k: k for k in ("kinetic_J", "strain_J", "max_strain_final")}}
    if data.get("output", {}).get("probe") is None:
        return {}
    return {f"probe_u{c}_m": f"probe_u{c}_m" for c in "xyz"}


def accuracy_summary_key(data: dict, quantity: str) -> str:
    """The summary.json key of an accuracy quantity; SceneError naming it when the scene does not monitor it."""
    allowed = accuracy_quantities(data)
    if quantity not in allowed:
        hint = "" if allowed else (" (a wear scene: the explicit engine or the compression route)"
                                   if "garment" in data else " (a static scene needs output.probe)")
        raise SceneError(f"accuracy.quantity: {quantity!r} is not a monitored output of this scene"
                         f"{_suggest(str(quantity), allowed)}; allowed: {sorted(allowed)}{hint}")
    return allowed[quantity]


def _numbers(where: str, values, n: int | None = None, allow_inf: bool = False) -> list[float]:
    """A list of (n) real numbers (finite unless allow_inf), or SceneError naming `where`."""
    if not isinstance(values, list) or (n is not None and len(values) != n):
        raise SceneError(f"{where}: expected a list of {n if n is not None else ''} numbers, got {values!r}")
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or \
                (not allow_inf and not math.isfinite(v)):
            raise SceneError(f"{where}: expected {'' if allow_inf else 'finite '}numbers, got {values!r}")
    return [float(v) for v in values]


def _check_verdict_keys(data: dict) -> None:
    """[fabric] failure_strain (a positive finite Green strain), [output] windows ([[a, b], ...] with a < b) and
    sensor_diameter (a positive length [m]): the bounds, windows and sensor of a run's verdict and statistics."""
    if "failure_strain" in data.get("fabric", {}):
        _finite("fabric.failure_strain", data["fabric"]["failure_strain"], 0.0)
    if "sensor_diameter" in data.get("output", {}):
        _finite("output.sensor_diameter", data["output"]["sensor_diameter"], 0.0)
    for i, window in enumerate(data.get("output", {}).get("windows") or []):
        a, b = _numbers(f"output.windows[{i}]", window, 2)
        if not a < b:
            raise SceneError(f"output.windows[{i}]: a window [a, b] needs a < b, got {window!r}")


def _finite(where: str, value, minimum: float | None = None, strict: bool = True) -> float:
    if not math.isfinite(value):
        raise SceneError(f"{where}: must be finite, got {value!r}")
    if minimum is not None and (value <= minimum if strict else value < minimum):
        raise SceneError(f"{where}: must be {'>' if strict else '>='} {minimum:g}, got {value!r}")
    return float(value)


def _check_dynamics(data: dict) -> None:
    """[dynamics]: integrator, positive times, damping >= 0, obstacles and monitors complete, and for the
    explicit integrator a numeric dt at most the critical time step unless force = true."""
    dyn = data["dynamics"]
    integrator = dyn["integrator"]
    if integrator not in INTEGRATORS:
        raise SceneError(f"dynamics.integrator: unknown integrator {integrator!r}{_suggest(integrator, INTEGRATORS)}; "
                         f"allowed: {sorted(INTEGRATORS)}")
    if integrator == "generalized-alpha" and importlib.util.find_spec("fabricfem.dynamics.ts") is None:
        raise SceneError("dynamics.integrator: 'generalized-alpha' needs fabricfem.dynamics.ts "
                         "(GeneralizedAlphaIntegrator), which is not installed yet; use 'newmark'")
    explicit = integrator == "explicit"
    density = data["fabric"].get("density", 0.0)
    if not (isinstance(density, (int, float)) and density > 0):
        raise SceneError(f"fabric.density: a dynamic scene needs a positive density [kg/m^3], got {density!r}")
    end_time = _finite("dynamics.end_time", dyn["end_time"], 0.0)
    dt = dyn["dt"]
    if isinstance(dt, str):
        if dt != "auto":
            raise SceneError(f"dynamics.dt: a time step in seconds or \"auto\", got {dt!r}")
        if not explicit:
            raise SceneError(f"dynamics.dt: \"auto\" (a fraction of the critical step) is for the explicit "
                             f"integrator; give {integrator!r} a time step in seconds")
    else:
        dt = _finite("dynamics.dt", dt, 0.0)
        if dt > end_time:
            raise SceneError(f"dynamics.dt: the time step {dt:g} s exceeds dynamics.end_time = {end_time:g} s")
    if "dt_fraction" in dyn:
        fraction = _finite("dynamics.dt_fraction", dyn["dt_fraction"], 0.0)
        if fraction > 1.0 or dyn["dt"] != "auto":
            raise SceneError(f"dynamics.dt_fraction: in (0, 1] and only with dt = \"auto\", got {fraction!r} "
                             f"(dt = {dyn['dt']!r})")
    for key, allowed in (("force", explicit), ("beta", integrator == "newmark"), ("gamma", integrator == "newmark"),
                         ("lumped", not explicit), ("rho_inf", integrator == "generalized-alpha")):
        if key in dyn and not allowed:
            raise SceneError(f"dynamics.{key}: not a parameter of the {integrator!r} integrator"
                             + (" (it always uses the lumped mass)" if key == "lumped" else ""))
    for key in ("beta", "gamma"):
        if key in dyn:
            _finite(f"dynamics.{key}", dyn[key], 0.0)
    if "rho_inf" in dyn and not 0.0 <= dyn["rho_inf"] <= 1.0:
        raise SceneError(f"dynamics.rho_inf: the spectral radius at infinite step must lie in [0, 1], got "
                         f"{dyn['rho_inf']!r}")
    if "rayleigh" in dyn:
        for i, c in enumerate(_numbers("dynamics.rayleigh", dyn["rayleigh"], 2)):
            _finite(f"dynamics.rayleigh[{i}]", c, 0.0, strict=False)
    for key in ("air_drag", "ramp_time"):
        if key in dyn:
            _finite(f"dynamics.{key}", dyn[key], 0.0, strict=False)
    for key in ("strain_limit", "strain_limit_tol", "contact_penalty"):
        if key in dyn:
            _finite(f"dynamics.{key}", dyn[key], 0.0)
    if "strain_limit_tol" in dyn and "strain_limit" not in dyn:
        raise SceneError("dynamics.strain_limit_tol: given without dynamics.strain_limit")
    if "output_every" in dyn and dyn["output_every"] < 1:
        raise SceneError(f"dynamics.output_every: must be a positive number of steps, got {dyn['output_every']!r}")
    if "gravity" in dyn:
        _numbers("dynamics.gravity", dyn["gravity"], 3)
        if any(load["type"] == "gravity" for load in data.get("load", [])):
            raise SceneError("dynamics.gravity: gravity is also a [[load]] of type 'gravity'; give it once")
    _check_obstacles(dyn)
    _check_monitors(data)


def _array_of_tables(dyn: dict, key: str) -> list[tuple[str, dict]]:
    """[(location, table)] of the array of tables dynamics.<key>, each checked against its schema."""
    items = dyn.get(key, [])
    if not isinstance(items, list):
        raise SceneError(f"dynamics.{key}: must be an array of tables: write [[dynamics.{key}]]")
    checked = []
    for i, item in enumerate(items):
        where = f"dynamics.{key}[{i}]"
        if not isinstance(item, dict):
            raise SceneError(f"{where}: must be a table: write [[dynamics.{key}]]")
        check_table("dynamic", f"dynamics.{key}", item, where)
        checked.append((where, item))
    return checked


def _check_obstacles(dyn: dict) -> None:
    for where, obstacle in _array_of_tables(dyn, "obstacles"):
        kind = obstacle["type"]
        if kind not in OBSTACLE_KEYS:
            raise SceneError(f"{where}.type: unknown obstacle {kind!r}{_suggest(kind, OBSTACLE_KEYS)}; "
                             f"allowed: {sorted(OBSTACLE_KEYS)}")
        keys = set(obstacle) - {"type"}
        if keys != OBSTACLE_KEYS[kind]:
            missing, extra = OBSTACLE_KEYS[kind] - keys, keys - OBSTACLE_KEYS[kind]
            raise SceneError(f"{where}: a {kind} needs {sorted(OBSTACLE_KEYS[kind])}"
                             + (f"; missing {sorted(missing)}" if missing else "")
                             + (f"; {sorted(extra)} do not apply" if extra else ""))
        for key in ("point", "normal"):
            if key in obstacle:
                _numbers(f"{where}.{key}", obstacle[key], 3)
        for key in ("lower", "upper"):
            if key in obstacle:
                _numbers(f"{where}.{key}", obstacle[key], 3, allow_inf=True)
        if "center" in obstacle:
            _numbers(f"{where}.center", obstacle["center"], 2)
        for key in ("radius", "half_x", "half_y", "fillet_radius"):
            if key in obstacle:
                _finite(f"{where}.{key}", obstacle[key], 0.0)
        if "height" in obstacle:
            _finite(f"{where}.height", obstacle["height"])


def _check_monitors(data: dict) -> None:
    names = set()
    naghdi = data.get("model", {}).get("kind", "naghdi") == "naghdi"
    for where, monitor in _array_of_tables(data["dynamics"], "monitors"):
        name = monitor["name"]
        if name in names or name in STANDARD_COLUMNS:
            raise SceneError(f"{where}.name: {name!r} is already a column of the CSV")
        names.add(name)
        if ("point" in monitor) == ("quantity" in monitor):
            raise SceneError(f"{where}: give exactly one of 'point' = [x, y, z] or 'quantity'")
        if "quantity" in monitor:
            quantity = monitor["quantity"]
            if quantity not in MONITOR_QUANTITIES:
                raise SceneError(f"{where}.quantity: unknown quantity {quantity!r}"
                                 f"{_suggest(quantity, MONITOR_QUANTITIES)}; allowed: {sorted(MONITOR_QUANTITIES)}")
            for key in ("field", "component"):
                if key in monitor:
                    raise SceneError(f"{where}.{key}: only for point monitors")
            continue
        _numbers(f"{where}.point", monitor["point"], 3)
        field = monitor.get("field", "u")
        if field not in ("u", "theta"):
            raise SceneError(f"{where}.field: 'u' (displacement, m) or 'theta' (rotation, rad), got {field!r}")
        if field == "theta" and not naghdi:
            raise SceneError(f"{where}.field: 'theta' needs the naghdi model (the membrane has no rotations)")
        n = 3 if field == "u" else 2
        component = monitor.get("component", 2 if field == "u" else 0)
        if not 0 <= component < n:
            raise SceneError(f"{where}.component: {field} has components 0..{n - 1}, got {component!r}")


def load(path: str | Path) -> Scene:
    """Read and validate the data of a scene file (checks that need objects: fabricfem.scenes.build.load)."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"scene file {str(path)!r} does not exist or is not a file")
    try:
        data = tomllib.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file (a scene is a TOML text file)") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None
    return dataclasses.replace(validate(data, str(path)), path=path)
