"""The wearer contract: what every route of a garment on a moving wearer gives its callers.

A route (explicit central differences, implicit backward Euler, quasi-static Newton per pose) is built from a
config by `fabricfem.wear.run.build_run` and returns a `WearRun`; callers (the scene runner, the recorder,
studies) use only this interface and never branch on the route's name. The torque comes from the contact's
torque monitors (fabricfem.contact.torque.TorqueMonitor: one path), the pressure from the contact's one
pressure field (fabricfem.contact.nodal.pressure_function: force per unit deformed cloth area [Pa]).
"""
from __future__ import annotations

from typing import Callable, Protocol

from dolfinx import fem
from mpi4py import MPI

from fabricfem.body.pose import Body
from fabricfem.shell import ShellModel


class WearRun(Protocol):
    """A garment on a moving wearer, ready to run (SI units; angles in degrees).

    Attributes: `config` (the run's configuration), `model` (the garment's ShellModel), `body` (the posed
    wearer), `comm` (its communicator)."""

    config: object
    model: ShellModel
    body: Body

    @property
    def comm(self) -> MPI.Comm: ...

    def describe(self) -> str:
        """One line naming the route and its step (for the run's log)."""

    def run(self, on_step: Callable | None = None, stop_on_failure: bool = True):
        """Run the motion; `on_step(step)` after every record; returns the torque history (its `failure` says
        why a run with stop_on_failure=False stopped early)."""

    def pressure_field(self) -> fem.Function:
        """The contact pressure on the body [Pa] per unit deformed cloth area at the last record."""

    def posed_bodies(self, coordinate: float) -> list:
        """The body's ellipsoid segments at a record coordinate (the steps' `coordinate`: a joint angle [deg]
        or a time [s])."""

    def body_time(self, step) -> float:
        """The body time [s] of record `step`."""

    def fraction(self, step) -> float:
        """The done fraction in [0, 1] of the run at record `step` (progress and time left)."""

    def destroy(self) -> None:
        """Free the PETSc objects of the route."""
