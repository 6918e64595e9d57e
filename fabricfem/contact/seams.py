"""Seams of a garment in explicit central differences: stitched nodes sewn together, then held node to node.

A seam pairs the nodes of two panel edges one to one (fabricfem.meshes.pattern: equal node counts on the two
edges of a stitch). Pairs that share a node (a corner where several stitches meet) form one group G. The
seam is a kinematic constraint on the translations only, applied as a forward-increment correction like the
body contact of [Man2006, Box 5]: after the division a^{n+1} = rhs / (M + dt/2 C), the predictor of step n+2

    y_i = X_i + d_i^{n+1} + dt v~_i + dt^2 a_i^{n+1}

of every node i of a group G is moved to

    y_i' = c_G + r_i(t_{n+2}),   c_G = sum_{j in G} m_j y_j / sum_{j in G} m_j,
    r_i(t) = (1 - s(t)) r_i(0),  r_i(0) = x_i(0) - c_G(0),   s = smoothstep(t / T_sew)

and a_i^{n+1} += (y_i' - y_i) / dt^2, with m the diagonal M + dt/2 C of the translations. sum_G m_j r_j = 0,
so the correction conserves the group's momentum; the seam force on node i is f_i = m_i (y_i' - y_i) / dt^2
[N]. During the sewing time T_sew [s] the stitched nodes are drawn together along straight lines (the
"sewing phase" of garment CAD tools); after it they coincide and move as one (r = 0). A panel that starts
coincident with its partner (a placement that allows it) has r(0) = 0 and is held from the first step.
A stitched node on a held edge (the shoulder end of a sleeve) anchors its group: it counts
HELD_MASS_FACTOR times its mass in the centre and is not moved. Rotations are not tied: a seam is a hinge, the directors of the two panels turn independently. The engine
(fabricfem.wear.garment) applies the seams before the body contact, so that a seam drawn across the body
cannot pull a node into it; coincident stitched nodes get the same contact projection, so frictionless seams
stay closed exactly (with friction, their stick points may differ and the gap is reported).

Parallel: the groups' nodes may live on different ranks; each step the owned members' y and (once) m are
summed into a small array over the ranks (one MPI Allreduce of 3 x members doubles), so the result does not
depend on the partition.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fabricfem.body.blend import smoothstep
from fabricfem.contact.node_sets import PanelNodeSet

HELD_MASS_FACTOR = 1e12    # a held stitched node weighs this much more in its group's centre: the group follows it


@dataclass(frozen=True)
class SeamSpec:
    """One stitch as the seams need it: `name`, and per side the 3-D reference positions [m] of the paired
    nodes (n, 3), in pairing order, and the cell tag of the panel they belong to; `length` [m] of the seam."""

    name: str
    points_a: np.ndarray
    tag_a: int
    points_b: np.ndarray
    tag_b: int
    length: float


def group_means(group: np.ndarray, weight: np.ndarray, values: np.ndarray, count: int | None = None) -> np.ndarray:
    """(count, 3) weighted mean sum_G w v / sum_G w of the rows `values` (n, 3) in each group, `group` (n,) the
    group index of each row (0 .. count - 1; count default max + 1), `weight` (n,) positive."""
    count = int(group.max()) + 1 if count is None else count
    total = np.bincount(group, weight, count)
    sums = np.stack([np.bincount(group, weight * values[:, i], count) for i in range(3)], axis=1)
    return sums / total[:, None]


class SeamTies:
    """The seams of a garment (module docstring) as an explicit contact hook (fabricfem.solvers.system.ExplicitHook:
    `correct`; `forces` is a no-op) that keeps the masses M + dt/2 C of its nodes (`on_time_step` drops them).

    Args:
        model: the garment's ShellModel (its fabric_mesh has the panels' cell tags).
        seams: the stitches (SeamSpec) with their paired reference points.
        sewing_time: T_sew [s]; 0 for seams that start closed (a gap above `closed_gap` is then refused).
        closed_gap: m, largest distance of paired nodes accepted as closed at the start when sewing_time = 0.
    """

    def __init__(self, model, seams: Sequence[SeamSpec], sewing_time: float = 0.0, closed_gap: float = 1e-9):
        if not (math.isfinite(sewing_time) and sewing_time >= 0.0):
            raise ValueError(f"sewing_time must be a finite time >= 0 [s], got {sewing_time!r}")
        self.model, self.comm = model, model.comm
        self.seams = list(seams)
        self.sewing_time = float(sewing_time)
        for seam in self.seams:
            if len(seam.points_a) != len(seam.points_b):
                raise ValueError(f"seams: stitch {seam.name!r} pairs {len(seam.points_a)} with "
                                 f"{len(seam.points_b)} nodes; a seam needs equal node counts on its two edges")
        chunks = [c for s in self.seams for c in ((s.tag_a, s.points_a), (s.tag_b, s.points_b))]
        self.nodes = PanelNodeSet(model, chunks, [f"seams: stitch {s.name!r}" for s in self.seams for _ in "ab"])
        half = [len(s.points_a) for s in self.seams]
        offsets = np.cumsum([0] + [2 * n for n in half])
        member = self.nodes.point_member
        a = [member[o:o + n] for o, n in zip(offsets[:-1], half)]
        b = [member[o + n:o + 2 * n] for o, n in zip(offsets[:-1], half)]
        self._pair_a = np.concatenate(a) if a else np.zeros(0, dtype=np.int64)
        self._pair_b = np.concatenate(b) if b else np.zeros(0, dtype=np.int64)
        self._pair_seam = np.repeat(np.arange(len(self.seams)), half)
        # pairs -> groups (connected components over the member nodes)
        n_members, n_pairs = len(self.nodes.members), len(self._pair_a)
        graph = coo_matrix((np.ones(n_pairs), (self._pair_a, self._pair_b)), shape=(n_members,) * 2)
        self.n_groups, self.group = connected_components(graph, directed=False)
        # a held stitched node (a seam end on a held edge) anchors its group: the others follow it
        self._held = self.nodes.held
        self._owned_member, self._rows, self._reference = (self.nodes.owned_member, self.nodes.rows,
                                                           self.nodes.reference)
        self._mass = None            # (members,) m of every member, summed over the ranks on first use
        self._offset0 = None         # (members, 3) r(0)
        self.force = np.zeros((len(self._owned_member), 3))   # seam force on the owned member nodes [N]
        self.closed_gap = float(closed_gap)
        self._gap0 = self._pair_gaps(self._gather(self._reference))
        if self.sewing_time == 0.0 and len(self._gap0) and self._gap0.max() > self.closed_gap:
            worst = int(np.argmax(self._gap0))
            raise ValueError(f"sewing_time: stitch {self.seams[self._pair_seam[worst]].name!r} starts open "
                             f"({self._gap0[worst]:.3g} m between paired nodes); give a sewing time [s] or a "
                             f"placement with the stitched edges together")

    # ------------------------------------------------------------------ helpers
    def _gather(self, values: np.ndarray) -> np.ndarray:
        """(members, ...) array of per-member values, each filled by the owning rank and summed over the ranks."""
        return self.nodes.gather(values)

    def _pair_gaps(self, x: np.ndarray) -> np.ndarray:
        """|x_a - x_b| [m] of every stitched pair from the members' positions x (members, 3)."""
        return np.linalg.norm(x[self._pair_a] - x[self._pair_b], axis=1)

    def _centroids(self, x: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Mass-weighted centre of each member's group, per member (members, 3)."""
        return group_means(self.group, m, x, self.n_groups)[self.group]

    def closure(self, t: float) -> float:
        """s(t) in [0, 1]: how far the sewing has closed the seams at time t [s] (1: closed)."""
        return 1.0 if self.sewing_time == 0.0 else smoothstep(t / self.sewing_time)

    # ------------------------------------------------------------------ integrator hooks
    def forces(self, integrator, t: float, rhs) -> None:
        """No force before the division: the seams are a forward-increment constraint (`correct`)."""

    def on_time_step(self, dt: float) -> None:
        """The integrator's step became dt [s]: the masses M + dt/2 C (and the offsets r(0) weighted by them) are
        taken again from the integrator at the next correction."""
        self._mass = None
        self._offset0 = None

    def correct(self, integrator, t: float) -> None:
        """a^{n+1} += (y' - y) / dt^2 on the stitched nodes (module docstring), for the predictor at t + dt."""
        dt = integrator.dt
        if self._mass is None:
            m = integrator.denominator.getArray(readonly=True)[self._rows[:, 0]]
            self._mass = self._gather(np.where(self._held, HELD_MASS_FACTOR * m, m))
            x0 = self._gather(self._reference)
            self._offset0 = x0 - self._centroids(x0, self._mass)
        d = integrator.d.getArray(readonly=True)
        v = integrator.velocity_predictor.getArray(readonly=True)
        a = integrator.a.getArray()
        rows = self._rows
        y = self._reference + d[rows] + dt * v[rows] + dt ** 2 * a[rows]
        y_all = self._gather(y)
        target = self._centroids(y_all, self._mass) + (1.0 - self.closure(t + dt)) * self._offset0
        change = np.where(self._held[:, None], 0.0, target[self._owned_member] - y)
        a[rows] += change / dt ** 2
        self.force = self._mass[self._owned_member, None] * change / dt ** 2

    # ------------------------------------------------------------------ monitors
    def gaps(self, d: np.ndarray) -> np.ndarray:
        """|x_a - x_b| [m] of every stitched pair at displacements `d` (local array of W), all ranks."""
        return self._pair_gaps(self._gather(self._reference + d[self._rows]))

    def joined_nodes(self) -> np.ndarray:
        """(k, 2) global node indices (the scalar space's index map: fabricfem.contact.cloth_surface numbering) of
        the stitched node pairs, the same on every rank."""
        members = self.nodes.members.astype(np.int64)
        return np.column_stack([members[self._pair_a], members[self._pair_b]])

    def max_gap(self, d: np.ndarray) -> float:
        """Largest distance [m] between paired nodes (all ranks)."""
        g = self.gaps(d)
        return float(g.max()) if len(g) else 0.0

    def line_forces(self) -> dict[str, float]:
        """Per seam: the mean seam force per unit seam length [N/m] of the last step, sum |f| over its side-a
        nodes / its length (a seam's tension across the stitch line), all ranks."""
        f = np.linalg.norm(self._gather(self.force), axis=1)
        out = {}
        for k, seam in enumerate(self.seams):
            members = np.unique(self._pair_a[self._pair_seam == k])
            out[seam.name] = float(f[members].sum() / seam.length) if seam.length > 0 else 0.0
        return out
