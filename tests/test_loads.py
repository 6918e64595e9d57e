"""Prescribed rotations with their reaction, gravity, and point loads against closed forms."""
import numpy as np
import pytest

from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import references

L, WIDTH, T, E = 1.0, 0.05, 1e-3, 1e7
EI = E * WIDTH * T ** 3 / 12.0


def strip(nx=20, **fabric_kw):
    model = ShellModel(plate(L, WIDTH, nx, 1, cell="quadrilateral"), Fabric.isotropic(E, 0.0, T, **fabric_kw))
    return model.clamp("left")


@pytest.mark.mpi
def test_prescribed_end_rotation_rolls_up_with_exact_moment():
    """Thesis sec. 2.3.2.2: the free end turned by a prescribed angle phi (up to a full turn) bends the
    strip into an arc of curvature phi / L; the reaction moment at the end equals EI phi / L and the tip
    lies on the circle. Tolerance 1%: P2 arc interpolation error O((h/R)^3) is far below it."""
    model = strip()
    full_turn = 2.0 * np.pi
    model.constrain("right", theta=(None, -full_turn))  # about -y: curls towards +z
    tip = np.array([L, 0.0, 0.0])
    checks = []

    def check(lam):
        phi = lam * full_turn
        moment = -model.reaction("right", "theta", 1)  # moment the support applies about +y, sign flipped
        position = tip + model.node_value(tip)
        exact = references.rollup_tip(L, phi / L)
        checks.append((phi, moment, EI * phi / L, np.hypot(position[0] - exact[0], position[2] - exact[1])))
    solve_load_path(model, [0.25, 0.5, 1.0], initial_step=0.05, on_target=check)
    for phi, moment, moment_exact, position_error in checks:
        assert moment == pytest.approx(moment_exact, rel=1e-2), phi
        assert position_error < 1e-2 * L, phi


def test_gravity_small_deflection_matches_beam_theory():
    """Cantilever under its own weight, small load: tip deflection q L^4 / (8 EI) with q = rho t b g
    (Euler-Bernoulli). Density chosen so that w/L ~ 1e-4 (geometric nonlinearity ~1e-8). Tolerance 0.5%:
    shear deformation (t/L)^2 ~ 1e-6 and the P2 discretisation of a quartic are far below it."""
    g = 9.81
    rho = 1e-4 * L * 8 * EI / (T * WIDTH * g * L ** 4)  # so that w / L = 1e-4
    model = strip(density=rho)
    model.add_gravity((0.0, 0.0, -g))
    solve_load_path(model, 1.0, initial_step=1.0)
    q = rho * T * WIDTH * g
    w = -model.node_value((L, 0.0, 0.0))[2]
    assert w == pytest.approx(q * L ** 4 / (8 * EI), rel=5e-3)


def test_point_loads_and_reactions_balance():
    """Two point loads at the tip corners: the clamp's vertical reaction equals their sum (equilibrium,
    to the Newton tolerance: 1e-5) and the tip deflection is P L^3 / (3 EI) in the linear range (0.5%)."""
    model = strip()
    P = 1e-4 * 3 * EI / L ** 3 * L  # w/L = 1e-4
    for y in (0.0, WIDTH):
        model.add_point_load((L, y, 0.0), (0.0, 0.0, -P / 2))
    solve_load_path(model, 1.0, initial_step=1.0)
    assert model.reaction("left", "u", 2) == pytest.approx(P, rel=1e-5)  # Newton stops at 1e-9 of the first residual
    assert -model.node_value((L, 0.0, 0.0))[2] == pytest.approx(P * L ** 3 / (3 * EI), rel=5e-3)
