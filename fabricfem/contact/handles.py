"""Handles that put a garment on: a grip that pulls an edge along a path, and a belt that tensions an edge.

Both act on nodes of panel edges (fabricfem.contact.node_sets.PanelNodeSet) as hooks of the explicit integrator
(fabricfem.dynamics.explicit):

* `EdgeGrip` (pulling the garment along a path over the body, the thesis's donning of the pants [Man2006, sec.
  5.4]): from `start` to `end` [s] the gripped nodes follow the path along its direction
  u = (p_last - p_first) / |p_last - p_first|: the predictor of step n+2 of node i is moved to
  y_i' = y_i + ((x_i(start) + p(t_{n+2}) - p(start) - y_i) . u) u, a forward-increment constraint like the body
  contact [Man2006, Box 5] (a^{n+1} += (y' - y) / dt^2), with p the piecewise-linear path through `waypoints`
  (offsets [m] at equal time intervals from start to end); across u the nodes are free, as a waistband pulled up
  by hands slides out over the hips (a path that does not move holds the nodes in all directions). From `end` to
  `release` (default `end`) the grip holds them at the path's end the same way (hands holding the waistband up
  while the body grows into it), then lets go. The force the grip exerts, sum m (y' - y) / dt^2 [N], is reported.
* `Belt` (a waistband or cuff tensioned by a drawstring): each edge is an ordered chain of nodes; every segment of
  the chain carries the tension T(t) [N] (ramped from 0 at `start` to `tension` at `start + ramp`, smoothstep),
  which pulls its two end nodes towards each other: f_k += T e_k, f_{k+1} -= T e_k, e_k the unit vector of the
  segment (a string under tension T: on a curved edge the nodal forces are T times the turning of the chain,
  the line force T kappa towards the centre of curvature). The chains of edges sewn end to end meet at their
  seams, where the seam ties pass the tension on, so the belt of a four-panel waistband is one loop. Added to the
  right-hand side before the division (a penalty-like explicit force; its frequency is far below the fabric's).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from fabricfem.body.blend import smoothstep
from fabricfem.contact.node_sets import PanelNodeSet


def _chunks(edges: Sequence[tuple[str, int, np.ndarray]]) -> tuple[list, list]:
    return [(tag, points) for _, tag, points in edges], [f"edge {name!r}" for name, _, _ in edges]


class EdgeGrip:
    """Grip the nodes of `edges` = [(name, panel cell tag, ordered points (n, 3) [m]), ...] and move them along
    `waypoints` ((k, 3) offsets [m], the first usually 0) between `start` and `end` [s], then hold them along the
    path's direction until `release` [s] (default `end`; module docstring)."""

    def __init__(self, model, edges, waypoints, start: float, end: float, release: float | None = None):
        if not (math.isfinite(start) and math.isfinite(end) and end > start >= 0.0):
            raise ValueError(f"pull: needs 0 <= start < end [s], got start = {start!r}, end = {end!r}")
        release = end if release is None else float(release)
        if not (math.isfinite(release) and release >= end):
            raise ValueError(f"pull: the release {release!r} [s] must be a time at or after the pull's end {end!r}")
        path = np.asarray(waypoints, dtype=float)
        if path.ndim != 2 or path.shape[1] != 3 or len(path) < 2 or not np.all(np.isfinite(path)):
            raise ValueError(f"pull_path: needs at least two finite [x, y, z] offsets [m], got {waypoints!r}")
        chunks, names = _chunks(edges)
        self.nodes = PanelNodeSet(model, chunks, names)
        self.start, self.end, self.release, self.path = float(start), float(end), release, path
        travel = path[-1] - path[0]
        norm = float(np.linalg.norm(travel))
        self._direction = travel / norm if norm > 0.0 else None
        self._anchor = None          # (k, 3) positions of the owned gripped nodes at the start
        self.force = np.zeros(3)     # N, the grip's force on the garment in the last step (this rank's nodes)

    def state(self) -> dict:
        """What a checkpoint keeps of the grip: the start positions [m] of its owned nodes (None before the pull)."""
        return {"anchor": None if self._anchor is None else self._anchor.copy()}

    def restore(self, state: dict) -> None:
        """Continue from a `state()` of a grip built on the same mesh and ranks."""
        anchor = state["anchor"]
        self._anchor = None if anchor is None else np.array(anchor, dtype=float)

    def offset(self, t: float) -> np.ndarray:
        """p(t) [m]: the path's offset at time t (held at its ends outside [start, end])."""
        s = min(max((t - self.start) / (self.end - self.start), 0.0), 1.0) * (len(self.path) - 1)
        k = min(int(s), len(self.path) - 2)
        return self.path[k] + (s - k) * (self.path[k + 1] - self.path[k])

    def forces(self, integrator, t: float, rhs) -> None:
        """No force before the division: the grip is a forward-increment constraint (`correct`)."""

    def correct(self, integrator, t: float) -> None:
        dt = integrator.dt
        t_next = t + dt
        self.force = np.zeros(3)
        if not (self.start <= t < self.release):
            return
        rows = self.nodes.rows[~self.nodes.held]
        d = integrator.d.getArray(readonly=True)
        if self._anchor is None:
            self._anchor = self.nodes.reference[~self.nodes.held] + d[rows]
        v = integrator.velocity_predictor.getArray(readonly=True)
        a = integrator.a.getArray()
        y = self.nodes.reference[~self.nodes.held] + d[rows] + dt * v[rows] + dt ** 2 * a[rows]
        change = self._anchor + self.offset(t_next) - self.offset(self.start) - y
        if self._direction is not None:         # along the path's direction only
            change = np.outer(change @ self._direction, self._direction)
        a[rows] += change / dt ** 2
        m = integrator.denominator.getArray(readonly=True)[rows]
        self.force = (m * change).sum(axis=0) / dt ** 2


class Belt:
    """A drawstring of tension T(t) [N] along the ordered node chains of `edges` = [(name, panel cell tag, ordered
    points (n, 3) [m]), ...], ramped over `ramp` [s] from `start` [s] (module docstring)."""

    def __init__(self, model, edges, tension: float, start: float, ramp: float):
        if not (math.isfinite(tension) and tension >= 0.0):
            raise ValueError(f"belt_tension must be a force >= 0 [N], got {tension!r}")
        if not (math.isfinite(start) and start >= 0.0 and math.isfinite(ramp) and ramp >= 0.0):
            raise ValueError(f"belt: start and ramp must be times >= 0 [s], got {start!r}, {ramp!r}")
        chunks, names = _chunks(edges)
        self.nodes = PanelNodeSet(model, chunks, names)
        counts = [len(points) for _, points in chunks]
        offsets = np.cumsum([0] + counts)
        member = self.nodes.point_member
        self._from = np.concatenate([member[o:o + n - 1] for o, n in zip(offsets[:-1], counts)])
        self._to = np.concatenate([member[o + 1:o + n] for o, n in zip(offsets[:-1], counts)])
        self.tension, self.start, self.ramp = float(tension), float(start), float(ramp)
        self.length0 = self.length(np.zeros(0), reference=True)

    def state(self) -> dict:
        """What a checkpoint keeps of the belt: nothing (its force is a function of the time and the state)."""
        return {}

    def restore(self, state: dict) -> None:
        """Continue from a `state()`: the belt keeps nothing between steps."""

    def tension_at(self, t: float) -> float:
        """T(t) [N]."""
        if t < self.start:
            return 0.0
        return self.tension * (1.0 if self.ramp == 0.0 else smoothstep((t - self.start) / self.ramp))

    def length(self, d: np.ndarray, reference: bool = False) -> float:
        """Total length [m] of the chains at displacements `d` (local array of W), or in the reference."""
        x = self.nodes.gather(self.nodes.reference) if reference else self.nodes.positions(d)
        return float(np.linalg.norm(x[self._to] - x[self._from], axis=1).sum())

    def forces(self, integrator, t: float, rhs) -> None:
        """rhs += the drawstring's nodal forces at d^{n+1} (owned rows)."""
        T = self.tension_at(t)
        if T == 0.0:
            return
        x = self.nodes.positions(integrator.d.getArray(readonly=True))
        e = x[self._to] - x[self._from]
        e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
        f = np.zeros_like(x)
        np.add.at(f, self._from, T * e)
        np.add.at(f, self._to, -T * e)
        owned = ~self.nodes.held
        rhs.getArray()[self.nodes.rows[owned]] += f[self.nodes.owned_member[owned]]

    def correct(self, integrator, t: float) -> None:
        """No correction: the belt is a force."""
