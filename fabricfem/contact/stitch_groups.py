"""The stitched groups of a sewn garment in the cloth-cloth corrections: a seam's stitched nodes are one point of
the cloth (fabricfem.contact.seams), so the impulses and the impact zones must not move them apart.

The seams close a group by a forward-increment correction before the body and cloth-cloth contact
(fabricfem.wear.garment). The cloth-cloth impulses and the rigid impact zones (fabricfem.contact.impulses,
fabricfem.contact.impact_zones) then act on single nodes: an impulse on one node of a group, or a zone that holds
one node of a group and not its partner, opened the seam by dt |du_a - du_b| in each step, and the seams closed
it again in the next one only to see it reopened. On the pants walk with self-contact the seam gap after the
sewing stayed at 3.4-9 mm (bound 2 mm; 0 without self-contact; docs/findings/2026-11-28-stitched-zones.md).
Two rules keep a group together:

* `weld`: after the impulses, every node of a group takes the group's mass-weighted mean velocity change
  du_G = sum_G w_i du_i / sum_G w_i (w_i the lumped mass, HELD_MASS_FACTOR times it for a node of infinite mass,
  so a held node anchors its group as in the seams); sum_G w_i du_i is unchanged, so the momentum is conserved;
* `join_zones`: a zone that holds a node of a group takes the whole group (fabricfem.contact.impact_zones.merge),
  whose nodes then move with one rigid velocity field and keep their distances.

`star_pairs` lists the groups as (member, first member) node pairs, `closed` those already sewn (the sewing draws a
group's nodes together over the sewing time; until then they are panels apart and are left alone). SI units.
"""
from __future__ import annotations

import numpy as np

from fabricfem.contact.seams import HELD_MASS_FACTOR, group_means


def star_pairs(labels: np.ndarray, held: np.ndarray | None = None) -> np.ndarray:
    """(k, 2) int64 pairs (node, first node of its group) for every node of a group of more than one node, the
    groups given by `labels` (N,) (one label per point of the cloth, fabricfem.contact.cloth_surface.joined_labels);
    (0, 2) when nothing is stitched. `held` (N,) bool: nodes with a prescribed motion; their groups are left out
    (the seams already move such a group with its held node, and a zone that took it would move rigidly with the
    grip, through the growing body)."""
    labels = np.asarray(labels, dtype=np.int64)
    nodes = np.flatnonzero(np.bincount(labels, minlength=1)[labels] > 1) if len(labels) else np.zeros(0, np.int64)
    if held is not None and len(nodes):
        nodes = nodes[~np.isin(labels[nodes], labels[np.flatnonzero(held)])]
    unique, first = np.unique(labels[nodes], return_index=True)
    representative = nodes[first][np.searchsorted(unique, labels[nodes])]
    keep = nodes != representative
    return np.column_stack([nodes[keep], representative[keep]]).astype(np.int64).reshape(-1, 2)


def closed(star: np.ndarray, x: np.ndarray, tolerance: float) -> np.ndarray:
    """The rows of `star` whose group is sewn: every member within `tolerance` [m] of the first member at the
    positions x (N, 3) [m]. A group still being drawn together by the sewing (its nodes up to the panels' distance
    apart) is left out: a rigid zone spanning it would swing its far nodes at the zone's rotation."""
    if not len(star):
        return star
    apart = np.linalg.norm(x[star[:, 0]] - x[star[:, 1]], axis=1) > tolerance
    return star[~np.isin(star[:, 1], star[apart, 1])]


def weld(u: np.ndarray, u0: np.ndarray, star: np.ndarray, mass: np.ndarray, held: np.ndarray) -> None:
    """u (N, 3) [m/s] in place: every node of a stitched group (`star` from `star_pairs`) takes u0 + du_G, the
    group's mass-weighted mean change du = u - u0 (module docstring); mass (N,) finite lumped masses [kg], held
    (N,) bool: a node of infinite mass (weight HELD_MASS_FACTOR x its mass)."""
    if not len(star):
        return
    nodes = np.unique(star)
    group = np.searchsorted(np.unique(star[:, 1]), _representative(star, nodes))
    weight = mass[nodes] * np.where(held[nodes], HELD_MASS_FACTOR, 1.0)
    u[nodes] = u0[nodes] + group_means(group, weight, u[nodes] - u0[nodes])[group]


def join_zones(star: np.ndarray, parent: np.ndarray, merge) -> None:
    """Put the whole stitched group of every node in a zone into that zone: `parent` (N,) the zones' union-find
    (-1 outside any zone), `merge(nodes (k, 4), parent)` the zones' merge (fabricfem.contact.impact_zones.merge)."""
    if not len(star):
        return
    zoned = (parent[star[:, 0]] >= 0) | (parent[star[:, 1]] >= 0)
    if not zoned.any():
        return
    rows = star[np.isin(star[:, 1], star[zoned, 1])]
    merge(np.repeat(rows, 2, axis=1), parent)


def _representative(star: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The first member of the group of each of `nodes` (sorted, every node of `star`)."""
    first = nodes.copy()
    first[np.searchsorted(nodes, star[:, 0])] = star[:, 1]
    return first
