"""Moment vectors and symmetry planes: bad input is refused naming the parameter, before any solve."""
import numpy as np
import pytest

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
