"""The compiled passes of the central-difference step (fabricfem.dynamics.explicit_update) give the values of the
PETSc calls they replace to the bit: on random vectors, and over Python-loop runs of a cloth with a load ramp, a
prescribed corner displacement, air drag (diagonal damping) and Rayleigh mass damping, the passes on and off
(serial and on 2 ranks: each rank's owned entries)."""
from __future__ import annotations

import numpy as np
import pytest

from fabricfem.dynamics import CentralDifference, critical_time_step
from fabricfem.dynamics.explicit_update import _compare, matches_petsc
from fabricfem.verify.strain_limit import corner_pinned_cloth

K_OVER_RHO = 1000.0    # (m/s)^2
DRAG = 0.351           # kg/(m^2 s)


@pytest.mark.mpi
def test_passes_round_as_petsc():
    """Random vectors of several lengths (the vector loops' tails), Dirichlet rows every 7th entry."""
    assert matches_petsc()
    for n, seed in ((1, 1), (13, 2), (4097, 3)):
        assert _compare(n, seed)


def _run(model, dt: float, steps: int, passes: bool, **options) -> dict:
    """Python-loop run from rest with the passes on or off: d, v, a, the damping force and the kinetic energies."""
    model.w.x.array[:] = 0.0
    integ = CentralDifference(model, dt, compiled=False, **options)
    integ.vector_passes = passes
    kinetic = []
    integ.run(steps, output_every=10, after_record=lambda h: kinetic.append(integ.kinetic_energy()))
    out = {name: getattr(integ, name).getArray().copy() for name in ("d", "v", "a", "_cv")}
    out["kinetic"], out["route"], out["passes"] = np.array(kinetic), integ.route, integ._passes
    integ.destroy()
    return out


@pytest.mark.mpi
@pytest.mark.parametrize("options", [{"air_drag": DRAG}, {"rayleigh": (5.0, 0.0)}, {}])
def test_same_run_to_the_bit(options):
    model = corner_pinned_cloth(K_OVER_RHO, 2)
    model.constrain(lambda x: np.isclose(x[0], 1.0) & np.isclose(x[1], 0.0), u=(0.05, None, None))
    dt = 0.9 * critical_time_step(model)

    def ramp(t: float) -> float:
        return min(1.0, t / 0.05)
    petsc = _run(model, dt, 200, False, load_factor=ramp, **options)
    passes = _run(model, dt, 200, True, load_factor=ramp, **options)
    assert petsc["route"].startswith("python") and petsc["passes"] is None and passes["passes"]
    for key in ("d", "v", "a", "_cv", "kinetic"):
        assert np.array_equal(petsc[key], passes[key]), key
    assert np.abs(passes["d"]).max() > 0.04       # the prescribed corner moved


def test_damping_matrix_keeps_petsc():
    """Stiffness-proportional damping (a matrix C): the step keeps PETSc's calls."""
    model = corner_pinned_cloth(K_OVER_RHO, 2)
    dt = 0.5 * critical_time_step(model)
    integ = CentralDifference(model, dt, rayleigh=(0.0, 1e-5), compiled=False, force=True)
    assert integ._step_passes() is None
    integ.destroy()
