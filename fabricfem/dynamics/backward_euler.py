"""Backward-Euler inertia and mass-proportional damping as a ResidualTerm (fabricfem.solvers.system).

One step of M x'' + c M x' + R(x) = 0 from (x^n, v^n) with step dt, in the end-of-step state x:

    M (x - x^n - dt v^n) / dt^2 + c M (x - x^n) / dt + R(x) = 0,   v^{n+1} = (x - x^n) / dt

([Man2006, eq. 2.84] with the accelerations and velocities of backward Euler; M: a lumped diagonal mass of
eq. 2.82 [kg, kg m^2] as a PETSc Vec, fabricfem.dynamics.mass.lumped_mass; c [1/s]: mass-proportional damping,
e.g. air drag eta / (rho t) [[Peng2022, eq. 17d]]). The term adds

    r = M ((x - x^n) (1 / dt^2 + c / dt) - v^n / dt)      [N, N m],   tangent (1 / dt^2 + c / dt) M,

on every row but the Dirichlet ones. Backward Euler is L-stable: modes far above 1 / dt are damped (amplification
-> 0 as omega dt -> inf), at the price of a numerical damping ratio ~ omega dt / 2 on the resolved motion.
Rows with zero mass (e.g. the director angles with `lumped_mass(model, rotational=False)`) carry no inertia.

Used by the tablecloth drop (fabricfem.verify.drape) and the implicit sleeve (fabricfem.wear.sleeve_implicit):
`CompositeSystem(model, [contact, BackwardEulerInertia(model, mass, c, dt)])`, whose `after_converged_step`
re-bases the director first (angles to zero), then commits x^n, v^n here.
"""
from __future__ import annotations

import math

import numpy as np
from petsc4py import PETSc

from fabricfem.solvers.system import owned_dirichlet_rows


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive time step [s], got {value!r}")
    return float(value)


class BackwardEulerInertia:
    """ResidualTerm of one backward-Euler step (module docstring).

    Args:
        model: the system whose state `w` the term reads (a ShellModel; its `bcs` give the Dirichlet rows).
        mass: lumped diagonal mass M [kg, kg m^2] (PETSc Vec of the model's layout, entries >= 0); kept, not
            copied (the caller destroys it after `destroy`).
        damping: c >= 0 [1/s] (damping force c M v).
        dt: step [s] > 0 (`set_time_step` changes it for the next solve).

    The committed state x^n starts as the model's current state, v^n as zero (`reset`).
    """

    def __init__(self, model, mass: PETSc.Vec, damping: float, dt: float):
        entries = mass.getArray()
        if not (np.all(np.isfinite(entries)) and np.all(entries >= 0.0)):
            raise ValueError("mass: the lumped masses must be finite and >= 0 [kg]")
        if not (isinstance(damping, (int, float, np.floating)) and math.isfinite(damping) and damping >= 0.0):
            raise ValueError(f"damping must be a number >= 0 [1/s], got {damping!r}")
        self.model, self.mass, self.damping = model, mass, float(damping)
        self.dt = _positive("dt", dt)
        self.d = model.create_vector()        # x^n
        self.v = model.create_vector()        # v^n
        self._tmp = model.create_vector()
        self._diag = model.create_vector()
        self._bc_rows = owned_dirichlet_rows(model)
        moving = np.ones(self.d.getLocalSize(), dtype=bool)
        moving[self._bc_rows] = False
        self._predicted = np.flatnonzero(moving & (entries > 0.0)).astype(np.int32)
        self.reset()

    def reset(self):
        """x^n <- the model's current state, v^n <- 0 (a start from rest)."""
        self.model.w.vector.copy(self.d)
        self.v.set(0.0)

    def set_time_step(self, dt: float):
        """Use step dt [s] for the next solve (from the committed x^n, v^n)."""
        self.dt = _positive("dt", dt)

    def add_residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """b += M ((x - x^n) (1 / dt^2 + c / dt) - v^n / dt) off the Dirichlet rows."""
        dt, c = self.dt, self.damping
        x.copy(self._tmp)
        self._tmp.axpy(-1.0, self.d)
        self._tmp.scale(1.0 / dt ** 2 + c / dt)
        self._tmp.axpy(-1.0 / dt, self.v)
        self._tmp.pointwiseMult(self._tmp, self.mass)
        self._tmp.getArray()[self._bc_rows] = 0.0
        b.axpy(1.0, self._tmp)

    def add_jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        """A += (1 / dt^2 + c / dt) M off the Dirichlet rows."""
        self.mass.copy(self._diag)
        self._diag.scale(1.0 / self.dt ** 2 + self.damping / self.dt)
        self._diag.getArray()[self._bc_rows] = 0.0
        A.setDiagonal(self._diag, addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()

    def commit(self):
        """After a converged step (model re-based first): v^{n+1} = (x - x^n) / dt, x^n <- x."""
        self.model.w.vector.copy(self.v)
        self.v.axpy(-1.0, self.d)
        self.v.scale(1.0 / self.dt)
        self.model.w.vector.copy(self.d)

    def predict(self):
        """Start the next solve from x^n + dt v^n on the rows with mass (not the Dirichlet ones); ghosts updated."""
        w, rows = self.model.w, self._predicted
        w.x.array[rows] = self.d.getArray()[rows] + self.dt * self.v.getArray()[rows]
        w.x.scatter_forward()

    def kinetic_energy(self) -> float:
        """1/2 v^n . M v^n [J] over all ranks."""
        return 0.5 * self.model.comm.allreduce(float(np.sum(self.mass.getArray() * self.v.getArray() ** 2)))

    def destroy(self):
        for vec in (self.d, self.v, self._tmp, self._diag):
            vec.destroy()
