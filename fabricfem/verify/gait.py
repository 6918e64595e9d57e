"""The obstacle walk (fabricfem.body.crossing) checked on the posed body, record by record (every 10 ms).

* Joint angles recovered from the posed segments' long axes e1 (`Body.pose`, i.e. `segment_frame`, not the
  code that built the positions): hip = signed sagittal angle from the pelvis axis (waist -> crotch) to the
  thigh axis, knee = from the thigh to the shank (flexion positive), ankle = from the shank to the foot
  minus 90 deg; against the prescribed angles within 0.1 deg.
* Segment lengths |J2 - J1| against the dimensions to 1e-12 relative.
* Clearance of each foot ellipsoid from the box while the foot overlaps the box's x-range: a certified
  lower bound of the distance, max over sampled unit directions n of  min_{box corners v} n.v - h_E(n)
  with the ellipsoid's support function h_E(n) = c.n + |diag(r) R^T n| (each direction separates the two
  convex sets by at least that much, so every term is <= the distance); an upper bound from sampled surface
  points (exact point-to-box distances). Passes when the lower bound >= the prescribed clearance.
"""
from __future__ import annotations

import numpy as np

from fabricfem.body.crossing import ObstacleWalk, obstacle_walk
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.lower_body import lower_body
from fabricfem.body.placement import fibonacci_sphere
from fabricfem.verify import CaseResult, Timer, case, result

NAME = "gait-kinematics"
RECORD_DT = 0.01          # s
ANGLE_TOLERANCE = 0.1     # deg
DIRECTIONS = 20000        # sampled unit directions of the lower bound
SURFACE_POINTS = 20000    # sampled surface points of the upper bound
LENGTHS = {"trunk": "rise", "pelvis": "rise", "thigh": "thigh_length", "shank": "shank_length",
           "foot": "toe_distance"}   # segment kind -> LowerBodyDimensions attribute of |J2 - J1|


def sagittal_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Signed angle [deg] from a to b (T, 3), positive for a rotation carrying -z towards +x (about -y)."""
    return -np.degrees(np.arctan2(np.cross(a, b)[:, 1], np.sum(a * b, axis=1)))


def box_distance_bounds(e: Ellipsoid, lower: np.ndarray, upper: np.ndarray, directions: np.ndarray,
                        unit_points: np.ndarray) -> tuple[float, float]:
    """(lower, upper) bounds [m] of the distance of ellipsoid e to the box [lower, upper] (module docstring)."""
    corners = np.array([[x, y, z] for x in (lower[0], upper[0]) for y in (lower[1], upper[1])
                        for z in (lower[2], upper[2])])
    support = directions @ e.center + np.linalg.norm((directions @ e.rotation) * e.radii, axis=1)
    lower_bound = float(np.max(np.min(directions @ corners.T, axis=1) - support))
    surface = e.center + (unit_points * e.radii) @ e.rotation.T
    outside = np.maximum(np.maximum(lower - surface, surface - upper), 0.0)
    return lower_bound, float(np.min(np.linalg.norm(outside, axis=1)))


def _x_extent(e: Ellipsoid) -> tuple[float, float]:
    half = float(np.linalg.norm(e.rotation[0] * e.radii))
    return e.center[0] - half, e.center[0] + half


def _range_row(quantity: str, value: float, low: float, high: float, wall: float) -> CaseResult:
    return CaseResult(NAME, f"{quantity} in [{low:g}, {high:g}]", value, 0.5 * (low + high), float("nan"),
                      float("nan"), bool(low <= value <= high), 0, wall)


def _clearance_rows(walk: ObstacleWalk, poses: list, wall: float) -> list[CaseResult]:
    lower, upper = walk.obstacle
    directions, unit_points = fibonacci_sphere(DIRECTIONS), fibonacci_sphere(SURFACE_POINTS)
    out = []
    lead = walk.lead[0]
    for side in "rl":
        role, gap = ("lead", walk.clearance) if side == lead else ("trail", walk.trail_clearance)
        bounds = [box_distance_bounds(p[f"foot_{side}"], lower, upper, directions, unit_points) for p in poses
                  if _x_extent(p[f"foot_{side}"])[1] > lower[0] and _x_extent(p[f"foot_{side}"])[0] < upper[0]]
        lb, ub = (min(b[i] for b in bounds) for i in (0, 1))
        out.append(CaseResult(NAME, f"{role} foot ({side}) over the box, {len(bounds)} records: certified lower "
                              f"bound of the least distance to the box [m] >= clearance {gap:g} (upper bound "
                              f"{ub:.5f})", lb, gap, (lb - gap) / gap, 0.0, bool(lb >= gap and len(bounds) > 0),
                              len(bounds), wall))
    return out


@case(NAME)
def gait_kinematics() -> list[CaseResult]:
    """The default obstacle walk on DEFAULT_LOWER_BODY (module docstring)."""
    with Timer() as timer:
        walk = obstacle_walk()
        body = lower_body(walk.dimensions, walk)
        times = np.arange(0.0, walk.time_range[1], RECORD_DT)
        poses = [body.pose(t) for t in times]
        axis = {name: np.array([p[name].rotation[:, 0] for p in poses]) for name in body.segments}
        points = walk.points(times)
    wall = timer.elapsed
    out = []
    for s in "rl":
        recovered = np.column_stack([sagittal_angle(axis["pelvis"], axis[f"thigh_{s}"]),
                                     -sagittal_angle(axis[f"thigh_{s}"], axis[f"shank_{s}"]),
                                     sagittal_angle(axis[f"shank_{s}"], axis[f"foot_{s}"]) - 90.0])
        error = np.abs(recovered - walk.angles(times, s)).max(axis=0)
        for name, e in zip(("hip", "knee", "ankle"), error):
            out.append(result(NAME, f"max |{name}_{s} posed - prescribed| over {len(times)} records [deg]", e, 0.0,
                              ANGLE_TOLERANCE, len(times), wall, scale=1.0))
    dims = walk.dimensions
    worst = 0.0
    for seg in body.segments.values():
        length = np.linalg.norm(points[seg.distal] - points[seg.proximal], axis=1)
        nominal = getattr(dims, LENGTHS[seg.name.split("_")[0]])
        worst = max(worst, float(np.max(np.abs(length / nominal - 1.0))))
    out.append(result(NAME, "max | |J2 - J1| / length - 1 | over the segments and records", worst, 0.0, 1e-12,
                      len(times), wall, scale=1.0))
    out += _clearance_rows(walk, poses, wall)
    lead = walk.lead[0]
    peaks = walk.angles(times, lead).max(axis=0)
    out.append(_range_row(f"peak lead hip flexion ({lead}) [deg]", peaks[0], 90.0, 100.0, wall))
    out.append(_range_row(f"peak lead knee flexion ({lead}) [deg]", peaks[1], 115.0, 125.0, wall))
    rise = float(np.max(points["hip_l"][:, 2]) - dims.hip_height)
    out.append(result(NAME, "pelvis rise [m] (computed: the standing foot floats by it)", rise, walk.rise, 1e-9,
                      len(times), wall))
    t0, t1 = walk.crossing_window
    inside = (times > t0) & (times < t1)
    pace = np.diff(points["hip_l"][inside, 0]) / RECORD_DT
    worst_pace = float(pace[np.argmax(np.abs(pace - walk.crossing_speed))])
    out.append(result(NAME, "pelvis pace in the crossing stride (records' differences), farthest [m/s]",
                      worst_pace, walk.crossing_speed, 1e-9, int(inside.sum()), wall))
    return out
