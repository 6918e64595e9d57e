"""The system contract: what Newton, load stepping, arc-length and the time integrators drive.

A **NonlinearSystem** (e.g. `fabricfem.shell.ShellModel`, or a `CompositeSystem` of one plus terms) offers

* `residual(x, b)`: b = R(x) [N, N m] for the solver vector x (owned + ghost layout of `create_vector`);
  Dirichlet rows hold x - lambda g. Sets the state the forms read (`w`) from x first.
* `jacobian(x, A)`: A = dR/dx at x (assembled; Dirichlet rows and columns as identity).
* `set_state(x)`: copy x into `w` (never alias the two, see fabricfem.shell.ShellModel.set_state).
* `create_vector()`, `create_matrix()`: a vector and a matrix of R's layout and dR/dx's sparsity.
* `after_converged_step()`: hook after each converged (load or time) step, e.g. re-basing the director
  [Man2006, sec. 2.3.1.5] and committing history (friction stick points, x^n and v^n of an integrator).
* `compile()`: build the forms and `F_ref` (idempotent).
* attributes `w` (dolfinx Function of the state), `comm` (MPI communicator), `F_ref` (PETSc Vec of the
  reference load [N], the absolute Newton tolerance scales with its norm), `load_factor` (dolfinx Constant
  lambda), `set_load_factor(lam)`, `bcs` (dolfinx Dirichlet conditions);
* for the explicit and Newmark / PETSc TS integrators also `internal_force(x, b)`: b = R_int(x) without the
  load and without touching the Dirichlet rows (the integrators add M a, C v and lambda F_ref themselves).

NewtonSolver reads `compile`, `F_ref`, `create_vector`, `create_matrix`, `residual`, `jacobian`, `comm`,
`w`, `set_state`, `load_factor`; solve_load_path and arc-length in addition `set_load_factor` and
`after_converged_step` (arc-length also `bcs`); the integrators the shell model's forms (`jacobian_form`,
`energy`, the mass) through `CompositeSystem.model` and the terms through `CompositeSystem.terms`.

A **ResidualTerm** is a force of the state added to a model's residual:

* `add_residual(x, b)`: b += r_term(x) (the model's residual has already set the state `w` from x, so a
  term may read `w`); owned rows only, Dirichlet rows untouched.
* `add_jacobian(x, A)`: A += dr_term/dx (assembled on return).
* `commit()`: after a converged step, store the history (stick points, x^n and v^n, anchors).

Frictional contact with rigid bodies (fabricfem.contact.problem.ContactProblem), the quasi-static drag of
the sleeve and backward-Euler inertia (fabricfem.dynamics.backward_euler) are terms.

An **ExplicitHook** is a layer of the explicit central-difference step (fabricfem.dynamics.explicit.CentralDifference:
body contact, seams, grips, belts), called once per step with the integrator and the new time t_{n+1} [s]:

* `forces(integrator, t, rhs)`: add nodal forces at d^{n+1} [N, N m] to the right-hand side `rhs` (owned rows)
  before the division by the diagonal M + dt/2 C (a penalty force; a no-op for a pure constraint).
* `correct(integrator, t)`: after the division, modify a^{n+1} (`integrator.a`) so that the next predictor
  d^{n+1} + dt v~ + dt^2 a^{n+1} meets a constraint ([Man2006, Box 5]; a no-op for a pure force).
* optionally (**TimeStepListener**) `on_time_step(dt)`: the integrator's step became dt [s]
  (CentralDifference.set_time_step); a hook drops what it derived from the former step (e.g. M + dt/2 C).

Hooks read the integrator's public state: `d`, `a`, `velocity_predictor` (v~), `denominator` (M + dt/2 C), `dt`.

`CompositeSystem(model, terms)` is a model plus its terms: residual = model.residual then each term's
add_residual in order, Jacobian likewise; `after_converged_step` runs the model's hook first, then commits the
terms in order (the model may re-base the director and zero the angles: the history a term commits, e.g. the
x^n of backward-Euler inertia, must be that of the re-based state the next step starts from; contact and
drag read only the displacements, which re-basing leaves unchanged). Everything else (w, comm, F_ref, bcs,
load_factor, set_load_factor, compile, set_state, create_vector, create_matrix, jacobian_form, ...) is the
model's.
"""
from __future__ import annotations

from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np
from petsc4py import PETSc


@runtime_checkable
class ResidualTerm(Protocol):
    """A force of the state added to a model's residual (module docstring)."""

    def add_residual(self, x: PETSc.Vec, b: PETSc.Vec) -> None: ...

    def add_jacobian(self, x: PETSc.Vec, A: PETSc.Mat) -> None: ...

    def commit(self) -> None: ...


@runtime_checkable
class ExplicitHook(Protocol):
    """A layer of the explicit step (module docstring): forces before the division, a correction after it."""

    def forces(self, integrator: Any, t: float, rhs: PETSc.Vec) -> None: ...

    def correct(self, integrator: Any, t: float) -> None: ...


@runtime_checkable
class TimeStepListener(Protocol):
    """A hook that keeps quantities of the time step: told the new step dt [s] when it changes."""

    def on_time_step(self, dt: float) -> None: ...


@runtime_checkable
class NonlinearSystem(Protocol):
    """What the solvers and integrators drive (module docstring lists the attributes they read)."""

    w: Any
    comm: Any
    F_ref: PETSc.Vec
    load_factor: Any

    def residual(self, x: PETSc.Vec, b: PETSc.Vec) -> None: ...

    def jacobian(self, x: PETSc.Vec, A: PETSc.Mat) -> None: ...

    def set_state(self, x: PETSc.Vec) -> None: ...

    def create_vector(self) -> PETSc.Vec: ...

    def create_matrix(self) -> PETSc.Mat: ...

    def after_converged_step(self) -> None: ...

    def compile(self) -> None: ...

    def set_load_factor(self, lam: float) -> None: ...


class CompositeSystem:
    """A model (NonlinearSystem) plus ResidualTerms, itself a NonlinearSystem (module docstring).

    Args:
        model: the base system, e.g. a ShellModel; its attributes are the composite's.
        terms: the ResidualTerms, added in this order.
    """

    def __init__(self, model, terms: Sequence[ResidualTerm] = ()):
        terms = list(terms)
        for term in terms:
            if not isinstance(term, ResidualTerm):
                raise TypeError(f"terms: {type(term).__name__} has no add_residual / add_jacobian / commit")
        self.model = model
        self.terms = terms

    def __getattr__(self, name: str):
        # w, comm, F_ref, bcs, load_factor, set_load_factor, compile, set_state, create_vector, ...
        model = self.__dict__.get("model")
        if model is None:
            raise AttributeError(name)
        return getattr(model, name)

    def add_term_residuals(self, x: PETSc.Vec, b: PETSc.Vec):
        """b += sum of the terms' residuals (the model has set the state from x)."""
        for term in self.terms:
            term.add_residual(x, b)

    def add_term_jacobians(self, x: PETSc.Vec, A: PETSc.Mat):
        """A += sum of the terms' tangents."""
        for term in self.terms:
            term.add_jacobian(x, A)

    def residual(self, x: PETSc.Vec, b: PETSc.Vec):
        """b = R_model(x) + sum r_term(x)."""
        self.model.residual(x, b)
        self.add_term_residuals(x, b)

    def internal_force(self, x: PETSc.Vec, b: PETSc.Vec):
        """b = R_int,model(x) + sum r_term(x) (for the integrators: forces of the state, no load)."""
        self.model.internal_force(x, b)
        self.add_term_residuals(x, b)

    def jacobian(self, x: PETSc.Vec, A: PETSc.Mat):
        """A = J_model(x) + sum dr_term/dx."""
        self.model.jacobian(x, A)
        self.add_term_jacobians(x, A)

    def after_converged_step(self):
        """The model's hook (e.g. director re-basing), then each term's commit in order."""
        self.model.after_converged_step()
        for term in self.terms:
            term.commit()


def base_model(system):
    """The model under a CompositeSystem (the system itself otherwise): what owns the forms and `w`."""
    return system.model if isinstance(system, CompositeSystem) else system


def add_term_jacobians(system, x: PETSc.Vec, A: PETSc.Mat):
    """A += the terms' tangents of `system` (nothing for a bare model): for integrators that assemble the
    model's tangent together with their own mass and damping forms."""
    if isinstance(system, CompositeSystem):
        system.add_term_jacobians(x, A)


def owned_dirichlet_rows(model) -> np.ndarray:
    """Sorted local indices (int32) of the owned rows of `model`'s vectors that carry a Dirichlet condition."""
    rows = [bc.dof_indices()[0][:bc.dof_indices()[1]] for bc in model.bcs]
    rows = np.unique(np.concatenate(rows)) if rows else np.zeros(0, dtype=np.int32)
    return rows[rows < model.w.vector.getLocalSize()].astype(np.int32)
