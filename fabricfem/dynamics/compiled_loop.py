"""The explicit time loop in compiled code: `CentralDifference` runs its steps between two records (and two safe-step
checks) in one C call (fabricfem.dynamics.explicit_source) instead of a Python step with a dozen PETSc calls and a
dolfinx assembly each. On a small cloth that per-step overhead is the whole cost (about 100 us per step on the 2x2
Q2 membrane, whose arithmetic takes a few us); the compiled loop costs what the kernels cost.

Same trajectory: the step and the run loop's bookkeeping are written with the operations and the order of the
Python loop ([Man2006, eqs. 2.76, 2.82-2.84]; `CentralDifference.step`, `TimeIntegrator._advance`), the internal
force by the model's own compiled kernels (FFCx's tabulate_tensor of the residual form, or the hand-written
Naghdi kernel) on dolfinx's packed coefficients, cells in dolfinx's order, so that d, v, a agree with the Python
loop's to round-off (tests/test_compiled_loop.py).

When it applies (`reason_not_compiled` gives why not, "" when it does): one MPI rank (serial only: the loop does no
ghost exchange; under MPI with more than one rank the Python loop runs); the bare model (no ResidualTerms of a
CompositeSystem); no explicit hooks (contact, seams); `step` neither overridden by a subclass nor wrapped on the
instance (fabricfem.dynamics.strain_limit.attach: the strain limit is a Python projection, so a strain-limited
run takes the Python loop); no stiffness-proportional damping (b K_M needs a matrix); the internal force and the
energy as cell integrals of compiled kernels with dof layouts that need no transformations (Lagrange fields).

Assumed fixed during a run (as fabricfem.shell_reference.PrepackedForms assumes): every coefficient and constant of
the forms but the state (packed at each `run`), the lumped mass and damping, F_ref and the Dirichlet rows. The load
factor lambda(t) is evaluated in Python for the steps of a chunk before the C call (a function of t alone).
Between chunks Python records, reports progress (at chunk ends only: records and safe-step checks), asks
`should_stop` and estimates the safe step (fabricfem.dynamics.safe_step). Units: SI.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np
from dolfinx import cpp as _cpp
from dolfinx import fem
from mpi4py import MPI

from fabricfem.dynamics.explicit_source import CDEF, SOURCE
from fabricfem.dynamics.integrator import ENERGY_FLOOR, History, compiled_energy, record_and_ask
from fabricfem.forms import naghdi_kernel
from fabricfem.forms.jit import KERNEL_JIT, ROUNDING_FLAGS, built_once


def _module(comm):
    """(lib, ffi) of the compiled loop, built once per process (fabricfem.forms.jit.built_once)."""
    return built_once("fabricfem_explicit_loop", CDEF, SOURCE, comm, ROUNDING_FLAGS)


def _cell_kernels(form) -> list[tuple[int, int, np.ndarray]] | None:
    """(address of the float64 kernel, subdomain id, cells) of each cell integral of a compiled dolfinx form (FFCx's, or a form
    of a hand-written kernel carrying `kernel_address`); None when the form has other integrals or no known
    kernel."""
    if set(form.integral_types) != {fem.IntegralType.cell}:
        return None
    if hasattr(form, "kernel_address"):
        return [(int(form.kernel_address), -1, np.asarray(form.domains(fem.IntegralType.cell, -1), dtype=np.int32))]
    ufcx = getattr(form, "ufcx_form", None)
    if ufcx is None:
        return None
    _, ffi = _module(MPI.COMM_SELF)
    kernels = []
    for i in range(ufcx.num_integrals(0)):
        integral = ufcx.integrals(0)[i]
        address = int(ffi.cast("uintptr_t", integral.tabulate_tensor_float64))
        subdomain = int(ufcx.integral_ids(0)[i])
        kernels.append((address, subdomain, np.asarray(form.domains(fem.IntegralType.cell, subdomain), dtype=np.int32)))
    return kernels


def reason_not_compiled(integrator) -> str:
    """Why `integrator` (a CentralDifference whose `step` is its class's own) cannot run its steps in the compiled
    loop ("" when it can; module docstring)."""
    model = integrator.model
    checks = (
        (model.comm.size > 1, f"{model.comm.size} MPI ranks (the compiled loop is serial)"),
        (integrator.system is not model, "the system has residual terms (a CompositeSystem)"),
        (bool(integrator._hooks), "explicit hooks (contact, seams) are called in each step"),
        (integrator.ops.stiffness_ufl is not None or integrator.ops.C is not None,
         "the damping is not diagonal (stiffness-proportional Rayleigh damping)"),
        (integrator.accounts_substeps, "the step books its own work"),
        (model.W.element.needs_dof_transformations, "the state's element needs dof transformations"))
    for failed, why in checks:
        if failed:
            return why
    forms = list(model.internal_force_forms.forms) + [integrator._energy_form]
    if any(_cell_kernels(form) is None for form in forms):
        return "the internal force or the energy has integrals other than compiled cell kernels"
    return ""


def _state_position(form, state) -> int:
    """Start of the state's block in a cell's packed coefficients of `form`."""
    sizes = [c.function_space.element.space_dimension for c in form.coefficients]
    position = next(i for i, c in enumerate(form.coefficients) if np.shares_memory(c.x.array, state.x.array))
    return int(np.sum(sizes[:position]))


class CompiledLoop:
    """The compiled steps of one CentralDifference (module docstring); built by `CentralDifference` when
    `reason_not_compiled` is "", kept for its life. `advance` is `TimeIntegrator._advance` in chunks."""

    def __init__(self, integrator):
        self.integrator = integrator
        self.lib, self.ffi = _module(integrator.model.comm)
        model = integrator.model
        dofmap = model.W.dofmap
        blocks = dofmap.list.array.reshape(-1, dofmap.dof_layout.num_dofs)
        self._cell_dofs = (blocks[:, :, None] * dofmap.bs + np.arange(dofmap.bs)).reshape(len(blocks), -1)
        geometry = model.mesh.geometry
        self._coordinates = geometry.x[geometry.dofmap.array.reshape(len(blocks), -1)].reshape(len(blocks), -1)
        self._keep: list = []
        # the blow-up check's strain energy, compiled as the internal force is (the records keep the integrator's)
        self._energy_form = compiled_energy(model, KERNEL_JIT)
        self.loop = self.ffi.new("ff_loop*")
        self._bc_values()

    def _bc_values(self) -> None:
        """The Dirichlet values on the owned Dirichlet rows as lambda g (scaled) or fixed: set_bc at lambda = 1 and
        0 (a row that is 0 at lambda = 0 and not at 1 is scaled)."""
        integ, model = self.integrator, self.integrator.model
        lam = float(model.load_factor.value)
        values = []
        for factor in (1.0, 0.0):
            model.set_load_factor(factor)
            x = np.zeros(model.w.x.array.size)
            fem.set_bc(x, model.bcs)
            values.append(x[integ.bc_rows])
        model.set_load_factor(lam)
        one, zero = values
        scaled = (zero == 0.0) & (one != 0.0)
        self._bc_scaled = np.where(scaled, one, 0.0)
        self._bc_fixed = np.where(scaled, 0.0, zero)

    def _pointer(self, array: np.ndarray, ctype: str = "double*"):
        """A C pointer into `array` (kept alive by this loop until the next `_pack`)."""
        self._keep.append(array)
        return self.ffi.cast(ctype, array.ctypes.data)

    def _forms(self, forms: list):
        """ff_form structs of the forms (linear forms on the state space, or functionals of the state) with their
        coefficients and constants packed now."""
        state = self.integrator.model.w
        structs = []
        for form in forms:
            packed = _cpp.fem.pack_coefficients(form)
            constants = np.ascontiguousarray(_cpp.fem.pack_constants(form), dtype=np.float64)
            for address, subdomain, cells in _cell_kernels(form):
                coefficients = np.ascontiguousarray(packed[(fem.IntegralType.cell, subdomain)])   # a row per cell
                if hasattr(form, "cells_address"):     # the hand-written kernel's batched loop (state first)
                    reference = naghdi_kernel.batched_reference(coefficients, self._cell_dofs.shape[1])
                    batched = dict(cells=self.ffi.cast("ff_cells", form.cells_address),
                                   reference=self._pointer(reference))
                    coefficients = np.zeros((1, 1))
                else:
                    batched = {}
                structs.append(dict(kernel=self.ffi.cast("ff_kernel", address), ncells=len(cells), **batched,
                                    ndofs=self._cell_dofs.shape[1], width=coefficients.shape[1],
                                    state_start=_state_position(form, state), ncoord=self._coordinates.shape[1],
                                    dofs=self._pointer(np.ascontiguousarray(self._cell_dofs[cells], np.int32),
                                                       "int32_t*"),
                                    coefficients=self._pointer(coefficients),
                                    constants=self._pointer(constants if constants.size else np.zeros(1)),
                                    coordinates=self._pointer(np.ascontiguousarray(self._coordinates[cells]))))
        array = self.ffi.new("ff_form[]", max(1, len(structs)))
        for i, fields in enumerate(structs):
            for name, value in fields.items():
                setattr(array[i], name, value)
        self._keep.append(array)
        return array, len(structs)

    def _vectors(self) -> None:
        """Point the loop at the integrator's current vectors, step and scalars (before each chunk: the step and
        M + dt/2 C may have changed). Arrays obtained by getArray (which marks the Vecs changed for PETSc)."""
        integ, loop = self.integrator, self.loop
        ops = integ.ops
        for name, vec in (("d", integ.d), ("v", integ.v), ("a", integ.a), ("cv", integ._cv),
                          ("v_pred", integ.velocity_predictor), ("rhs", integ._rhs)):
            setattr(loop, name, self._pointer(vec.getArray()))
        loop.mass = self._pointer(ops.mass_diag.getArray(readonly=True))
        loop.damping = self._pointer(ops.damping_diag.getArray(readonly=True))
        loop.denominator = self._pointer(integ.denominator.getArray(readonly=True))
        loop.f_ref = self._pointer(integ.model.F_ref.getArray(readonly=True))
        loop.dt, loop.half_dt, loop.half_dt2 = integ.dt, 0.5 * integ.dt, 0.5 * integ.dt ** 2
        loop.t, loop.lam = integ.t, float(integ.model.load_factor.value)
        loop.external_work, loop.dissipated = integ.external_work, integ.dissipated
        loop.max_work, loop.energy0 = integ.max_work, integ.energy0

    def _pack(self) -> None:
        """Pack the forms' coefficients and constants and set the loop's fixed fields (at the start of a run)."""
        integ, loop = self.integrator, self.loop
        self._keep = []
        n = integ.d.getLocalSize()
        loop.n, loop.nbc = n, len(integ.bc_rows)
        loop.force, loop.nforce = self._forms(list(integ.model.internal_force_forms.forms))
        loop.energy, loop.nenergy = self._forms([self._energy_form])
        loop.has_damping = int(bool(integ.ops.has_damping))
        loop.check_energy = int(integ.energy_bound is not None)
        loop.energy_bound = float(integ.energy_bound or 0.0)
        loop.energy_floor = ENERGY_FLOOR
        for name in ("d_old", "cv_old"):
            setattr(loop, name, self._pointer(np.zeros(n)))
        loop.d_old_bc = self._pointer(np.zeros(max(1, loop.nbc)))
        loop.element = self._pointer(np.zeros(max(1, self._cell_dofs.shape[1])))
        loop.bc_rows = self._pointer(np.ascontiguousarray(integ.bc_rows, dtype=np.int32), "int32_t*")
        loop.bc_scaled = self._pointer(np.ascontiguousarray(self._bc_scaled))
        loop.bc_fixed = self._pointer(np.ascontiguousarray(self._bc_fixed))
        self._fixed = len(self._keep)

    def steps(self, n_steps: int) -> int:
        """Take up to n_steps steps in C; returns the status of the last step taken (0: all taken, 1: non-finite
        state, 2: energy above the bound) and updates the integrator's state, time, counts, work, dissipation and
        load factor, and the model's state w."""
        integ, loop = self.integrator, self.loop
        del self._keep[self._fixed:]
        self._vectors()
        lams = np.empty(n_steps)
        t = integ.t
        for k in range(n_steps):          # lambda(t) at the steps' ends, t accumulated as the Python loop does
            t = t + integ.dt
            lams[k] = integ.load(t)
        tic = time.perf_counter()
        code = self.lib.ff_run(loop, n_steps, self._pointer(lams))
        integ.timings["compiled_steps"] = integ.timings.get("compiled_steps", 0.0) + time.perf_counter() - tic
        taken, status = (code // 4, code % 4)
        for vec in (integ.d, integ.v, integ.a, integ._cv, integ.velocity_predictor, integ._rhs):
            vec.getArray()                # PETSc: the arrays changed (cached norms dropped)
        integ.t = loop.t
        integ.step_count += taken
        integ.run_step += taken
        integ.external_work, integ.dissipated, integ.max_work = loop.external_work, loop.dissipated, loop.max_work
        integ.model.set_load_factor(loop.lam)
        integ._sync_model()
        return status

    def _chunk(self, n_steps: int, output_every: int) -> int:
        """Steps to the next record, the last step or the next safe-step check, whichever comes first."""
        integ = self.integrator
        k = integ.run_step
        end = min(n_steps, (k // output_every + 1) * output_every)
        if integ.tracker is not None:
            end = min(end, k + integ.step_check_every - integ.step_count % integ.step_check_every)
        return end - k

    def advance(self, n_steps: int, output_every: int, record: Callable[[int], None],
                report: Callable[[int, int, float, float], None] | None, should_stop: Callable[[], str] | None,
                history: History) -> None:
        """`TimeIntegrator._advance` with the steps between records (and safe-step checks) in C: record, progress
        and should_stop after each chunk; a failed blow-up check in C is repeated by `_check` (raises)."""
        integ = self.integrator
        self._pack()
        start = time.perf_counter()
        while integ.run_step < n_steps:
            if integ.tracker is not None and integ.step_count % integ.step_check_every == 0:
                integ._safe_step()
            if self.steps(self._chunk(n_steps, output_every)):
                integ._check(integ.energy0, integ.max_work)
            k = integ.run_step
            if record_and_ask(integ.t, k, n_steps, output_every, lambda: record(0), report, should_stop, history,
                              start):
                break
