"""A motion that starts from another pose: the body stands still (the garment goes on), then blends into a gait.

`BlendedStart(motion, start_pose, blend_time)` is a kinematics source (fabricfem.body.motion.KinematicsSource) on
[0, blend_time + motion duration] [s]:

    p(t) = P0 + smoothstep(t / T_b) (m(t0) - P0)     for t < T_b     (P0 the start pose, m(t0) the motion's start)
    p(t) = m(t0 + t - T_b)                            after

with smoothstep(s) = 3 s^2 - 2 s^3, so that the joints leave the start pose and reach the motion at rest relative
to a linear blend (zero velocity at both ends of the blend in the blend's own part). Positions are blended, not
angles: during the blend the distance of two joints of a segment may differ from its length (by at most the
chord of the rotation between the poses); the segments' ellipsoids keep their radii, so the posed body stays a
body; the records of the blend are a transition, not part of the motion.
"""
from __future__ import annotations

import math

import numpy as np


def smoothstep(s: float) -> float:
    """3 s^2 - 2 s^3 on [0, 1], 0 before, 1 after: a transition that starts and ends at rest (the blends here, the
    seams' sewing closure, the body's growth and the belt's ramp of fabricfem.wear)."""
    s = min(max(s, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


class BlendedStart:
    """`motion` entered from the joint and marker positions `start_pose` ({name: (3,) [m]}) over `blend_time` [s]
    (module docstring)."""

    def __init__(self, motion, start_pose: dict, blend_time: float):
        if not (math.isfinite(blend_time) and blend_time > 0.0):
            raise ValueError(f"blend_time must be a positive time [s], got {blend_time!r}")
        missing = [n for n in motion.names if n not in start_pose]
        if missing:
            raise ValueError(f"start_pose: lacks the motion's points {missing}")
        self.motion, self.blend_time = motion, float(blend_time)
        self.names = tuple(motion.names)
        self._start = {n: np.asarray(start_pose[n], dtype=float) for n in self.names}
        t0, t1 = motion.time_range
        self._t0 = t0
        self._first = motion.positions(t0)
        self.time_range = (0.0, self.blend_time + t1 - t0)

    def inner_time(self, t: float) -> float:
        """The motion's own time [s] at time t [s] of the blend: t0 + t - blend_time (before t0 during the blend)."""
        return self._t0 + float(t) - self.blend_time

    def positions(self, t: float) -> dict[str, np.ndarray]:
        if t >= self.blend_time:
            return self.motion.positions(self._t0 + t - self.blend_time)
        w = smoothstep(t / self.blend_time)
        return {n: self._start[n] + w * (self._first[n] - self._start[n]) for n in self.names}
