"""The cloth's kinetic energy relative to the body (fabricfem.wear.relative_motion) against closed forms, and the
verdict's kinetic energy check using it where a record has it."""
import math

import numpy as np

from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.relative_motion import body_relative_energy
from fabricfem.wear.verdict import Bounds, wear_checks


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


def _step(**values) -> WearStep:
    base = dict(phase="motion", time=1.0, torques={"knee": 0.1}, peak_pressure=2e3, peak_segment="shank",
                peak_position=(0.0, 0.0, 0.0), mean_pressure=1e3, max_penetration=1e-5, contact_force=1.0,
                seam_gap=1e-4, seam_forces={}, max_strain=0.05, time_steps=10, kinetic_energy=1e-2,
                strain_energy=1e-2, wall=0.0)
    return WearStep(**{**base, **values})


def test_the_check_takes_the_relative_energy_where_a_record_has_it():
    """A record whose ground-frame kinetic energy equals its strain energy (ratio 1, above the bound 0.5) passes when
    its energy relative to the body is a tenth of it, and fails without that measurement (nan)."""
    def ratio(step):
        history = WearHistory("walk", steps=[_step(phase="settle"), step], initial_gap=0.01)
        return {c.name: c for c in wear_checks(history, Bounds(), failure_strain=0.3)}["kinetic energy"]
    assert ratio(_step(relative_kinetic_energy=1e-3)).passed and ratio(_step(relative_kinetic_energy=1e-3)).value == 0.1
    assert not ratio(_step()).passed and ratio(_step()).value == 1.0
