"""The wear loop's record check stops a state that blows up while staying finite (fabricfem.wear.engine): a node
faster than BLOW_UP_SPEED ends the run with reason EXPLICIT_BLOW_UP, the phase, the time and the step, and
`history.failure` set, instead of carrying numbers of 1e150 into the contact searches."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.contact.self_contact import BLOW_UP_SPEED
from fabricfem.wear.engine import Phase, WearError, run_phases


class _GrowingState:
    """A stand-in integrator of two nodes whose velocity components double every step from 1 mm/s (speeds of
    sqrt(3) x 1.02 = 1.77 m/s after 10 steps, sqrt(3) x 1049 = 1816 m/s after 20; finite for a thousand steps)."""

    def __init__(self):
        self.d = PETSc.Vec().createMPI(6, comm=MPI.COMM_SELF)
        self.v = self.d.duplicate()
        self.d.set(0.0)
        self.v.set(1e-3)
        self.t, self.dt, self.step_count = 0.0, 1e-4, 0
        self.timings = {"internal_forces": 0.0, "contact": 0.0}

    def step(self) -> None:
        self.v.scale(2.0)
        self.d.axpy(self.dt, self.v)
        self.t += self.dt


def test_a_finite_but_blown_up_state_stops_at_the_record():
    """Records of 10 steps: the first (1.77 m/s) is kept, the second (1816 m/s > BLOW_UP_SPEED) stops the run."""
    assert 1.77 < BLOW_UP_SPEED < 1816.0
    integrator = _GrowingState()
    contact = SimpleNamespace(reset_means=lambda: None, timings={"pose_torque": 0.0},
                              nodes=SimpleNamespace(dofs=np.arange(6).reshape(2, 3)))
    history = SimpleNamespace(steps=[], failure="")
    phase = Phase("motion", records=3)
    with pytest.raises(WearError, match=r"phase 'motion' before t = 0.002 s \(step 20, .*a node moves at 1.82e\+03 m/s "
                                        r"\(above 1000 m/s") as caught:
        run_phases(integrator, contact, [phase], 10, lambda phase, k, steps: k, history)
    assert caught.value.reason == "EXPLICIT_BLOW_UP"
    assert history.failure.startswith("wear: the explicit run stopped")
    assert history.steps == [0]                                    # the record at step 10 (1.77 m/s) only
    assert np.isfinite(integrator.v.norm())                        # the old check (finite state) would go on


def _still_run(rows: list[int], values: list[float], nodes: int) -> SimpleNamespace:
    """run_phases over 2 records of a state that does not change, with `values` [m/s or rad/s] in the velocity
    `rows` and the first `nodes` x 3 rows the nodes' displacement rows; returns the history."""
    integrator = _GrowingState()
    integrator.step = lambda: None
    integrator.v.setValues(rows, values)
    integrator.v.assemble()
    contact = SimpleNamespace(reset_means=lambda: None, timings={"pose_torque": 0.0},
                              nodes=SimpleNamespace(dofs=np.arange(3 * nodes).reshape(nodes, 3)))
    history = SimpleNamespace(steps=[], failure="")
    run_phases(integrator, contact, [Phase("motion", records=2)], 10, lambda phase, k, steps: k, history)
    return history


def test_rotation_rates_are_not_speeds():
    """A rate of 5000 rad/s in rows that are not displacements does not stop the run: the bound is a speed [m/s]
    (a first version, over all rows, stopped the pants at the start of the donning on 4.8e3 in such a row)."""
    history = _still_run([3, 4, 5], [5e3, 5e3, 5e3], nodes=1)
    assert history.steps == [0, 1] and history.failure == ""


def test_the_bound_is_on_the_speed_not_a_component():
    """A node at (800, 800, 800) m/s moves at 1386 m/s: stopped, though no component exceeds 1000 m/s."""
    with pytest.raises(WearError, match=r"a node moves at 1.39e\+03 m/s"):
        _still_run([0, 1, 2], [800.0, 800.0, 800.0], nodes=2)
