"""Moment vectors (edge and point) and symmetry planes: point moments against the exact roll-up circle; bad
input is refused naming the parameter, before any solve."""
import numpy as np
import pytest

from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.verify import references
from fabricfem.verify.cantilevers import strip_model


@pytest.mark.parametrize("moment", [(np.nan, 0.0, 1.0), (0.0, 0.0, 0.0), (1.0, 0.0)])
def test_bad_moment_is_refused(moment):
    with pytest.raises(ValueError, match="moment"):
        strip_model(1.0, 0.1, 1e7, 1e-3, 2).add_edge_moment("right", moment)


@pytest.mark.parametrize("normal, why", [((np.nan, 0.0, 0.0), "finite"), ((0.0, 0.0, 0.0), "non-zero"),
                                         ((0.0, 1.0, 0.0), "does not contain"), ((1.0, 1.0, 0.0), "does not contain"),
                                         ((1.0, 0.0, 1.0), "normal along"),
                                         ((0.0, 0.0, 1.0), "normal along")])
def test_bad_symmetry_normal_is_refused(normal, why):
    """NaN, zero, a plane that does not contain the edge x = L (normal y, or tilted), and a plane that contains
    the edge but not the sheet's normal (z) are refused naming `normal`."""
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 2)
    with pytest.raises(ValueError, match=f"normal.*{why}"):
        model.symmetry("right", normal)


def test_symmetry_at_an_angle_turns_the_base_and_keeps_the_moment_path():
    """A symmetry plane at 30 degrees to the warp turns the director base to it (a2 = -n on the edge)."""
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 2, warp_angle=np.radians(30))
    model.symmetry("right", (1.0, 0.0, 0.0))
    assert np.allclose(model.a2.x.array.reshape(-1, 3), (-1.0, 0.0, 0.0))


@pytest.mark.mpi
@pytest.mark.parametrize("warp_degrees", [0.0, 45.0])
def test_point_moments_roll_the_strip_into_the_exact_circle(warp_degrees):
    """Point moments (1/6, 2/3, 1/6) M at the three tip nodes of a one-element-wide Q2 strip (the consistent
    nodal split of a uniform edge moment; exact here, since the tip section turns rigidly) roll the strip
    with its warp along it or at 45 degrees into the circle of radius EI / M: tip error below 1e-3 L at
    m = 0.5 and 1 (the edge-moment roll-up on the same mesh is 4.5e-5 L off)."""
    L, width, t, E = 1.0, 0.1, 1e-3, 1e7
    model = strip_model(L, width, E, t, 40, warp_angle=np.radians(warp_degrees))
    EI = E * width * t ** 3 / 12.0
    M = 2.0 * np.pi * EI / L
    for y, share in ((0.0, 1 / 6), (width / 2, 2 / 3), (width, 1 / 6)):
        model.add_point_moment((L, y, 0.0), (0.0, -share * M, 0.0))
    tip, positions = np.array([L, 0.0, 0.0]), {}
    solve_load_path(model, [0.5, 1.0], initial_step=0.05, max_step=0.05,
                    on_target=lambda m: positions.__setitem__(round(m, 12), tip + model.node_value(tip)))
    for m, x in positions.items():
        exact = references.rollup_tip(L, m * 2.0 * np.pi / L)
        assert np.hypot(x[0] - exact[0], x[2] - exact[1]) + abs(x[1]) < 1e-3 * L, (m, x, exact)


@pytest.mark.parametrize("moment, point, message", [((0.0, float("nan"), 0.0), (1.0, 0.0, 0.0), "moment"),
                                                    ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), "moment"),
                                                    ((0.0, 1.0, 0.0), (0.5013, 0.0, 0.0), "not a mesh node")])
def test_bad_point_moment_is_refused(moment, point, message):
    model = strip_model(1.0, 0.1, 1e7, 1e-3, 10)
    with pytest.raises(ValueError, match=message):
        model.add_point_moment(point, moment)
        model.compile()
