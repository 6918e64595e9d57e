"""Newton's method by PETSc SNES with the exact UFL Jacobian (MUMPS LU by default)."""
from __future__ import annotations

import contextlib
import itertools
from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

DEFAULT_OPTIONS = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "basic",
    "snes_rtol": 1e-9,
    "snes_stol": 1e-10,
    "snes_max_it": 25,
    "snes_divergence_tolerance": -1,  # the first Newton step of a bending step often overshoots
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
}

_prefix_counter = itertools.count()


@contextlib.contextmanager
def prefixed_options(prefix: str, options: dict):
    """Put `options` into the PETSc options database under `prefix` for the duration of a
    setFromOptions call, then remove them: the database holds a limited number of entries
    (PETSc error 55 'Out of memory' once full), and every solver uses its own prefix."""
    database = PETSc.Options()
    for key, value in options.items():
        database[prefix + key] = value
    try:
        yield
    finally:
        for key in options:
            database.delValue(prefix + key)


class SolverError(RuntimeError):
    """A solve that did not converge; carries the last converged load factor and the reason."""

    def __init__(self, message: str, last_converged_load_factor: float | None = None, reason: str = ""):
        super().__init__(message)
        self.last_converged_load_factor = last_converged_load_factor
        self.reason = reason


@dataclass
class NewtonResult:
    converged: bool
    iterations: int
    reason: str
    residual_norms: list[float] = field(default_factory=list)


_REASONS = {v: k for k, v in vars(PETSc.SNES.ConvergedReason).items() if isinstance(v, int)}


class NewtonSolver:
    """SNES Newton solver for a model exposing residual/jacobian callbacks (e.g. ShellModel).

    SNES iterates on its own vector; the callbacks copy it into the Function the forms read
    (see shared notes: aliasing the two slows Newton down). `options` are PETSc options
    (without prefix) overriding DEFAULT_OPTIONS; the absolute tolerance defaults to
    1e-10 |F_ref| so that it scales with the load.
    """

    def __init__(self, model, options: dict | None = None):
        self.model = model
        model.compile()
        self.prefix = f"fabricfem_newton_{next(_prefix_counter)}_"
        opts = dict(DEFAULT_OPTIONS)
        fref = model.F_ref.norm()
        opts["snes_atol"] = 1e-10 * fref if fref > 0 else 1e-12
        opts.update(options or {})
        self.options = opts
        self.b = model.create_vector()
        self.A = model.create_matrix()
        self.x = model.create_vector()
        snes = PETSc.SNES().create(model.comm)
        snes.setOptionsPrefix(self.prefix)
        snes.setFunction(lambda s, x, b: model.residual(x, b), self.b)
        snes.setJacobian(lambda s, x, A, P: model.jacobian(x, A), self.A)
        with prefixed_options(self.prefix, opts):
            snes.setFromOptions()
            snes.getKSP().setFromOptions()
            snes.getKSP().getPC().setFromOptions()
        self._norms: list[float] = []
        snes.setMonitor(lambda s, it, norm: self._norms.append(float(norm)))
        self.snes = snes

    def solve(self) -> NewtonResult:
        """Solve R(w; lambda) = 0 at the current load factor, starting from the model's state.
        On failure the model's state is left as SNES left it (the caller restores)."""
        self._norms = []
        self.model.w.vector.copy(self.x)
        self.snes.solve(None, self.x)
        reason = self.snes.getConvergedReason()
        finite = bool(np.isfinite(self.x.norm()))
        converged = reason > 0 and finite
        if converged:
            self.model.set_state(self.x)
        name = _REASONS.get(reason, str(reason)) if finite else "NAN_IN_SOLUTION"
        return NewtonResult(converged, self.snes.getIterationNumber(), name, list(self._norms))

    def destroy(self):
        for obj in (self.snes, self.A, self.b, self.x):
            obj.destroy()
