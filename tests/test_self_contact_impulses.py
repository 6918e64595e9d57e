"""The velocity-level impulses of cloth-cloth contact (fabricfem.contact.impulses) against closed forms and
conservation laws: one pair's inelastic impulse stops its relative normal velocity and conserves momentum, its
friction is mu times the normal impulse while sliding and stops the slip otherwise; two free sheets thrown at each
other with a negligible penalty stay apart and keep their total momentum; 1 and 2 ranks agree."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact import impulses
from fabricfem.contact.edge_contact import EdgePairs, no_edge_pairs
from fabricfem.contact.proximity import Pairs
from fabricfem.contact.self_contact import SelfContact
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.stability import critical_time_step
from fabricfem.meshes.gmsh_io import mesh_from_gmsh
from fabricfem.shell import ShellModel
from fabricfem.verify import self_contact as case

D_C = 1e-3          # m, the contact distance


def _vertex_triangle(u: np.ndarray, mass: np.ndarray, mu: float):
    """A vertex 0.5 mm above the triangle (0,0,0), (1,0,0), (0,1,0) at the barycentric point w; velocities u (4, 3)
    [m/s] (triangle's nodes, then the vertex), masses (4,) [kg]. Returns (u after, normal, friction impulses, w)."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.3, 5e-4]])
    w = np.array([0.5, 0.2, 0.3])
    pairs = Pairs(np.array([3]), np.array([0]), np.array([5e-4]), w[None, :])
    after = u.copy()
    normal, friction, acted, _ = impulses.apply(pairs, no_edge_pairs(), np.array([[0, 1, 2]], dtype=np.int64),
                                                np.zeros((0, 2), dtype=np.int64), x, after, 1.0 / mass, D_C, mu, 3,
                                                MPI.COMM_SELF)
    assert acted.tolist() == [1]
    return after, normal, friction, w


def test_vertex_triangle_impulse_closed_form():
    """The vertex falls at 1 m/s onto the rising triangle and slides along x: after the impulse its relative normal
    velocity is 0 (the gap no longer shrinks), the total momentum sum m u is unchanged to round-off, the normal
    impulse is m_eff times the approach speed (1 / m_eff = 1 / m_p + sum w_i^2 / m_i) and, sliding, the friction
    impulse is mu times it, against the slip."""
    mass = np.array([1.0, 2.0, 3.0, 0.5])
    u = np.array([[0.0, 0.0, 0.5], [0.1, 0.0, 0.5], [0.0, 0.0, 0.2], [0.3, 0.0, -1.0]])
    after, normal, friction, w = _vertex_triangle(u, mass, mu=0.1)
    relative = after[3] - w @ after[:3]
    assert relative[2] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose((mass[:, None] * after).sum(0), (mass[:, None] * u).sum(0), rtol=0, atol=1e-15)
    approach = (u[3] - w @ u[:3])[2]
    m_eff = 1.0 / (1.0 / mass[3] + (w ** 2 / mass[:3]).sum())
    assert normal[3, 2] == pytest.approx(-m_eff * approach, rel=1e-14)
    assert friction[3, 0] == pytest.approx(-0.1 * normal[3, 2], rel=1e-14)
    assert relative[0] == pytest.approx((u[3] - w @ u[:3])[0] - 0.1 * abs(approach), rel=1e-14)


def test_vertex_triangle_friction_sticks_and_separating_pairs_are_left_alone():
    """A slow slip (below mu times the approach speed) is stopped: the relative tangential velocity is 0, the
    friction impulse below mu times the normal one; a separating pair takes no impulse."""
    mass = np.array([1.0, 1.0, 1.0, 1.0])
    u = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, -0.02, -1.0]])
    after, normal, friction, w = _vertex_triangle(u, mass, mu=0.3)
    np.testing.assert_allclose(after[3] - w @ after[:3], 0.0, atol=1e-15)
    assert np.linalg.norm(friction[3]) < 0.3 * np.linalg.norm(normal[3])
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.3, 5e-4]])
    up = u * np.array([1.0, 1.0, -1.0])
    before = up.copy()
    pairs = Pairs(np.array([3]), np.array([0]), np.array([5e-4]), w[None, :])
    _, _, acted, taken = impulses.apply(pairs, no_edge_pairs(), np.array([[0, 1, 2]], dtype=np.int64),
                                        np.zeros((0, 2), dtype=np.int64), x, up, 1.0 / mass, D_C, 0.3, 4,
                                        MPI.COMM_SELF)
    assert acted.tolist() == [0] and taken == 1
    np.testing.assert_array_equal(up, before)


def test_edge_edge_impulse_closed_form():
    """Two crossed edges 0.4 mm apart closing at 2 m/s: the relative normal velocity at the closest points (weights
    1 - s, s, -(1 - t), -t) becomes 0, momentum is conserved, the normal impulse is m_eff times the approach speed."""
    x = np.array([[-1.0, 0.0, 4e-4], [1.0, 0.0, 4e-4], [0.0, -1.0, 0.0], [0.0, 3.0, 0.0]])
    s, t = 0.5, 0.25
    mass = np.array([1.0, 3.0, 2.0, 0.5])
    u = np.array([[0.0, 0.0, -1.0], [0.0, 0.5, -1.0], [0.0, 0.0, 1.0], [0.2, 0.0, 1.0]])
    w = np.array([1.0 - s, s, -(1.0 - t), -t])
    edge_pairs = EdgePairs(np.array([0]), np.array([1]), np.array([4e-4]), np.array([s]), np.array([t]))
    after = u.copy()
    normal, _, acted, _ = impulses.apply(Pairs(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros((0, 3))),
                                         edge_pairs, np.zeros((0, 3), dtype=np.int64),
                                         np.array([[0, 1], [2, 3]], dtype=np.int64), x, after, 1.0 / mass, D_C,
                                         0.0, 3, MPI.COMM_SELF)
    assert acted.tolist() == [1]
    assert (w @ after)[2] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose((mass[:, None] * after).sum(0), (mass[:, None] * u).sum(0), rtol=0, atol=1e-15)
    m_eff = 1.0 / (w ** 2 / mass).sum()
    assert normal[0, 2] * (1.0 - s) ** -1 == pytest.approx(-m_eff * (w @ u)[2], rel=1e-14)



@pytest.mark.parametrize("s_weight", [0.1, 0.3, 0.45])
def test_a_pair_with_one_free_node_is_bounded_in_friction_too(s_weight):
    """Crossed edges (a, b) and (c, d) 0.4 mm apart; only node b is free (a, c, d held: inverse mass 0), at the
    weight s of the closest point. The held edge slides along x at 1 m/s under b, which approaches at 0.1 m/s:
    a pair sliding fast with little approach, as cloth on a moving body. The bound of the normal impulse (no node's
    change above |u_N|) now holds for the friction as well: b's tangential change is at most the relative
    tangential speed (here mu |u_N| = 0.05 m/s: Coulomb's limit binds), and |J_T| <= mu |J_N| for the impulses
    that act. With 1 / m_eff in the friction, b took mu |u_N| / s: 0.5 m/s at s = 0.1."""
    x = np.array([[-2.0 * s_weight, 0.0, 4e-4], [2.0 * (1.0 - s_weight), 0.0, 4e-4], [0.0, -1.0, 0.0],
                  [0.0, 3.0, 0.0]])                                          # they cross at s and t = 0.25
    t, mu = 0.25, 0.5
    inverse = np.array([0.0, 2.0, 0.0, 0.0])
    u = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.1], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    edge_pairs = EdgePairs(np.array([0]), np.array([1]), np.array([4e-4]), np.array([s_weight]), np.array([t]))
    after = u.copy()
    normal, friction, acted, _ = impulses.apply(
        Pairs(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros((0, 3))), edge_pairs,
        np.zeros((0, 3), dtype=np.int64), np.array([[0, 1], [2, 3]], dtype=np.int64), x, after, inverse, D_C, mu, 1,
        MPI.COMM_SELF)
    assert acted.tolist() == [1]
    np.testing.assert_array_equal(after[[0, 2, 3]], u[[0, 2, 3]])           # the held nodes do not move
    change = after[1] - u[1]
    assert abs(change[2]) <= 0.1 * (1 + 1e-12)                                # the normal bound: |u_N|
    assert np.hypot(change[0], change[1]) <= mu * 0.1 * (1 + 1e-12)           # the friction bound: mu |u_N|
    assert np.linalg.norm(friction[1]) <= mu * np.linalg.norm(normal[1]) * (1 + 1e-12)

def test_a_bounded_pair_acts_in_one_pass_only():
    """The crossed edges above with only b free, at the weight s = 0.1 of the closest point, b approaching at 1 m/s
    (the pair at |u_N| = s x 1 = 0.1 m/s), no sliding, 8 passes: b's change is |u_N| = 0.1 m/s (the bound of one
    pass) and the pair acts in one pass. When every pass applied the bound again to the remaining approach
    (1 - s) |u_N|, b's change added up to 0.1 (1 - 0.9^8) / (1 - 0.9) = 0.57 m/s here; on the pants walk a node
    went from 4.7 to 102 m/s in one step."""
    s_weight = 0.1
    x = np.array([[-2.0 * s_weight, 0.0, 4e-4], [2.0 * (1.0 - s_weight), 0.0, 4e-4], [0.0, -1.0, 0.0],
                  [0.0, 3.0, 0.0]])
    inverse = np.array([0.0, 2.0, 0.0, 0.0])
    u = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    edge_pairs = EdgePairs(np.array([0]), np.array([1]), np.array([4e-4]), np.array([s_weight]), np.array([0.25]))
    after = u.copy()
    _, _, acted, _ = impulses.apply(
        Pairs(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros((0, 3))), edge_pairs,
        np.zeros((0, 3), dtype=np.int64), np.array([[0, 1], [2, 3]], dtype=np.int64), x, after, inverse, D_C, 0.0, 8,
        MPI.COMM_SELF)
    assert acted.tolist() == [1]
    assert np.linalg.norm(after[1] - u[1]) == pytest.approx(0.1, rel=1e-12)


def _thrown_sheets(passes: int, speed: float = 0.5, steps: int = 400, comm=MPI.COMM_WORLD) -> dict:
    """Two free sheets (case._two_rectangles, 2 mm apart), the upper thrown down at `speed` [m/s], the lower up at
    half of it; no gravity, no damping, a penalty k_N = 1e-3 Pa/m (it cannot hold them). Returns the smallest
    pair distance over the run [m], the largest |change| of the total momentum sum M v [kg m/s] and its scale."""
    fmesh = mesh_from_gmsh(lambda m: case._two_rectangles(m, 6, 4, 2.0 * case.THICKNESS), (1.0, 0.0, 0.0),
                           (0.0, 0.0, 1.0), comm, name="two-sheets")
    model = ShellModel(fmesh, case.cotton())
    model.compile()
    contact = SelfContact(model, penalty=1e-3, passes=passes)
    dt = 0.8 * critical_time_step(model, (0.0, 0.0), rotary_inertia_scale=case.ROTARY_SCALE)
    integrator = CentralDifference(model, dt, rotary_inertia_scale=case.ROTARY_SCALE, contact=[contact],
                                   energy_bound=None)
    nodes = contact.surface.nodes
    rows = nodes.dofs
    upper = nodes.reference[:, 2] > 0.5 * case.THICKNESS
    v = integrator.v.getArray()
    v[rows[upper, 2]], v[rows[~upper, 2]] = -speed, 0.5 * speed
    mass = integrator.ops.mass_diag.getArray(readonly=True)[rows]

    def momentum() -> np.ndarray:
        return comm.allreduce((mass * integrator.v.getArray(readonly=True)[rows]).sum(axis=0), op=MPI.SUM)

    start, drift, smallest = momentum(), 0.0, np.inf
    for _ in range(steps):
        integrator.step()
        drift = max(drift, float(np.abs(momentum() - start).max()))
        if len(contact.pairs):
            smallest = min(smallest, float(contact.pairs.distance.min()))
    scale = comm.allreduce(float((mass[:, 2] * speed).sum()), op=MPI.SUM)
    integrator.destroy()
    return {"smallest": smallest, "drift": drift, "scale": scale, "dt": dt}


def test_thrown_sheets_stay_apart_and_keep_their_momentum():
    """Closing at 0.75 m/s with a penalty too weak to act: with the impulses the smallest pair distance stays within
    one step's approach (0.75 m/s x dt) of d_c and the total momentum changes by round-off only (1e-12 of the
    sheets' m v); without them the sheets pass through (pairs at distance far below d_c)."""
    held = _thrown_sheets(passes=4)
    assert held["smallest"] >= case.THICKNESS - 0.75 * held["dt"] - 1e-9
    assert held["drift"] < 1e-12 * held["scale"]
    through = _thrown_sheets(passes=0)
    assert through["smallest"] < 0.5 * case.THICKNESS


def _fold_positions(comm, passes: int = 4, steps: int = 2000) -> np.ndarray:
    """All nodes' positions (N, 3) [m], ordered by reference coordinates, after `steps` of the fold
    (fabricfem.verify.self_contact.fold_model) with the impulses' `passes`."""
    model = case.fold_model(comm)
    contact = SelfContact(model, passes=passes)
    integrator = case._integrator(model, [contact], case.FOLD_RAYLEIGH)
    acted = 0
    for _ in range(steps):
        integrator.step()
        acted += contact.impulse_passes > 0
    assert acted > 0
    x = contact.surface.positions(integrator.d.getArray(readonly=True))
    order = np.lexsort(np.round(contact.surface.reference / 1e-9).T)
    integrator.destroy()
    return x[order]


@pytest.mark.mpi
def test_one_and_two_ranks_agree_with_impulses():
    """The fold's upper leg landing on the lower one with the impulses acting: the ranks of COMM_WORLD and one rank
    agree within 1e-6 m (the pairs swept in the reference order on any partition)."""
    np.testing.assert_allclose(_fold_positions(MPI.COMM_WORLD), _fold_positions(MPI.COMM_SELF), rtol=0, atol=1e-6)


def test_refused_passes():
    """A negative or non-integer number of passes is refused naming the key."""
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="passes"):
            impulses.checked_passes(bad)
