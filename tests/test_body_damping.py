"""Mass damping relative to the body (`[route] damping_frame = "body"`, fabricfem.contact.body_frame): closed-form
checks on a free, weightless sheet driven by nothing but its initial velocity and the damping.

- carried with a body in rigid translation at V: the damping force vanishes, the momentum stays m V (to round-off);
  against the ground it decays by the trapezoidal factor ((1 - a dt/2) / (1 + a dt/2))^n, exp(-a t) to O((a dt)^2);
- a velocity u relative to the body decays as the ODE w' = -a w says: w_n = u ((1 - a dt/2) / (1 + a dt/2))^n;
- spinning in its plane with a body rotating at the same omega: the angular momentum about the axis stays I omega
  (body frame), while against the ground dL/dt = -a L gives L0 exp(-a t) (mass-proportional damping, the internal
  forces' moment vanishing); the hook's reference velocity is omega x r to (omega dt)^2 / 6.
"""
import math

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import scene_data

from fabricfem import scenes as scene_module
from fabricfem.body.pose import Body, Segment
from fabricfem.contact.body_frame import BodyFrameDamping, segment_weights
from fabricfem.dynamics import stability
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.scenes.run import build_wear_run
from fabricfem.shell import ShellModel

COTTON = Fabric(E1=1.2e6, E2=1.2e6, G12=1e5, nu12=0.0, thickness=1e-3, density=436.0)
ALPHA = 10.0          # 1/s
CENTER = np.array([0.05, 0.05, 0.0])


class Moving:
    """Joints a, b along z through CENTER + V t and a marker m turning about z at omega [rad/s]."""

    names = ("a", "b", "m")
    time_range = (0.0, 10.0)

    def __init__(self, velocity=(0.0, 0.0, 0.0), omega: float = 0.0):
        self.velocity, self.omega = np.asarray(velocity, dtype=float), float(omega)

    def positions(self, t: float) -> dict:
        c = CENTER + self.velocity * t
        turn = np.array([math.cos(self.omega * t), math.sin(self.omega * t), 0.0])
        return {"a": c + (0, 0, -1.0), "b": c + (0, 0, -0.5), "m": c + turn + (0, 0, -0.75)}


def _sheet(kinematics: Moving, frame: str):
    """A free 0.1 m sheet (4x4 Q2), no gravity, and its integrator with the mass damping ALPHA in `frame`."""
    model = ShellModel(plate(0.1, 0.1, 4, 4, cell="quadrilateral", comm=MPI.COMM_SELF), COTTON, rebase=False)
    model.compile()
    body = Body([Segment("post", "a", "b", "m", (0.3, 0.05, 0.05))], kinematics)
    hooks = [BodyFrameDamping(model, body)] if frame == "body" else None
    dt_crit = stability.critical_time_step(model, (ALPHA, 0.0), rotary_inertia_scale=100.0)
    integ = CentralDifference(model, 0.5 * dt_crit, rayleigh=(ALPHA, 0.0), energy_bound=None,
                              rotary_inertia_scale=100.0, contact=hooks, dt_crit=dt_crit)
    return model, integ, (hooks[0] if hooks else BodyFrameDamping(model, body))


def _start(integ, hook, velocity: np.ndarray, frame: str) -> None:
    """v^0 = `velocity` (N, 3) on the translations and a^0 = -alpha (v^0 - v_b) (the body's v_b in its frame)."""
    integ.initialize()
    v, a = integ.v.getArray(), integ.a.getArray()
    v[hook.dofs] = velocity
    relative = velocity - (hook.body_velocity(hook.reference, 0.0, -integ.dt, integ.dt) if frame == "body" else 0.0)
    a[:] = 0.0
    a[hook.dofs] = -ALPHA * relative


def _momentum(integ, hook) -> np.ndarray:
    m = integ.ops.mass_diag.getArray(readonly=True)[hook.dofs]
    return (m * integ.v.getArray(readonly=True)[hook.dofs]).sum(axis=0)


@pytest.mark.parametrize("frame", ["body", "ground"])
def test_a_sheet_carried_in_translation_keeps_its_momentum_only_in_the_body_frame(frame):
    V = np.array([0.3, -0.1, 0.05])                      # m/s
    model, integ, hook = _sheet(Moving(velocity=V), frame)
    _start(integ, hook, np.tile(V, (len(hook.dofs), 1)), frame)
    p0 = _momentum(integ, hook)
    n = 200
    for _ in range(n):
        integ.step()
    factor = ((1 - ALPHA * integ.dt / 2) / (1 + ALPHA * integ.dt / 2)) ** n
    expected = p0 if frame == "body" else p0 * factor
    assert np.allclose(_momentum(integ, hook), expected, rtol=1e-9, atol=0.0)
    if frame == "ground":      # the trapezoidal factor is the ODE's exp(-a t) to (a dt)^2 a t / 12
        t = n * integ.dt
        assert factor == pytest.approx(math.exp(-ALPHA * t), rel=2 * (ALPHA * integ.dt) ** 2 * ALPHA * t / 12)
    integ.destroy()


def test_a_velocity_relative_to_the_body_decays_at_the_rate_alpha():
    V, u = np.array([0.3, -0.1, 0.05]), np.array([0.0, 0.02, -0.04])
    model, integ, hook = _sheet(Moving(velocity=V), "body")
    _start(integ, hook, np.tile(V + u, (len(hook.dofs), 1)), "body")
    n = 300
    for _ in range(n):
        integ.step()
    factor = ((1 - ALPHA * integ.dt / 2) / (1 + ALPHA * integ.dt / 2)) ** n
    w = integ.v.getArray(readonly=True)[hook.dofs] - V
    assert np.allclose(w, u * factor, rtol=1e-9, atol=1e-12)
    assert factor == pytest.approx(math.exp(-ALPHA * n * integ.dt), rel=1e-4)
    integ.destroy()


def test_the_reference_velocity_of_a_rotating_body_is_omega_cross_r():
    omega = 2.0                                            # rad/s about z through CENTER
    model, integ, hook = _sheet(Moving(omega=omega), "body")
    h = 1e-3
    x = hook.reference + np.array([0.0, 0.0, 0.01])
    v_b = hook.body_velocity(x, 0.3, 0.3 - h, 0.3 + h)
    exact = np.cross([0.0, 0.0, omega], x - CENTER)
    assert np.abs(v_b - exact).max() <= (omega * h) ** 2 / 6 * np.abs(exact).max() + 1e-14
    integ.destroy()


@pytest.mark.parametrize("frame", ["body", "ground"])
def test_a_sheet_spinning_with_the_body_keeps_its_angular_momentum_only_in_the_body_frame(frame):
    omega = 2.0
    model, integ, hook = _sheet(Moving(omega=omega), frame)
    r = hook.reference - CENTER
    _start(integ, hook, np.cross([0.0, 0.0, omega], r), frame)
    m = integ.ops.mass_diag.getArray(readonly=True)[hook.dofs][:, 0]

    def spin() -> float:
        x = hook.reference + integ.d.getArray(readonly=True)[hook.dofs] - CENTER
        v = integ.v.getArray(readonly=True)[hook.dofs]
        return float(np.sum(m * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0])))

    L0, n = spin(), 400
    for _ in range(n):
        integ.step()
    t = n * integ.dt
    expected = L0 if frame == "body" else L0 * math.exp(-ALPHA * t)
    assert spin() == pytest.approx(expected, rel=1e-4)
    integ.destroy()


def test_the_segment_weights_are_a_partition_of_unity_and_one_segment_away_from_the_joint():
    body = Body([Segment("upper", "a", "b", "m", (0.15, 0.04, 0.04)),
                 Segment("lower", "b", "c", "n", (0.15, 0.04, 0.04))],
                type("Still", (), {"names": ("a", "b", "c", "m", "n"), "time_range": (0.0, 1.0),
                                   "positions": staticmethod(lambda t: {
                                       "a": np.zeros(3), "b": np.array([0.3, 0, 0]), "c": np.array([0.6, 0, 0]),
                                       "m": np.array([0.15, 1, 0]), "n": np.array([0.45, 1, 0])})})())
    ellipsoids = list(body.pose(0.0).values())
    x = np.stack([np.linspace(0.0, 0.6, 601), np.full(601, 0.05), np.zeros(601)], axis=1)
    W = segment_weights(x, ellipsoids, 0.05)
    assert np.allclose(W.sum(axis=1), 1.0) and W.min() >= 0.0
    assert np.all(W[x[:, 0] < 0.2, 0] == 1.0) and np.all(W[x[:, 0] > 0.4, 1] == 1.0)
    assert np.abs(np.diff(W[:, 0])).max() < 0.05                   # no jump across the joint
    assert np.all(segment_weights(x, ellipsoids, 0.05, np.array([False, False])) == 0.0)


def test_the_sleeve_takes_the_body_frame_with_the_same_step():
    data = scene_data("sleeve.toml")
    data["motion"].update(final_angle=3.0, output_angle_step=1.5)
    data["garment"].update(n_around=10, n_along=13)
    data["output"] = {"render": False}
    runs = {}
    for frame in ("ground", "body"):
        data["route"]["damping_frame"] = frame
        runs[frame] = build_wear_run(scene_module.validate(data), MPI.COMM_SELF)[0]
    assert runs["ground"].body_damping is None
    assert isinstance(runs["body"].body_damping, BodyFrameDamping)
    assert runs["body"].integrator._hooks[0] is runs["body"].body_damping
    assert runs["body"].dt == runs["ground"].dt and runs["body"].dt_estimate == runs["ground"].dt_estimate
    for run in runs.values():
        run.destroy()
