"""Posing ellipsoidal segments from joint and marker positions ([Man2006, sec. 5.1], Fig. 35).

For a segment with joints J1, J2 and auxiliary marker M (positions in m):

    x^c = (J1 + J2) / 2                                              ([Man2006, sec. 5.1], "Center")
    e1 = (J2 - J1) / |J2 - J1|
    e2 = [(M - x^c) - ((M - x^c) . e1) e1] / |...|,   e3 = e1 x e2     ([Man2006, sec. 5.1], "Orientations")

so e1 runs along the segment, e2 points from the axis towards the marker and the ellipsoid radii
(r1, r2, r3) are the semi-axes along (e1, e2, e3). A `Body` is a set of named segments sharing named
joints; a kinematics source (`fabricfem.body.motion`) supplies the joint and marker positions at
time t [s], and `Body.pose(t)` returns the posed ellipsoids.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid, _as_points, nearest_gap
from fabricfem.body.motion import KinematicsSource
from fabricfem.body.schedule import SegmentSchedule

MIN_SEGMENT_LENGTH = 1e-9    # m: J1 and J2 closer than this are treated as coincident
MIN_MARKER_OFFSET = 1e-9     # m: marker closer than this to the long axis does not fix a direction


def _point(name: str, value) -> np.ndarray:
    p = np.asarray(value, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be a finite point of shape (3,), got {value!r}")
    return p


def _labels(names: tuple[str, str, str] | None, segment: str | None) -> tuple[str, str, str, str]:
    """(prefix, J1, J2, M) of the messages: the segment's and points' names, or the symbols J1, J2, M."""
    prefix = f"segment {segment!r}: " if segment is not None else ""
    if names is None:
        return prefix, "J1", "J2", "M"
    return prefix, names[0], names[1], repr(names[2])


def _degenerate(length, distance, offset) -> tuple[np.ndarray, np.ndarray]:
    """(J1 and J2 coincide, the marker is on the long axis) for axis lengths |J2 - J1|, marker distances from the
    axis and marker distances from the centre [m] (scalars or arrays of frames): the thresholds of
    `segment_frame`."""
    length, distance, offset = (np.asarray(v, dtype=float) for v in (length, distance, offset))
    coincide = length < MIN_SEGMENT_LENGTH
    collinear = (distance < MIN_MARKER_OFFSET) | (distance < 1e-9 * np.maximum(offset, length))
    return coincide, collinear & ~coincide


def segment_frame(J1, J2, M, center_fraction: float = 0.5, names: tuple[str, str, str] | None = None,
                  segment: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centre x^c [m] and rotation R = [e1 e2 e3] of a segment [Man2006, sec. 5.1].

    Args:
        J1, J2: proximal and distal joint positions [m].
        M: auxiliary marker [m], not on the line J1-J2.
        center_fraction: x^c = J1 + f (J2 - J1); the thesis uses f = 1/2.
        names, segment: the names of J1, J2, M and of the segment, for the messages.

    Raises:
        ValueError when J1 and J2 coincide or M lies on the long axis (naming the segment, marker and joints).
    """
    j1, j2, m = _point("J1", J1), _point("J2", J2), _point("marker", M)
    if not (0.0 <= center_fraction <= 1.0):
        raise ValueError(f"center_fraction must lie in [0, 1], got {center_fraction!r}")
    axis = j2 - j1
    length = float(np.linalg.norm(axis))
    prefix, a, b, marker = _labels(names, segment)
    if _degenerate(length, 1.0, 1.0)[0]:
        raise ValueError(f"{prefix}the joints {a} and {b} coincide (|J2 - J1| = {length:.3g} m): the long axis is "
                         "undefined")
    center = j1 + center_fraction * axis
    e1 = axis / length
    offset = m - center
    perpendicular = offset - np.dot(offset, e1) * e1
    distance = float(np.linalg.norm(perpendicular))
    if _degenerate(length, distance, float(np.linalg.norm(offset)))[1]:
        raise ValueError(f"{prefix}marker {marker} is collinear with the long axis {a}-{b}: it does not fix the "
                         "rotation about the axis")
    e2 = perpendicular / distance
    e3 = np.cross(e1, e2)
    return center, np.column_stack([e1, e2, e3])


def check_posable(segments: Sequence[Segment], times: np.ndarray, samples: Mapping[str, np.ndarray]) -> None:
    """Every segment can be posed on every frame of sampled positions (`samples`: name -> (T, 3) [m] at `times`
    [s]): its joints apart and its marker off its long axis (vectorised over the frames, the thresholds of
    `segment_frame`).

    Raises:
        ValueError from `segment_frame` naming the segment, its marker and joints, with the first such frame and
        its time.
    """
    for s in segments:
        j1, j2, m = (np.asarray(samples[n], dtype=float) for n in (s.proximal, s.distal, s.marker))
        axis = j2 - j1
        length = np.linalg.norm(axis, axis=1)
        e1 = axis / np.maximum(length, MIN_SEGMENT_LENGTH)[:, None]
        offset = m - (j1 + s.center_fraction * axis)
        perpendicular = offset - np.sum(offset * e1, axis=1)[:, None] * e1
        coincide, collinear = _degenerate(length, np.linalg.norm(perpendicular, axis=1),
                                          np.linalg.norm(offset, axis=1))
        for k in np.flatnonzero(coincide | collinear):
            try:
                segment_frame(j1[k], j2[k], m[k], s.center_fraction, (s.proximal, s.distal, s.marker), s.name)
            except ValueError as exc:
                raise ValueError(f"{exc} (frame {k}, t = {times[k]:.6g} s)") from None


@dataclass(frozen=True)
class Segment:
    """A body segment: an ellipsoid posed from two joints and a marker.

    Args:
        name: segment name, e.g. "forearm".
        proximal: name of joint J1 (e.g. "elbow").
        distal: name of joint J2 (e.g. "wrist").
        marker: name of the auxiliary marker M.
        radii: semi-axes (r1 along J1->J2, r2 towards the marker, r3) [m], each > 0.
        center_fraction: centre position along J1->J2 (1/2 in the thesis).
    """

    name: str
    proximal: str
    distal: str
    marker: str
    radii: tuple[float, float, float]
    center_fraction: float = 0.5

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        if self.proximal == self.distal:
            raise ValueError(f"segment {self.name!r}: proximal and distal joints must differ "
                             f"(J1 == J2 == {self.proximal!r})")
        radii = tuple(float(r) for r in self.radii)
        if len(radii) != 3 or not all(math.isfinite(r) and r > 0.0 for r in radii):
            raise ValueError(f"segment {self.name!r}: radii must be three positive lengths, got {self.radii!r}")
        if not (0.0 <= self.center_fraction <= 1.0):
            raise ValueError(f"segment {self.name!r}: center_fraction must lie in [0, 1]")
        object.__setattr__(self, "radii", radii)

    def pose(self, positions: Mapping[str, np.ndarray]) -> Ellipsoid:
        """The ellipsoid for the given joint/marker positions [m] (a name -> (3,) mapping)."""
        center, rotation = segment_frame(positions[self.proximal], positions[self.distal],
                                         positions[self.marker], self.center_fraction,
                                         (self.proximal, self.distal, self.marker), self.name)
        return Ellipsoid(center, rotation, np.array(self.radii))


def _vee(skew: np.ndarray) -> np.ndarray:
    """Axial vector of the skew part of a 3x3 matrix."""
    return 0.5 * np.array([skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1]])


class Body:
    """Named ellipsoidal segments joined at named joints, driven by a kinematics source.

    Args:
        segments: the segments (unique names).
        kinematics: source of joint and marker positions over time (see `fabricfem.body.motion`).
        schedule: segment groups switched off over time intervals (`active(t)`); default: all on.
    """

    def __init__(self, segments: Sequence[Segment], kinematics: KinematicsSource,
                 schedule: SegmentSchedule | None = None):
        names = [s.name for s in segments]
        if len(names) == 0:
            raise ValueError("segments must not be empty")
        if len(set(names)) != len(names):
            raise ValueError(f"segments: duplicate segment names in {names}")
        available = set(kinematics.names)
        for s in segments:
            missing = [p for p in (s.proximal, s.distal, s.marker) if p not in available]
            if missing:
                raise ValueError(f"segment {s.name!r}: kinematics has no point named {missing} "
                                 f"(available: {sorted(available)})")
        self.segments: dict[str, Segment] = {s.name: s for s in segments}
        self.kinematics = kinematics
        self.schedule = schedule
        if schedule is not None:
            for group, (names, _) in schedule.groups.items():
                try:
                    self.check_segments(names)
                except ValueError as err:
                    raise ValueError(f"schedule group {group!r}: {err}") from None

    def check_segments(self, names: Sequence[str]) -> list[str]:
        """The segment names as a list; ValueError for an empty set or naming the unknown segments."""
        names = [names] if isinstance(names, str) else list(names)
        if not names:
            raise ValueError("segments: the segment set is empty")
        unknown = [n for n in names if n not in self.segments]
        if unknown:
            raise ValueError(f"segments: unknown segments {unknown} (known: {list(self.segments)})")
        return names

    def check_joint(self, name: str) -> list[str]:
        """The segments that share joint `name` (as J1 or J2); ValueError naming the joint when fewer than
        two do (a torque about it would have no distal/proximal pair)."""
        sharing = [n for n, s in self.segments.items() if name in (s.proximal, s.distal)]
        if len(sharing) < 2:
            raise ValueError(f"joint {name!r} is shared by {len(sharing)} segment(s) {sharing}, need 2 "
                             f"(joints: {list(self.joints)})")
        return sharing

    def active(self, t: float) -> list[str]:
        """Names of the segments switched on at time t [s] (all without a schedule), in segment order."""
        off = self.schedule.inactive(t) if self.schedule is not None else set()
        return [n for n in self.segments if n not in off]

    @property
    def joints(self) -> tuple[str, ...]:
        """Joint names (the J1/J2 names of the segments)."""
        seen: dict[str, None] = {}
        for s in self.segments.values():
            seen.setdefault(s.proximal)
            seen.setdefault(s.distal)
        return tuple(seen)

    def segment(self, name: str) -> Segment:
        if name not in self.segments:
            raise ValueError(f"segment: unknown segment name {name!r} (known: {sorted(self.segments)})")
        return self.segments[name]

    def pose(self, t: float) -> dict[str, Ellipsoid]:
        """Posed ellipsoids at time t [s], by segment name."""
        positions = self.kinematics.positions(t)
        return {name: s.pose(positions) for name, s in self.segments.items()}

    def joint_position(self, name: str, t: float) -> np.ndarray:
        """Position [m] of a joint or marker at time t [s]."""
        if name not in self.kinematics.names:
            raise ValueError(f"name: unknown joint or marker {name!r}")
        return np.asarray(self.kinematics.positions(t)[name], dtype=float)

    def velocities(self, t: float, dt: float = 1e-4) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Rigid-body velocity (v_center [m/s], omega [rad/s]) of each segment at time t [s].

        Central differences of the posed frames over +-dt (one-sided at the ends of the kinematics'
        time range): v_c = dx^c/dt, omega = axial(dR/dt R^T); truncation error O(dt^2) (O(dt) one-sided).
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a positive time step [s], got {dt!r}")
        t0, t1 = self.kinematics.time_range
        ta, tb = max(t - dt, t0), min(t + dt, t1)
        if tb <= ta:
            raise ValueError(f"t: no time window around t = {t} within {self.kinematics.time_range}")
        before, now, after = self.pose(ta), self.pose(t), self.pose(tb)
        out = {}
        for name in self.segments:
            v_c = (after[name].center - before[name].center) / (tb - ta)
            rate = (after[name].rotation - before[name].rotation) / (tb - ta)
            out[name] = (v_c, _vee(rate @ now[name].rotation.T))
        return out

    def gap(self, x, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Smallest gap over the segments active at time t [s] (see `Ellipsoid.gap`, `active`).

        Returns:
            (g [m] (N,), unit outward normal (N, 3), index (N,) into `list(self.segments)`); with no
            segment active: g = inf, normal 0, index -1.
        """
        pts, _ = _as_points(x)
        active = self.active(t)
        if not active:
            return np.full(len(pts), np.inf), np.zeros((len(pts), 3)), np.full(len(pts), -1, dtype=np.int64)
        posed = self.pose(t)
        g, n, k = nearest_gap(pts, [posed[name] for name in active])
        order = np.array([list(self.segments).index(name) for name in active], dtype=np.int64)
        return g, n, order[k]
