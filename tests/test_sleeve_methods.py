"""Contact methods of the explicit sleeve (the three-method table) on a case with a closed-form answer,
and dynamic similarity of the sleeve flexion.

Plate on a support: a free square plate (no supports, mu = 0) under its own weight settles by damped central
differences onto a rigid, nearly flat ellipsoid (radii 1000, 1000, 1 m: the top sags 2.5e-9 m over the
plate). At rest the contact forces carry the weight (force balance, a conservation law independent of the
contact algorithm): sum_i f_i = rho t g A. For the penalty law f_i = w_i k_N <-g_i> (w_i = int N_i dA, the
same weights as the consistent nodal weight of the uniform gravity load) the penetration is then uniform,
-g = rho t g / k_N (closed form), so the penetration falls like 1/k_N; the Lagrange multipliers of [Man2006, Box 5]
leave no penetration at all and carry the same weight.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.body.motion import JointTrajectory
from fabricfem.body.pose import Body, Segment
from fabricfem.contact.explicit import ExplicitBodyContact
from fabricfem.dynamics import stability
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel

E, T, RHO, G = 1e6, 1e-3, 400.0, 9.81      # Pa, m, kg/m^3, m/s^2
SIDE = 0.1                                  # m
WEIGHT_PER_AREA = RHO * T * G               # rho t g [Pa]


def support(top: float = 0.0) -> Body:
    """A fixed ellipsoid with radii (1000, 1000, 1) m whose top point is (SIDE/2, SIDE/2, top)."""
    c = np.array([SIDE / 2, SIDE / 2, top - 1.0])
    points = {"a": c - [1.0, 0, 0], "b": c + [1.0, 0, 0], "m": c + [0, 1.0, 0]}
    kinematics = JointTrajectory([0.0, 100.0], {k: np.array([v, v]) for k, v in points.items()})
    return Body([Segment("support", "a", "b", "m", (1000.0, 1000.0, 1.0))], kinematics)


def settle(method: str, penalty: float | None, periods: float = 12.0):
    """Drop-free settling (starting in touch) of the plate on the support; returns (contact, integrator)."""
    model = ShellModel(plate(SIDE, SIDE, 4, 4, cell="quadrilateral", comm=MPI.COMM_SELF),
                       Fabric.isotropic(E, 0.0, T, density=RHO))
    model.add_gravity((0.0, 0.0, -G))
    model.compile()
    contact = ExplicitBodyContact(model, support(), friction=0.0, method=method, penalty=penalty)
    omega_p = contact.penalty_frequency()
    omega_shell = stability.max_frequency_estimate(model, 100.0)
    # mass damping: a quarter of the slowest of the penalty spring and the plate's rigid settling (omega_p)
    # frequencies, or 200 1/s for the rigid Lagrange contact; the transient then decays like exp(-alpha t / 2)
    alpha = 0.5 * omega_p if omega_p > 0 else 200.0
    dt_crit = stability.critical_time_step(model, (alpha, 0.0), omega_max=math.hypot(omega_shell, omega_p))
    integrator = CentralDifference(model, 0.8 * dt_crit, rayleigh=(alpha, 0.0), dt_crit=dt_crit, energy_bound=None,
                                   rotary_inertia_scale=100.0, contact=contact)
    integrator.initialize(t0=0.0)
    n_steps = int(math.ceil(periods * 2.0 / alpha / integrator.dt))   # exp(-6 periods) ~ 2.5e-3 per e-fold x 12
    for _ in range(n_steps):
        integrator.step()
        integrator.step_count += 1
    return contact, integrator, n_steps


@pytest.mark.parametrize("factor", [1.0, 10.0, 100.0])
def test_penalty_penetration_is_weight_over_stiffness(factor):
    """Penalty k_N = 6.4e4 x {1, 10, 100} Pa/m (two decades): at rest (after 12 decay times 2 / alpha of the
    mass damping: transient exp(-12) ~ 6e-6 of the initial out-of-balance) the area-weighted mean penetration
    equals rho t g / k_N and the total contact force the weight, both within 1e-4 relative (the remaining
    transient, plus the support's tilt over the plate, 1 - cos(7e-5 rad) ~ 2e-9); the largest penetration
    within 1e-3 of it (the support's sag of 2.5e-9 m over the plate against penetrations >= 6e-7 m: 4e-3 at
    most for the stiffest case, a bound rather than an estimate; measured below)."""
    k = 6.4e4 * factor
    contact, integrator, n_steps = settle("penalty", k)
    d = integrator.d.getArray(readonly=True)
    x = contact.reference + d[contact.dofs]
    g = contact.poses.ellipsoids(integrator.t)[0].gap(x)[0]
    w = contact.area
    mean_penetration = float(np.sum(w * -g) / np.sum(w))
    expected = WEIGHT_PER_AREA / k
    total = contact.force.sum(axis=0)
    weight = WEIGHT_PER_AREA * SIDE ** 2
    print(f"k_N = {k:.3g} Pa/m ({n_steps} steps): mean penetration {mean_penetration:.6e} m, rho t g / k "
          f"{expected:.6e} m, max {float(np.max(-g)):.6e} m, contact force {total[2]:.6e} N vs weight {weight:.6e} N")
    assert np.all(contact.active)
    assert mean_penetration == pytest.approx(expected, rel=1e-4)
    assert total[2] == pytest.approx(weight, rel=1e-4)
    assert float(np.max(-g)) == pytest.approx(expected, rel=4e-3)
    integrator.destroy()


def test_lagrange_contact_carries_the_weight_without_penetration():
    """[Man2006, Box 5] forward-increment multipliers on the same plate: the time-averaged contact force over the last
    100 steps carries the weight within 1e-4 (the transient has decayed by exp(-12)), and no node penetrates
    by more than 1e-12 m (the projection puts the next predictor on the surface; round-off of positions of
    order 1 m is ~1e-16 m)."""
    contact, integrator, _ = settle("lagrange", None)
    contact.reset_means()
    forces = []
    for _ in range(100):
        integrator.step()
        forces.append(contact.force.sum(axis=0)[2])
    d = integrator.d.getArray(readonly=True)
    g = contact.poses.ellipsoids(integrator.t)[0].gap(contact.reference + d[contact.dofs])[0]
    weight = WEIGHT_PER_AREA * SIDE ** 2
    print(f"Lagrange: mean contact force {np.mean(forces):.6e} N vs weight {weight:.6e} N, min gap {g.min():.3e} m")
    assert np.mean(forces) == pytest.approx(weight, rel=1e-4)
    assert float(np.min(g)) > -1e-12
    integrator.destroy()
