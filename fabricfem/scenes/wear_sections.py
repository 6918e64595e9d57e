"""The sections of a wear scene (`[scene] kind = "wear"`): each key's type, default and unit declared once as a
field of a frozen dataclass (fabricfem.parameters.param), beside those of fabricfem.wear.config (ContactSpec,
RouteSpec, FlexionSpec) and fabricfem.body (ArmDimensions, LowerBodyDimensions); the schema is read from them."""
from __future__ import annotations

import dataclasses

from fabricfem.parameters import param as doc


@dataclasses.dataclass(frozen=True)
class GarmentSection:
    """[garment]: a tube along +x (fabricfem.meshes.tube) or the panels of a sewing pattern (fabricfem.meshes.pattern)
    sewn along its stitches; [[garment]]: several tube garments worn one over the other, listed from the inside out
    (fabricfem.scenes.garments)."""

    builder: str = doc("tube | pattern", "pattern")
    pattern: str | None = doc("pattern: a shipped pattern name (fabricfem/patterns) or a GarmentCode JSON / TOML file, "
                              "relative to the scene file", None)
    h: float = doc("pattern: element size [m]", 0.05)
    order: int = doc("geometry order (2: curved edges and tubes without facets)", 2)
    stitch_tolerance: float = doc("pattern: largest relative length difference of stitched edges", 0.02)
    sewing_time: float = doc("pattern: time the seams take to close [s] (0: they must start closed)", 0.0)
    scale: float = doc("pattern: grading factor on the panels' outlines and placements (1: as drawn)", 1.0)
    rotate: list | None = doc("pattern: [rx, ry, rz] extrinsic XYZ Euler angles [deg] applied to the placed garment "
                              "(GarmentCode files are Y-up: [90, 0, 0] turns them Z-up)", None)
    translate: list | None = doc("pattern: [x, y, z] [m] added after `rotate`", None)
    wrap: dict | None = doc("pattern: panels rolled onto cylinders instead of their own placement, panel name -> "
                            "{axis_point = [x, y, z] [m], axis = [x, y, z], radius [m], zero_direction = [x, y, z], "
                            "angle0 [deg]} in the scene's frame (`rotate` and `translate` do not apply; "
                            "fabricfem.scenes.panel_placement)", None)
    hold: list = doc("edge tags whose nodes are held in place (tube: end0 at x = 0, end1)", default_factory=list)
    length: float | None = doc("tube: length along x [m]", None)
    radius: float | None = doc("tube: radius [m]", None)
    n_around: int | None = doc("tube: Q2 cells around", None)
    n_along: int | None = doc("tube: Q2 cells along", None)
    quadrature: list | None = doc("tube and pattern: (full, reduced) PSRI quadrature degrees", None)
    hold_rotations: bool = doc("tube (quasistatic and implicit sleeve routes): clamp the rotations of end0", False)
    name: str | None = doc("several garments ([[garment]], inside out): the garment's name in the monitors' columns "
                           "and the prefix of its edge tags (default garment0, garment1, ...)", None)
    fabric: str | None = doc("several garments: the stored fabric of this garment; the shell takes one fabric per "
                             "run, so it must be the scene's [fabric] catalogue (a different one is refused)", None)


def garment_tables(data: dict) -> list[dict]:
    """The garment tables of a wear scene's data, inside out: [garment] as one, [[garment]] as given."""
    garment = data.get("garment", {})
    return list(garment) if isinstance(garment, list) else [garment]


def first_garment(data: dict) -> dict:
    """The innermost garment's table of a wear scene's data (the only one of a [garment] scene); {} if none."""
    tables = garment_tables(data)
    return tables[0] if tables and isinstance(tables[0], dict) else {}


@dataclasses.dataclass(frozen=True)
class WearFabricSection:
    """[fabric] of a wear scene: a stored fabric by name (`catalogue`) or the keys of [fabric]."""

    catalogue: str | None = doc("a stored fabric (fabricfem.fabrics: a name or a .json path) instead of E1 ...", None)


@dataclasses.dataclass(frozen=True)
class WearBodySection:
    """[body]: the wearer, a preset of named ellipsoid segments: arm (upper arm + forearm, ANSUR II; the keys of
    ArmDimensions), lower_body (trunk, pelvis, thighs, shanks, feet, ANSUR II; the keys of LowerBodyDimensions),
    limb (one ellipsoid along x: center, radii), or mesh: a closed triangulated skin read from `file` and rigged
    by linear blend skinning to the segments of `skeleton` (fabricfem.body.mesh_skin), which the motion moves."""

    type: str = doc("arm | lower_body | limb | mesh (default_arm = arm)")
    file: str | None = doc("mesh: the skin's surface mesh (OBJ, PLY, STL, glTF/GLB, COLLADA .dae/.zae), relative "
                           "to the scene file, or \"human\" (the Debian assimp-testmodels human.zae)", None)
    units: str | float = doc("mesh: the file's length unit (m, cm, mm, in, or metres per file unit)", "m")
    up: str = doc("mesh: the file's up axis, z or y", "z")
    repair: bool = doc("mesh: close holes and flip inverted normals instead of refusing the file", False)
    components: str = doc("mesh: largest (keep the part of largest area) or all (every part, each closed)",
                          "largest")
    skeleton: str | None = doc("mesh: the segments it is rigged to and moved by: lower_body or arm (their dimension "
                               "keys apply)", None)
    rest_positions: str | dict | None = doc("mesh: the skeleton's joints and markers in the mesh [m]: a table name "
                                            "-> [x, y, z] (body frame), or \"human\" (measured on the Debian "
                                            "human, fabricfem.body.human; its lower-body dimensions are then the "
                                            "defaults); default: the skeleton's own first pose", None)
    skinning: str = doc("mesh: linear (linear blend skinning) or implicit (the vertices near the joints kept on the "
                        "level of the skeleton's blended ellipsoids they had at rest, fabricfem.body.implicit_skinning)",
                        "linear")
    center: list | None = doc("limb: [x, y, z] centre [m]", None)
    radii: list | None = doc("limb: [r1, r2, r3] semi-axes along x, y, z [m]", None)
    blend_width: float = doc("width of the smooth blend of the segments at the joints [m]: the skin has no crease "
                             "there and lies at most blend_width / 4 outside the segments (fabricfem.body.blended)",
                             0.05)


@dataclasses.dataclass(frozen=True)
class WearMotionSection:
    """[motion]: what drives the body: elbow_flexion (arm; FlexionSpec's keys), still (the start pose held),
    walking (lower body: Winter's normative gait, both legs), obstacle_walk (Winter's gait with one stride over a
    box, fabricfem.body.crossing) or file (a C3D, TRC, BVH or CSV motion capture with
    a mapping of its markers or joints to the body's joint and marker names)."""

    type: str = doc("elbow_flexion | still | walking | obstacle_walk | file")
    duration: float | None = doc("still: length of the motion phase [s]; file, walking: at most this long", None)
    record_time: float | None = doc("record interval [s] (elbow_flexion: output_angle_step / angular velocity)", None)
    strides: int | None = doc("walking, obstacle_walk: gait cycles (default: walking 2, obstacle_walk 4)", None)
    cycle_time: float = doc("walking, obstacle_walk: duration of one gait cycle [s]", 0.987)
    speed: float = doc("walking, obstacle_walk: forward speed of the pelvis [m/s]", 1.43)
    crossing_stride: int = doc("obstacle_walk: the stride that steps over the obstacle", 3)
    obstacle_height: float = doc("obstacle_walk: height of the obstacle [m]", 0.5)
    obstacle_depth: float = doc("obstacle_walk: depth of the obstacle along the walk [m]", 0.1)
    clearance: float = doc("obstacle_walk: lead foot's clearance over the obstacle [m]", 0.12)
    trail_clearance: float = doc("obstacle_walk: trail foot's clearance over the obstacle [m]", 0.05)
    crossing_speed: float = doc("obstacle_walk: pelvis speed during the crossing stride [m/s]", 0.6)
    path: str | None = doc("file: the motion file (.c3d, .trc, .bvh, .csv), relative to the scene file", None)
    units: str | float | None = doc("file: length unit of the file: mm, cm, m, in, or a number of metres per file "
                                    "unit (CMU BVH: 0.0254 / 0.45 = 0.0564444); default the file's metadata; BVH: "
                                    "required", None)
    up: str | None = doc("file: the file's up axis (y: mapped to z; default the reader's)", None)
    fill_gaps: bool = doc("file: fill marker gaps by interpolation instead of refusing them", False)
    blend_time: float = doc("walking, file (lower body): the body stands during the donning and enters the motion "
                            "over this time [s] (fabricfem.body.blend; 0: it starts in the motion's first pose)", 0.0)
    mapping: dict | None = doc("file: body joint/marker name -> the file's marker or joint name, or a table "
                               "{marker = \"M\"} or {mean = [\"A\", \"B\"]} (their mean) with an optional offset = "
                               "[dx, dy, dz] [m] (body frame: x forward, y left, z up); unmapped points: the same "
                               "names", None)
    place: str | None = doc("explicit engine: \"garment\" moves the whole motion so that the centre of volume of the "
                            "body's first pose is at the centre of the garment's reference bounding box (the lower "
                            "body keeps its height: horizontally only); default: where the file or preset puts "
                            "it (docs/bodies.md)", None)


@dataclasses.dataclass(frozen=True)
class WearDonningSection:
    """[donning]: putting the garment on. grow: the body starts at `start` x its transverse radii and grows to full
    size over `time` [s] (the compression sleeve: fabricfem.wear.compression)."""

    method: str = doc("none | grow", "none")
    remove: list | None = doc("segments switched off while the garment goes on (the thesis removes the feet)", None)
    restore_at: float | None = doc("time [s] at which the removed segments come back (default: the start of the "
                                   "belt phase, after the pull and the growth)", None)
    regrow_time: float = doc("the removed segments regrow from 0.2 of their size to full size over this time [s] "
                             "after they come back, pushing aside the cloth where they reappear (0: at once)", 0.0)
    pull_edges: list | None = doc("pattern edges \"panel.edge\" gripped and pulled along pull_path (the waistband)",
                                  None)
    pull_path: list | None = doc("[[dx, dy, dz], ...] offsets [m] of the grip at equal times over pull_time "
                                 "(the first usually [0, 0, 0])", None)
    pull_time: float = doc("duration of the pull [s]", 0.0)
    pull_hold: bool = doc("after the pull, hold the pulled edges at their height (along the pull) while the body "
                          "grows, letting go when the belt phase starts (hands holding a waistband up)", False)
    belt_edges: list | None = doc("pattern edges \"panel.edge\" tensioned as one drawstring (a belt, a cuff)", None)
    belt_tension: float = doc("the belt's tension [N] (a drawstring force along the edges)", 0.0)
    belt_time: float = doc("the belt's tension ramps from 0 over this time [s]", 0.0)
    start: float | None = doc("grow: starting size of the body's transverse radii (0, 1]", None)
    time: float = doc("grow, explicit: growth time [s]", 0.1)


@dataclasses.dataclass(frozen=True)
class TorqueSection:
    """[[torque]]: a resisting-torque monitor about a joint from the contact forces on chosen segments."""

    name: str = doc("column name")
    joint: str = doc("joint name of the body")
    axis: list = doc("[ax, ay, az] flexion axis (positive torque opposes a right-handed rotation about it)")
    segments: list = doc("segment names whose contact forces count")


@dataclasses.dataclass(frozen=True)
class WearRouteSection:
    """[route] keys of the explicit engine besides RouteSpec's."""

    end_time: float | None = doc("explicit engine: stop the run at this body time [s] (the phases as scheduled, cut "
                                 "there; the accuracy pilots' window); default: the whole scene", None)
