"""BVH motion files: parse the HIERARCHY and MOTION sections, forward kinematics, write.

A BVH file stores a joint tree (each joint: OFFSET from its parent in the parent's frame, CHANNELS
in file order) and per frame the channel values (positions in file units, rotations in degrees).
Forward kinematics, for each joint j with parent p (the root has none):

    R_local = E_c1(a_1) E_c2(a_2) E_c3(a_3)      (elementary rotations in the joint's channel order)
    R_j = R_p R_local,   x_j = x_p + R_p (offset_j + d_j)

with d_j the joint's position channels (usually only the root's; x_root = offset + d). End Sites
are leaves without channels, named "<parent>_end". Positions are vectorised over the frames (the
loop runs over the joints of the hierarchy). Reading maps units and axes to the body frame
(`fabricfem.body.conventions`); BVH files have no unit metadata, so `units` is required.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fabricfem.body.conventions import check_times, fill_or_refuse_gaps, to_body, unit_scale
from fabricfem.body.motion import JointTrajectory

ROTATIONS = ("Xrotation", "Yrotation", "Zrotation")
POSITIONS = ("Xposition", "Yposition", "Zposition")


@dataclass(frozen=True)
class BvhSkeleton:
    """A BVH joint tree in file order (parents before children).

    Args:
        names: joint names; End Sites are named "<parent>_end".
        parents: index of each joint's parent, -1 for the root (only the first joint).
        offsets: (K, 3) offsets from the parent, in file units and axes.
        channels: each joint's channel names in file order (() for End Sites).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]

    def __post_init__(self):
        k = len(self.names)
        if len(set(self.names)) != k:
            raise ValueError(f"names: duplicate joint names in {list(self.names)}")
        if len(self.parents) != k or len(self.channels) != k or np.shape(self.offsets) != (k, 3):
            raise ValueError("names, parents, offsets (K, 3) and channels must describe the same K joints")
        if k == 0 or self.parents[0] != -1 or any(not (0 <= p < j) for j, p in enumerate(self.parents[1:], 1)):
            raise ValueError("parents: the first joint must be the root (-1) and every parent must precede its child")
        for name, ch in zip(self.names, self.channels):
            unknown = [c for c in ch if c not in ROTATIONS + POSITIONS]
            if unknown:
                raise ValueError(f"channels of joint {name!r}: unknown channel names {unknown}")

    @property
    def n_channels(self) -> int:
        return sum(len(c) for c in self.channels)


def _elementary(axis: str, angle: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotation by angle [rad] (T,) about the x, y or z axis."""
    c, s = np.cos(angle), np.sin(angle)
    one, zero = np.ones_like(c), np.zeros_like(c)
    rows = {"X": ((one, zero, zero), (zero, c, -s), (zero, s, c)),
            "Y": ((c, zero, s), (zero, one, zero), (-s, zero, c)),
            "Z": ((c, -s, zero), (s, c, zero), (zero, zero, one))}[axis]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def forward_kinematics(skeleton: BvhSkeleton, motion: np.ndarray) -> np.ndarray:
    """Positions (T, K, 3) of every joint and End Site, in file units and axes, for the channel values
    `motion` (T, C) (positions in file units, rotations in degrees; C = skeleton.n_channels)."""
    motion = np.asarray(motion, dtype=float)
    if motion.ndim != 2 or motion.shape[1] != skeleton.n_channels:
        raise ValueError(f"motion must have shape (T, {skeleton.n_channels}), got {motion.shape}")
    n_frames = motion.shape[0]
    positions = np.empty((n_frames, len(skeleton.names), 3))
    frames: list[np.ndarray] = []
    column = 0
    for j, (parent, offset, channels) in enumerate(zip(skeleton.parents, skeleton.offsets, skeleton.channels)):
        local = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        shift = np.broadcast_to(np.asarray(offset, dtype=float), (n_frames, 3)).copy()
        for name in channels:
            value = motion[:, column]
            column += 1
            if name in ROTATIONS:
                local = local @ _elementary(name[0], np.radians(value))
            else:
                shift[:, POSITIONS.index(name)] += value
        if parent < 0:
            positions[:, j], rotation = shift, local
        else:
            positions[:, j] = positions[:, parent] + np.einsum("tij,tj->ti", frames[parent], shift)
            rotation = frames[parent] @ local
        frames.append(rotation)
    return positions


@dataclass(frozen=True)
class BvhMotion:
    """A parsed BVH file: skeleton, frame time [s] and channel values (T, C)."""

    skeleton: BvhSkeleton
    frame_time: float
    motion: np.ndarray


def parse_bvh(path: str | Path) -> BvhMotion:
    """Parse a BVH file (HIERARCHY with ROOT/JOINT/End Site blocks, then MOTION, Frames, Frame Time
    and one line of channel values per frame)."""
    text = Path(path).read_text()
    head, sep, tail = text.partition("MOTION")
    tokens = head.split()
    if not sep or not tokens or tokens[0] != "HIERARCHY":
        raise ValueError(f"path: {path} is not a BVH file (needs HIERARCHY ... MOTION)")
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []
    i = 1
    while i < len(tokens):
        tok = tokens[i]
        if tok in ("ROOT", "JOINT") or (tok == "End" and tokens[i + 1] == "Site"):
            name = tokens[i + 1] if tok != "End" else f"{names[stack[-1]]}_end"
            parents.append(stack[-1] if stack else -1)
            names.append(name)
            offsets.append(None)
            channels.append(())
            i += 2
        elif tok == "{":
            stack.append(len(names) - 1)
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            offsets[stack[-1]] = [float(v) for v in tokens[i + 1:i + 4]]
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels[stack[-1]] = tuple(tokens[i + 2:i + 2 + n])
            i += 2 + n
        else:
            raise ValueError(f"path: {path}: unexpected token {tok!r} in HIERARCHY")
    missing = [n for n, o in zip(names, offsets) if o is None]
    if missing or stack:
        raise ValueError(f"path: {path}: unbalanced braces or joints without OFFSET: {missing}")
    skeleton = BvhSkeleton(tuple(names), tuple(parents), np.array(offsets, dtype=float), tuple(channels))
    lines = [line for line in tail.splitlines() if line.strip()]
    if len(lines) < 2 or not lines[0].startswith("Frames:") or not lines[1].startswith("Frame Time:"):
        raise ValueError(f"path: {path}: MOTION must be followed by 'Frames:' and 'Frame Time:' lines")
    n_frames, frame_time = int(lines[0].split(":")[1]), float(lines[1].split(":")[1])
    if not (math.isfinite(frame_time) and frame_time > 0.0):
        raise ValueError(f"path: {path}: Frame Time must be positive [s], got {frame_time}")
    rows = [line.split() for line in lines[2:]]
    if len(rows) != n_frames:
        raise ValueError(f"path: {path}: 'Frames: {n_frames}' but {len(rows)} frame lines")
    short = [k for k, r in enumerate(rows) if len(r) != skeleton.n_channels]
    if short:
        raise ValueError(f"path: {path}: frame {short[0]} has {len(rows[short[0]])} values, expected "
                         f"{skeleton.n_channels} channels")
    return BvhMotion(skeleton, frame_time, np.array(rows, dtype=float).reshape(n_frames, skeleton.n_channels))


def read_bvh(path: str | Path, units: str | float, up: str = "y", fill_gaps: bool = False) -> JointTrajectory:
    """Joint and End Site positions [m, body frame] of a BVH file, frame k at t = k x Frame Time [s].

    Args:
        units: the file's length unit (name or metres per unit; BVH has no unit metadata).
        up: the file's up axis ("y", the BVH convention, or "z"); see `fabricfem.body.conventions`.
        fill_gaps: interpolate non-finite channel values in time instead of refusing them.
    """
    bvh = parse_bvh(path)
    times = check_times(bvh.frame_time * np.arange(len(bvh.motion)), f"path: {path}")
    data = forward_kinematics(bvh.skeleton, bvh.motion)
    data = fill_or_refuse_gaps(times, bvh.skeleton.names, data, f"path: {path}", fill_gaps)
    data = to_body(data, unit_scale(units), up)
    return JointTrajectory(times, {name: data[:, k] for k, name in enumerate(bvh.skeleton.names)})


def write_bvh(path: str | Path, skeleton: BvhSkeleton, motion: np.ndarray, frame_time: float,
              digits: int = 6) -> None:
    """Write a BVH file: the skeleton (offsets in file units) and the channel values (T, C) (positions
    in file units, rotations in degrees), every number printed with `digits` decimals (the stored
    precision: 0.5 x 10^-digits file units or degrees). Joints named "<parent>_end" without channels
    are written as End Sites."""
    motion = np.asarray(motion, dtype=float)
    if motion.ndim != 2 or motion.shape[1] != skeleton.n_channels:
        raise ValueError(f"motion must have shape (T, {skeleton.n_channels}), got {motion.shape}")
    if not (math.isfinite(frame_time) and frame_time > 0.0):
        raise ValueError(f"frame_time must be positive [s], got {frame_time!r}")
    children: dict[int, list[int]] = {j: [] for j in range(len(skeleton.names))}
    for j, p in enumerate(skeleton.parents[1:], 1):
        children[p].append(j)
    out = ["HIERARCHY"]

    def block(j: int, depth: int) -> None:
        pad, name = "\t" * depth, skeleton.names[j]
        end = not skeleton.channels[j] and not children[j] and name.endswith("_end")
        out.append(pad + ("End Site" if end else f"{'ROOT' if j == 0 else 'JOINT'} {name}"))
        out.append(pad + "{")
        out.append(pad + "\tOFFSET " + " ".join(f"{v:.{digits}f}" for v in skeleton.offsets[j]))
        if not end:
            out.append(pad + f"\tCHANNELS {len(skeleton.channels[j])} " + " ".join(skeleton.channels[j]))
        for c in children[j]:
            block(c, depth + 1)
        out.append(pad + "}")

    block(0, 0)
    out += ["MOTION", f"Frames: {len(motion)}", f"Frame Time: {frame_time:.12g}"]
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")
        np.savetxt(fh, motion, fmt=f"%.{digits}f", delimiter=" ")
