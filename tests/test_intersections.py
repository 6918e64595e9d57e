"""The intersecting-pair count of a cloth state (fabricfem.contact.intersections): the vectorised tests give the count
of libigl's triangle-triangle test run pair by pair on every pair of triangles that share no node (the brute force:
an independent count), on random triangle soups and on a sheet folded onto itself; exact equality, the
configurations perturbed by 1e-7 m so that no node lies exactly on another triangle's plane (touching pairs are
decided by round-off in either count)."""
from __future__ import annotations

import itertools

import igl
import numpy as np
import pytest

from fabricfem.contact.intersections import candidate_pairs, intersecting, intersecting_pairs


def brute_force(points: np.ndarray, triangles: np.ndarray) -> int:
    """libigl's test on every pair of triangles sharing no node whose bounding boxes overlap (a necessary
    condition): the number of intersecting pairs."""
    return len(brute_force_pairs(points, triangles))


def brute_force_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """The pairs (i < j) of `brute_force`."""
    corners = points[triangles]
    low, high = corners.min(axis=1), corners.max(axis=1)
    found = set()
    for i, j in itertools.combinations(range(len(triangles)), 2):
        if set(triangles[i]) & set(triangles[j]) or (low[i] > high[j]).any() or (low[j] > high[i]).any():
            continue
        p, q = points[triangles[i]], points[triangles[j]]
        if igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0]:
            found.add((i, j))
    return found


def folded_sheet(nx: int, ny: int, fold: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit square grid whose half x > 0.5 is folded back over the other half, 1 cm above it, and waved by
    `fold` [m] across the flat half (fold > 0.01 m: through it); nodes perturbed by 1e-7 m."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    back = x > 0.5
    points = np.c_[np.where(back, 1.0 - x, x).ravel(), y.ravel(),
                   (back * (0.01 + fold * np.sin(4 * np.pi * x) * y)).ravel()]
    points += 1e-7 * np.random.default_rng(seed).standard_normal(points.shape)
    index = np.arange(nx * ny).reshape(nx, ny)
    triangles = np.r_[np.c_[index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel()],
                      np.c_[index[:-1, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()]]
    return points, triangles


@pytest.mark.parametrize("spread", [0.3, 0.8, 1.6])
def test_count_of_a_triangle_soup_is_the_brute_force_count(spread):
    rng = np.random.default_rng(int(10 * spread))
    n = 120
    centres = spread * rng.random((n, 3))
    points = (centres[:, None, :] + 0.08 * rng.standard_normal((n, 3, 3))).reshape(-1, 3)
    triangles = np.arange(3 * n).reshape(n, 3)
    expected = brute_force(points, triangles)
    assert expected > 0
    assert intersecting_pairs(points, triangles) == expected
    assert {tuple(p) for p in intersecting(points, triangles).tolist()} == brute_force_pairs(points, triangles)


@pytest.mark.parametrize("fold", [0.0, 0.05, 0.3])
def test_count_of_a_folded_sheet_is_the_brute_force_count(fold):
    points, triangles = folded_sheet(24, 16, fold, seed=3)
    expected = brute_force(points, triangles)
    assert (expected > 0) == (fold > 0.01)
    assert intersecting_pairs(points, triangles) == expected


def test_a_flat_sheet_has_no_intersecting_pairs():
    points, triangles = folded_sheet(20, 20, 0.0, seed=1)
    keep = points[:, 0] <= 0.5       # the half before the fold: one layer
    assert intersecting_pairs(points, triangles[keep[triangles].all(axis=1)]) == 0


@pytest.mark.parametrize("parts", [2, 3])
def test_the_parts_of_the_count_list_every_pair_once(parts):
    """The ranks of a run count one part each (candidate_pairs' part k: first triangle in slab k): the parts'
    candidate pairs are the whole list, each once, and their counts sum to the whole count."""
    points, triangles = folded_sheet(24, 16, 0.3, seed=5)
    whole = candidate_pairs(points, triangles)
    pieces = np.concatenate([candidate_pairs(points, triangles, (k, parts)) for k in range(parts)])
    assert len(pieces) == len(whole) and set(map(tuple, pieces.tolist())) == set(map(tuple, whole.tolist()))
    counts = [intersecting_pairs(points, triangles, (k, parts)) for k in range(parts)]
    assert sum(counts) == intersecting_pairs(points, triangles) > 0
