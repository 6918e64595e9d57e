"""Walking over an obstacle: four strides of Winter's gait [Winter2009, Table A.1], the third stepping over a
box 0.5 m high [Man2006, sec. 5.4] (docs/bodies.md, "Walking over an obstacle").

Gait phase p (strides, p = 0 at the first heel strike of the trail limb; the lead limb runs half a cycle
ahead, as the right leg of `LowerBodyGait`); u = p - (crossing_stride - 1) is the phase within the crossing
stride. The motion, all of it kinematic:

* Joint angles: Winter's Fourier curves (`fabricfem.body.lower_body`) plus, in the crossing stride, plateau
  bumps (sin^2 ramps, `plateau`) in the swing of each limb: the lead swings in u in [0.109, 0.5], the trail
  in [0.609, 1]. Hip and knee bump amplitudes are solved so that the peaks equal the chosen targets (lead
  hip 95 deg, knee 120 deg: the lead limb onto a 40.6 cm step, 92.5 / 119.9 deg [StepAscent2009]; trail
  hip 60 deg, knee 128 deg: assumed); the ankle bumps have fixed amplitudes. The windows and the ankle
  amplitudes were chosen by a short search (differential evolution, DEFAULT_LOWER_BODY) maximising the
  lowest sole over the box with the angular rates of the bumped curves below 1000 deg per stride phase
  (425 deg/s at the crossing's pace, Winter's knee peaks at 365 deg per stride phase) and the ankle within
  [-50, +30] deg.
* Pelvis forward: x = S p with S = speed x cycle_time the stride length, so the stance feet keep Winter's
  contact; the pace dx/dt is `speed`, eases (raised cosine in time, over half a stride) to `crossing_speed`
  for the whole crossing stride and back: the crossing stride lasts S / crossing_speed.
* Pelvis rise (assumed): a plateau in u with sin^2 ramps from u = 0 to the first instant a foot is over the
  box and from the last back to u = 1; its height is the smallest that lets the lead foot ellipsoid clear
  the box by `clearance` and the trail foot by `trail_clearance` (plus RISE_MARGIN). In the body it stands
  for the standing foot rising onto its toes and the hip hiking; this rigid-segment model does neither, so
  the standing foot leaves the ground by the rise (the model floats).
* The box: depth x full width (2 hip_breadth), centred between the planted trail toe and the lead heel
  strike of the crossing stride.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from fabricfem.body.lower_body import (
    DEFAULT_LOWER_BODY,
    SIDES,
    WINTER_ANKLE_DEG,
    WINTER_CYCLE_TIME,
    WINTER_KNEE_DEG,
    WINTER_SPEED,
    WINTER_THIGH_DEG,
    LowerBodyDimensions,
    fourier_curve,
    lower_body_points,
)
from fabricfem.body.motion import _finite_time

LEAD_SWING = (0.109, 0.5)      # u of toe-off and heel strike of the lead limb (Winter: stance 60.9 %)
TRAIL_SWING = (0.609, 1.0)
# plateau windows (u_a, u_b, u_c, u_d) of the bumps and the ankle amplitudes [deg] (module docstring)
LEAD_WINDOWS = {"hip": (0.109, 0.250, 0.304, 0.478), "knee": (0.109, 0.233, 0.256, 0.418),
                "ankle": (0.109, 0.185, 0.236, 0.489)}
TRAIL_WINDOWS = {"hip": (0.609, 0.895, 0.918, 0.990), "knee": (0.609, 0.735, 0.772, 0.984),
                 "ankle": (0.609, 0.685, 0.792, 0.863)}
LEAD_ANKLE_DEG, TRAIL_ANKLE_DEG = 39.4, -26.0
LEAD_PEAKS_DEG = (95.0, 120.0)     # hip, knee [StepAscent2009]
TRAIL_PEAKS_DEG = (60.0, 128.0)    # assumed
RISE_MARGIN = 0.005     # m: added to the computed rise (covers the sampling of the foot outline)
MAX_RISE = 0.3          # m: why, in the docstring of `obstacle_walk`
OUTLINE_POINTS = 1024   # samples of the foot outline in the clearance computation
PHASE_GRID = 1001       # samples of u in [0, 1] for the box placement and the rise


def plateau(u, window: tuple[float, float, float, float]) -> np.ndarray:
    """0 before u_a, sin^2 ramp up to 1 at u_b, 1 until u_c, cos^2 ramp down to 0 at u_d (C^1)."""
    a, b, c, d = window
    u = np.asarray(u, dtype=float)
    up = np.sin(0.5 * np.pi * np.clip((u - a) / (b - a), 0.0, 1.0)) ** 2
    down = np.cos(0.5 * np.pi * np.clip((u - c) / (d - c), 0.0, 1.0)) ** 2
    return up * down


def bump_amplitude(base: np.ndarray, shape: np.ndarray, peak: float) -> float:
    """A >= 0 [rad] with max(base + A shape) = peak [rad] (0 when the base already reaches it)."""
    if base.max() >= peak:
        return 0.0
    return brentq(lambda a: float(np.max(base + a * shape)) - peak, 0.0, 4.0 * (peak - base.min()))


class _Pace:
    """Pelvis pace v(t) [m/s] and phase p(t): `speed`, a raised-cosine ease to `crossing_speed` over the half
    stride before the crossing stride, the crossing stride at `crossing_speed`, the ease back over the half
    stride after it (ramps shortened at the ends of the walk)."""

    def __init__(self, stride: float, strides: int, crossing: int, speed: float, crossing_speed: float):
        down, up = min(0.5, crossing - 1.0), min(0.5, strides - crossing)
        pieces = [(crossing - 1.0 - down, speed, speed), (down, speed, crossing_speed),
                  (1.0, crossing_speed, crossing_speed), (up, crossing_speed, speed),
                  (strides - crossing - up, speed, speed)]
        pieces = [p for p in pieces if p[0] > 0.0]
        self.stride = stride
        self.length = np.array([p[0] for p in pieces])
        self.v0, self.v1 = np.array([p[1] for p in pieces]), np.array([p[2] for p in pieces])
        self.tau = self.length * stride / (0.5 * (self.v0 + self.v1))
        self.t0 = np.concatenate([[0.0], np.cumsum(self.tau)[:-1]])
        self.p0 = np.concatenate([[0.0], np.cumsum(self.length)[:-1]])
        self.duration = float(np.sum(self.tau))

    def _locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = np.clip(np.searchsorted(self.t0, t, side="right") - 1, 0, len(self.t0) - 1)
        return k, np.clip((t - self.t0[k]) / self.tau[k], 0.0, 1.0)

    def phase(self, t: np.ndarray) -> np.ndarray:
        """p(t) [strides] = p_k + (tau_k / S) (v0 s + (v1 - v0) (s - sin(pi s) / pi) / 2), s in the piece."""
        k, s = self._locate(t)
        dv = self.v1[k] - self.v0[k]
        return self.p0[k] + self.tau[k] / self.stride * (self.v0[k] * s + 0.5 * dv * (s - np.sin(np.pi * s) / np.pi))

    def speed(self, t: np.ndarray) -> np.ndarray:
        """v(t) [m/s]."""
        k, s = self._locate(t)
        return self.v0[k] + 0.5 * (self.v1[k] - self.v0[k]) * (1.0 - np.cos(np.pi * s))

    def time_of_phase(self, p: float) -> float:
        """The time [s] at which the phase reaches p (p at a piece boundary or inside the walk)."""
        return float(brentq(lambda t: float(self.phase(np.array([t]))[0]) - p, 0.0, self.duration))


def foot_outline(dims: LowerBodyDimensions, ankle: np.ndarray, toe: np.ndarray, n: int = OUTLINE_POINTS
                 ) -> np.ndarray:
    """(T, n, 2) sagittal (x, z) outline [m] of the foot ellipsoid (the section through its y-axis, which
    is also its projection on the x-z plane) from the ankle and toe points (T, 3)."""
    axis = (toe - ankle)[:, [0, 2]]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    up = np.column_stack([-axis[:, 1], axis[:, 0]])
    fraction = (0.5 - dims.heel_fraction) / (1.0 - dims.heel_fraction)
    centre = ankle[:, [0, 2]] + fraction * (toe - ankle)[:, [0, 2]]
    theta = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return (centre[:, None, :] + 0.5 * dims.foot_length * np.cos(theta)[None, :, None] * axis[:, None, :]
            + dims.ankle_height * np.sin(theta)[None, :, None] * up[:, None, :])


def rise_needed(outline: np.ndarray, x0: float, x1: float, height: float, clearance: float) -> np.ndarray:
    """(T,) smallest upward shift [m] putting every outline point (T, n, 2) at least `clearance` [m] from the
    rectangle [x0, x1] x [0, height] (point x outside the rectangle's x-range by dx < clearance needs its z
    at height + sqrt(clearance^2 - dx^2); dx >= clearance needs nothing)."""
    x, z = outline[..., 0], outline[..., 1]
    dx = np.maximum(np.maximum(x0 - x, x - x1), 0.0)
    lift = np.sqrt(np.maximum(clearance ** 2 - dx ** 2, 0.0))
    need = np.where(dx < clearance, height + lift - z, -np.inf)
    return need.max(axis=1)


class ObstacleWalk:
    """The obstacle walk (module docstring); a kinematics source like `LowerBodyGait`. Build it with
    `obstacle_walk`, which documents the arguments."""

    def __init__(self, dimensions: LowerBodyDimensions, strides: int, crossing_stride: int, obstacle_height: float,
                 obstacle_depth: float, clearance: float, trail_clearance: float, cycle_time: float, speed: float,
                 crossing_speed: float, lead: str, max_rise: float):
        self.dimensions, self.strides, self.crossing_stride = dimensions, strides, crossing_stride
        self.cycle_time, self.lead, self.max_rise = cycle_time, lead, max_rise
        self.clearance, self.trail_clearance = clearance, trail_clearance
        self.speed, self.crossing_speed = speed, crossing_speed
        self.stride_length = speed * cycle_time
        self.pace = _Pace(self.stride_length, strides, crossing_stride, speed, crossing_speed)
        self._thigh, self._knee, self._ankle = (fourier_curve(c) for c in
                                                (WINTER_THIGH_DEG, WINTER_KNEE_DEG, WINTER_ANKLE_DEG))
        self._amplitudes = {role: self._solve_bumps(role) for role in ("lead", "trail")}
        self._rise_window, self.rise = (0.0, 0.5, 0.5, 1.0), 0.0     # no rise while the box is placed
        self.obstacle = self._place_box(obstacle_height, obstacle_depth)
        self._rise_window, self.rise = self._solve_rise()
        self.names = tuple(self.points(np.zeros(1)))

    # -- the angles -------------------------------------------------------------------------------------
    def _base(self, p: np.ndarray, role: str) -> list[np.ndarray]:
        q = p + (0.5 if role == "lead" else 0.0)
        return [self._thigh(q), self._knee(q), self._ankle(q)]

    def _solve_bumps(self, role: str) -> tuple[float, float, float]:
        windows, peaks = (LEAD_WINDOWS, LEAD_PEAKS_DEG) if role == "lead" else (TRAIL_WINDOWS, TRAIL_PEAKS_DEG)
        u = np.linspace(0.0, 1.0, 20001)
        base = self._base(u + self.crossing_stride - 1.0, role)
        hip = bump_amplitude(base[0], plateau(u, windows["hip"]), math.radians(peaks[0]))
        knee = bump_amplitude(base[1], plateau(u, windows["knee"]), math.radians(peaks[1]))
        return hip, knee, math.radians(LEAD_ANKLE_DEG if role == "lead" else TRAIL_ANKLE_DEG)

    def _role_angles(self, p: np.ndarray, role: str) -> np.ndarray:
        """(T, 3) thigh, knee, ankle [rad] of the lead or trail limb at the phases p."""
        windows = LEAD_WINDOWS if role == "lead" else TRAIL_WINDOWS
        u = p - (self.crossing_stride - 1.0)
        base = self._base(p, role)
        return np.column_stack([b + a * plateau(u, windows[j]) for b, a, j in
                                zip(base, self._amplitudes[role], ("hip", "knee", "ankle"))])

    def _role(self, side: str) -> str:
        if side not in SIDES:
            raise ValueError(f"side must be 'l' or 'r', got {side!r}")
        return "lead" if side == self.lead[0] else "trail"

    def angles(self, times, side: str) -> np.ndarray:
        """(T, 3) hip flexion (thigh from the vertical; the pelvis stays upright), knee flexion and ankle
        dorsiflexion [deg] of leg `side` ("l" or "r") at the times (T,) [s]."""
        p = self.pace.phase(np.atleast_1d(np.asarray(times, dtype=float)))
        return np.degrees(self._role_angles(p, self._role(side)))

    def knee_angle_r(self, times) -> np.ndarray:
        """Right knee flexion [deg], positive in flexion (the sign of Rajagopal 2016's `knee_angle_r`)."""
        return self.angles(times, "r")[:, 1]

    # -- the pelvis ---------------------------------------------------------------------------------------
    def pelvis_rise(self, times) -> np.ndarray:
        """(T,) rise of the hip midpoint above the standing hip height [m] at the times [s]."""
        p = self.pace.phase(np.atleast_1d(np.asarray(times, dtype=float)))
        return self.rise * plateau(p - (self.crossing_stride - 1.0), self._rise_window)

    def pelvis_speed(self, times) -> np.ndarray:
        """(T,) forward speed of the pelvis [m/s] at the times [s]."""
        return self.pace.speed(np.atleast_1d(np.asarray(times, dtype=float)))

    @property
    def crossing_window(self) -> tuple[float, float]:
        """(t0, t1) [s]: start and end of the crossing stride."""
        c = self.crossing_stride
        return self.pace.time_of_phase(c - 1.0), self.pace.time_of_phase(float(c))

    @property
    def time_range(self) -> tuple[float, float]:
        return (0.0, self.pace.duration)

    # -- positions ----------------------------------------------------------------------------------------
    def _points_at_phase(self, p: np.ndarray) -> dict[str, np.ndarray]:
        rise = self.rise * plateau(p - (self.crossing_stride - 1.0), self._rise_window)
        pelvis = np.column_stack([self.stride_length * p, np.zeros_like(p), self.dimensions.hip_height + rise])
        legs = {s: self._role_angles(p, self._role(s)) for s in SIDES}
        return lower_body_points(self.dimensions, pelvis, legs["l"], legs["r"])

    def points(self, times) -> dict[str, np.ndarray]:
        """Joint and marker positions (T, 3) [m] at the times (T,) [s], vectorised."""
        return self._points_at_phase(self.pace.phase(np.atleast_1d(np.asarray(times, dtype=float))))

    def positions(self, t: float) -> dict[str, np.ndarray]:
        return {name: p[0] for name, p in self.points([_finite_time(t)]).items()}

    # -- the box and the rise ----------------------------------------------------------------------------
    def _outlines(self, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Phases u (PHASE_GRID) of the crossing stride and the foot outlines (u, n, 2) by role."""
        u = np.linspace(0.0, 1.0, PHASE_GRID)
        pts = self._points_at_phase(u + self.crossing_stride - 1.0)
        side = {"lead": self.lead[0], "trail": "r" if self.lead == "left" else "l"}
        return u, {role: foot_outline(self.dimensions, pts[f"ankle_{s}"], pts[f"toe_{s}"], n)
                   for role, s in side.items()}

    def _place_box(self, height: float, depth: float) -> tuple[np.ndarray, np.ndarray]:
        u, outline = self._outlines(256)
        toe = outline["trail"][u <= TRAIL_SWING[0], :, 0].max()
        heel = outline["lead"][u >= LEAD_SWING[1], :, 0].min()
        if heel - toe <= depth:
            raise ValueError(f"obstacle_depth ({depth} m) must be below the free length between the planted "
                             f"trail toe and the lead heel strike ({heel - toe:.3f} m)")
        centre, half_width = 0.5 * (toe + heel), self.dimensions.hip_breadth
        return (np.array([centre - 0.5 * depth, -half_width, 0.0]),
                np.array([centre + 0.5 * depth, half_width, height]))

    def over_box(self, outline: np.ndarray) -> np.ndarray:
        """(T,) True where the foot outline (T, n, 2) overlaps the box's x-range."""
        x0, x1 = self.obstacle[0][0], self.obstacle[1][0]
        return (outline[..., 0].max(axis=1) > x0) & (outline[..., 0].min(axis=1) < x1)

    def _solve_rise(self) -> tuple[tuple[float, float, float, float], float]:
        """The rise plateau's window and height [m] (module docstring), from the walk without rise."""
        u, outline = self._outlines(OUTLINE_POINTS)
        (x0, _, _), (x1, _, height) = self.obstacle
        need, over = 0.0, np.zeros(len(u), dtype=bool)
        for role, gap in (("lead", self.clearance), ("trail", self.trail_clearance)):
            here = self.over_box(outline[role])
            over |= here
            if here.any():
                need = max(need, float(rise_needed(outline[role][here], x0, x1, height, gap).max()))
        rise = need + RISE_MARGIN if need > 0.0 else 0.0
        if rise > self.max_rise:
            raise ValueError(f"obstacle_height ({height} m) with clearance {self.clearance} m (lead) and "
                             f"{self.trail_clearance} m (trail) needs a pelvis rise of {rise:.3f} m > max_rise "
                             f"{self.max_rise} m: the leg cannot clear it")
        return (0.0, float(u[over].min()), float(u[over].max()), 1.0), rise


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be positive, got {value!r}")
    return float(value)


def obstacle_walk(dimensions: LowerBodyDimensions = DEFAULT_LOWER_BODY, strides: int = 4, crossing_stride: int = 3,
                  obstacle_height: float = 0.5, obstacle_depth: float = 0.1, clearance: float = 0.12,
                  trail_clearance: float = 0.05, cycle_time: float = WINTER_CYCLE_TIME, speed: float = WINTER_SPEED,
                  crossing_speed: float = 0.6, lead: str = "right", max_rise: float = MAX_RISE) -> ObstacleWalk:
    """Walking `strides` strides of Winter's gait, stride `crossing_stride` (1-based) over a box (module
    docstring).

    Args:
        obstacle_height, obstacle_depth: box height and length along x [m].
        clearance, trail_clearance: smallest distance [m] of the lead / trail foot ellipsoid to the box while
            the foot is over it (lead 0.12 m: toe clearance 0.10-0.15 m of the prescription in the notes;
            trail 0.05 m: the literature's trail clearance is smaller than the lead's, 129-149 vs 148-184 mm
            over obstacles of 10-30 % leg length [SciRep2022, Table 1], and for 0.5 m we accept less).
        cycle_time: stride time [s]; speed: walking speed [m/s] (stride length speed x cycle_time).
        crossing_speed: pace of the crossing stride [m/s] (0.6: 0.64-0.80 m/s over 10-30 % leg length
            [SciRep2022, Table 1], slower for the higher box).
        lead: "right" or "left", the limb that crosses first.
        max_rise: largest pelvis rise [m] accepted (0.3 m, a third of the hip height: about twice what rising
            onto the toes, ~0.15 m for a 0.2 m heel-to-ball length at 50 deg, and hiking the hip give; beyond
            it the crossing is a jump, which this model does not represent).

    Raises ValueError naming the parameter: strides < crossing_stride, non-positive lengths, times or speeds,
    and an obstacle the leg cannot clear within max_rise (named obstacle_height).
    """
    for name, value in (("strides", strides), ("crossing_stride", crossing_stride)):
        if int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if strides < crossing_stride:
        raise ValueError(f"strides ({strides}) must be at least crossing_stride ({crossing_stride})")
    for name, value in (("obstacle_height", obstacle_height), ("obstacle_depth", obstacle_depth),
                        ("cycle_time", cycle_time), ("speed", speed), ("crossing_speed", crossing_speed)):
        _positive(name, value)
    for name, value in (("clearance", clearance), ("trail_clearance", trail_clearance), ("max_rise", max_rise)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name} must be a non-negative length [m], got {value!r}")
    if lead not in ("left", "right"):
        raise ValueError(f"lead must be 'left' or 'right', got {lead!r}")
    return ObstacleWalk(dimensions, int(strides), int(crossing_stride), float(obstacle_height), float(obstacle_depth),
                        float(clearance), float(trail_clearance), float(cycle_time), float(speed),
                        float(crossing_speed), lead, float(max_rise))
