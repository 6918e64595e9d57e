"""The lower body of the pants study [Man2006, sec. 5.4]: eight ellipsoid segments sized from ANSUR II
adult male medians [ANSUR2014], a standing pose and a two-leg gait.

Frame: x forward (walking direction), y left, z up, ground z = 0; the left leg is at +y.

Segments (J1, J2, M; radii (r1 along J1->J2, r2 towards M, r3)):

    trunk     waist -> chest,     M trunk_marker (front)  (D, r_w, r_w), centre at the waist
    pelvis    waist -> crotch,    M pelvis_marker (front) (r_v, r_ap, hip_breadth / 2)
    thigh_s   hip_s -> knee_s,    M thigh_marker_s        (f L_t, r_t, r_t)
    shank_s   knee_s -> ankle_s,  M shank_marker_s        (f L_s, r_c, r_c)
    foot_s    ankle_s -> toe_s,   M foot_marker_s (above) (L_f / 2, h_a, b_f / 2)

for the sides s = l, r, with r = C / (2 pi) the circle-equivalent radius of a girth C, f the long-axis
factor (as `fabricfem.body.arm`), h_a the ankle height and b_f the foot breadth. Derived here:

* hip joints at height H = L_t + L_s + h_a (legs straight, foot flat) and +-w / 2 laterally, w the hip
  joint spacing; default w = thigh_girth / pi (the two thighs touch at the midline);
* pelvis (its own joints: the waist and crotch points on the midline, D = waist_height - crotch_height
  apart): the largest horizontal section, at the centre, is an ellipse (r_ap front-back,
  hip_breadth / 2 lateral) of perimeter buttock_girth (Ramanujan's perimeter formula); the bottom tip is at
  crotch height and the section at waist height is a similar ellipse of perimeter waist_girth:
  with q = sqrt(1 - (waist_girth / buttock_girth)^2), r_v = D / (1 + q), centre r_v above the crotch;
* trunk: a spheroid of the waist girth centred at the waist, semi-axis D along the body axis (from the
  crotch up to `chest`, D above the waist): the region a waistband touches, not a model of the chest;
* foot: the toe point lies (1 - heel_fraction) L_f ahead of the ankle at ankle height, the centre
  (1/2 - heel_fraction) L_f ahead of the ankle, so the ellipsoid runs from heel to toe tip and, with
  vertical semi-axis h_a, stands on z = 0 when the foot is flat.

Markers sit `MARKER_OFFSET` from the segment midpoints: laterally (outwards) on thighs and shanks,
above the foot (perpendicular to its axis in the sagittal plane), in front of the pelvis centre and
of the waist (trunk). The hip joints belong to the thighs only (`Body.check_joint("hip_l")` refuses):
the pelvis joints are the waist (shared with the trunk) and the crotch.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from fabricfem.body.motion import JointTrajectory, KinematicsSource, _finite_time
from fabricfem.body.pose import Body, Segment
from fabricfem.body.schedule import SegmentSchedule

MARKER_OFFSET = 0.15   # m: distance of the markers from their segment midpoints
SIDES = {"l": 1.0, "r": -1.0}   # lateral sign: the left side is at +y


def ellipse_perimeter(a: float, b: float) -> float:
    """Ramanujan's approximation pi (3 (a + b) - sqrt((3a + b)(a + 3b))) [m] (relative error < 4e-5
    for b / a >= 0.5)."""
    return math.pi * (3.0 * (a + b) - math.sqrt((3.0 * a + b) * (a + 3.0 * b)))


@dataclass(frozen=True)
class LowerBodyDimensions:
    """Lengths and girths [m] of the lower body (defaults: ANSUR II male medians [ANSUR2014], except
    where marked assumed); each is overridable (a scene key).

    Args:
        thigh_length, shank_length: hip-knee and knee-ankle lengths (0.408, 0.418).
        foot_length, foot_breadth: 0.271, 0.102.
        thigh_girth, calf_girth, ankle_girth: 0.624, 0.392, 0.228 (ankle_girth: for the trouser hem;
            the ellipsoid shank does not taper to it).
        hip_breadth: standing hip breadth 0.344.
        waist_girth, buttock_girth: 0.937 (omphalion), 1.017.
        waist_height, crotch_height: 1.055 (omphalion), 0.845.
        ankle_height: lateral malleolus height 0.073 (as `fabricfem.body.motion.LegKinematics`).
        heel_fraction: part of the foot length behind the ankle joint, 0.2 (assumed).
        hip_spacing: distance between the hip joint centres; None: thigh_girth / pi (derived).
        long_axis_factor: thigh and shank long semi-axis / length, in [0.5, 1] (0.5: tips at the joints).
    """

    thigh_length: float = 0.408
    shank_length: float = 0.418
    foot_length: float = 0.271
    foot_breadth: float = 0.102
    thigh_girth: float = 0.624
    calf_girth: float = 0.392
    ankle_girth: float = 0.228
    hip_breadth: float = 0.344
    waist_girth: float = 0.937
    buttock_girth: float = 1.017
    waist_height: float = 1.055
    crotch_height: float = 0.845
    ankle_height: float = 0.073
    heel_fraction: float = 0.2
    hip_spacing: float | None = None
    long_axis_factor: float = 0.5

    def __post_init__(self):
        for name in ("thigh_length", "shank_length", "foot_length", "foot_breadth", "thigh_girth", "calf_girth",
                     "ankle_girth", "hip_breadth", "waist_girth", "buttock_girth", "waist_height", "crotch_height",
                     "ankle_height"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be a positive length [m], got {v!r}")
        if self.hip_spacing is not None and not (math.isfinite(self.hip_spacing) and self.hip_spacing > 0.0):
            raise ValueError(f"hip_spacing must be a positive length [m] or None, got {self.hip_spacing!r}")
        if not (0.0 <= self.heel_fraction < 0.5):
            raise ValueError(f"heel_fraction must lie in [0, 0.5), got {self.heel_fraction!r}")
        if not (0.5 <= self.long_axis_factor <= 1.0):
            raise ValueError(f"long_axis_factor must lie in [0.5, 1], got {self.long_axis_factor!r}")
        if self.waist_height <= self.crotch_height:
            raise ValueError(f"waist_height ({self.waist_height} m) must exceed crotch_height ({self.crotch_height} m)")
        if self.waist_girth >= self.buttock_girth:
            raise ValueError(f"waist_girth ({self.waist_girth} m) must be below buttock_girth "
                             f"({self.buttock_girth} m) for the pelvis ellipsoid")
        if self.buttock_girth <= 4.0 * 0.5 * self.hip_breadth:
            raise ValueError(f"buttock_girth ({self.buttock_girth} m) must exceed twice hip_breadth "
                             f"({2 * self.hip_breadth} m): no ellipse has that perimeter")

    @property
    def hip_height(self) -> float:
        """Hip joint height H = L_t + L_s + h_a [m] (standing, derived)."""
        return self.thigh_length + self.shank_length + self.ankle_height

    @property
    def hip_joint_spacing(self) -> float:
        """Distance between the hip joint centres [m] (hip_spacing, or thigh_girth / pi)."""
        return self.hip_spacing if self.hip_spacing is not None else self.thigh_girth / math.pi

    @property
    def thigh_radius(self) -> float:
        return self.thigh_girth / (2.0 * math.pi)

    @property
    def calf_radius(self) -> float:
        return self.calf_girth / (2.0 * math.pi)

    @property
    def ankle_radius(self) -> float:
        return self.ankle_girth / (2.0 * math.pi)

    @property
    def rise(self) -> float:
        """D = waist_height - crotch_height [m]."""
        return self.waist_height - self.crotch_height

    @property
    def pelvis_radii(self) -> tuple[float, float, float]:
        """(vertical, front-back, lateral) semi-axes of the pelvis [m] (module docstring)."""
        a = 0.5 * self.hip_breadth
        r_ap = brentq(lambda b: ellipse_perimeter(a, b) - self.buttock_girth, 1e-6 * a, self.buttock_girth)
        q = math.sqrt(1.0 - (self.waist_girth / self.buttock_girth) ** 2)
        return self.rise / (1.0 + q), r_ap, a

    @property
    def toe_distance(self) -> float:
        """Ankle to toe point [m]: (1 - heel_fraction) L_f."""
        return (1.0 - self.heel_fraction) * self.foot_length

    def segments(self) -> tuple[Segment, ...]:
        """The eight segments (trunk, pelvis, thigh/shank/foot left and right)."""
        f, r_t, r_c = self.long_axis_factor, self.thigh_radius, self.calf_radius
        r_w = self.waist_girth / (2.0 * math.pi)
        foot_centre = (0.5 - self.heel_fraction) / (1.0 - self.heel_fraction)
        r_v = self.pelvis_radii[0]
        out = [Segment("trunk", "waist", "chest", "trunk_marker", (self.rise, r_w, r_w), center_fraction=0.0),
               Segment("pelvis", "waist", "crotch", "pelvis_marker", self.pelvis_radii,
                       center_fraction=(self.rise - r_v) / self.rise)]
        for s in SIDES:
            out += [Segment(f"thigh_{s}", f"hip_{s}", f"knee_{s}", f"thigh_marker_{s}",
                            (f * self.thigh_length, r_t, r_t)),
                    Segment(f"shank_{s}", f"knee_{s}", f"ankle_{s}", f"shank_marker_{s}",
                            (f * self.shank_length, r_c, r_c)),
                    Segment(f"foot_{s}", f"ankle_{s}", f"toe_{s}", f"foot_marker_{s}",
                            (0.5 * self.foot_length, self.ankle_height, 0.5 * self.foot_breadth),
                            center_fraction=foot_centre)]
        return tuple(out)


DEFAULT_LOWER_BODY = LowerBodyDimensions()


def lower_body_points(dims: LowerBodyDimensions, pelvis: np.ndarray, left: np.ndarray, right: np.ndarray
                      ) -> dict[str, np.ndarray]:
    """Joint and marker positions [m] of the sagittal lower-body chain, vectorised over T samples.

    Args:
        pelvis: (T, 3) midpoint of the hip joints [m]; the pelvis does not rotate.
        left, right: (T, 3) leg angles [rad]: thigh flexion from the vertical phi_h, knee flexion phi_k,
            ankle dorsiflexion phi_a. Thigh direction (sin phi_h, 0, -cos phi_h); shank at
            phi_h - phi_k from the vertical; foot at beta = phi_h - phi_k + phi_a above the horizontal,
            direction (cos beta, 0, sin beta).
    """
    pelvis = np.asarray(pelvis, dtype=float)
    zero = np.zeros(len(pelvis))
    up = np.array([0.0, 0.0, 1.0])
    front = np.array([MARKER_OFFSET, 0.0, 0.0])
    waist = pelvis + (dims.waist_height - dims.hip_height) * up
    crotch = waist - dims.rise * up
    out = {"waist": waist, "crotch": crotch, "chest": waist + dims.rise * up, "trunk_marker": waist + front,
           "pelvis_marker": crotch + dims.pelvis_radii[0] * up + front}
    for s, angles in (("l", left), ("r", right)):
        phi_h, phi_k, phi_a = np.asarray(angles, dtype=float).T
        side = np.array([0.0, SIDES[s], 0.0])
        shank_angle, beta = phi_h - phi_k, phi_h - phi_k + phi_a
        hip = pelvis + 0.5 * dims.hip_joint_spacing * side
        knee = hip + dims.thigh_length * np.column_stack([np.sin(phi_h), zero, -np.cos(phi_h)])
        ankle = knee + dims.shank_length * np.column_stack([np.sin(shank_angle), zero, -np.cos(shank_angle)])
        foot_axis = np.column_stack([np.cos(beta), zero, np.sin(beta)])
        foot_up = np.column_stack([-np.sin(beta), zero, np.cos(beta)])
        toe = ankle + dims.toe_distance * foot_axis
        out.update({f"hip_{s}": hip, f"knee_{s}": knee, f"ankle_{s}": ankle, f"toe_{s}": toe,
                    f"thigh_marker_{s}": 0.5 * (hip + knee) + MARKER_OFFSET * side,
                    f"shank_marker_{s}": 0.5 * (knee + ankle) + MARKER_OFFSET * side,
                    f"foot_marker_{s}": 0.5 * (ankle + toe) + MARKER_OFFSET * foot_up})
    return out


def standing(dimensions: LowerBodyDimensions = DEFAULT_LOWER_BODY, duration: float = 1.0) -> JointTrajectory:
    """Standing still for `duration` [s]: legs straight, feet flat on z = 0, hip midpoint at (0, 0, H)."""
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be positive [s], got {duration!r}")
    pelvis = np.tile([0.0, 0.0, dimensions.hip_height], (2, 1))
    return JointTrajectory([0.0, duration], lower_body_points(dimensions, pelvis, np.zeros((2, 3)), np.zeros((2, 3))))


def fourier_curve(coefficients: tuple[float, ...]) -> Callable[[np.ndarray], np.ndarray]:
    """theta(p) = a0 + sum_k a_k cos(2 pi k p) + b_k sin(2 pi k p) [deg -> rad], coefficients
    (a0, a1, b1, a2, b2, ...), p the gait phase (period 1)."""
    a0, rest = coefficients[0], np.reshape(coefficients[1:], (-1, 2))
    k = np.arange(1, len(rest) + 1)

    def curve(p):
        arg = 2.0 * np.pi * np.multiply.outer(np.asarray(p, dtype=float), k)
        return np.radians(a0 + np.cos(arg) @ rest[:, 0] + np.sin(arg) @ rest[:, 1])
    return curve


# Fourier fit (k = 1..4, degrees, phase 0 at heel strike) of the sagittal angles of Winter's normal walking
# data [Winter2009, Table A.1]; fit residuals (rms) 0.28, 0.49, 0.87 deg.
WINTER_THIGH_DEG = (6.52, 18.87, -6.86, -4.89, -0.96, -0.30, 1.70, -0.25, 0.03)
WINTER_KNEE_DEG = (21.78, -7.48, -19.31, -12.95, 9.01, 0.12, 3.59, -0.93, 0.81)
WINTER_ANKLE_DEG = (-3.02, 1.12, 9.00, 2.16, -9.35, -2.24, 0.37, 2.23, -1.37)
WINTER_CYCLE_TIME = 0.987   # s, stride time [Winter2009, Table A.1]
WINTER_SPEED = 1.43         # m/s


@dataclass
class LowerBodyGait:
    """Both legs driven by thigh, knee and ankle angle curves of the gait phase p (period 1, rad),
    the right leg half a cycle behind the left (phase p + 1/2); the hip midpoint moves at `speed` along
    x at the standing hip height (vertical pelvis motion neglected). A kinematics source.

    Args:
        thigh, knee, ankle: vectorised functions of the phase -> angle [rad] (see `lower_body_points`).
        cycle_time: stride time [s]; strides: number of cycles (duration = strides x cycle_time).
        speed: walking speed [m/s].
    """

    thigh: Callable[[np.ndarray], np.ndarray]
    knee: Callable[[np.ndarray], np.ndarray]
    ankle: Callable[[np.ndarray], np.ndarray]
    dimensions: LowerBodyDimensions = DEFAULT_LOWER_BODY
    cycle_time: float = WINTER_CYCLE_TIME
    strides: int = 2
    speed: float = WINTER_SPEED
    names: tuple[str, ...] = field(init=False)

    def __post_init__(self):
        if not (math.isfinite(self.cycle_time) and self.cycle_time > 0.0):
            raise ValueError(f"cycle_time must be positive [s], got {self.cycle_time!r}")
        if int(self.strides) != self.strides or self.strides < 1:
            raise ValueError(f"strides must be a positive integer, got {self.strides!r}")
        if not math.isfinite(self.speed):
            raise ValueError(f"speed must be finite [m/s], got {self.speed!r}")
        self.names = tuple(self.points(np.zeros(1)))

    @property
    def time_range(self) -> tuple[float, float]:
        return (0.0, self.strides * self.cycle_time)

    def angles(self, times, side: str) -> np.ndarray:
        """(T, 3) thigh, knee, ankle angles [rad] of leg `side` ("l" or "r") at the times [s]."""
        if side not in SIDES:
            raise ValueError(f"side must be 'l' or 'r', got {side!r}")
        p = np.asarray(times, dtype=float) / self.cycle_time + (0.5 if side == "r" else 0.0)
        return np.column_stack([self.thigh(p), self.knee(p), self.ankle(p)])

    def points(self, times) -> dict[str, np.ndarray]:
        """Joint and marker positions (T, 3) [m] at the times (T,) [s], vectorised."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        pelvis = np.column_stack([self.speed * t, np.zeros_like(t), np.full_like(t, self.dimensions.hip_height)])
        return lower_body_points(self.dimensions, pelvis, self.angles(t, "l"), self.angles(t, "r"))

    def trajectory(self, times) -> JointTrajectory:
        """The motion sampled at the times [s] (e.g. to write a motion file)."""
        return JointTrajectory(times, self.points(times))

    def positions(self, t: float) -> dict[str, np.ndarray]:
        return {name: p[0] for name, p in self.points([_finite_time(t)]).items()}


def winter_walking(dimensions: LowerBodyDimensions = DEFAULT_LOWER_BODY, strides: int = 2,
                   cycle_time: float = WINTER_CYCLE_TIME, speed: float = WINTER_SPEED) -> LowerBodyGait:
    """Normal walking of both legs from the Fourier fit of [Winter2009, Table A.1] (constants above)."""
    return LowerBodyGait(fourier_curve(WINTER_THIGH_DEG), fourier_curve(WINTER_KNEE_DEG),
                         fourier_curve(WINTER_ANKLE_DEG), dimensions, cycle_time, strides, speed)


def lower_body(dimensions: LowerBodyDimensions = DEFAULT_LOWER_BODY, kinematics: KinematicsSource | None = None,
               schedule: SegmentSchedule | None = None) -> Body:
    """The eight-segment lower body; kinematics default: `standing(dimensions)`."""
    return Body(dimensions.segments(), kinematics if kinematics is not None else standing(dimensions), schedule)
