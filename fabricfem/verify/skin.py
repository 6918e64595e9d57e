"""The blended skin (fabricfem.body.blended) across the creases of the arm and the lower body: continuity of the gap
and the normal, the gap against an independent closest-point search on a triangulation, and the rounding bound."""
from __future__ import annotations

import math

import igl
import numpy as np
from skimage.measure import find_contours

from fabricfem.body import default_arm, elbow_flexion, lower_body, obstacle_walk
from fabricfem.body.blended import BlendedEllipsoids, closest_points, triangulate
from fabricfem.verify import Timer, case, result

FLEXION_DEG = 120.0          # the arm's flexion and the crossing's peak knee flexion of the acceptance
PATH_SPACING = 1e-3          # m: points of the paths across the crease
OFFSETS = (-0.002, 0.002)    # m: points 2 mm inside and outside the skin along its normal (where the cloth is)
PLANE_OFFSETS = (0.0, 0.015, -0.015)   # m: the paths' planes, through the joint and beside it
TURN_LIMIT_DEG = 5.0         # largest turn of the normal between path points 1 mm apart
TRIANGULATION = 1e-3         # m: marching-cubes spacing of the independent triangulation
GAP_TOLERANCE = 1e-4         # m: analytic gap against the triangulation's closest point
CONTOUR_GRID = 2e-4          # m: the grid on which the paths are traced (find_contours)
HALF_WIDTH = 0.04            # m: the paths reach this far from the crease


def arm_crease(flexion_deg: float = FLEXION_DEG) -> tuple[BlendedEllipsoids, float, np.ndarray, np.ndarray]:
    """The default arm flexed to `flexion_deg`, its time [s], the elbow [m] and the unit bisector of the two
    segment axes (pointing into the crease)."""
    kinematics = elbow_flexion(final_angle=math.radians(flexion_deg))
    body = default_arm(kinematics)
    t = kinematics.time_range[1]
    p = kinematics.positions(t)
    return BlendedEllipsoids(body), t, p["elbow"], _bisector(p["shoulder"] - p["elbow"], p["wrist"] - p["elbow"])


def knee_crease() -> tuple[BlendedEllipsoids, float, np.ndarray, np.ndarray]:
    """The lower body of the obstacle crossing at the lead knee's peak flexion (120 deg), its time [s], the knee
    [m] and the bisector of thigh and shank."""
    walk = obstacle_walk()
    body = lower_body(kinematics=walk)
    t0, t1 = walk.time_range
    times = np.linspace(t0, t1, 4001)
    side = "r" if "knee_r" in walk.names else "l"
    angles = walk.knee_angle_r(times)
    t = float(times[int(np.argmax(angles))])
    p = walk.positions(t)
    knee, hip, ankle = p[f"knee_{side}"], p[f"hip_{side}"], p[f"ankle_{side}"]
    return BlendedEllipsoids(body), t, knee, _bisector(hip - knee, ankle - knee)


def _bisector(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    u = a / np.linalg.norm(a) + b / np.linalg.norm(b)
    return u / np.linalg.norm(u)


def crease_paths(skin: BlendedEllipsoids, t: float, joint: np.ndarray, bisector: np.ndarray
                 ) -> list[np.ndarray]:
    """Paths across the crease: the skin's sections by planes through the bisector (and beside it), traced on a
    CONTOUR_GRID by marching squares (skimage.measure.find_contours, independent of the closest-point code),
    resampled every PATH_SPACING of arc length within HALF_WIDTH of the crease point."""
    s = np.linspace(0.0, 0.3, 30001)
    along = joint + s[:, None] * bisector
    crease = along[int(np.argmax(skin.implicit(along, t) > 0.0))]
    across = np.cross(np.cross(bisector, np.array([0.0, 0.0, 1.0])), bisector)
    normal_to_plane = np.cross(bisector, across / np.linalg.norm(across))
    e1, e2 = bisector, np.cross(normal_to_plane, bisector)
    grid = np.arange(-HALF_WIDTH, HALF_WIDTH + CONTOUR_GRID, CONTOUR_GRID)
    a, b = np.meshgrid(grid, grid, indexing="ij")
    paths = []
    for offset in PLANE_OFFSETS:
        centre = crease + offset * normal_to_plane
        points = centre + a[..., None] * e1 + b[..., None] * e2
        phi = skin.implicit(points.reshape(-1, 3), t).reshape(a.shape)
        contour = max(find_contours(phi, 0.0), key=len)
        curve = centre + (contour[:, :1] * CONTOUR_GRID - HALF_WIDTH) * e1 + (contour[:, 1:] * CONTOUR_GRID
                                                                              - HALF_WIDTH) * e2
        curve = curve[np.linalg.norm(curve - centre, axis=1) < 0.9 * HALF_WIDTH]
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
        samples = np.arange(0.0, arc[-1], PATH_SPACING)
        paths.append(np.stack([np.interp(samples, arc, curve[:, i]) for i in range(3)], axis=1))
    return paths


def crease_rows(name: str, skin: BlendedEllipsoids, t: float, joint: np.ndarray, bisector: np.ndarray) -> list:
    """The rows of one crease: the normal's largest turn per mm and the gap's continuity on each offset path, the
    gap against the triangulation, the rounding against the segments' exact distance."""
    out = []
    with Timer() as timer:
        paths = crease_paths(skin, t, joint, bisector)
        posed = skin.posed(t)
        on_skin = [closest_points(p, *posed, skin.widths) for p in paths]
    for offset in OFFSETS:
        turns, jumps = [], []
        for skin_point in on_skin:
            q = closest_points(skin_point.foot + offset * skin_point.normal, *posed, skin.widths)
            cosine = np.clip((q.normal[1:] * q.normal[:-1]).sum(axis=1), -1.0, 1.0)
            turns.append(np.degrees(np.arccos(cosine)).max())
            jumps.append(np.abs(q.gap - offset).max())
        out.append(result("skin-continuity", f"{name}, offset {1e3 * offset:+g} mm: largest turn of the normal "
                          f"between points {1e3 * PATH_SPACING:g} mm apart [deg]", max(turns), 0.0, TURN_LIMIT_DEG,
                          sum(len(p) for p in paths), timer.elapsed, scale=1.0))
        out.append(result("skin-continuity", f"{name}, offset {1e3 * offset:+g} mm: largest |gap - offset| [m]",
                          max(jumps), 0.0, 1e-8, sum(len(p) for p in paths), timer.elapsed, scale=1.0))
    with Timer() as timer:
        probe = np.concatenate([q.foot + OFFSETS[-1] * q.normal for q in on_skin])
        centre = probe.mean(axis=0)
        vertices, triangles = triangulate(lambda x: skin.implicit(x, t), (centre - 0.06, centre + 0.06),
                                          TRIANGULATION)
        squared, _, _ = igl.point_mesh_squared_distance(probe, vertices, triangles)
        gap = closest_points(probe, *posed, skin.widths).gap
    out.append(result("skin-continuity", f"{name}: max |gap - distance to the {1e3 * TRIANGULATION:g} mm "
                      f"triangulation| [m]", float(np.abs(np.sqrt(squared) - gap).max()), 0.0, GAP_TOLERANCE,
                      len(probe), timer.elapsed, scale=1.0))
    feet = np.concatenate([q.foot for q in on_skin])
    ellipsoids = skin.body.pose(t)
    union = np.min([e.closest_point(feet)[1] for e in ellipsoids.values()], axis=0)
    out.append(result("skin-continuity", f"{name}: largest distance of the skin outside the segments' union [m] "
                      f"(bound w / 4 = {skin.rounding_bound:g} m)", float(union.max()), 0.0, skin.rounding_bound,
                      len(feet), timer.elapsed, scale=1.0))
    return out


@case("skin-continuity")
def skin_continuity() -> list:
    """The blended skin on the arm flexed to 120 deg and the lower body at the crossing's 120 deg knee, along paths
    across the crease (three planes, on the skin and 2 mm out): the normal turns by less than 5 deg between points
    1 mm apart (the acceptance), the gap of a point placed at a known offset along the normal equals it (1e-8 m:
    the closest-point iteration's tolerance 1e-9 m plus rounding), the gap agrees with libigl's closest point on a
    1 mm marching-cubes triangulation of the same surface within 1e-4 m (the triangulation's chord error is
    ~ h^2 kappa / 8 ~ 1e-5 m at the blend's ~ 1 cm radius, plus the linear interpolation of phi), and the skin lies
    outside the union of the segments by at most the documented rounding w / 4 (exact ellipsoid distances)."""
    return crease_rows("arm at 120 deg", *arm_crease()) + crease_rows("knee at the crossing", *knee_crease())
