"""Motion files: an analytic two-leg walk written as C3D, TRC and BVH, read back and used to pose the
lower body, against the analytic poses; a real CMU BVH recording poses the lower body with constant
segment lengths."""
from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from fabricfem.body.bvh import BvhSkeleton, parse_bvh, write_bvh
from fabricfem.body.conventions import to_file, unit_scale
from fabricfem.body.lower_body import MARKER_OFFSET, LowerBodyGait, lower_body, winter_walking
from fabricfem.body.mocap import Mean, Offset, load_motion, read_c3d, read_trc, write_c3d, write_trc
from fabricfem.body.pose import Body
from fabricfem.verify import Timer, case, result

FRAME_TIME = 0.01           # s: 100 Hz, exact in every format's time stamps
BVH_DIGITS = 6              # decimals written to the BVH file (cm and degrees)
BVH_UNITS = "cm"
# CMU motion capture (mocap.cs.cmu.edu), BVH conversion shipped by Debian's assimp-testmodels: subject 1,
# trial 3 (climbing a step ladder), 120 Hz; 1 unit = 1 / 0.45 inch
CMU_BVH = Path("/usr/share/assimp/models/BVH/01_03.bvh")
CMU_UNITS = 0.0254 / 0.45   # m per file unit
CMU_DIGITS = 5              # decimals of the OFFSET lines of the CMU files
CMU_POSE_STRIDE = 20        # pose every 20th frame (the lengths are checked on every frame)


def _pose_errors(body: Body, reference: Body, times: np.ndarray) -> tuple[float, float]:
    """max |x^c - x^c_ref| [m] and max r_max ||R - R_ref||_2 [m] (the largest surface displacement a
    rotation error causes) over the segments and times."""
    centre, axes = 0.0, 0.0
    for t in times:                                   # posing is per time (Body.pose)
        posed, ref = body.pose(t), reference.pose(t)
        for name, e in ref.items():
            centre = max(centre, float(np.linalg.norm(posed[name].center - e.center)))
            axes = max(axes, float(np.max(e.radii) * np.linalg.norm(posed[name].rotation - e.rotation, 2)))
    return centre, axes


def _gait_bvh(gait: LowerBodyGait, times: np.ndarray, units: str) -> tuple[BvhSkeleton, np.ndarray]:
    """The gait as a BVH joint tree in a Y-up file frame (`fabricfem.body.conventions`): root "pelvis"
    at the hip midpoint (translation only), hip_s -> knee_s -> ankle_s -> End Site (the toe). Every
    flexion is a rotation about the file's x axis (the body's lateral y): hip -phi_h, knee +phi_k,
    ankle -phi_a [deg] (signs of `lower_body_points`)."""
    d, scale = gait.dimensions, unit_scale(units)
    names, parents, offsets, channels = ["pelvis"], [-1], [np.zeros(3)], [
        ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")]
    rotation = ("Zrotation", "Yrotation", "Xrotation")
    points = gait.points(times)
    columns = [to_file(0.5 * (points["hip_l"] + points["hip_r"]), scale, "y"), np.zeros((len(times), 3))]
    for s, side in (("l", 1.0), ("r", -1.0)):
        root = len(names)
        body_offsets = [(0.0, 0.5 * side * d.hip_joint_spacing, 0.0), (0.0, 0.0, -d.thigh_length),
                        (0.0, 0.0, -d.shank_length), (d.toe_distance, 0.0, 0.0)]
        for k, (name, offset) in enumerate(zip((f"hip_{s}", f"knee_{s}", f"ankle_{s}", f"ankle_{s}_end"),
                                               body_offsets)):
            names.append(name)
            parents.append(root + k - 1 if k else 0)
            offsets.append(to_file(np.array(offset), scale, "y"))
            channels.append(rotation if k < 3 else ())
        phi_h, phi_k, phi_a = np.degrees(gait.angles(times, s)).T
        zero = np.zeros_like(phi_h)
        columns += [np.column_stack([zero, zero, x]) for x in (-phi_h, phi_k, -phi_a)]
    skeleton = BvhSkeleton(tuple(names), tuple(parents), np.array(offsets), tuple(channels))
    return skeleton, np.hstack(columns)


def _bvh_mapping(gait: LowerBodyGait, root: Mean | str, left: dict, right: dict) -> dict:
    """Body points of the lower body from BVH joints: the leg joints by name (left/right: body joint ->
    file joint), markers and pelvis/trunk points as offsets [m] of joint means (they do not rotate with
    the segment, which leaves the pose unchanged for the sagittal gait: only the marker's component
    perpendicular to the segment axis counts)."""
    d = gait.dimensions
    lift = d.waist_height - d.hip_height
    mapping = {"waist": Offset(root, (0.0, 0.0, lift)), "crotch": Offset(root, (0.0, 0.0, lift - d.rise)),
               "chest": Offset(root, (0.0, 0.0, lift + d.rise)),
               "trunk_marker": Offset(root, (MARKER_OFFSET, 0.0, lift)),
               "pelvis_marker": Offset(root, (MARKER_OFFSET, 0.0, lift - d.rise + d.pelvis_radii[0]))}
    for s, side, joints in (("l", 1.0, left), ("r", -1.0, right)):
        mapping.update({f"{j}_{s}": joints[j] for j in ("hip", "knee", "ankle", "toe")})
        mapping[f"thigh_marker_{s}"] = Offset(Mean((joints["hip"], joints["knee"])), (0.0, side * MARKER_OFFSET, 0.0))
        mapping[f"shank_marker_{s}"] = Offset(Mean((joints["knee"], joints["ankle"])),
                                              (0.0, side * MARKER_OFFSET, 0.0))
        mapping[f"foot_marker_{s}"] = Offset(Mean((joints["ankle"], joints["toe"])), (0.0, 0.0, MARKER_OFFSET))
    return mapping


def bvh_pose_tolerance(gait: LowerBodyGait, digits: int, units: str) -> float:
    """Bound [m] on the pose error caused by printing a BVH file with `digits` decimals: each number is
    off by at most h = 0.5 x 10^-digits (file units or degrees); a point at the end of the leg chain
    moves by at most 5 sqrt(3) h s (root + four offsets, s = metres per unit) + 3 sqrt(3) h pi/180 x
    (thigh + shank + toe distance) (three rotated joints, lever at most the chain length); x 4 for the
    axes rows, which scale point errors by 2 r_max / min(segment length, marker distance) <= 2.7."""
    d = gait.dimensions
    h = 0.5 * 10.0 ** -digits
    chain = d.thigh_length + d.shank_length + d.toe_distance
    point = 5.0 * math.sqrt(3.0) * h * unit_scale(units) + 3.0 * math.sqrt(3.0) * math.radians(h) * chain
    return 4.0 * point


def _cmu_rows(out: list) -> None:
    """Lower body posed from the CMU recording: segment lengths vs the file's OFFSETs on every frame."""
    if not CMU_BVH.exists():
        print(f"mocap-roundtrip: {CMU_BVH} absent (Debian package assimp-testmodels): CMU rows left out",
              file=sys.stderr)
        return
    with Timer() as timer:
        joints = {s: {"hip": f"{side}UpLeg", "knee": f"{side}Leg", "ankle": f"{side}Foot", "toe": f"{side}ToeBase"}
                  for s, side in (("l", "Left"), ("r", "Right"))}
        gait = winter_walking()
        mapping = _bvh_mapping(gait, Mean(("LeftUpLeg", "RightUpLeg")), joints["l"], joints["r"])
        motion = load_motion(CMU_BVH, mapping, units=CMU_UNITS, up="y")
        skeleton = parse_bvh(CMU_BVH).skeleton
        samples = motion.samples()
        body = lower_body(gait.dimensions, motion)
        posed = [body.pose(t) for t in motion.times[::CMU_POSE_STRIDE]]
    tolerance = math.sqrt(3.0) * 0.5 * 10.0 ** -CMU_DIGITS * CMU_UNITS
    for s in ("l", "r"):
        for segment, (a, b) in (("thigh", ("hip", "knee")), ("shank", ("knee", "ankle")), ("foot", ("ankle", "toe"))):
            length = np.linalg.norm(samples[f"{b}_{s}"] - samples[f"{a}_{s}"], axis=1)
            stored = CMU_UNITS * np.linalg.norm(skeleton.offsets[skeleton.names.index(joints[s][b])])
            out.append(result("mocap-roundtrip", f"CMU {CMU_BVH.name}: max | |J2 - J1| - OFFSET | of {segment}_{s} "
                              f"({stored:.4f} m) [m]", float(np.max(np.abs(length - stored))), 0.0, tolerance,
                              len(length), timer.elapsed, scale=1.0))
    out.append(result("mocap-roundtrip", f"CMU {CMU_BVH.name}: frames posed (every {CMU_POSE_STRIDE}th, 8 segments)",
                      len(posed), len(motion.times[::CMU_POSE_STRIDE]), 0.0, len(motion.times), timer.elapsed))


@case("mocap-roundtrip")
def mocap_roundtrip() -> list:
    """One stride of the two-leg walk (`winter_walking`, 100 Hz) written as C3D (mm, float32), TRC (mm, 10
    significant digits) and BVH (cm and degrees, 6 decimals; joint angles, poses by forward kinematics),
    all with the Y-up axis convention, read back and used to pose the lower body: segment centres and
    axes (as r_max ||R - R_ref||_2) equal the analytic poses within 1e-6 m for C3D and TRC (float32 at
    <= 1.5 m in mm: half an ulp <= 6e-8 m) and within `bvh_pose_tolerance` (~2e-7 m) for BVH. Then the
    CMU recording `CMU_BVH` (if installed) poses the lower body, with each leg segment's length equal to
    its file OFFSET within the printed precision on every frame."""
    gait = winter_walking(strides=1)
    times = FRAME_TIME * np.arange(int(gait.time_range[1] / FRAME_TIME) + 1)
    reference = lower_body(gait.dimensions, gait)
    analytic = gait.trajectory(times)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt, write, read in (("c3d", write_c3d, read_c3d), ("trc", write_trc, read_trc)):
            with Timer() as timer:
                path = Path(tmp) / f"gait.{fmt}"
                write(path, analytic, units="mm", up="y")
                body = lower_body(gait.dimensions, read(path, up="y"))
                centre, axes = _pose_errors(body, reference, times)
            for label, value in (("centres", centre), ("axes", axes)):
                out.append(result("mocap-roundtrip", f"{fmt.upper()}: max pose error of the segment {label} [m]",
                                  value, 0.0, 1e-6, len(times), timer.elapsed, scale=1.0))
        with Timer() as timer:
            path = Path(tmp) / "gait.bvh"
            skeleton, motion = _gait_bvh(gait, times, BVH_UNITS)
            write_bvh(path, skeleton, motion, FRAME_TIME, digits=BVH_DIGITS)
            legs = {s: {j: f"{j}_{s}" for j in ("hip", "knee", "ankle")} | {"toe": f"ankle_{s}_end"} for s in "lr"}
            trajectory = load_motion(path, _bvh_mapping(gait, "pelvis", legs["l"], legs["r"]), units=BVH_UNITS)
            body = lower_body(gait.dimensions, trajectory)
            centre, axes = _pose_errors(body, reference, times)
        tolerance = bvh_pose_tolerance(gait, BVH_DIGITS, BVH_UNITS)
        for label, value in (("centres", centre), ("axes", axes)):
            out.append(result("mocap-roundtrip", f"BVH ({BVH_DIGITS} decimals): max pose error of the segment "
                              f"{label} [m]", value, 0.0, tolerance, len(times), timer.elapsed, scale=1.0))
    _cmu_rows(out)
    return out

