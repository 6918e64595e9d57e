"""Newton's method by PETSc SNES with the exact UFL Jacobian (MUMPS LU by default).

Guard against absurd "converged" states: SNES may report convergence for a state that is no equilibrium
of the cloth -- e.g. when an iterate loses all contact, the tangent has a free rigid mode, the next steps
are huge and from there the relative step test (snes_stol) is met while Newton only converges linearly.
`NewtonSolver.solve` therefore checks every converged state once (one reduction): all entries finite; the
displacement increment of the solve |du|_inf <= max_increment_ratio x the diagonal of the mesh's bounding
box (default DEFAULT_MAX_INCREMENT_RATIO = 10); and, when SNES converged by the step test, a final residual
norm not above both the first one of the solve and 1e3 x snes_atol (measured on the 5 x 5 tablecloth with a
loose step test: a state with residual 1.2e6 N accepted after linear convergence, for a weight of 0.023 N).
A state failing it raises SolverError (reason NON_FINITE_STATE, ABSURD_INCREMENT or RESIDUAL_GREW; the
message names it, the convergence order of the last iterations and the last converged load factor) and the
model is put back to the start state; solve_load_path then cuts the step.
"""
from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import ufl
from mpi4py import MPI
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
# A converged Newton solve whose displacement increment exceeds this multiple of the mesh's bounding-box
# diagonal is refused. Physical increments of one static load step or one time step are at most of the
# order of the model's size (a cloth draping from flat moves by < 1 diagonal); the absurd states this guards
# against are 1e6..1e20 diagonals. 10 leaves an order of magnitude of margin to both.
DEFAULT_MAX_INCREMENT_RATIO = 10.0

_prefix_counter = itertools.count()


@contextlib.contextmanager
def prefixed_options(prefix: str, options: dict):
    """Put `options` into the PETSc options database under `prefix` for the duration of a
    setFromOptions call (or a solve), then remove them: the database holds a limited number of entries
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


def _displacement_dofs_and_size(model) -> tuple[np.ndarray | None, float]:
    """Owned local indices of the displacement dofs of `model.w` and the diagonal [m] of the mesh's bounding
    box (same on all ranks). The displacement is the whole space for a vector space (membrane) and the first
    sub-space of a mixed one (the Naghdi shell's u of w = (u, theta)). (None, inf) when the model has no
    dolfinx Function `w` (then only the finiteness check applies)."""
    V = getattr(getattr(model, "w", None), "function_space", None)
    if V is None or not hasattr(V, "mesh"):
        return None, math.inf
    index_map = V.dofmap.index_map
    n_owned = index_map.size_local * V.dofmap.index_map_bs
    element = V.ufl_element()
    if isinstance(element, ufl.MixedElement) and not isinstance(element, ufl.VectorElement):
        dofs = np.asarray(V.sub(0).collapse()[1], dtype=np.int64)
    else:
        dofs = np.arange(n_owned, dtype=np.int64)
    dofs = np.unique(dofs[dofs < n_owned]).astype(np.int32)
    x = V.mesh.geometry.x
    comm = V.mesh.comm
    extent = np.concatenate([np.max(x, axis=0, initial=-np.inf), -np.min(x, axis=0, initial=np.inf)])
    comm.Allreduce(MPI.IN_PLACE, extent, op=MPI.MAX)
    return dofs, float(np.linalg.norm(extent[:3] + extent[3:]))


def convergence_order(norms: list[float]) -> float:
    """Estimated order q of the last Newton iterations from the residual norms r: q = log(r_k+1 / r_k) /
    log(r_k / r_k-1) over the last three positive norms (1: linear, 2: quadratic); NaN with fewer."""
    r = [v for v in norms if v > 0.0 and math.isfinite(v)][-3:]
    if len(r) < 3 or r[1] == r[0]:
        return math.nan
    return math.log(r[2] / r[1]) / math.log(r[1] / r[0])


class NewtonSolver:
    """SNES Newton solver for a model exposing residual/jacobian callbacks (e.g. ShellModel).

    SNES iterates on its own vector; the callbacks copy it into the Function the forms read
    (see shared notes: aliasing the two slows Newton down). `options` are PETSc options
    (without prefix) overriding DEFAULT_OPTIONS; the absolute tolerance defaults to
    1e-10 |F_ref| so that it scales with the load. The options stay in the database during each
    solve as well, so that options read when the factorization is set up (e.g. mat_mumps_icntl_*)
    take effect. `max_increment_ratio`: the guard of the module docstring (a converged solve whose
    displacement increment exceeds this multiple of the bounding-box diagonal raises SolverError).
    """

    def __init__(self, model, options: dict | None = None,
                 max_increment_ratio: float = DEFAULT_MAX_INCREMENT_RATIO):
        if not (isinstance(max_increment_ratio, (int, float)) and math.isfinite(max_increment_ratio)
                and max_increment_ratio > 0):
            raise ValueError(f"max_increment_ratio must be a finite positive number, got {max_increment_ratio!r}")
        self.model = model
        self.max_increment_ratio = float(max_increment_ratio)
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
        self._start = model.create_vector()   # the start state of a solve, restored when it is refused
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
        self._displacement_dofs, self.model_size = _displacement_dofs_and_size(model)
        # load factor of the last converged solve (None before the first one: the solver does not know
        # whether the model's initial state is an equilibrium)
        self.last_converged_load_factor: float | None = None

    def _load_factor(self) -> float | None:
        lam = getattr(self.model, "load_factor", None)
        return None if lam is None else float(lam.value)

    def solve(self) -> NewtonResult:
        """Solve R(w; lambda) = 0 at the current load factor, starting from the model's state.

        On failure (SNES diverged, or NaN) the model's state is left as SNES left it (the caller restores).
        Raises SolverError when SNES reports convergence to an absurd state (module docstring); the model
        is then put back to the start state."""
        self._norms = []
        self.model.w.vector.copy(self.x)
        self.model.w.vector.copy(self._start)
        start = self.x.getArray()[self._displacement_dofs].copy() if self._displacement_dofs is not None else None
        with prefixed_options(self.prefix, self.options):
            self.snes.solve(None, self.x)
        reason = self.snes.getConvergedReason()
        iterations = self.snes.getIterationNumber()
        increment, finite = self._increment(start)
        snes_name = _REASONS.get(reason, str(reason))
        name = snes_name if finite else "NAN_IN_SOLUTION"
        if reason > 0:
            self._refuse_absurd(snes_name, iterations, increment, finite)
            self.model.set_state(self.x)
            self.last_converged_load_factor = self._load_factor()
        return NewtonResult(reason > 0 and finite, iterations, name, list(self._norms))

    def _increment(self, start: np.ndarray | None) -> tuple[float, bool]:
        """(|du|_inf over the displacement dofs of all ranks, all entries finite): one reduction."""
        local = self.x.getArray()
        finite = bool(np.all(np.isfinite(local)))
        du = 0.0
        if finite and start is not None:
            du = float(np.max(np.abs(local[self._displacement_dofs] - start), initial=0.0))
        du_bad = np.array([du, 0.0 if finite else 1.0])
        self.model.comm.Allreduce(MPI.IN_PLACE, du_bad, op=MPI.MAX)
        return float(du_bad[0]), du_bad[1] == 0.0

    def _refuse_absurd(self, name: str, iterations: int, increment: float, finite: bool):
        """SolverError (model back at the start state) if a converged state is non-finite or absurdly far."""
        limit = self.max_increment_ratio * self.model_size
        norms = self._norms
        # convergence by the step test (snes_stol) with a residual that ends above both its start and
        # 1e3 x atol is no equilibrium (a stagnating round-off residual stays far below the start). Only that
        # test: one Newton step (ksponly, CONVERGED_ITS) may well raise the residual (measured: x650 on the
        # first step of a cantilever, the membrane-bending coupling) without being absurd.
        grew = (name == "CONVERGED_SNORM_RELATIVE" and len(norms) >= 2
                and norms[-1] > max(norms[0], 1e3 * self.snes.getTolerances()[1]))
        if finite and increment <= limit and not grew:
            return
        if not finite:
            reason, what = "NON_FINITE_STATE", "the state has NaN/inf entries"
        elif increment > limit:
            reason = "ABSURD_INCREMENT"
            what = (f"displacement increment |du|_inf = {increment:.3e} m > {self.max_increment_ratio:g} x the "
                    f"bounding-box diagonal {self.model_size:.3e} m")
        else:
            reason = "RESIDUAL_GREW"
            what = f"the residual norm grew from {norms[0]:.3e} to {norms[-1]:.3e}"
        order = convergence_order(self._norms)
        rate = "unknown" if math.isnan(order) else f"{order:.2f}, {'linear' if order < 1.5 else 'superlinear'}"
        lam, last = self._load_factor(), self.last_converged_load_factor
        self.model.set_state(self._start)   # the absurd state must not reach the caller
        raise SolverError(
            f"{reason}: Newton reported {name} after {iterations} iterations"
            + (f" at load factor {lam:.6g}" if lam is not None else "")
            + f" but {what} (convergence order of the last iterations: {rate}); state restored to the start of "
            f"the solve" + (f", last converged load factor {last:.6g}" if last is not None else ""),
            last_converged_load_factor=last, reason=reason)

    def destroy(self):
        for obj in (self.snes, self.A, self.b, self.x, self._start):
            obj.destroy()
