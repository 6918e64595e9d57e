"""The cloth's kinetic energy relative to the body (fabricfem.wear.relative_motion) against closed forms (the
verdict's use of it: tests/test_verdict.py)."""
import math

import numpy as np

from fabricfem.wear.relative_motion import body_relative_energy


def test_nodes_moving_with_their_segment_have_no_relative_energy():
    """Nodes carried rigidly by their nearest segment (v = v_k + omega_k x (x - c_k), two segments with different
    motions) have K_rel = 0 to round-off; adding a uniform velocity u to every node gives 1/2 M |u|^2 (closed form,
    M the total mass), whatever the segments do."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(40, 3))
    mass = np.repeat(rng.uniform(0.1, 1.0, size=(40, 1)), 3, axis=1)
    centre, linear, angular = rng.normal(size=(2, 3)), rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
    nearest = (x[:, 0] > 0).astype(int)
    carried = linear[nearest] + np.cross(angular[nearest], x - centre[nearest])
    assert body_relative_energy(mass, carried, x, centre, linear, angular, nearest) < 1e-28
    u = np.array([0.3, -0.2, 0.5])
    expected = 0.5 * mass[:, 0].sum() * u @ u
    assert math.isclose(body_relative_energy(mass, carried + u, x, centre, linear, angular, nearest), expected,
                        rel_tol=1e-12)
