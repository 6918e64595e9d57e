"""Stiffness-proportional damping on the wear engine (`[route] stiffness_damping`, C = b K_M(d)): it damps
deformation only. Independent checks: a rigid translation of a free sheet has K_M v = 0 (no drag), while the mass
damping's C v = a M v is the full drag; and the setting reaches the engine's integrator with the critical step of
[Man2006, eq. 2.86] reduced by the Rayleigh ratio xi = a / (2 omega) + b omega / 2."""
import math
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import scene_data

from fabricfem import scenes as scene_module
from fabricfem.dynamics.mass import InertiaDamping
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.scenes.run import build_wear_run
from fabricfem.shell import ShellModel

ROOT = Path(__file__).resolve().parents[1]
COTTON = Fabric(E1=1.2e6, E2=1.2e6, G12=1e5, nu12=0.0, thickness=1e-3, density=436.0)


def _rigid_translation(model) -> object:
    v = model.w.vector.duplicate()
    v.set(0.0)
    u_dofs = np.asarray(model.W.sub(0).collapse()[1])
    arr = v.getArray()
    arr[u_dofs[u_dofs < len(arr)]] = 1.0 / math.sqrt(3.0)        # 1 m/s along (1, 1, 1) / sqrt(3), no rotation
    return v


def test_stiffness_damping_does_not_drag_a_rigid_translation():
    """|b K_M v| over |a M v| for a rigid translation of an undeformed 0.3 m sheet: round-off (bound 1e-8 with
    a = 1 1/s, b = 1 s, so that the two are compared at the same weight)."""
    model = ShellModel(plate(0.3, 0.3, 4, 4, cell="quadrilateral"), COTTON)
    v = _rigid_translation(model)
    out = v.duplicate()
    InertiaDamping(model, lumped=True, rayleigh=(0.0, 1.0)).damping_action(v, out)
    stiffness = out.norm()
    InertiaDamping(model, lumped=True, rayleigh=(1.0, 0.0)).damping_action(v, out)
    assert out.norm() > 0.0 and stiffness <= 1e-8 * out.norm()


def test_the_sleeve_takes_its_stiffness_damping_with_a_shorter_step():
    data = scene_data("sleeve.toml")
    data["motion"].update(final_angle=3.0, output_angle_step=1.5)
    data["output"] = {"render": False}
    runs = {}
    for b in (0.0, 2e-5):
        data["route"]["stiffness_damping"] = b
        runs[b] = build_wear_run(scene_module.validate(data), MPI.COMM_SELF)[0]
    a = data["route"]["mass_damping"]
    assert (runs[2e-5].integrator.ops.a, runs[2e-5].integrator.ops.b) == (a, 2e-5)
    # omega_max recovered from the estimate without b, then eq. 2.86 with both Rayleigh terms
    omega = stability_omega(runs[0.0].dt_estimate, a)
    xi = a / (2.0 * omega) + 2e-5 * omega / 2.0
    assert runs[2e-5].dt_estimate == pytest.approx(2.0 / omega * (math.sqrt(1.0 + xi * xi) - xi), rel=1e-9)
    for run in runs.values():
        run.destroy()


def stability_omega(dt: float, a: float) -> float:
    """The omega_max whose mass-damped critical step (eq. 2.86 with xi = a / (2 omega)) is dt, by bisection."""
    lo, hi = 1.0, 1e9
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        xi = a / (2.0 * mid)
        lo, hi = (mid, hi) if 2.0 / mid * (math.sqrt(1.0 + xi * xi) - xi) > dt else (lo, mid)
    return math.sqrt(lo * hi)
