"""Posed segments of a Body cached over the last few times of an explicit run: one pose per step
(fabricfem.contact.explicit.ExplicitBodyContact)."""
from __future__ import annotations

import math

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid


class PoseCache:
    """Posed segments and joint positions of a `Body` at the last few times [s]. An explicit step asks for
    the pose at t_{n+2} and the joint position at t_{n+1}, which the previous step has posed already (the
    same floating-point time), so each step poses the body once. Returns the same ellipsoids as
    `Body.pose(t)` (in segment order) and the same points as `Body.joint_position`."""

    SIZE = 3

    def __init__(self, body):
        self.body = body
        self._positions: dict[float, dict] = {}
        self._ellipsoids: dict[float, list[Ellipsoid]] = {}
        self._last_pose: dict[str, tuple[bytes, Ellipsoid]] = {}   # segment -> (its three points, its pose)
        self._validated = False

    def positions(self, t: float) -> dict:
        t = float(t)
        p = self._positions.get(t)
        if p is None:
            if len(self._positions) >= self.SIZE:
                self._positions.pop(next(iter(self._positions)))
            p = self._positions[t] = self.body.kinematics.positions(t)
        return p

    def ellipsoids(self, t: float) -> list[Ellipsoid]:
        t = float(t)
        e = self._ellipsoids.get(t)
        if e is None:
            if len(self._ellipsoids) >= self.SIZE:
                self._ellipsoids.pop(next(iter(self._ellipsoids)))
            positions = self.positions(t)
            if self._validated:
                e = [self._posed(name, s, positions) for name, s in self.body.segments.items()]
            else:   # the first pose goes through the validating constructors (Segment.pose, Ellipsoid)
                e = [s.pose(positions) for s in self.body.segments.values()]
                self._validated = True
            self._ellipsoids[t] = e
        return e

    def _posed(self, name: str, segment, positions: dict) -> Ellipsoid:
        """`_posed_segment`, or the segment's last pose when its joints and marker have not moved (the same
        function of the same three points: a still upper arm is posed once)."""
        key = b"".join(np.asarray(positions[p], dtype=float).tobytes()
                       for p in (segment.proximal, segment.distal, segment.marker))
        last = self._last_pose.get(name)
        if last is not None and last[0] == key:
            return last[1]
        posed = _posed_segment(segment, positions)
        self._last_pose[name] = (key, posed)
        return posed

    def joint(self, name: str, t: float) -> np.ndarray:
        """Position [m] of a joint or marker at time t (ValueError for an unknown name)."""
        if name not in self.body.kinematics.names:
            raise ValueError(f"name: unknown joint or marker {name!r}")
        return np.asarray(self.positions(t)[name], dtype=float)


def _posed_segment(segment, positions) -> Ellipsoid:
    """`Segment.pose` (fabricfem.body.pose.segment_frame, [Man2006, sec. 5.1]) with the same arithmetic but
    without re-validating the inputs of every explicit step (the rigid motion keeps the frame proper; the
    first pose of a PoseCache is validated): x^c = J1 + f (J2 - J1), e1 = (J2 - J1) / |J2 - J1|,
    e2 = the unit part of M - x^c normal to e1, e3 = e1 x e2. On Python floats: the products and sums of three
    of numpy's dot and norm in the same order, without the calls on 3-vectors."""
    j1, j2, marker = (np.asarray(positions[name], dtype=float).tolist()
                      for name in (segment.proximal, segment.distal, segment.marker))
    axis = [b - a for a, b in zip(j1, j2)]
    length = math.sqrt(_dot(axis, axis))
    center = [a + segment.center_fraction * d for a, d in zip(j1, axis)]
    e1 = [d / length for d in axis]
    offset = [m - c for m, c in zip(marker, center)]
    along = _dot(offset, e1)
    perpendicular = [o - along * e for o, e in zip(offset, e1)]
    width = math.sqrt(_dot(perpendicular, perpendicular))
    e2 = [p / width for p in perpendicular]
    e3 = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
    return unchecked_ellipsoid(np.array(center), np.array(list(zip(e1, e2, e3))), np.array(segment.radii, dtype=float))


def _dot(a: list[float], b: list[float]) -> float:
    """a . b of two 3-vectors as numpy sums them: (a0 b0 + a1 b1) + a2 b2."""
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


def unchecked_ellipsoid(center: np.ndarray, rotation: np.ndarray, radii: np.ndarray) -> Ellipsoid:
    """An Ellipsoid from already valid parts, without the checks of its constructor (an explicit step poses the
    body every step; the first pose of a PoseCache is validated)."""
    posed = object.__new__(Ellipsoid)        # frozen dataclass: fields set as its __post_init__ does
    object.__setattr__(posed, "center", center)
    object.__setattr__(posed, "rotation", rotation)
    object.__setattr__(posed, "radii", radii)
    return posed
