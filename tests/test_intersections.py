"""The intersecting-pair count of a cloth state (fabricfem.contact.intersections): the compiled tests give the count
of libigl's triangle-triangle test run pair by pair on every pair of triangles that share no node (the brute force:
an independent count), on random triangle soups and on a sheet folded onto itself; exact equality, the
configurations perturbed by 1e-7 m so that no node lies exactly on another triangle's plane (touching pairs are
decided by round-off in either count). The compiled count is also compared with the numpy count it replaced
(`numpy_reference_pairs`, its expressions restated here: the same pairs, bit for bit in every decision) on soups
snapped to a lattice (coplanar, touching and node-on-plane pairs: libigl's cases), folded sheets and a crossing
tube."""
from __future__ import annotations

import itertools

import igl
import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial import cKDTree

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



def grid_triangles(nx: int, ny: int) -> np.ndarray:
    """The triangles (T, 3) of an nx x ny node grid numbered row-major (two per grid square)."""
    index = np.arange(nx * ny).reshape(nx, ny)
    return np.r_[np.c_[index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel()],
                 np.c_[index[:-1, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()]]

def folded_sheet(nx: int, ny: int, fold: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit square grid whose half x > 0.5 is folded back over the other half, 1 cm above it, and waved by
    `fold` [m] across the flat half (fold > 0.01 m: through it); nodes perturbed by 1e-7 m."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    back = x > 0.5
    points = np.c_[np.where(back, 1.0 - x, x).ravel(), y.ravel(),
                   (back * (0.01 + fold * np.sin(4 * np.pi * x) * y)).ravel()]
    points += 1e-7 * np.random.default_rng(seed).standard_normal(points.shape)
    return points, grid_triangles(nx, ny)


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
    """The ranks of a run count one part each (candidate_pairs' part k: the pairs met by run k of the triangles in
    grid order): the parts' candidate pairs are the whole list, each once, and their counts sum to the whole count."""
    points, triangles = folded_sheet(24, 16, 0.3, seed=5)
    whole = candidate_pairs(points, triangles)
    pieces = np.concatenate([candidate_pairs(points, triangles, (k, parts)) for k in range(parts)])
    assert len(pieces) == len(whole) and set(map(tuple, pieces.tolist())) == set(map(tuple, whole.tolist()))
    counts = [intersecting_pairs(points, triangles, (k, parts)) for k in range(parts)]
    assert sum(counts) == intersecting_pairs(points, triangles) > 0


def numpy_reference_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """The numpy count that the compiled pass replaced (serial): cKDTree's pairs within twice the largest
    circumradius, the sphere, box and shared-node filters, the plane and interval tests, libigl for the rest."""
    corners = points[triangles]
    centroid = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centroid[:, None], axis=2).max(axis=1)
    pairs = cKDTree(centroid).query_pairs(2.0 * float(radius.max(initial=0.0)), output_type="ndarray")
    pairs = pairs[np.linalg.norm(centroid[pairs[:, 0]] - centroid[pairs[:, 1]], axis=1)
                  <= radius[pairs[:, 0]] + radius[pairs[:, 1]]]
    low, high = corners.min(axis=1), corners.max(axis=1)
    pairs = pairs[((low[pairs[:, 0]] <= high[pairs[:, 1]]) & (low[pairs[:, 1]] <= high[pairs[:, 0]])).all(axis=1)]
    pairs = pairs[~(triangles[pairs[:, 0]][:, :, None] == triangles[pairs[:, 1]][:, None, :]).any(axis=(1, 2))]
    a, b = points[triangles[pairs[:, 0]]], points[triangles[pairs[:, 1]]]
    normal_a, normal_b = np.cross(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]), np.cross(b[:, 1] - b[:, 0], b[:, 2] - b[:, 0])
    side_b, side_a = np.einsum("ij,ikj->ik", normal_a, b - a[:, :1]), np.einsum("ij,ikj->ik", normal_b, a - b[:, :1])
    keep = ~((side_b > 0).all(axis=1) | (side_b < 0).all(axis=1) | (side_a > 0).all(axis=1) | (side_a < 0).all(axis=1))
    pairs, a, b, side_a, side_b, normal_a, normal_b = (v[keep] for v in (pairs, a, b, side_a, side_b, normal_a,
                                                                          normal_b))
    size = np.maximum(np.ptp(a, axis=1).max(axis=1), np.ptp(b, axis=1).max(axis=1))
    general = ((np.abs(side_a).min(axis=1) > 1e-9 * size * np.linalg.norm(normal_b, axis=1))
               & (np.abs(side_b).min(axis=1) > 1e-9 * size * np.linalg.norm(normal_a, axis=1)))
    direction = np.cross(normal_a, normal_b)
    general &= np.linalg.norm(direction, axis=1) > 1e-9 * (np.linalg.norm(normal_a, axis=1)
                                                          * np.linalg.norm(normal_b, axis=1))
    hits = np.zeros(len(pairs), dtype=bool)
    (low_a, high_a), (low_b, high_b) = (_reference_interval(u[general], s[general], direction[general])
                                        for u, s in ((a, side_a), (b, side_b)))
    hits[general] = np.maximum(low_a, low_b) <= np.minimum(high_a, high_b)
    for k in np.flatnonzero(~general):
        p, q = a[k], b[k]
        hits[k] = bool(igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0])
    return {tuple(p) for p in pairs[hits].tolist()}


def _reference_interval(corners, side, direction):
    projection = np.einsum("ikj,ij->ik", corners, direction)
    positive = side > 0.0
    lone = np.where(positive.sum(axis=1) == 1, np.argmax(positive, axis=1), np.argmin(positive, axis=1))
    rows = np.arange(len(side))
    others = (lone[:, None] + np.array([1, 2])) % 3
    p_v, s_v = projection[rows, lone][:, None], side[rows, lone][:, None]
    p_w, s_w = projection[rows[:, None], others], side[rows[:, None], others]
    t = p_v + (p_w - p_v) * s_v / (s_v - s_w)
    return t.min(axis=1), t.max(axis=1)


def lattice_soup(n: int, lattice: float, shared: bool, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n random triangles (edges ~0.1 m in a unit box) with nodes snapped to a lattice of spacing `lattice` [m]:
    coplanar, touching and node-on-plane pairs; `shared`: equal nodes merged (neighbours share them)."""
    rng = np.random.default_rng(seed)
    points = np.round((rng.random((n, 1, 3)) + 0.1 * rng.standard_normal((n, 3, 3))).reshape(-1, 3) / lattice)
    points, triangles = lattice * points, np.arange(3 * n).reshape(n, 3)
    if shared:
        points, inverse = np.unique(points, axis=0, return_inverse=True)
        triangles = inverse.reshape(-1, 3)
    return points, triangles


def crossing_tube(nz: int = 30, na: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A tube (radius 6 cm, 0.5 m) whose cross-section is flattened and then turned inside out in its middle
    third (x scaled by 1 -> -0.4 and back): the two sides pass through each other along a band."""
    z, angle = np.meshgrid(np.linspace(0.0, 0.5, nz), np.linspace(0.0, 2 * np.pi, na, endpoint=False), indexing="ij")
    scale = 1.0 - 1.4 * np.sin(np.pi * z / 0.5) ** 2
    points = np.c_[(0.06 * scale * np.cos(angle)).ravel(), (0.06 * np.sin(angle)).ravel(), z.ravel()]
    index = np.arange(nz * na).reshape(nz, na)
    right = np.roll(index, -1, axis=1)
    triangles = np.r_[np.c_[index[:-1].ravel(), index[1:].ravel(), right[1:].ravel()],
                      np.c_[index[:-1].ravel(), right[1:].ravel(), right[:-1].ravel()]]
    return points, triangles


@pytest.mark.parametrize("seed", range(6))
def test_count_equals_the_numpy_count_on_degenerate_soups(seed):
    points, triangles = lattice_soup(250, (0.1, 0.05, 0.25)[seed % 3], shared=seed % 2 == 1, seed=seed)
    expected = numpy_reference_pairs(points, triangles)
    assert len(expected) > 0
    assert {tuple(p) for p in intersecting(points, triangles).tolist()} == expected


@pytest.mark.parametrize("case", ["folded", "folded_exact", "tube"])
def test_count_equals_the_numpy_count_on_folds(case):
    if case == "tube":
        points, triangles = crossing_tube()
    else:
        points, triangles = folded_sheet(24, 16, 0.3, seed=2)
        points = np.round(points, 3) if case == "folded_exact" else points
    expected = numpy_reference_pairs(points, triangles)
    assert len(expected) > 0
    assert {tuple(p) for p in intersecting(points, triangles).tolist()} == expected


def test_count_is_the_brute_force_count_over_all_non_neighbour_pairs():
    """libigl on every pair sharing no node (no box pre-filter) of a soup with shared nodes and of a folded
    sheet, nodes perturbed (module docstring)."""
    rng = np.random.default_rng(11)
    soup = lattice_soup(150, 0.05, shared=True, seed=4)
    for points, triangles in (soup, folded_sheet(16, 10, 0.3, seed=7)):
        points = points + 1e-7 * rng.standard_normal(points.shape)
        found = set()
        for i, j in itertools.combinations(range(len(triangles)), 2):
            p, q = points[triangles[i]], points[triangles[j]]
            if not set(triangles[i]) & set(triangles[j]) and igl.tri_tri_intersection_test_3d(
                    p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0]:
                found.add((i, j))
        assert len(found) > 0
        assert {tuple(p) for p in intersecting(points, triangles).tolist()} == found


@pytest.mark.parametrize("parts", [1, 2, 3, 5])
def test_the_part_counts_sum_to_the_whole(parts):
    for points, triangles in (crossing_tube(), lattice_soup(250, 0.05, shared=True, seed=1)):
        whole = {tuple(p) for p in intersecting(points, triangles).tolist()}
        pieces = [{tuple(p) for p in intersecting(points, triangles, (k, parts)).tolist()} for k in range(parts)]
        assert sum(map(len, pieces)) == len(whole) > 0 and set().union(*pieces) == whole
        assert sum(intersecting_pairs(points, triangles, (k, parts)) for k in range(parts)) == len(whole)


def test_bad_input_is_refused():
    points, triangles = crossing_tube(6, 8)
    with pytest.raises(ValueError):
        intersecting_pairs(points, triangles, (2, 2))
    with pytest.raises(ValueError):
        intersecting_pairs(np.where(np.arange(len(points))[:, None] == 3, np.nan, points), triangles)
    assert intersecting_pairs(points[:0], triangles[:0]) == 0


@pytest.mark.mpi
def test_the_ranks_parts_sum_to_the_serial_count():
    """Each rank of COMM_WORLD counts its part (as fabricfem.wear.garment does); the sum is the serial count."""
    comm = MPI.COMM_WORLD
    points, triangles = crossing_tube()
    total = comm.allreduce(intersecting_pairs(points, triangles, (comm.rank, comm.size)), op=MPI.SUM)
    assert total == intersecting_pairs(points, triangles) == len(numpy_reference_pairs(points, triangles)) > 0


def _grid(nx: int, ny: int, corner: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An nx x ny node grid corner + s u + t v (s, t in [0, 1]) and its triangles."""
    s, t = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    points = corner + s.reshape(-1, 1) * u + t.reshape(-1, 1) * v
    return points, grid_triangles(nx, ny)


@pytest.mark.parametrize("angle", [30.0, 90.0, 179.0])
def test_panels_joined_by_a_seam_are_neighbours_and_a_real_crossing_still_counts(angle):
    """Two 5 x 5 panels sewn along an edge (the seam's nodes duplicated, as a garment's stitched pairs are) at a
    dihedral angle, and a strip that pierces the first panel away from the seam. The reference is the same cloth
    with the seam's nodes merged (one node each), where the only pairs the count may list are those that share no
    node: the strip's crossings. With the stitched nodes given as `same` labels the count equals it; without them the
    seam's touching triangles are listed too (31 pairs at each angle)."""
    a_points, a_tri = _grid(5, 5, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    turn = np.radians(angle)
    b_points, b_tri = _grid(5, 5, np.array([1.0, 0.0, 0.0]), np.array([-np.cos(turn), 0.0, np.sin(turn)]),
                            np.array([0.0, 1.0, 0.0]))
    strip, strip_tri = _grid(2, 2, np.array([0.3, 0.35, -0.2]), np.array([0.0, 0.0, 0.4]), np.array([0.0, 0.3, 0.0]))
    points = np.r_[a_points, b_points, strip]
    triangles = np.r_[a_tri, b_tri + len(a_points), strip_tri + len(a_points) + len(b_points)]
    seam_a = np.flatnonzero(np.isclose(a_points[:, 0], 1.0))                      # x = 1 on the first panel
    seam_b = len(a_points) + np.flatnonzero(np.isclose(b_points[:, 0] - 1.0, 0.0) & np.isclose(b_points[:, 2], 0.0))
    assert len(seam_a) == len(seam_b) == 5
    same = np.arange(len(points))
    same[seam_b] = seam_a                                                         # one label per point of the cloth
    merged = same[triangles]                                                      # the seam's nodes merged
    reference = brute_force_pairs(points, merged)
    assert reference and all(i >= 2 * len(a_tri) or j >= 2 * len(a_tri) for i, j in reference)   # the strip's
    assert {tuple(p) for p in intersecting(points, triangles, same=same)} == reference
    unlabelled = set(map(tuple, intersecting(points, triangles)))
    assert unlabelled > reference           # the seam's touching triangles are listed without the labels
    with pytest.raises(ValueError, match="same must hold one label per point"):
        intersecting(points, triangles, same=same[:-1])
