"""The fused compiled contact step (fabricfem.contact.compiled.contact_step, what ExplicitBodyContact.correct calls for
the blended skin) against the two calls it replaces: `project` of every node, then `friction` of the nodes moved and
the clearing of the others (zero force, no slip, no stick point). Over steps in which nodes touch down, stick, slip
and lift off, in and out of the elbow's crease, the two give the same bits: positions, segments, flags, forces,
stick points, corrected accelerations and torques."""
from __future__ import annotations

import functools

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact import compiled
from fabricfem.contact.projection import INSIDE_TOLERANCE, MAX_PROJECTION_PASSES, project_compiled, resolve_widths
from fabricfem.forms.jit import pointer

DT = 1e-4          # s
MU = 0.3


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _elbow() -> list[Ellipsoid]:
    """An upper arm and a forearm flexed by 1 rad about the elbow at the origin, and a third segment apart [m]."""
    forearm = 0.15 * np.array([np.cos(1.0), np.sin(1.0), 0.0])
    return [Ellipsoid(np.array([-0.15, 0.0, 0.0]), _rotation(0.0), np.array([0.15, 0.04, 0.04])),
            Ellipsoid(forearm, _rotation(1.0), np.array([0.15, 0.04, 0.04])),
            Ellipsoid(np.array([0.4, 0.0, 0.0]), _rotation(0.3), np.array([0.1, 0.03, 0.03]))]


class _State:
    """The contact state of M nodes that a step updates in place."""

    def __init__(self, M: int, rng):
        self.a = rng.normal(0.0, 20.0, 3 * M)
        self.force, self.normal_force = np.zeros((M, 3)), np.zeros(M)
        self.slip, self.active = np.zeros(M, dtype=np.uint8), np.zeros(M, dtype=np.uint8)
        self.stick_segment = np.full(M, -1, dtype=np.int64)
        self.stick_local = np.zeros((M, 3))
        self.torques = np.zeros(2)
        self.position = self.segment = None

    def arrays(self) -> dict:
        return {k: v.copy() for k, v in vars(self).items()}


def _monitors(ffi, K: int, state: _State) -> tuple:
    p = functools.partial(pointer, ffi)
    on = np.ascontiguousarray([[1] + [0] * (K - 1), [0, 1] + [0] * (K - 2)], dtype=np.uint8)
    joints, axes = np.zeros((2, 3)), np.ascontiguousarray([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    return 2, p(on, "uint8_t"), p(joints, "double"), p(axes, "double"), p(state.torques, "double")


def _two_calls(lib, ffi, x, rows, d, v, segments, widths, mass, s: _State):
    """`project`, then `friction` of the moved nodes and the clearing of the others (the step before the fusion)."""
    p = functools.partial(pointer, ffi)
    trial, skin = project_compiled(x, rows, d, v, s.a, DT, segments, widths, MPI.COMM_SELF)
    index = np.flatnonzero(skin.moved)
    for buffer in (s.force, s.normal_force, s.slip):
        buffer.fill(0)
    lib.friction(len(index), p(index, "int64_t"), p(rows, "int64_t"), p(trial, "double"), p(skin.position, "double"),
                 p(skin.segment, "int64_t"), p(mass, "double"), DT, MU, *(p(a, "double") for a in segments),
                 p(s.stick_segment, "int64_t"), p(s.stick_local, "double"), p(s.a, "double"), p(s.force, "double"),
                 p(s.normal_force, "double"), p(s.slip, "uint8_t"), len(segments[0]), *_monitors(ffi, 3, s),
                 p(skin.crease.view(np.uint8), "uint8_t"), p(skin.normal, "double"), p(skin.weights, "double"))
    s.stick_segment[~skin.moved] = -1
    s.active[:] = skin.moved
    s.position, s.segment = skin.position, skin.segment


def _fused(lib, ffi, buffers, x, rows, d, v, segments, widths, mass, s: _State):
    p = functools.partial(pointer, ffi)
    M = len(x)
    s.position, s.segment = np.empty((M, 3)), np.empty(M, dtype=np.int64)
    trial, *work = buffers.work()
    trapped = lib.contact_step(M, p(x, "double"), p(rows, "int64_t"), p(d, "double"), p(v, "double"), p(s.a, "double"),
                               DT, len(segments[0]), *(p(a, "double") for a in segments), INSIDE_TOLERANCE,
                               MAX_PROJECTION_PASSES, p(widths, "double"), trial, p(s.position, "double"),
                               p(s.segment, "int64_t"), p(s.active, "uint8_t"), *work, p(mass, "double"), MU,
                               p(s.stick_segment, "int64_t"), p(s.stick_local, "double"), p(s.force, "double"),
                               p(s.normal_force, "double"), p(s.slip, "uint8_t"), *_monitors(ffi, 3, s))
    assert trapped == 0


def test_the_fused_step_gives_the_bits_of_project_then_friction():
    """Eight steps of 3000 nodes around the inner elbow (many in the crease) drifting by up to 2 mm a step: the
    same bits every step; then a restart (stick points of every node, the work arrays made anew) again."""
    lib, ffi = compiled.module(MPI.COMM_SELF)
    rng = np.random.default_rng(7)
    M = 3000
    x = rng.uniform([-0.12, -0.06, -0.05], [0.08, 0.12, 0.05], size=(M, 3))
    rows = np.arange(3 * M, dtype=np.int64).reshape(M, 3)
    mass = rng.uniform(1e-5, 2e-5, size=(M, 3))
    segments, widths = compiled.stacked(_elbow()), resolve_widths(None, 3)
    one, two = _State(M, np.random.default_rng(1)), _State(M, np.random.default_rng(1))
    buffers = compiled.StepBuffers(ffi, M, 3)
    d, v = np.zeros(3 * M), np.zeros(3 * M)
    slipped = 0
    for step in range(10):
        if step == 8:      # a restart: stick points everywhere, new work arrays (every node cleared first)
            for s in (one, two):
                s.stick_segment[:] = rng.integers(-1, 3, M)
                s.stick_local[:] = rng.normal(0.0, 0.05, (M, 3))
            one.stick_segment[:], one.stick_local[:] = two.stick_segment, two.stick_local
            buffers = compiled.StepBuffers(ffi, M, 3)
        d += rng.uniform(-2e-3, 2e-3, 3 * M)
        v = rng.normal(0.0, 0.5, 3 * M)
        for s in (one, two):
            s.a[:] = rng.normal(0.0, 20.0, 3 * M) if s is one else one.a
        _two_calls(lib, ffi, x, rows, d, v, segments, widths, mass, one)
        _fused(lib, ffi, buffers, x, rows, d, v, segments, widths, mass, two)
        a, b = one.arrays(), two.arrays()
        for name in a:
            assert np.array_equal(np.asarray(a[name]).view(np.uint8), np.asarray(b[name]).view(np.uint8)), (step, name)
        slipped += int(one.slip.sum())
    assert one.active.sum() > 300 and slipped > 0 and (one.stick_segment >= 0).sum() > 300
