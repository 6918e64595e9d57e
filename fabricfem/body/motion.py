"""Kinematics sources: joint and marker positions over time for posing the body [Man2006, sec. 5.1].

A kinematics source has `names` (the joints and markers it knows), `time_range` (t_start, t_end) [s]
and `positions(t)` -> {name: (3,) position [m]}. Provided here:

* `ElbowFlexion`: upper arm fixed, forearm rotating about the elbow at constant angular velocity up
  to a final angle (the sleeve study, [Man2006, sec. 5.3]: 57 degrees).
* `JointTrajectory`: positions sampled at given times, linearly interpolated; the motion-capture
  readers of `fabricfem.body.mocap` (C3D, BVH, TRC, CSV) build one.
* `LegKinematics` with `walking` / `stepping_over`: a planar hip-knee-ankle chain driven by
  prescribed hip and knee flexion curves (see `fabricfem.body.gait` notes below).

Joint torque sign convention (`joint_torque`): for contact forces f_i [N] exerted by the clothing at
points x_i [m], the torque about a joint at J along the unit flexion axis a is

    tau = a . sum_i (x_i - J) x f_i   [N m],

positive when the clothing pushes the distal segment in the direction of positive flexion (right-
handed rotation about a). The resisting torque reported for the sleeve study is -tau: positive when
the clothing opposes flexion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Mapping, Protocol, runtime_checkable

import numpy as np
from scipy.optimize import brentq


@runtime_checkable
class KinematicsSource(Protocol):
    names: tuple[str, ...]
    time_range: tuple[float, float]

    def positions(self, t: float) -> dict[str, np.ndarray]:
        ...


def _finite_time(t) -> float:
    if not isinstance(t, (int, float, np.floating, np.integer)) or not math.isfinite(t):
        raise ValueError(f"t must be a finite time [s], got {t!r}")
    return float(t)


def _vector(name: str, value) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite vector of shape (3,), got {value!r}")
    return v


def rotation_about(axis, angle: float) -> np.ndarray:
    """Rotation matrix for a right-handed rotation by `angle` [rad] about the unit vector `axis`
    (Rodrigues: R = I + sin a K + (1 - cos a) K^2)."""
    return _rodrigues(_axis_matrices(axis), angle)


def _axis_matrices(axis) -> tuple[np.ndarray, np.ndarray]:
    """(K, K^2) of `rotation_about` for the axis normalised: K v = a x v."""
    a = _vector("axis", axis)
    a = a / np.linalg.norm(a)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return K, K @ K


def _rodrigues(matrices: tuple[np.ndarray, np.ndarray], angle: float) -> np.ndarray:
    """R = I + sin a K + (1 - cos a) K^2 from the (K, K^2) of `_axis_matrices` and the angle [rad]."""
    K, K2 = matrices
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K2


def joint_torque(points, forces, joint, axis) -> float:
    """tau = a . sum_i (x_i - J) x f_i [N m] (sign convention in the module docstring)."""
    x = np.atleast_2d(np.asarray(points, dtype=float))
    f = np.atleast_2d(np.asarray(forces, dtype=float))
    if x.shape != f.shape or x.shape[1] != 3:
        raise ValueError(f"points and forces must both have shape (N, 3), got {x.shape} and {f.shape}")
    a = _vector("axis", axis)
    norm = np.linalg.norm(a)
    if norm == 0.0:
        raise ValueError("axis must be non-zero")
    return float(np.dot(np.cross(x - _vector("joint", joint), f).sum(axis=0), a / norm))


# ------------------------------------------------------------------------------------------------
# Elbow flexion [Man2006, sec. 5.3]
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ElbowFlexion:
    """Forearm flexing about the elbow at constant angular velocity; upper arm fixed [Man2006, sec. 5.3].

    The flexion angle is alpha(t) = clip(omega (t - t_start), 0, final_angle) [rad]; the forearm
    points (wrist, forearm marker) rotate about `axis` (unit, right-handed: positive alpha is
    flexion) through the elbow. Beyond t_end = t_start + final_angle / omega the arm holds still.

    Args:
        shoulder, elbow, wrist: joint positions in the extended pose [m].
        axis: flexion axis (normalised here); positive rotation about it is flexion.
        angular_velocity: omega [rad/s] > 0 (default 45 deg/s; 30-60 deg/s is a typical voluntary
            flexion speed; the thesis gives no value).
        final_angle: total rotation [rad] ([Man2006, sec. 5.3]: 57 degrees), > 0.
        marker_offset: the markers sit at the segment midpoints displaced by this vector [m]
            (must not be parallel to the segments).
        t_start: time the flexion starts [s].
    """

    shoulder: tuple[float, float, float] = (0.0, 0.0, 0.0)
    elbow: tuple[float, float, float] = (0.335, 0.0, 0.0)
    wrist: tuple[float, float, float] = (0.602, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    angular_velocity: float = math.radians(45.0)
    final_angle: float = math.radians(57.0)
    marker_offset: tuple[float, float, float] = (0.0, 0.0, 0.1)
    t_start: float = 0.0
    names: tuple[str, ...] = ("shoulder", "elbow", "wrist", "upper_arm_marker", "forearm_marker")

    def __post_init__(self):
        for name in ("shoulder", "elbow", "wrist", "axis", "marker_offset"):
            _vector(name, getattr(self, name))
        if np.linalg.norm(self.axis) == 0.0:
            raise ValueError("axis must be non-zero")
        if not (math.isfinite(self.angular_velocity) and self.angular_velocity > 0.0):
            raise ValueError(f"angular_velocity must be positive [rad/s], got {self.angular_velocity!r}")
        if not (math.isfinite(self.final_angle) and 0.0 < self.final_angle < math.pi):
            raise ValueError(f"final_angle must lie in (0, pi) rad, got {self.final_angle!r}")
        _finite_time(self.t_start)

    @property
    def unit_axis(self) -> np.ndarray:
        a = np.asarray(self.axis, dtype=float)
        return a / np.linalg.norm(a)

    @property
    def t_end(self) -> float:
        """Time [s] at which the final angle is reached."""
        return self.t_start + self.final_angle / self.angular_velocity

    @property
    def time_range(self) -> tuple[float, float]:
        return (self.t_start, self.t_end)

    def time_at(self, angle: float) -> float:
        """Time t [s] at which the flexion reaches `angle` [rad] (the inverse of `angle` on the flexion)."""
        return self.t_start + angle / self.angular_velocity

    def angle(self, t: float) -> float:
        """Flexion angle alpha(t) [rad]."""
        t = _finite_time(t)
        return min(max(self.angular_velocity * (t - self.t_start), 0.0), self.final_angle)

    def angular_velocity_vector(self, t: float) -> np.ndarray:
        """Angular velocity of the forearm [rad/s] (omega a while flexing, 0 before and after)."""
        t = _finite_time(t)
        moving = self.t_start < t < self.t_end
        return self.unit_axis * (self.angular_velocity if moving else 0.0)

    def positions(self, t: float) -> dict[str, np.ndarray]:
        fixed = self._fixed_points
        rot = _rodrigues(self._axis_matrices, self.angle(t))
        return {
            "shoulder": fixed["shoulder"].copy(),
            "elbow": fixed["elbow"].copy(),
            "wrist": fixed["elbow"] + rot @ fixed["wrist_arm"],
            "upper_arm_marker": fixed["upper_arm_marker"].copy(),
            "forearm_marker": fixed["elbow"] + rot @ fixed["forearm_marker_arm"],
        }

    @cached_property
    def _fixed_points(self) -> dict[str, np.ndarray]:
        """The points [m] that `positions` needs at every time: the shoulder, the elbow, the upper-arm marker,
        and the wrist and forearm marker relative to the elbow in the extended pose."""
        shoulder, elbow, wrist = (np.asarray(p, dtype=float) for p in (self.shoulder, self.elbow, self.wrist))
        offset = np.asarray(self.marker_offset, dtype=float)
        forearm_marker0 = 0.5 * (elbow + wrist) + offset
        return {"shoulder": shoulder, "elbow": elbow, "wrist_arm": wrist - elbow,
                "upper_arm_marker": 0.5 * (shoulder + elbow) + offset, "forearm_marker_arm": forearm_marker0 - elbow}

    @cached_property
    def _axis_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, K^2) of the flexion axis (`rotation_about`), computed once."""
        return _axis_matrices(self.unit_axis)

    def resisting_torque(self, points, forces) -> float:
        """Clothing resistance to flexion [N m]: -tau about the elbow and flexion axis (positive when
        the forces f_i [N] at points x_i [m] oppose flexion)."""
        return -joint_torque(points, forces, self.elbow, self.unit_axis)


# ------------------------------------------------------------------------------------------------
# Sampled trajectories and motion-capture readers
# ------------------------------------------------------------------------------------------------
class JointTrajectory:
    """Joint/marker positions sampled at times t_k, linearly interpolated in between.

    Args:
        times: strictly increasing sample times [s], shape (T,), T >= 2.
        positions: name -> (T, 3) positions [m]; all finite.
    """

    def __init__(self, times, positions: Mapping[str, np.ndarray]):
        t = np.asarray(times, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
            raise ValueError("times must be a 1-D array of at least 2 strictly increasing finite values [s]")
        if len(positions) == 0:
            raise ValueError("positions must name at least one joint or marker")
        data = []
        for name, p in positions.items():
            arr = np.asarray(p, dtype=float)
            if arr.shape != (len(t), 3):
                raise ValueError(f"positions[{name!r}] must have shape ({len(t)}, 3), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                bad = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))[0])
                raise ValueError(f"positions[{name!r}] has a missing/non-finite value at sample {bad} "
                                 f"(t = {t[bad]} s)")
            data.append(arr)
        self.times = t
        self.names: tuple[str, ...] = tuple(positions)
        self._data = np.stack(data, axis=1)  # (T, K, 3)

    @property
    def time_range(self) -> tuple[float, float]:
        return (float(self.times[0]), float(self.times[-1]))

    def positions(self, t: float) -> dict[str, np.ndarray]:
        t = _finite_time(t)
        t0, t1 = self.time_range
        if not (t0 <= t <= t1):
            raise ValueError(f"t = {t} s is outside the trajectory's time range [{t0}, {t1}]")
        k = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2))
        w = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        p = (1.0 - w) * self._data[k] + w * self._data[k + 1]
        return {name: p[i].copy() for i, name in enumerate(self.names)}

    def renamed(self, mapping: Mapping[str, str]) -> "JointTrajectory":
        """A copy with names replaced (e.g. motion-capture labels -> the body's joint names)."""
        unknown = [m for m in mapping if m not in self.names]
        if unknown:
            raise ValueError(f"mapping: unknown names {unknown} (known: {list(self.names)})")
        return JointTrajectory(self.times, {mapping.get(n, n): self._data[:, i] for i, n in enumerate(self.names)})

    def samples(self) -> dict[str, np.ndarray]:
        """The sampled positions, name -> (T, 3) [m] (copies), at `times`."""
        return {name: self._data[:, i].copy() for i, name in enumerate(self.names)}

    def resampled(self, times) -> "JointTrajectory":
        """The trajectory linearly interpolated at new `times` [s] (strictly increasing, inside
        `time_range`); vectorised over the new times."""
        t = np.asarray(times, dtype=float)
        t0, t1 = self.time_range
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
            raise ValueError("times must be a 1-D array of at least 2 strictly increasing finite values [s]")
        if t[0] < t0 or t[-1] > t1:
            raise ValueError(f"times: [{t[0]}, {t[-1]}] s reaches outside the trajectory's time range [{t0}, {t1}]")
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        w = ((t - self.times[k]) / (self.times[k + 1] - self.times[k]))[:, None, None]
        data = (1.0 - w) * self._data[k] + w * self._data[k + 1]
        return JointTrajectory(t, {name: data[:, i] for i, name in enumerate(self.names)})


# ------------------------------------------------------------------------------------------------
# Gait: planar leg driven by prescribed hip and knee flexion curves
# ------------------------------------------------------------------------------------------------
# Normal walking, sagittal plane, one gait cycle from initial contact (0) to the next (1):
# (fraction of cycle, angle in degrees). Key points of the normative curves described in
# J. Perry, J. M. Burnfield, "Gait Analysis: Normal and Pathological Function", 2nd ed., SLACK 2010,
# ch. 11 (hip) and 12 (knee), and D. A. Winter, "Biomechanics and Motor Control of Human Movement",
# 4th ed., 2009, appendix A (normal gait): knee 5 deg at initial contact, ~18 deg loading-response peak
# at ~15 %, ~5 deg at ~40 % (terminal stance), ~40 deg at toe-off (~60 %), ~60 deg swing peak at ~72 %,
# back to ~5 deg; hip ~30 deg flexed at contact, ~-10 deg (extension) at ~50 %, ~35 deg peak at ~85 %.
# These are approximate key points read from those descriptions, NOT digitised data: use them as a
# plausible prescribed motion, not as a measured reference.
WALKING_KNEE_FLEXION_DEG = ((0.0, 5.0), (0.15, 18.0), (0.40, 5.0), (0.60, 40.0), (0.72, 60.0),
                            (0.87, 25.0), (1.0, 5.0))
WALKING_HIP_FLEXION_DEG = ((0.0, 30.0), (0.30, 5.0), (0.50, -10.0), (0.62, 0.0), (0.85, 35.0), (1.0, 30.0))
SWING_WINDOW = (0.60, 1.0)   # fraction of the cycle in which the foot is off the ground


def periodic_curve(keypoints: tuple[tuple[float, float], ...]) -> Callable[[np.ndarray], np.ndarray]:
    """Periodic C2 cubic spline through (phase, degrees) key points -> function of phase returning rad."""

    phase = np.array([p for p, _ in keypoints])
    value = np.radians([v for _, v in keypoints])
    if phase[0] != 0.0 or phase[-1] != 1.0 or not math.isclose(value[0], value[-1]):
        raise ValueError("keypoints must span phase 0 to 1 with equal end values (periodic)")
    from scipy.interpolate import CubicSpline  # loaded only for a gait curve (0.1 s of imports)

    spline = CubicSpline(phase, value, bc_type="periodic")
    return lambda s: spline(np.mod(s, 1.0))


def crossing_angles(obstacle_height: float, thigh: float, shank: float, hip_height: float,
                    clearance: float = 0.05, shank_tilt: float = math.radians(-20.0)) -> tuple[float, float]:
    """Hip and knee flexion [rad] that lift the ankle to obstacle_height + clearance [m] in a planar leg.

    Ankle height y_a = H - L_t cos(phi_hip) - L_s cos(phi_hip - phi_knee) (angles from the vertical,
    flexion positive); with the shank at `shank_tilt` from the vertical (negative: foot behind the knee)
    this gives phi_hip = arccos((H - h - c - L_s cos(tilt)) / L_t) and phi_knee = phi_hip - tilt. A
    kinematic construction (pelvis rise, abduction and stance-limb plantarflexion neglected, so the
    angles are upper estimates), not measured data.
    """
    for name, v in (("obstacle_height", obstacle_height), ("thigh", thigh), ("shank", shank),
                    ("hip_height", hip_height)):
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"{name} must be a positive length [m], got {v!r}")
    cos_hip = (hip_height - obstacle_height - clearance - shank * math.cos(shank_tilt)) / thigh
    if not -1.0 <= cos_hip <= 1.0:
        raise ValueError(f"obstacle_height: {obstacle_height} m cannot be cleared by this leg")
    hip = math.acos(cos_hip)
    return hip, hip - shank_tilt


@dataclass
class LegKinematics:
    """Planar hip-knee-ankle chain in the x (walking direction) - z (up) plane driven by flexion curves.

    hip(t) = hip0 + (speed t, 0, 0); knee = hip + L_t (sin phi_h, 0, -cos phi_h); ankle = knee +
    L_s (sin(phi_h - phi_k), 0, -cos(phi_h - phi_k)) with hip flexion phi_h and knee flexion phi_k [rad]
    from `hip_flexion(t)`, `knee_flexion(t)`. Markers sit laterally (+y) at the segment midpoints.
    Names: hip, knee, ankle, thigh_marker, shank_marker.
    """

    hip_flexion: Callable[[float], float]
    knee_flexion: Callable[[float], float]
    duration: float
    thigh: float = 0.409          # ANSUR II male thigh link (mean 409.3 mm), m
    shank: float = 0.419          # ANSUR II male calf link (mean 418.8 mm), m
    hip_height: float = 0.901     # m, derived: thigh + shank + ANSUR II male lateral malleolus height 0.073 m
    speed: float = 1.3            # walking speed, m/s (typical adult self-selected speed)
    marker_offset: float = 0.08   # lateral marker distance, m
    names: tuple[str, ...] = field(default=("hip", "knee", "ankle", "thigh_marker", "shank_marker"))

    def __post_init__(self):
        for name in ("duration", "thigh", "shank", "hip_height", "marker_offset"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be positive, got {v!r}")

    @property
    def time_range(self) -> tuple[float, float]:
        return (0.0, self.duration)

    def angles(self, t: float) -> tuple[float, float]:
        """(hip flexion, knee flexion) [rad] at t [s]."""
        t = _finite_time(t)
        return float(self.hip_flexion(t)), float(self.knee_flexion(t))

    def positions(self, t: float) -> dict[str, np.ndarray]:
        phi_h, phi_k = self.angles(t)
        hip = np.array([self.speed * t, 0.0, self.hip_height])
        knee = hip + self.thigh * np.array([math.sin(phi_h), 0.0, -math.cos(phi_h)])
        shank_angle = phi_h - phi_k
        ankle = knee + self.shank * np.array([math.sin(shank_angle), 0.0, -math.cos(shank_angle)])
        lateral = np.array([0.0, self.marker_offset, 0.0])
        return {"hip": hip, "knee": knee, "ankle": ankle,
                "thigh_marker": 0.5 * (hip + knee) + lateral, "shank_marker": 0.5 * (knee + ankle) + lateral}


def walking(strides: int = 4, cycle_time: float = 1.1, **leg) -> LegKinematics:
    """Right leg walking `strides` gait cycles of `cycle_time` [s] (normative curves above)."""
    if int(strides) != strides or strides < 1:
        raise ValueError(f"strides must be a positive integer, got {strides!r}")
    if not (math.isfinite(cycle_time) and cycle_time > 0.0):
        raise ValueError(f"cycle_time must be positive [s], got {cycle_time!r}")
    knee, hip = periodic_curve(WALKING_KNEE_FLEXION_DEG), periodic_curve(WALKING_HIP_FLEXION_DEG)
    return LegKinematics(lambda t: hip(t / cycle_time), lambda t: knee(t / cycle_time),
                         duration=strides * cycle_time, **leg)


def stepping_over(obstacle_height: float = 0.5, strides: int = 4, crossing_stride: int = 3,
                  cycle_time: float = 1.1, **leg) -> LegKinematics:
    """Walking in which the swing of stride `crossing_stride` (1-based) clears an obstacle (thesis
    sec. 5.4: four strides, the third over a 0.5 m obstacle). In that stride hip and knee flexion get
    an extra A x sin^2 bump over `SWING_WINDOW`, A chosen so that the swing peaks equal the targets of
    `crossing_angles(...)` (a kinematic construction, see there). Hip and knee peak at slightly
    different instants, so the ankle rises somewhat less than the construction's height."""
    if not (1 <= crossing_stride <= strides):
        raise ValueError(f"crossing_stride must lie in [1, strides], got {crossing_stride!r}")
    base = walking(strides, cycle_time, **leg)
    hip_peak, knee_peak = crossing_angles(obstacle_height, base.thigh, base.shank, base.hip_height)
    knee, hip = periodic_curve(WALKING_KNEE_FLEXION_DEG), periodic_curve(WALKING_HIP_FLEXION_DEG)

    lo, hi = SWING_WINDOW
    s = np.linspace(lo, hi, 801)
    window = np.sin(np.pi * (s - lo) / (hi - lo)) ** 2

    def extra(curve, target: float) -> float:
        # bump amplitude A with max_s(curve(s) + A window(s)) = target (monotone in A)
        base_curve = curve(s)
        excess = target - float(np.max(base_curve))
        if excess <= 0.0:
            return 0.0
        return brentq(lambda a: float(np.max(base_curve + a * window)) - target, 0.0, 4.0 * excess + 1.0)

    knee_extra, hip_extra = extra(knee, knee_peak), extra(hip, hip_peak)

    def bump(t: float) -> float:
        cycle = t / cycle_time
        if not (crossing_stride - 1 <= cycle < crossing_stride):
            return 0.0
        phase = cycle - (crossing_stride - 1)
        if not (lo <= phase <= hi):
            return 0.0
        return math.sin(math.pi * (phase - lo) / (hi - lo)) ** 2

    return LegKinematics(lambda t: hip(t / cycle_time) + hip_extra * bump(t),
                         lambda t: knee(t / cycle_time) + knee_extra * bump(t),
                         duration=strides * cycle_time, **leg)
