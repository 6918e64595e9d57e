"""Wear scenes (`[scene] kind = "wear"`): any garment on any moving wearer, from a scene file.

Sections: [garment] (a tube or a sewing pattern), [fabric] (any fabric: the orthotropic St. Venant-Kirchhoff
keys with optional bending laws, or `catalogue` = a stored fabric of fabricfem.fabrics), [body] (a preset:
arm, lower_body or limb, with its dimensions), [motion] (elbow_flexion, still or a motion-capture file),
[donning], [contact], [route], [[torque]] monitors and [output]. Keys, types, defaults and units are the
fields of the dataclasses below and of fabricfem.wear.config (ContactSpec, RouteSpec, FlexionSpec, TubeSpec),
declared once; `fabricfem scenes` prints them.

Routes: the explicit engine (fabricfem.wear.garment.GarmentRun) runs every wear scene; two scenes keep
their own routes, chosen by [route] solver: the arm in a tube with the elbow flexion by "quasistatic" or
"implicit" (fabricfem.wear.sleeve, the SleeveConfig routes; E1 = E2) and a limb grown into a tube by
"quasistatic" (the compression sleeve, fabricfem.wear.compression).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from fabricfem.body.arm import default_arm
from fabricfem.body.blend import BlendedStart
from fabricfem.body.blended import BLEND_WIDTH
from fabricfem.body.conventions import LENGTH_UNITS
from fabricfem.body.crossing import obstacle_walk
from fabricfem.body.lower_body import lower_body, standing, winter_walking
from fabricfem.body.mocap import load_motion, mapping_sources
from fabricfem.body.placement import Translated, box_distance, placement_offset
from fabricfem.body.pose import Body, check_posable
from fabricfem.body.schedule import SegmentSchedule
from fabricfem.contact.handles import Belt, EdgeGrip
from fabricfem.contact.seams import SeamSpec
from fabricfem.dynamics.stability import step_safety
from fabricfem.fabrics import load_fabric
from fabricfem.meshes import tube
from fabricfem.meshes.pattern import (
    check_held_stitches,
    check_pattern,
    outline_polyline,
    read_garmentcode,
    read_pattern_toml,
)
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.patterns import pattern_path
from fabricfem.scenes.contract import WearScene
from fabricfem.scenes.errors import SceneError, finite_vector
from fabricfem.scenes.errors import suggest as _suggest
from fabricfem.scenes.garments import check_layers, first_garment, garment_tables, layered_garment_mesh
from fabricfem.scenes.mesh_body import check_mesh_keys, scene_skin
from fabricfem.scenes.panel_placement import check_wrap, panel_placements
from fabricfem.scenes.wear_sections import GarmentSection, WearDonningSection, WearMotionSection
from fabricfem.wear.compression import StillPose, limb_body
from fabricfem.wear.config import ROUTE_METHODS, ContactSpec
from fabricfem.wear.garment import ExplicitSettings, Timeline, TorqueSpec
from fabricfem.wear.sleeve import ARM_MONITORS, flexion_settings, flexion_timeline, similarity_factor

GRAVITY = 9.81                     # m/s^2
BODY_TYPES = ("arm", "default_arm", "limb", "lower_body", "mesh")
MOTION_TYPES = ("elbow_flexion", "still", "walking", "obstacle_walk", "file")
PLACES = ("garment",)
BUILDERS = ("tube", "pattern")


def _choice(where: str, value, options) -> None:
    if value not in options:
        raise SceneError(f"{where}: unknown {value!r}{_suggest(str(value), options)}; allowed: {list(options)}")


def is_tube_flexion(data: dict) -> bool:
    """An arm in a tube sleeve flexing at the elbow (the sleeve of [Man2006, sec. 5.3]; its routes: ROUTES)."""
    return (first_garment(data).get("builder", "pattern") == "tube" and data["body"]["type"] in ("arm", "default_arm")
            and data["motion"]["type"] == "elbow_flexion")


def route_of(data: dict) -> str:
    """The [route] solver: "explicit" (the engine, every wear scene) or the tube sleeve's Newton routes
    "quasistatic" and "implicit" (SceneError naming route.solver for any other scene)."""
    solver = data.get("route", {}).get("solver", "explicit")
    if solver != "explicit" and not is_tube_flexion(data):
        raise SceneError(f"route.solver: {solver!r} runs the arm in a tube sleeve flexing at the elbow; this scene "
                         f"runs on the explicit engine (route.solver = \"explicit\")")
    return solver


def _check_self_contact(contact: dict, garment: dict, solver: str) -> None:
    """[contact] self_contact on the explicit engine only; self_contact_distance in (0, mesh size] (the tube's
    sqrt(2 pi R L / (n_around n_along)), the pattern's element size h [m], as fabricfem.contact.nodal measures it)."""
    if contact.get("self_contact") and solver != "explicit":
        raise SceneError(f"contact.self_contact: the cloth's contact with itself runs on the explicit engine "
                         f"(route.solver = \"explicit\"), not the {solver} route")
    distance = contact.get("self_contact_distance")
    if distance is None:
        return
    if isinstance(distance, bool) or not (isinstance(distance, (int, float)) and math.isfinite(distance)
                                          and distance > 0.0):
        raise SceneError(f"contact.self_contact_distance: must be a positive length [m], got {distance!r}")
    if garment.get("builder", "pattern") == "tube":
        size = math.sqrt(2.0 * math.pi * garment["radius"] * garment["length"]
                         / (garment["n_around"] * garment["n_along"]))
    else:
        size = garment.get("h", GarmentSection.h)
    if distance > size:
        raise SceneError(f"contact.self_contact_distance: {distance:g} m exceeds the mesh size {size:g} m")


def check_wear(data: dict) -> None:
    """The data checks of a wear scene beyond its tables' keys and types (fabricfem.scenes.schema.check_sections):
    choices, vectors and cross-references, before any meshing."""
    check_layers(data)
    garment, body, motion = first_garment(data), data["body"], data["motion"]
    blend = body.get("blend_width", BLEND_WIDTH)
    if not (isinstance(blend, (int, float)) and math.isfinite(blend) and blend > 0.0):
        raise SceneError(f"body.blend_width: must be a positive length [m], got {blend!r}")
    _choice("garment.builder", garment.get("builder", "pattern"), BUILDERS)
    if garment.get("builder", "pattern") == "tube":
        missing = [k for k in ("length", "radius", "n_around", "n_along") if k not in garment]
        if missing:
            raise SceneError(f"garment: a tube needs {missing}")
    elif "pattern" not in garment:
        raise SceneError("garment.pattern: a pattern garment needs a pattern file or a shipped pattern name")
    for key in ("rotate", "translate"):
        if key in garment:
            finite_vector(f"garment.{key}", garment[key])
    check_wrap(garment)
    _choice("body.type", body["type"], BODY_TYPES)
    if body["type"] == "limb":
        for key in ("center", "radii"):
            if key not in body:
                raise SceneError(f"body.{key}: a limb needs its {key}")
            finite_vector(f"body.{key}", body[key])
        if min(body["radii"]) <= 0:
            raise SceneError(f"body.radii: must be positive, got {body['radii']}")
    if body["type"] == "mesh":
        check_mesh_keys(body)
    segments = body.get("skeleton") if body["type"] == "mesh" else body["type"]
    _choice("motion.type", motion["type"], MOTION_TYPES)
    if motion["type"] == "elbow_flexion" and segments not in ("arm", "default_arm"):
        raise SceneError(f"motion.type: elbow_flexion drives the arm, not a {body['type']!r}")
    solver = data.get("route", {}).get("solver", "explicit")
    method = data.get("contact", {}).get("method")
    if method is not None and solver in ROUTE_METHODS and method not in ROUTE_METHODS[solver]:
        raise SceneError(f"contact.method: method must be one of {ROUTE_METHODS[solver]} for solver {solver!r}, "
                         f"got {method!r}")
    for table in garment_tables(data):        # the contact distance against every garment's mesh size
        _check_self_contact(data.get("contact", {}), table, solver)
    donning = data.get("donning", {})
    _choice("donning.method", donning.get("method", "none"), ("none", "grow"))
    if donning.get("method") == "grow":
        start, time = donning.get("start"), donning.get("time", 0.1)
        if start is None or not (0.0 < start < 1.0):
            raise SceneError(f"donning.start: growing the body starts from a size in (0, 1) of its transverse radii, "
                             f"got {start!r}")
        if not (math.isfinite(time) and time > 0.0):
            raise SceneError(f"donning.time: growing the body needs a growth time > 0 [s], got {time!r}")
    for i, spec in enumerate(data.get("torque", [])):
        finite_vector(f"torque[{i}].axis", spec["axis"])
        if not spec["segments"] or not all(isinstance(s, str) for s in spec["segments"]):
            raise SceneError(f"torque[{i}].segments: a list of segment names, got {spec['segments']!r}")
    route = route_of(data)
    if motion["type"] in ("walking", "obstacle_walk") and segments != "lower_body":
        raise SceneError(f"motion.type: {motion['type']!r} drives the lower body, not a {body['type']!r}")
    if "place" in motion:
        _choice("motion.place", motion["place"], PLACES)
        if route != "explicit":
            raise SceneError(f"motion.place: places the body of the explicit engine (route.solver = \"explicit\"), "
                             f"not of the {route} route")
    end = data.get("route", {}).get("end_time")
    if end is not None and not (math.isfinite(end) and end > 0):
        raise SceneError(f"route.end_time: must be a positive body time [s], got {end!r}")
    if end is not None and route != "explicit":
        raise SceneError("route.end_time: stops a run of the explicit engine (route.solver = \"explicit\"), not of "
                         f"the {route} route")
    accuracy = data.get("accuracy", {})
    if accuracy and route != "explicit":
        raise SceneError("accuracy: an accuracy target runs a wear scene on the explicit engine (route.solver = "
                         "\"explicit\"), not the sleeve's quasistatic or implicit route")
    window, ratio = accuracy.get("window"), accuracy.get("ratio")
    if window is not None and route != "explicit":
        raise SceneError(f"accuracy.window: the {route} route is quasi-static (no body time to cut); leave it out")
    if window is not None and not (math.isfinite(window) and window > 0):
        raise SceneError(f"accuracy.window: must be a positive body time [s], got {window!r}")
    if ratio is not None and not (math.isfinite(ratio) and 1.0 < ratio <= 4.0):
        raise SceneError(f"accuracy.ratio: a refinement ratio in (1, 4], got {ratio!r}")


COMPRESSION_QUANTITIES = ("peak_pressure_Pa", "mean_pressure_Pa", "hoop_tension_N_per_m")


def wear_quantities(data: dict) -> dict[str, str]:
    """{accuracy quantity: its summary.json key} of a wear scene (a dotted key names a nested entry): on the
    explicit engine the peak and final torque [N m] of each monitor over the motion (the arm's presets and the
    [[torque]] monitors), the peak and mean contact pressure [Pa] over the motion and the largest fabric strain
    [-], and a tube on a limb its compression report (compression_<quantity>); none on the Newton routes."""
    if route_of(data) != "explicit":
        return {}
    monitors = [m.name for m in ARM_MONITORS] if data["body"]["type"] in ("arm", "default_arm") else []
    out = {}
    for name in monitors + [spec["name"] for spec in data.get("torque", [])]:
        out.update({f"torque_{name}_{which}_Nm": f"torque_{name}.{which}_Nm" for which in ("peak", "final")})
        out[f"torque_{name}_window_mean_Nm"] = f"torque_{name}.window_mean_Nm"
    if data["body"]["type"] == "limb" and first_garment(data).get("builder", "pattern") == "tube":   # is_tube_on_limb
        # the compression report of the final state (fabricfem.wear.compression.compression_report)
        out.update({f"compression_{k}": f"compression.{k}" for k in COMPRESSION_QUANTITIES})
    return {**out, "pressure_peak_Pa": "pressure.peak_Pa", "pressure_mean_Pa": "pressure.mean_Pa",
            "max_strain": "max_strain"}


def scene_body_time(plan: WearPlan) -> float:
    """Body time [s] of the whole run of a wear scene on the engine (every phase; route.end_time ignored)."""
    timeline = dataclasses.replace(plan.timeline, end_time=None)
    records = timeline.phase_records(timeline.motion_length(plan.body.kinematics))
    return sum(records.values()) * timeline.record_time


def check_window(wear: WearScene, plan: WearPlan) -> None:
    """accuracy.window must not exceed the scene's body time (SceneError naming it, before meshing)."""
    window = wear.accuracy.window
    if window is not None and window > (total := scene_body_time(plan)) + 1e-12:
        raise SceneError(f"accuracy.window: {window:g} s is longer than the scene ({total:.6g} s of body time: "
                         f"donning, settling and motion); give a shorter window or leave it out")


# ------------------------------------------------------------------------------------------ objects
def wear_fabric(wear: WearScene, build_fabric):
    """The scene's Fabric: the stored one named by fabric.catalogue, else `build_fabric` of [fabric]."""
    if wear.catalogue is not None:
        try:
            return load_fabric(wear.catalogue)
        except (ValueError, FileNotFoundError) as exc:
            raise SceneError(f"fabric.catalogue: {exc}") from None
    return build_fabric(dict(wear.fabric))


def pattern_file(wear: WearScene, scene_path: Path | None) -> Path:
    """The pattern file of [garment] pattern: a shipped name, or a path (relative to the scene file)."""
    name = wear.garment.pattern
    candidate = Path(name)
    if not candidate.is_absolute() and scene_path is not None:
        candidate = Path(scene_path).parent / candidate
    if candidate.is_file():
        return candidate
    try:
        return pattern_path(name)
    except ValueError as exc:
        raise SceneError(f"garment.pattern: {name!r} is neither a file nor a shipped pattern ({exc})") from None


@dataclasses.dataclass
class WearPlan:
    """What a wear scene runs on the explicit engine (everything but the mesh)."""

    body: Body
    torques: list[TorqueSpec]
    timeline: Timeline
    settings: ExplicitSettings
    contact: ContactSpec
    axis: tuple | None
    handles: list = dataclasses.field(default_factory=list)   # (kind, edge names, options) of the donning handles
    skin: object = None      # a mesh body's rigged skin (fabricfem.scenes.mesh_body.scene_skin), else None


def _motion_units(units: str | float | None) -> str | float | None:
    """motion.units checked: a unit name of LENGTH_UNITS or a positive finite number of metres per file unit
    (SceneError naming motion.units; a number written as a string is refused with the unquoted form)."""
    if units is None:
        return None
    if isinstance(units, str):
        try:
            float(units)
        except ValueError:
            if units.strip().lower() not in LENGTH_UNITS:
                raise SceneError(f"motion.units: unknown unit {units!r}{_suggest(units, LENGTH_UNITS)}; a name "
                                 f"{sorted(LENGTH_UNITS)} or a number of metres per file unit (CMU BVH: "
                                 f"0.0254 / 0.45 = 0.0564444)") from None
            return units
        raise SceneError(f"motion.units: {units!r} is a string; write metres per file unit as a number, without "
                         f"quotes (units = {units.strip()})")
    if not (math.isfinite(units) and units > 0.0):
        raise SceneError(f"motion.units: metres per file unit must be a positive finite number, got {units!r}")
    return float(units)


def _motion_mapping(motion: WearMotionSection, body_names) -> dict:
    """Body point name -> point source of motion.mapping (fabricfem.body.mocap.point_source), the body's points it
    leaves out mapped to the file's points of the same name (SceneError naming motion.mapping.NAME)."""
    try:
        sources = mapping_sources(dict(motion.mapping or {}))
    except ValueError as exc:
        raise SceneError(f"motion.{exc}") from None
    unknown = [name for name in sources if name not in body_names]
    if unknown:
        name = unknown[0]
        raise SceneError(f"motion.mapping.{name}: not a joint or marker of the body{_suggest(name, body_names)} "
                         f"(its points: {list(body_names)})")
    return {**{name: name for name in body_names}, **sources}


def _motion_file(motion: WearMotionSection, scene_path: Path | None, body_names) -> object:
    """The kinematics of [motion] type = "file": the file read in motion.units (`_motion_units`), mapped to the
    body's joint and marker names (`_motion_mapping`)."""
    units = _motion_units(motion.units)
    mapping = _motion_mapping(motion, body_names)
    if not motion.path:
        raise SceneError("motion.path: a file motion needs the path of its motion file")
    path = Path(motion.path)
    if not path.is_absolute() and scene_path is not None:
        path = Path(scene_path).parent / path
    if not path.is_file():
        raise SceneError(f"motion.path: no motion file {str(path)!r}")
    try:
        return load_motion(path, mapping, units=units, up=motion.up, fill_gaps=motion.fill_gaps)
    except ValueError as exc:
        raise SceneError(f"motion.path: {exc}") from None


def garment_box(wear: WearScene, scene_path: Path | None) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) [m]: the garment's reference bounding box before meshing: a tube's 0 <= x <= length,
    |y|, |z| <= radius; the box of a pattern's panel outlines (curved edges as 64-segment polylines) placed as
    `garment_mesh` places them."""
    g = wear.garment
    if g.builder == "tube":
        return np.array([0.0, -g.radius, -g.radius]), np.array([g.length, g.radius, g.radius])
    pattern = read_pattern(wear, scene_path)
    places = panel_placements(g, pattern)
    points = np.vstack([places[name].map(outline_polyline(panel)[0]) for name, panel in pattern.panels.items()])
    return points.min(axis=0), points.max(axis=0)


def _placed(wear: WearScene, kinematics, segments, scene_path: Path | None, keep_height: bool):
    """The motion moved by motion.place = "garment" (fabricfem.body.placement: the first pose's centre of volume
    to the centre of `garment_box`, horizontally only when `keep_height`) and checked to meet the garment: the
    first pose must reach into the garment's box (a motion file always, any motion when placed; SceneError naming
    motion.place with the distance [m])."""
    motion = wear.motion
    if motion.place is None and motion.type != "file":
        return kinematics
    check_garment(wear, scene_path)
    lower, upper = garment_box(wear, scene_path)
    t0 = kinematics.time_range[0]
    if motion.place == "garment":
        kinematics = Translated(kinematics, placement_offset(Body(segments, kinematics).pose(t0), lower, upper,
                                                             keep_height))
    distance = box_distance(Body(segments, kinematics).pose(t0), lower, upper)
    where = f"the body's first pose (t = {t0:g} s of the motion)"
    if distance > 0.0 and motion.place is None:
        raise SceneError(f"motion.place: {where} is {distance:.3f} m from the garment's reference bounding box: the "
                         f"garment never meets the body; write [motion] place = \"garment\" to move the motion "
                         f"into the garment")
    if distance > 0.0:
        kept = "the height is kept: the feet stay on the floor" if keep_height else "placed in 3D"
        raise SceneError(f"motion.place: placed, {where} is still {distance:.3f} m from the garment's reference "
                         f"bounding box ({kept}); move the garment (garment.translate)")
    return kinematics


def _arm_plan(wear: WearScene, fabric) -> tuple:
    """(body, torques, axis, record time [s], motion duration [s] or None, settle time [s], mass damping [1/s],
    critical-step default) of an arm: flexing at the elbow (fabricfem.wear.sleeve.flexion_timeline) or still."""
    motion, route, dims = wear.motion, wear.route, wear.arm
    if wear.flexion is None:
        kinematics = StillPose(default_arm(dimensions=dims).kinematics.positions(0.0), motion.duration or 0.0)
        return (default_arm(kinematics, dims), list(ARM_MONITORS), None, float(motion.record_time or 0.01),
                motion.duration, wear.settle_time, route.mass_damping, ExplicitSettings.critical_step)
    similarity = similarity_factor(fabric, route)
    body, timeline, axis = flexion_timeline(wear.flexion, route, similarity, dims)
    settings = flexion_settings(route, similarity)
    return (body, list(ARM_MONITORS), axis, timeline.record_time, timeline.motion_time, timeline.settle_time,
            settings.mass_damping, settings.critical_step)


def _lower_body_kinematics(wear: WearScene, stand, scene_path: Path | None):
    """The lower body's kinematics of [motion] (walking, obstacle_walk, file, or standing), every pose of a file
    posable (`check_posable`), placed in the garment and checked to meet it (`_placed`, its height kept), then
    entered from the standing pose over motion.blend_time; and the motion's duration [s] (None: the kinematics'
    own)."""
    motion, dims = wear.motion, wear.lower_body
    segments = list(lower_body(dims, stand).segments.values())
    try:
        if motion.type == "walking":
            kinematics = winter_walking(dims, strides=motion.strides or 2, cycle_time=motion.cycle_time,
                                        speed=motion.speed)
        elif motion.type == "obstacle_walk":
            kinematics = obstacle_walk(dims, strides=motion.strides or 4, crossing_stride=motion.crossing_stride,
                                       obstacle_height=motion.obstacle_height, obstacle_depth=motion.obstacle_depth,
                                       clearance=motion.clearance, trail_clearance=motion.trail_clearance,
                                       cycle_time=motion.cycle_time, speed=motion.speed,
                                       crossing_speed=motion.crossing_speed)
        elif motion.type == "file":
            kinematics = _motion_file(motion, scene_path, stand.names)
            try:
                check_posable(segments, kinematics.times, kinematics.samples())
            except ValueError as exc:
                raise SceneError(f"motion.mapping: {exc}") from None
        else:
            return _placed(wear, stand, segments, scene_path, keep_height=True), float(motion.duration or 0.0)
    except ValueError as exc:
        if isinstance(exc, SceneError):
            raise
        raise SceneError(f"motion: {exc}") from None
    kinematics = _placed(wear, kinematics, segments, scene_path, keep_height=True)
    if motion.blend_time > 0.0:
        # the garment goes on the standing body; the motion is entered from the standing pose
        kinematics = BlendedStart(kinematics, stand.positions(0.0), motion.blend_time)
    return kinematics, motion.duration


def _body_plan(wear: WearScene, fabric, scene_path: Path | None) -> tuple:
    """(body, torques, axis, record time [s], motion duration [s], settle time [s], mass damping [1/s], gravity
    [m/s^2], critical-step default) of the scene's body and motion (SceneError naming the key)."""
    motion, route = wear.motion, wear.route
    if wear.arm is not None:           # the sleeve's convention: the forearm rotates up, towards +y
        return (*_arm_plan(wear, fabric), (0.0, -GRAVITY, 0.0))
    duration = motion.duration
    if wear.body.type == "limb":
        body = limb_body(wear.body.center, wear.body.radii, duration or 0.0)
    else:
        stand = standing(wear.lower_body, duration=float(duration) if duration else 1.0)
        kinematics, duration = _lower_body_kinematics(wear, stand, scene_path)
        body = lower_body(wear.lower_body, kinematics)
    if motion.type in ("walking", "obstacle_walk", "file") and duration is not None:
        start, end = body.kinematics.time_range
        duration = min(float(duration), end - start)
    return (body, [], None, float(motion.record_time or 0.01), duration, wear.settle_time, route.mass_damping,
            ExplicitSettings.critical_step, (0.0, 0.0, -GRAVITY))


def plan(wear: WearScene, fabric, scene_path: Path | None = None) -> WearPlan:
    """Body, monitors, phases and explicit settings of a wear scene on the engine (SceneError naming the key)."""
    donning, route, garment = wear.donning, wear.route, wear.garment
    body, torques, axis, record_time, duration, settle, damping, critical_step, gravity = _body_plan(
        wear, fabric, scene_path)
    if wear.lower_body is None:       # the arm and the limb stand on no floor: placed in 3D
        segments = list(body.segments.values())
        body = Body(segments, _placed(wear, body.kinematics, segments, scene_path, keep_height=False))
    for i, spec in enumerate(wear.torques):
        torques.append(TorqueSpec(spec.name, spec.joint, tuple(spec.axis), tuple(spec.segments)))
        try:
            body.check_joint(spec.joint)
            body.check_segments(spec.segments)
        except ValueError as exc:
            raise SceneError(f"torque[{i}]: {exc}") from None
    grow_from = donning.start if (donning.method == "grow" and donning.start is not None) else 1.0
    try:
        timeline = Timeline(record_time=record_time, sewing_time=garment.sewing_time,
                            donning_time=donning.time if donning.method == "grow" else 0.0, grow_from=grow_from,
                            settle_time=settle, motion_time=duration, pull_time=donning.pull_time,
                            belt_time=donning.belt_time if donning.belt_edges else 0.0,
                            end_time=wear.end_time)
    except ValueError as exc:
        raise SceneError(f"donning: {exc}") from None
    if donning.pull_edges and not (donning.pull_path and donning.pull_time > 0):
        raise SceneError("donning.pull_path: pulling edges needs a pull_path of offsets and a pull_time > 0 [s]")
    if not (math.isfinite(donning.regrow_time) and donning.regrow_time >= 0.0):
        raise SceneError(f"donning.regrow_time must be a time >= 0 [s], got {donning.regrow_time!r}")
    if donning.remove:
        restore = timeline.start_of("belt") if donning.restore_at is None else float(donning.restore_at)
        try:
            body.check_segments(donning.remove)
            schedule = SegmentSchedule({"removed": (list(donning.remove), [(-1.0, restore)])},
                                       regrow_time=donning.regrow_time)
            body = Body(list(body.segments.values()), body.kinematics, schedule)
        except ValueError as exc:
            raise SceneError(f"donning.remove: {exc}") from None
    handles = handle_specs(donning, timeline)
    critical_step = route.critical_step or critical_step
    settings = ExplicitSettings(mass_damping=damping, stiffness_damping=route.stiffness_damping,
                                damping_frame=route.damping_frame,
                                rotary_inertia_scale=route.rotary_inertia_scale,
                                time_step_safety=step_safety(route.time_step_safety, critical_step),
                                mass_scale=route.mass_scale, critical_step=critical_step,
                                gravity=gravity if route.gravity else None)
    skin = scene_skin(wear.body, body, scene_path) if wear.body.type == "mesh" else None
    return WearPlan(body, torques, timeline, settings, wear.contact, axis, handles, skin)


def read_pattern(wear: WearScene, scene_path: Path | None):
    """The [garment] pattern, read, graded by `scale` and checked (stitches, outlines, stitched lengths) before
    meshing (SceneError naming the item)."""
    g = wear.garment
    path = pattern_file(wear, scene_path)
    try:
        pattern = read_pattern_toml(path) if path.suffix == ".toml" else read_garmentcode(path)
        if g.scale != 1.0:
            pattern = dataclasses.replace(pattern, panels={name: dataclasses.replace(
                p, vertices=g.scale * np.asarray(p.vertices), translation=g.scale * np.asarray(p.translation))
                for name, p in pattern.panels.items()})
        check_pattern(pattern, g.stitch_tolerance)
    except ValueError as exc:
        raise SceneError(f"garment.pattern: {exc}") from None
    return pattern


def check_garment(wear: WearScene, scene_path: Path | None) -> None:
    """The garment's checks before meshing: a pattern is read and checked (fabricfem.meshes.pattern.check_pattern:
    outlines, stitched lengths, twisted stitches), its edges named by garment.hold and the donning handles exist,
    and no stitch must pull together held nodes that are apart (check_held_stitches); a tube's sizes are positive."""
    g, donning = wear.garment, wear.donning
    if g.builder == "pattern":
        pattern = read_pattern(wear, scene_path)
        held = []
        for key in ("garment.hold", "donning.pull_edges", "donning.belt_edges"):
            for name in getattr(g if key == "garment.hold" else donning, key.partition(".")[2]) or []:
                panel, _, index = str(name).rpartition(".")
                if panel not in pattern.panels or not index.isdigit() or int(index) >= len(pattern.panels[panel].edges):
                    raise SceneError(f"{key}: no pattern edge {name!r} (write \"panel.edge\"; panels "
                                     f"{sorted(pattern.panels)})")
                held += [(panel, int(index))] if key == "garment.hold" else []
        try:
            check_held_stitches(pattern, held, g.stitch_tolerance)
        except ValueError as exc:
            raise SceneError(f"garment.hold: {exc}") from None
    elif donning.pull_edges or donning.belt_edges:
        raise SceneError("donning: pull_edges and belt_edges name pattern edges; this garment is a tube")
    else:
        for key in ("length", "radius", "n_around", "n_along"):
            if not getattr(g, key) > 0:
                raise SceneError(f"garment.{key}: must be positive, got {getattr(g, key)!r}")
    if g.h <= 0 or g.sewing_time < 0 or g.scale <= 0:
        raise SceneError("garment: h and scale must be positive and sewing_time >= 0 "
                         f"(got h = {g.h}, scale = {g.scale}, sewing_time = {g.sewing_time})")


def handle_specs(donning: WearDonningSection, timeline: Timeline) -> list[tuple[str, list[str], dict]]:
    """The donning handles of [donning]: ("grip", edges, path and times), ("belt", edges, tension and times)."""
    out = []
    if donning.pull_edges:
        start = timeline.start_of("pull")
        hold = timeline.start_of("belt") if donning.pull_hold else start + donning.pull_time
        out.append(("grip", list(donning.pull_edges), {"waypoints": donning.pull_path, "start": start,
                                                        "end": start + donning.pull_time, "release": hold}))
    if donning.belt_edges:
        out.append(("belt", list(donning.belt_edges), {"tension": donning.belt_tension,
                                                        "start": timeline.start_of("belt"),
                                                        "ramp": donning.belt_time}))
    return out


def edge_handles(specs, garment) -> list:
    """Builders model -> hook of the handle specs on the pattern garment (fabricfem.contact.handles); SceneError
    naming an unknown edge "panel.edge"."""
    builders = []
    for kind, names, options in specs:
        edges = []
        for name in names:
            panel, _, index = str(name).rpartition(".")
            if panel not in garment.panel_tags or not index.isdigit():
                raise SceneError(f"donning.{'pull' if kind == 'grip' else 'belt'}_edges: no pattern edge {name!r} "
                                 f"(write \"panel.edge\"; panels {sorted(garment.panel_tags)})")
            try:
                points = garment.edge_points(panel, int(index))
            except (KeyError, IndexError, ValueError) as exc:
                raise SceneError(f"donning: edge {name!r}: {exc}") from None
            edges.append((name, garment.panel_tags[panel], points))
        if kind == "grip":
            builders.append(lambda model, e=edges, o=options: EdgeGrip(model, e, **o))
        else:
            builders.append(lambda model, e=edges, o=options: Belt(model, e, **o))
    return builders


def garment_mesh(wear: WearScene, scene_path: Path | None, comm):
    """(FabricMesh, seams [SeamSpec], hold tags, the GarmentMesh of a pattern or None) of [garment]."""
    g = wear.garment
    if wear.layered:             # several tube garments, one mesh (fabricfem.scenes.garments)
        return layered_garment_mesh(wear, comm)
    if g.builder == "tube":
        return tube(g.length, g.radius, g.n_around, g.n_along, cell="quadrilateral", order=g.order, comm=comm), [], \
            list(g.hold), None
    pattern = read_pattern(wear, scene_path)
    try:
        garment = mesh_pattern(pattern, g.h, order=g.order, placements=panel_placements(g, pattern),
                               stitch_length_tolerance=g.stitch_tolerance, comm=comm)
    except ValueError as exc:
        raise SceneError(f"garment.pattern: {exc}") from None
    seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
             for s in garment.stitches]
    return garment.fabric, seams, list(g.hold), garment
