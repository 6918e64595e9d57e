"""Cloth-cloth contact (fabricfem.contact.self_contact): the pair search against brute force and ipctk, the edge-edge
search and distances likewise, the load balance of two pressed sheets and of two rails holding a crossing strip by
their edges alone, the independent intersection counter, the refused contact distances, and 1 against 2 ranks on a
short fold."""
from __future__ import annotations

import ipctk
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact import edge_contact, proximity
from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.intersections import intersecting_pairs
from fabricfem.contact.self_contact import SelfContact
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.verify import self_contact as case


def _grid(n: int, L: float = 0.1):
    """An n x n node grid in z = 0 split into triangles (two per square, a square is a 'cell')."""
    s = np.linspace(0.0, L, n)
    X, Y = np.meshgrid(s, s, indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    triangles = np.stack([np.stack([a, b, d], 1), np.stack([a, d, c], 1)], axis=1).reshape(-1, 3)
    cells = np.repeat(np.arange(len(a)), 2)
    cell_nodes = np.stack([a, b, c, d], axis=1)
    return x, triangles, cells, cell_nodes


def test_pair_search_matches_brute_force():
    """The compiled hash and ipctk's broad phase find exactly the pairs of the brute-force search (every vertex
    against every triangle) on a sheet folded onto itself 0.8 mm apart with 1e-5 m noise; distances and barycentric
    coordinates agree to round-off."""
    x, triangles, cells, cell_nodes = _grid(11)
    right = x[:, 0] > 0.05
    x[right, 0] = 0.1 - x[right, 0]
    x[right, 2] = 8e-4
    x += 1e-5 * np.random.default_rng(0).standard_normal(x.shape)
    reference = proximity.brute_force_pairs(x, triangles, cells, cell_nodes, 1e-3).sorted()
    assert len(reference) > 100
    for pairs in (proximity.compiled_pairs(x, triangles, cells, cell_nodes, 1e-3, MPI.COMM_SELF),
                  proximity.ipctk_pairs(x, triangles, cells, cell_nodes, 1e-3)):
        pairs = pairs.sorted()
        np.testing.assert_array_equal(pairs.vertex, reference.vertex)
        np.testing.assert_array_equal(pairs.triangle, reference.triangle)
        np.testing.assert_allclose(pairs.distance, reference.distance, rtol=0, atol=1e-15)
        np.testing.assert_allclose(pairs.bary, reference.bary, rtol=0, atol=1e-12)


def test_edge_pair_search_matches_brute_force():
    """On the folded sheet of the vertex-triangle test (its upper half shifted 3 mm so that the edges cross), the
    compiled hash finds exactly the edge pairs of testing every pair of edges, with and without the interior rule;
    distances and parameters agree to round-off."""
    x, triangles, _, _ = _grid(11)
    right = x[:, 0] > 0.05
    x[right, 0] = 0.103 - x[right, 0]
    x[right, 2] = 8e-4
    x += 1e-5 * np.random.default_rng(0).standard_normal(x.shape)
    edges = edge_contact.surface_edges(triangles)
    for interior in (True, False):
        reference = edge_contact.brute_force_pairs(x, edges, 1e-3, 1e-6, interior).sorted()
        pairs = edge_contact.compiled_pairs(x, edges, 1e-3, 1e-6, MPI.COMM_SELF, interior).sorted()
        assert len(reference) > 100
        np.testing.assert_array_equal(pairs.first, reference.first)
        np.testing.assert_array_equal(pairs.second, reference.second)
        np.testing.assert_allclose(pairs.distance, reference.distance, rtol=0, atol=1e-15)
        np.testing.assert_allclose(pairs.s, reference.s, rtol=0, atol=1e-10)
        np.testing.assert_allclose(pairs.t, reference.t, rtol=0, atol=1e-10)


def test_segment_distance_matches_ipctk():
    """The closest points of two segments: the distance equals ipctk's edge-edge distance for random segments (every
    clamping branch hit), and the closest points of two crossed segments are their crossing point's parameters."""
    rng = np.random.default_rng(2)
    p1, q1, p2, q2 = (rng.standard_normal((300, 3)) for _ in range(4))
    _, _, distance, _ = edge_contact.closest_segment_points(p1, q1, p2, q2)
    expected = [np.sqrt(ipctk.edge_edge_distance(*(v[i] for v in (p1, q1, p2, q2)))) for i in range(len(p1))]
    np.testing.assert_allclose(distance, expected, rtol=1e-12, atol=1e-14)
    s, t, d, _ = edge_contact.closest_segment_points(np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]),
                                                     np.array([[0.25, -1.0, 1e-3]]), np.array([[0.25, 3.0, 1e-3]]))
    np.testing.assert_allclose([s[0], t[0], d[0]], [0.25, 0.25, 1e-3], rtol=1e-12)


def test_crossed_strips_held_by_their_edges():
    """A strip pressed onto two held rails that it crosses with no node within 2.5 mm of the other's triangles: with
    the edge-edge term the contact force equals the applied load within 1 %, no vertex-triangle pair ever acts and
    no triangles intersect; without it the strip falls through the rails."""
    held = case.strips(True)
    assert held["contact"][2] == pytest.approx(-held["load"][2], rel=0.01)
    assert held["vertex_pairs"] == 0 and held["edge_pairs"] > 0 and max(held["intersections"]) == 0
    assert held["lowest"] > 0.0
    assert case.strips(False, steps=3000)["lowest"] < -case.THICKNESS


def test_closest_points_match_ipctk():
    """The numpy closest point's distance equals ipctk's point-triangle distance (sqrt of its squared distance)
    for random points around random triangles, every Voronoi region hit."""
    rng = np.random.default_rng(1)
    p, a, b, c = (rng.standard_normal((200, 3)) for _ in range(4))
    _, distance = proximity.closest_points(p, a, b, c)
    expected = [np.sqrt(ipctk.point_triangle_distance(*(v[i] for v in (p, a, b, c)))) for i in range(len(p))]
    np.testing.assert_allclose(distance, expected, rtol=1e-12, atol=1e-14)


def test_stacked_sheets_load_balance():
    """Two stacked sheets pressed by a uniform pressure: the contact force on the upper sheet equals the applied
    load within 1 % (static equilibrium), and the sheets stay at least half the thickness apart."""
    out = case.press(steps=900)
    assert out["contact"][2] == pytest.approx(-out["load"][2], rel=0.01)
    assert out["min_distance"] >= 0.5 * case.THICKNESS


def test_intersection_counter():
    """A flat sheet has no intersecting pairs; a flap through it at x = 0.3 of a cell (y in [0.1 W, 0.9 W], inside
    the cell) crosses the cell's two triangles: the flap's triangle over y in [0.1 W, W/2] at z = 0 meets both (the
    cell's diagonal is at y = 0.3 W there), the one over [W/2, 0.9 W] only the triangle above the diagonal: 3
    pairs."""
    x, triangles, _, _ = _grid(6, L=0.5)
    assert intersecting_pairs(x, triangles) == 0
    h, x0, W = 0.1, 0.2 + 0.3 * 0.1, 0.1       # the cell [0.2, 0.3] x [0, 0.1]; the flap at x0
    y0, y1 = 0.1 * W, 0.9 * W
    flap = np.array([(x0, y0, -h), (x0, y1, -h), (x0, y0, h), (x0, y1, h)])
    n = len(x)
    flap_triangles = np.array([(n, n + 1, n + 3), (n, n + 3, n + 2)])
    assert intersecting_pairs(np.vstack([x, flap]), np.vstack([triangles, flap_triangles])) == 3


def _small_model(comm=MPI.COMM_WORLD) -> ShellModel:
    model = ShellModel(plate(0.1, 0.1, 4, 4, cell="quadrilateral", comm=comm), case.cotton())
    model.compile()
    return model


def test_surface_triangulation_and_refused_distances():
    """The Q2 cells split through their nodes cover the sheet once (triangle areas sum to its area, none
    intersect); a contact distance <= 0 or above the mesh size is refused naming the key."""
    model = _small_model()
    surface = ClothSurface(model)
    x = surface.reference
    t = surface.triangles
    area = 0.5 * np.linalg.norm(np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]), axis=1)
    assert area.sum() == pytest.approx(0.01, rel=1e-12)
    assert intersecting_pairs(x, t) == 0
    assert SelfContact(model).distance == pytest.approx(case.THICKNESS)
    for bad in (0.0, -1e-3, 0.03, float("nan")):
        with pytest.raises(ValueError, match="contact_distance"):
            SelfContact(model, contact_distance=bad)



def test_stitched_labels_join_the_seams_pairs_and_leave_other_nodes_alone():
    """ClothSurface.stitched: the nodes of each joined pair (and chains of pairs) share one label, every other
    node has a label of its own (the partition of the nodes by the joined graph, checked against a union-find
    written here)."""
    surface = ClothSurface(_small_model())
    n = surface.count
    joined = np.array([[0, 5], [5, 9], [2, 3]])
    labels = surface.stitched(joined)
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for a, b in joined:
        parent[root(a)] = root(b)
    groups = {}
    for i in range(n):
        groups.setdefault(root(i), set()).add(int(labels[i]))
    assert all(len(g) == 1 for g in groups.values()) and len(set(labels)) == len(groups) == n - 3
    assert len(set(surface.stitched(None))) == n


def test_seam_neighbours_take_no_contact():
    """Two far nodes a, b of a sheet stitched together (a seam's pair): `seam_neighbours` lists, against a brute
    force over all vertex-triangle and edge-edge pairs, the vertex a or b with every triangle that has a or b as a
    node, and the edges that have a or b as an end; with a moved onto b (the seam sewn), the pairs of a with b's
    triangles take contact without the seam and none with it."""
    from fabricfem.contact.self_contact import seam_neighbours
    model = _small_model()
    surface = ClothSurface(model)
    x0 = surface.reference
    a, b = int(np.argmin(x0[:, 0] + x0[:, 1])), int(np.argmax(x0[:, 0] + x0[:, 1]))   # opposite corners
    joined = np.array([[a, b]])
    plain = SelfContact(model)
    sewn = SelfContact(model, joined=joined)
    keys, edge_keys = seam_neighbours(surface, surface.stitched(joined), sewn.edges)
    T, E = len(surface.triangles), len(sewn.edges)
    holds = [{a, b} & set(triangle) for triangle in surface.triangles]
    expected = sorted(v * T + t for v in (a, b) for t in range(T) if holds[t])
    assert keys.tolist() == expected
    ends = [set(e) & {a, b} for e in sewn.edges]
    expected_edges = sorted(i * E + j for i in range(E) for j in range(i + 1, E) if ends[i] and ends[j])
    assert edge_keys.tolist() == expected_edges
    x = x0.copy()
    x[a] = x0[b] + np.array([0.0, 0.0, 0.2 * case.THICKNESS])      # sewn, a hair above b's cells
    of_b = {t for t in range(T) if b in set(surface.triangles[t])}
    assert any(v == a and t in of_b for v, t in zip(*_pair_lists(plain.contact_pairs(x))))
    assert not any(v == a and t in of_b for v, t in zip(*_pair_lists(sewn.contact_pairs(x))))


def _pair_lists(pairs) -> tuple[list, list]:
    return pairs.vertex.tolist(), pairs.triangle.tolist()

def _short_fold(comm, steps: int = 2000) -> tuple[np.ndarray, int, int]:
    """Positions (N, 3) [m] of all nodes, ordered by their reference coordinates, after `steps` of the fold with
    self-contact, and the numbers of vertex-triangle and of edge-edge contact pairs then."""
    model = case.fold_model(comm)
    contact = SelfContact(model)
    integrator = case._integrator(model, [contact], case.FOLD_RAYLEIGH)
    for _ in range(steps):
        integrator.step()
    x = contact.surface.positions(integrator.d.getArray(readonly=True))
    order = np.lexsort(np.round(contact.surface.reference / 1e-9).T)
    integrator.destroy()
    return x[order], len(contact.pairs), len(contact.edge_pairs)


@pytest.mark.mpi
def test_one_and_two_ranks_agree_on_a_short_fold():
    """The fold's upper leg falling onto the lower one until contact acts: the positions on the ranks of
    COMM_WORLD and on one rank agree within 1e-6 m (the same pairs found across rank boundaries; only the
    summation order differs)."""
    parallel, pairs, edge_pairs = _short_fold(MPI.COMM_WORLD)
    serial, _, _ = _short_fold(MPI.COMM_SELF)
    assert pairs > 0 and edge_pairs > 0
    assert np.max(np.abs(parallel - serial)) < 1e-6


def test_verlet_list_and_compiled_response_match_the_direct_route():
    """Along the fold (serial, 3000 steps: contact from step ~1900), the Verlet list's vertex-triangle and edge-edge
    pairs equal a full search's at every 50th step, it searched far fewer times than it stepped (~200 of 3000 steps
    while the leg falls), and the compiled response of both kinds equals its numpy twin (forces to 1e-12 of the
    largest)."""
    model = case.fold_model(MPI.COMM_SELF)
    contact = SelfContact(model, friction=0.3)
    integrator = case._integrator(model, [contact], case.FOLD_RAYLEIGH)
    compared = 0
    for step in range(3000):
        integrator.step()
        if step % 50 == 49:
            x = contact.surface.positions(integrator.d.getArray(readonly=True))
            direct, kept = contact.contact_pairs(x).sorted(), contact.pairs.sorted()
            np.testing.assert_array_equal(kept.vertex, direct.vertex)
            np.testing.assert_array_equal(kept.triangle, direct.triangle)
            np.testing.assert_allclose(kept.distance, direct.distance, rtol=0, atol=1e-15)
            direct_edges, kept_edges = contact.contact_edge_pairs(x).sorted(), contact.edge_pairs.sorted()
            np.testing.assert_array_equal(kept_edges.first, direct_edges.first)
            np.testing.assert_array_equal(kept_edges.second, direct_edges.second)
            np.testing.assert_allclose(kept_edges.distance, direct_edges.distance, rtol=0, atol=1e-15)
            compared += len(direct) > 0
    assert compared >= 15 and contact.searches < 300
    pairs = contact.pairs
    compiled = contact.force.copy()
    vel = contact.surface.gather(integrator.velocity_predictor.getArray(readonly=True)[contact.surface.nodes.dofs])
    contact._respond(x, vel, pairs, contact._masses(integrator)[0], integrator.dt, contact.edge_pairs)
    assert len(pairs) > 0 and len(contact.edge_pairs) > 0
    np.testing.assert_allclose(compiled, contact.force, rtol=0, atol=1e-12 * np.abs(compiled).max())
    integrator.destroy()
