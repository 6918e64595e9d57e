"""Rigid planes and rounded boxes (fabricfem.contact.obstacles): gaps against closed forms, C1 normals across
the fillet, bad input, and shells resting on them under gravity (total contact force = weight)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact.obstacles import Plane, RoundedBox, table_edge, table_top
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify.drape import OVERHANG_THEORY_SEED, overhang_theory


def test_plane_gap_is_the_distance_along_the_normal():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, 3))
    plane = Plane((0.1, -0.2, 0.3), (1.0, 2.0, 2.0))
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    g, normal = plane.gap(x)
    assert np.allclose(g, (x - [0.1, -0.2, 0.3]) @ n, rtol=0, atol=1e-15)   # closed form, rounding only
    assert np.allclose(normal, n, rtol=0, atol=1e-15)
    assert np.all(plane.contains(x) == (g < 0))


def test_table_edge_gap_closed_form_on_top_fillet_and_inside():
    r, top = 1e-3, 0.02
    table = table_edge(0.0, top, r)
    # above the flat top: g = z - top, n = e_z
    g, n = table.gap(np.array([[-0.05, 0.3, top + 1e-3], [-1e-6, 0.0, top - 1e-4]]))
    assert np.allclose(g, [1e-3, -1e-4], rtol=0, atol=1e-15) and np.allclose(n, [0, 0, 1])
    # beyond the edge: distance to the fillet axis (x = 0, z = top - r) minus r, normal radial from the axis
    phi = np.linspace(0.0, 0.5 * math.pi, 7)
    rho = 1.7e-3
    pts = np.column_stack([rho * np.sin(phi), np.full(7, 0.1), top - r + rho * np.cos(phi)])
    g, n = table.gap(pts)
    assert np.allclose(g, rho - r, rtol=0, atol=1e-15)
    assert np.allclose(n, np.column_stack([np.sin(phi), np.zeros(7), np.cos(phi)]), rtol=0, atol=1e-12)
    # deep inside: distance to the nearest face (the vertical face x = 0 here)
    g, n = table.gap(np.array([[-0.001, 0.0, top - 0.05]]))
    assert np.isclose(g[0], -0.001 - r, rtol=0, atol=1e-15) and np.allclose(n, [[1, 0, 0]])


def test_rounded_box_gap_is_continuous_with_its_gradient_over_the_fillet():
    """g is C1: the normal returned equals the central-difference gradient of g along a path over the edge
    and the corner (exact signed distance: |grad g| = 1)."""
    box = table_top((0.0, 0.0), 0.04, 0.04, 0.0, 1e-3)
    s = np.linspace(-0.002, 0.002, 41)
    paths = [np.column_stack([0.04 + s, np.zeros_like(s), 2e-4 - 0.05 * s]),             # over an edge
             np.column_stack([0.04 + s, 0.04 + s, 2e-4 - 0.05 * s])]                      # over a corner
    h = 1e-8
    for x in paths:
        _, n = box.gap(x)
        grad = np.column_stack([(box.gap(x + h * e)[0] - box.gap(x - h * e)[0]) / (2 * h) for e in np.eye(3)])
        # central differences of an exact distance: error ~ h kappa = 1e-5 (kappa = 1/r), rounding 1e-8
        assert np.allclose(grad, n, rtol=0, atol=1e-5)
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
        assert np.max(np.linalg.norm(np.diff(n, axis=0), axis=1)) < 0.2   # no jump of the normal on the path


def test_obstacles_reject_bad_input():
    with pytest.raises(ValueError, match="normal"):
        Plane((0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="radius"):
        RoundedBox((0, 0, 0), (1, 1, 1), 0.0)
    with pytest.raises(ValueError, match="lower"):
        RoundedBox((1, 0, 0), (0, 1, 1), 0.1)
    with pytest.raises(ValueError, match="half_x"):
        table_top((0, 0), -1.0, 1.0, 0.0, 0.1)
    with pytest.raises(ValueError, match="x must be finite"):
        Plane((0, 0, 0), (0, 0, 1)).gap([np.nan, 0, 0])
    with pytest.raises(ValueError, match="obstacles"):
        ContactProblem.set_obstacles(object.__new__(ContactProblem), [object()])


def test_overhang_closed_form_reproduces_the_seed_theory_row():
    theory = overhang_theory()
    scale = {"p": 1e-2, "deflection": 1e-2, "R_b": 9.80665e-3, "R_c": 9.80665e-3}
    for k, v in OVERHANG_THEORY_SEED.items():
        assert math.isclose(theory[k] / scale[k], v, rel_tol=5e-3)   # the seed rounds to 3-4 digits


@pytest.mark.mpi
@pytest.mark.parametrize("obstacle", ["plane", "table"])
def test_shell_resting_on_obstacle_carries_its_weight(obstacle):
    """A 4 cm square Naghdi plate (4 x 4 quads) lying on a plane, or on an 8 cm table, under gravity: the
    total contact force equals the weight (global equilibrium; 1%: exact up to Newton's tolerance) and the
    nodes sink by the penalty penetration q / k_N (uniform pressure q = rho t g on a flat support)."""
    side, rho, t, grav = 0.04, 300.0, 5e-4, 9.81
    model = ShellModel(plate(side, side, 4, 4, cell="quadrilateral", origin=(-side / 2, -side / 2, 0.0)),
                       Fabric.isotropic(1e6, 0.3, t, density=rho))
    model.constrain(lambda x: np.isclose(x[0], -side / 2) & np.isclose(x[1], -side / 2), u=(0.0, 0.0, None))
    model.constrain(lambda x: np.isclose(x[0], side / 2) & np.isclose(x[1], -side / 2), u=(None, 0.0, None))
    model.add_gravity((0.0, 0.0, -grav))
    q = rho * t * grav
    k_N = ContactProblem(model, [Plane((0, 0, 0), (0, 0, 1))]).penalty
    top = 0.5 * q / k_N     # start in contact (interference) so that the vertical rigid mode is supported
    body = Plane((0, 0, top), (0, 0, 1)) if obstacle == "plane" else table_top((0, 0), 0.04, 0.04, top, 1e-3)
    problem = ContactProblem(model, [body])
    solve_load_path(problem.system, 1.0, initial_step=0.5)
    weight = q * side ** 2
    total = problem.total_force()
    assert math.isclose(total[2], weight, rel_tol=0.01)
    s = problem.evaluate()
    assert np.allclose(s.gap, -q / k_N, rtol=1e-3)   # uniform penetration of a rigid-body translation
    assert MPI.COMM_WORLD.allreduce(len(s.gap), op=MPI.SUM) == 81
