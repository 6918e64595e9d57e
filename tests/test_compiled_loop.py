"""The compiled explicit loop (fabricfem.dynamics.compiled_loop) against the Python loop of CentralDifference.

Tolerance: 1e-10 of the largest displacement [m] (velocity, acceleration alike). The compiled step does the Python
loop's operations in its order (no contraction of multiply-adds) with the same compiled element kernels, so the
trajectories agree bit for bit on this machine (measured 0.0 for every quantity below); 1e-10 leaves room for a
BLAS that rounds the vector updates differently (1e-16 per operation, grown by at most a few orders over a few
hundred stable steps), and is far below anything physical (the corner moves 1 m).
"""
from __future__ import annotations

import numpy as np
import pytest

from fabricfem.dynamics import CentralDifference, critical_time_step
from fabricfem.dynamics.newmark import DynamicsError
from fabricfem.dynamics.strain_limit import FastProjection, attach
from fabricfem.verify.strain_limit import corner_pinned_cloth

TOLERANCE = 1e-10      # relative to the largest |d| (module docstring)
K_OVER_RHO = 1000.0    # (m/s)^2, the speed-accuracy benchmark's cloth
DRAG = 0.351           # kg/(m^2 s)


def _run(model, dt: float, steps: int, compiled, output_every: int = 10, **options) -> dict:
    """Run from rest; the state at every record, the final d, v, a [SI] and the history."""
    model.w.x.array[:] = 0.0
    integ = CentralDifference(model, dt, air_drag=DRAG, compiled=compiled, **options)
    states = []
    history = integ.run(steps, output_every=output_every, monitors={"t": lambda: integ.t},
                        after_record=lambda h: states.append(integ.d.getArray().copy()))
    out = {"records": np.array(states), "d": integ.d.getArray().copy(), "v": integ.v.getArray().copy(),
           "a": integ.a.getArray().copy(), "history": history, "route": integ.route,
           "work": integ.external_work, "dissipated": integ.dissipated, "t": integ.t}
    integ.destroy()
    return out


def _same(python: dict, compiled: dict) -> None:
    """The two runs agree to TOLERANCE (states, records, time, energies of the history)."""
    scale = np.abs(python["d"]).max()
    assert scale > 0.01
    assert python["records"].shape == compiled["records"].shape
    for key in ("records", "d", "v", "a"):
        assert np.abs(python[key] - compiled[key]).max() <= TOLERANCE * max(scale, np.abs(python[key]).max()), key
    assert compiled["t"] == pytest.approx(python["t"], rel=1e-14)
    for key in ("kinetic", "strain", "external_work", "dissipated"):
        assert np.allclose(getattr(compiled["history"], key), getattr(python["history"], key), rtol=1e-10,
                           atol=1e-14), key


@pytest.fixture(scope="module")
def membrane():
    return corner_pinned_cloth(K_OVER_RHO, 2)


def test_membrane_same_trajectory(membrane):
    """300 steps of the 2x2 Q2 membrane swinging under gravity with air drag: 30 records of the whole state."""
    dt = 0.9 * critical_time_step(membrane)
    python = _run(membrane, dt, 300, False)
    compiled = _run(membrane, dt, 300, "auto")
    assert python["route"].startswith("python") and compiled["route"] == "compiled"
    _same(python, compiled)


def test_load_ramp_and_prescribed_motion():
    """A load factor lambda(t) (a ramp) scaling gravity and a prescribed corner displacement (energy check off, as
    "auto" does for prescribed values)."""
    model = corner_pinned_cloth(K_OVER_RHO, 2)
    model.constrain(lambda x: np.isclose(x[0], 1.0) & np.isclose(x[1], 0.0), u=(0.05, None, None))
    dt = 0.9 * critical_time_step(model)

    def ramp(t: float) -> float:
        return min(1.0, t / 0.05)
    python = _run(model, dt, 200, False, output_every=7, load_factor=ramp)
    compiled = _run(model, dt, 200, True, output_every=7, load_factor=ramp)
    _same(python, compiled)
    assert compiled["d"].max() > 0.04           # the prescribed corner moved


def test_shell_kernel_with_step_checks():
    """The Naghdi shell (hand-written kernel, rotary scale 100) with the safe-step estimate every 20 steps."""
    model = corner_pinned_cloth(K_OVER_RHO, 2, model="naghdi")
    dt = 0.9 * critical_time_step(model, rotary_inertia_scale=100.0)
    options = {"rotary_inertia_scale": 100.0, "step_check_every": 20}
    python = _run(model, dt, 200, False, output_every=25, **options)
    compiled = _run(model, dt, 200, True, output_every=25, **options)
    assert compiled["route"] == "compiled"
    _same(python, compiled)


def test_blowup_stops_at_the_same_step(membrane):
    """A step 3x the critical one blows up; both loops stop at the same step with the same message."""
    dt = 3.0 * critical_time_step(membrane)
    messages = []
    for compiled in (False, True):
        membrane.w.x.array[:] = 0.0
        integ = CentralDifference(membrane, dt, air_drag=DRAG, force=True, compiled=compiled)
        with pytest.raises(DynamicsError) as error:
            integ.run(500, output_every=50)
        messages.append((str(error.value), error.value.step))
        integ.destroy()
    assert messages[0] == messages[1]


def test_route_choice(membrane):
    """A Python hook (the strain limit's wrapped step) takes the Python loop under "auto" and is refused under
    compiled=True; a bad value is refused."""
    dt = 0.9 * critical_time_step(membrane)
    with pytest.raises(ValueError, match="compiled"):
        CentralDifference(membrane, dt, compiled="yes")
    for compiled in ("auto", True):
        membrane.w.x.array[:] = 0.0
        integ = CentralDifference(membrane, dt, air_drag=DRAG, compiled=compiled)
        projection = FastProjection(membrane, 0.01)
        attach(projection, integ)
        try:
            if compiled is True:
                with pytest.raises(ValueError, match="strain limit"):
                    integ.run(2)
            else:
                integ.run(2)
                assert integ.route.startswith("python: the step is wrapped")
        finally:
            integ.destroy()
            projection.destroy()
