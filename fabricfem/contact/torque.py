"""Joint torque of the contact forces ([Man2006, ch. 5] intro): the moment about a joint centre of all
contact forces (normal + friction) acting on the body segments adjacent to that joint.

"Clothing contact forces on a given body segment only contribute resisting torque to the joints
directly connected to the segment" [Man2006, ch. 5]. Sign convention of
`fabricfem.body.motion.joint_torque`: tau = a . sum_i (x_i - J) x f_i [N m] for forces f_i [N] that
the clothing exerts on the body at x_i [m] (the opposite of the forces on the cloth nodes).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem.body.motion import joint_torque


def adjacent_segments(body, joint: str) -> list[str]:
    """Names of the segments of `body` whose proximal or distal joint is `joint`."""
    names = [n for n, s in body.segments.items() if joint in (s.proximal, s.distal)]
    if not names:
        raise ValueError(f"joint: no segment of the body is attached to {joint!r} (joints: {body.joints})")
    return names


def contact_torque(points: np.ndarray, forces_on_body: np.ndarray, segment: np.ndarray,
                   segments: Sequence[int], joint, axis, comm: MPI.Comm | None = None) -> float:
    """tau = a . sum_{i on segments} (x_i - J) x f_i [N m], summed over the ranks of `comm`.

    Args:
        points: (N, 3) contact node positions [m] (owned nodes only under MPI).
        forces_on_body: (N, 3) forces the cloth exerts on the body [N].
        segment: (N,) index of the segment each node touches.
        segments: indices of the segments adjacent to the joint.
        joint: joint centre J [m]; axis: flexion axis (normalised here).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    forces_on_body = np.asarray(forces_on_body, dtype=float).reshape(-1, 3)
    mask = np.isin(np.asarray(segment), np.asarray(list(segments), dtype=int))
    local = joint_torque(points[mask], forces_on_body[mask], joint, axis) if mask.any() else 0.0
    if comm is None:
        return float(local)
    return float(comm.allreduce(local, op=MPI.SUM))


@dataclass(frozen=True)
class TorqueMonitor:
    """The resisting-torque monitor of a wear run: the torque [N m] about `joint` along the unit `axis` of the
    forces the cloth exerts on the body segments flagged in `on_segments` (a lookup table over the contact's
    segment indices), tau = a . sum_i (x_i - J) x f_i [Man2006, ch. 5 intro]. Every contact formulation
    (implicit ContactProblem, explicit ExplicitBodyContact) evaluates its torques through this one path; the
    joint is posed only when a node touches the segments (it is evaluated every explicit step)."""

    joint: str
    axis: np.ndarray
    on_segments: np.ndarray

    @classmethod
    def build(cls, names: Sequence[str], joint: str, axis, segments: Sequence[str]) -> "TorqueMonitor":
        """Validated monitor; ValueError naming `segments` (unknown names) or `axis` (not a non-zero 3-vector)."""
        unknown = [s for s in segments if s not in names]
        if unknown or not len(segments):
            raise ValueError(f"segments: unknown or no segment names {list(segments)} (known: {list(names)})")
        a = np.asarray(axis, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or not np.linalg.norm(a) > 0:
            raise ValueError(f"axis must be a finite non-zero 3-vector, got {axis!r}")
        on_segments = np.zeros(len(names), dtype=bool)
        on_segments[[list(names).index(s) for s in segments]] = True
        return cls(joint, a / np.linalg.norm(a), on_segments)

    def value(self, position: np.ndarray, force_on_cloth: np.ndarray, segment: np.ndarray,
              joint_position: Callable[[], np.ndarray], comm: MPI.Comm | None) -> float:
        """tau [N m] of the nodal forces on the cloth `force_on_cloth` (the body takes -f) at `position`, summed
        over the ranks of `comm` (None: this rank's nodes only); `joint_position()` gives J [m]."""
        local = local_torques([self], position, force_on_cloth, segment, lambda joint: joint_position())[0]
        return local if comm is None else float(comm.allreduce(local, op=MPI.SUM))


def local_torques(monitors: Sequence[TorqueMonitor], position: np.ndarray, force_on_cloth: np.ndarray,
                  segment: np.ndarray, joint_position: Callable[[str], np.ndarray],
                  weights: np.ndarray | None = None) -> list[float]:
    """This rank's torques [N m] of `monitors` (`TorqueMonitor.value` with comm None) for the nodal forces on the
    cloth `force_on_cloth` (N, 3) [N] at `position` (N, 3) [m] touching `segment` (N,). The moments
    (x_i - J) x (-f_i) of the nodes are computed once per joint (`joint_position(name)` gives J [m], asked only
    when a node touches the monitor's segments) and summed per monitor over the nodes on its segments. With the
    skin's segment `weights` (N, K) (fabricfem.body.skin), node i carries the share sum_{k on the monitor's
    segments} w_ik of its moment instead."""
    moments: dict[str, np.ndarray] = {}
    out = []
    for monitor in monitors:
        share = None if weights is None else weights @ monitor.on_segments.astype(float)
        mask = monitor.on_segments[segment] if share is None else share > 0.0
        if not mask.any():
            out.append(0.0)
            continue
        if monitor.joint not in moments:
            moments[monitor.joint] = _cross(position - joint_position(monitor.joint), -force_on_cloth)
        moment = moments[monitor.joint] if share is None else moments[monitor.joint] * share[:, None]
        out.append(float(np.dot((moment if mask.all() else moment[mask]).sum(axis=0), monitor.axis)))
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (N, 3) arrays (the products and differences of np.cross, without its axis handling)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out
