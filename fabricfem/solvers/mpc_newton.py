"""Newton's method on dolfinx_mpc assemblers (multi-point constraints such as periodicity).

dolfinx_mpc 0.5.0 has MPC-aware assemblers but no nonlinear problem class. This module
supplies one: the residual and Jacobian are assembled onto the master dofs (slave rows
condensed away, unit diagonal on slave rows), the Newton correction is solved by a KSP
(MUMPS LU by default), and after each update the slave dofs are refilled from their masters
(`mpc.homogenize` then `mpc.backsubstitution`: in 0.5.0 the latter adds to the slave entries).

The state Function must live on `mpc.function_space` (the original space with the master
dofs of other processes added as ghosts), not on the space the MPC was built from.
"""
from __future__ import annotations

import itertools
from typing import Callable, Sequence

import dolfinx.cpp as _cpp
import dolfinx.fem as fem
import dolfinx.fem.petsc as fem_petsc
import dolfinx_mpc
import numpy as np
import ufl
from petsc4py import PETSc

from fabricfem.solvers.newton import NewtonResult, prefixed_options

DEFAULT_KSP_OPTIONS = {
    "ksp_type": "preonly",
    "pc_type": "lu",
    "pc_factor_mat_solver_type": "mumps",
}

_prefix_counter = itertools.count()


class MPCNewtonSolver:
    """Newton solver for R(u; v) = 0 with u constrained by a finalized MultiPointConstraint.

    Parameters:
        residual: UFL form R(u; v), linear in the test function v of the MPC's original space
        u: the unknown, a Function on `mpc.function_space`
        mpc: finalized dolfinx_mpc.MultiPointConstraint
        bcs: Dirichlet conditions on the original space (also given to the MPC when it was built)
        jacobian: UFL form dR/du; by default ufl.derivative(residual, u, TrialFunction)
        rtol: converged when |R| <= rtol * force_scale (`force_scale` is passed to `solve`, in N)
        stol: or when the Newton correction |du| <= stol * length_scale (in m)
        max_it: at most this many Newton iterations
        ksp_options: PETSc options of the linear solver (default MUMPS LU)
        form_compiler_params: FFCx parameters of both forms
        contact: optional extra nodal forces (e.g. fabricfem.contact.yarn.YarnContact), a ResidualTerm
            (fabricfem.solvers.system) on the condensed (MPC) system: add_residual(x, b) (subtracts its forces
            from the owned rows of the assembled residual, before the Dirichlet rows are set) and
            add_jacobian(x, A) (adds its stiffness to the owned rows of the assembled Jacobian), x = u's vector;
            it must drop the rows/columns of `constrained_dofs()`
        line_search: halve the Newton step until the residual norm decreases (at most 5 times)
    """

    def __init__(self, residual: ufl.Form, u: fem.Function, mpc: dolfinx_mpc.MultiPointConstraint,
                 bcs: Sequence[fem.DirichletBCMetaClass] = (), jacobian: ufl.Form | None = None,
                 rtol: float = 1e-10, stol: float = 1e-13, max_it: int = 25,
                 ksp_options: dict | None = None, form_compiler_params: dict | None = None,
                 contact=None, line_search: bool = False):
        if not mpc.finalized:
            raise ValueError("mpc must be finalized before building the Newton solver")
        if u.function_space is not mpc.function_space:
            raise ValueError("u must be a Function on mpc.function_space (the MPC's own space)")
        for name, value in (("rtol", rtol), ("stol", stol)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if int(max_it) < 1:
            raise ValueError(f"max_it must be >= 1, got {max_it!r}")
        self.u, self.mpc, self.bcs = u, mpc, list(bcs)
        self.contact = contact
        self.line_search = bool(line_search)
        # optional admissibility test of the line search (see `backtrack`), e.g. set by the unit cell
        self.admissible_step: Callable[[], Callable[[], bool]] | None = None
        # damped fallback of an update whose line search cannot decrease |R| (see `_damped_update`); off by default
        self.damping = False
        self.damped_updates = 0  # updates that needed it in the last solve
        self.rtol, self.stol, self.max_it = float(rtol), float(stol), int(max_it)
        if jacobian is None:
            trial = ufl.TrialFunction(residual.arguments()[0].ufl_function_space())
            jacobian = ufl.derivative(residual, u, trial)
        params = form_compiler_params or {}
        self.L = fem.form(residual, form_compiler_params=params)
        self.a = fem.form(jacobian, form_compiler_params=params)
        V = mpc.function_space
        self.A = dolfinx_mpc.cpp.mpc.create_matrix(self.a, mpc._cpp_object, mpc._cpp_object)
        self.b = _cpp.la.petsc.create_vector(V.dofmap.index_map, V.dofmap.index_map_bs)
        self.du = _cpp.la.petsc.create_vector(V.dofmap.index_map, V.dofmap.index_map_bs)
        self.comm = V.mesh.comm
        ksp = PETSc.KSP().create(self.comm)
        prefix = f"fabricfem_mpc_newton_{next(_prefix_counter)}_"
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(self.A)
        with prefixed_options(prefix, {**DEFAULT_KSP_OPTIONS, **(ksp_options or {})}):
            ksp.setFromOptions()
        self.ksp = ksp

    @property
    def ndofs(self) -> int:
        """Global number of scalar dofs of u (slaves included)."""
        imap = self.mpc.function_space.dofmap.index_map
        return imap.size_global * self.mpc.function_space.dofmap.index_map_bs

    def assemble_residual(self) -> PETSc.Vec:
        """Condensed residual at the current u, with the Dirichlet rows set to u - g."""
        x = self.u.vector
        with self.b.localForm() as b_local:
            b_local.set(0.0)
        dolfinx_mpc.assemble_vector(self.L, self.mpc, b=self.b)
        dolfinx_mpc.apply_lifting(self.b, [self.a], [self.bcs], self.mpc, x0=[x], scale=-1.0)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.contact is not None:
            self.contact.add_residual(x, self.b)
        fem_petsc.set_bc(self.b, self.bcs, x, -1.0)
        return self.b

    def _assemble_jacobian(self) -> None:
        self.A.zeroEntries()
        dolfinx_mpc.assemble_matrix(self.a, self.mpc, bcs=self.bcs, A=self.A)
        self.A.assemble()
        if self.contact is not None:
            self.contact.add_jacobian(self.u.vector, self.A)

    def constrained_dofs(self) -> np.ndarray:
        """Global scalar indices of the Dirichlet and MPC-slave dofs held by this rank (owned or ghost):
        rows and columns that extra contributions such as contact must leave alone."""
        V = self.mpc.function_space
        imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
        local = [np.asarray(self.mpc.slaves, dtype=np.int64)]
        for bc in self.bcs:
            dofs, _ = bc.dof_indices()
            local.append(np.asarray(dofs, dtype=np.int64))  # unrolled (block * bs + component)
        local = np.unique(np.concatenate(local))
        blocks = imap.local_to_global((local // bs).astype(np.int32))
        return np.asarray(blocks, dtype=np.int64) * bs + local % bs

    def solve(self, force_scale: float, length_scale: float) -> NewtonResult:
        """Iterate from the current u until converged; u keeps the last iterate either way.

        `force_scale` [N] sets the residual tolerance rtol * force_scale; `length_scale` [m] sets
        the correction tolerance stol * length_scale. Returns a NewtonResult (reason
        CONVERGED_FNORM_ABS, CONVERGED_SNORM, DIVERGED_MAX_IT, DIVERGED_LINEAR_SOLVE or NAN_IN_SOLUTION).
        """
        if not (np.isfinite(force_scale) and force_scale > 0):
            raise ValueError(f"force_scale must be a positive finite number, got {force_scale!r}")
        if not (np.isfinite(length_scale) and length_scale > 0):
            raise ValueError(f"length_scale must be a positive finite number, got {length_scale!r}")
        norms: list[float] = []
        self.damped_updates = 0
        for it in range(self.max_it + 1):
            rnorm = self.assemble_residual().norm()
            norms.append(float(rnorm))
            if not np.isfinite(rnorm):
                return NewtonResult(False, it, "NAN_IN_SOLUTION", norms)
            if rnorm <= self.rtol * force_scale:
                return NewtonResult(True, it, "CONVERGED_FNORM_ABS", norms)
            if it == self.max_it:
                break
            self._assemble_jacobian()
            self.ksp.solve(self.b, self.du)
            if self.ksp.getConvergedReason() < 0:
                return NewtonResult(False, it, "DIVERGED_LINEAR_SOLVE", norms)
            if self.line_search and self.damping:
                x_start = self.u.vector.copy()
                self._backtrack(rnorm)
                if not self.assemble_residual().norm() < rnorm:
                    self._damped_update(rnorm, x_start)
                x_start.destroy()
            elif self.line_search:
                self._backtrack(rnorm)
            else:
                self.update(1.0)
            dnorm = self.du.norm()
            if not np.isfinite(dnorm):
                return NewtonResult(False, it + 1, "NAN_IN_SOLUTION", norms)
            if dnorm <= self.stol * length_scale:
                norms.append(float(self.assemble_residual().norm()))
                return NewtonResult(True, it + 1, "CONVERGED_SNORM", norms)
        return NewtonResult(False, self.max_it, "DIVERGED_MAX_IT", norms)

    def update(self, step: float) -> None:
        """u <- u - step J^{-1} R, then the MPC slaves refilled from their masters."""
        x = self.u.vector
        x.axpy(-step, self.du)
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        # backsubstitution ADDS the master combination to the slave entries: zero them first
        self.mpc.homogenize(x)
        self.mpc.backsubstitution(x)

    def _backtrack(self, rnorm: float) -> None:
        """Line search of one Newton update (backtrack)."""
        backtrack(self, rnorm, self.admissible_step)

    def _damped_update(self, rnorm: float, x_start: PETSc.Vec) -> None:
        """Fallback when the line search along the Newton direction cannot decrease |R| (a near-singular or
        indefinite tangent, e.g. crushed hexahedra under contact, makes the Newton correction far larger than
        the region where the linearisation holds): back to the start state, the correction is recomputed
        with the shifted matrix J + alpha d I (d = mean |diag J|, alpha = DAMPING_FACTORS in turn,
        Levenberg-Marquardt style) and line-searched the same way, until |R| decreases; the last, most
        damped one is kept otherwise. Only the iteration matrix changes: the residual, hence the converged
        state and the tolerance, are those of the undamped Newton method."""
        u = self.u.vector
        x_start.copy(u)
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self._assemble_jacobian()
        diag = self.A.getDiagonal()
        scale = diag.norm(PETSc.NormType.NORM_1) / diag.getSize()
        diag.destroy()
        shifted = 0.0
        self.damped_updates += 1
        for alpha in DAMPING_FACTORS:
            self.A.shift(alpha * scale - shifted)
            shifted = alpha * scale
            self.assemble_residual()
            self.ksp.solve(self.b, self.du)
            if self.ksp.getConvergedReason() < 0:
                continue
            self._backtrack(rnorm)
            if self.assemble_residual().norm() < rnorm:
                return

    def destroy(self) -> None:
        for obj in (self.ksp, self.A, self.b, self.du):
            obj.destroy()


ADMISSIBLE_HALVINGS = 12  # admissibility halvings of one Newton update (step >= 2^-12), see backtrack
RESIDUAL_HALVINGS = 5     # halvings until |R| decreases
# shifts alpha of the damped fallback J + alpha mean|diag J| I (MPCNewtonSolver._damped_update): from a
# perturbation far below the stiff modes up to the diagonal's own size
DAMPING_FACTORS = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)


def backtrack(solver, rnorm: float, admissible_step: Callable[[], Callable[[], bool]] | None = None) -> None:
    """Line search of the update u <- u - s du of `solver` (an MPCNewtonSolver: u, _update, assemble_residual).

    With `admissible_step` (called at the start of the search, it returns the predicate "the updated state is
    admissible", e.g. no element crushed relative to the start state), s is first halved (at most
    ADMISSIBLE_HALVINGS times) until the predicate holds. Then s is halved (at most RESIDUAL_HALVINGS times)
    until |R| < rnorm: breaks the two-cycles that Newton falls into on the kinks of a contact / friction law
    (stick-slip switches); if |R| never decreases the last, smallest step is kept."""
    u = solver.u.vector
    x0 = u.copy()

    def restore() -> None:
        x0.copy(u)
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    step = 1.0
    if admissible_step is not None:
        admissible = admissible_step()
        for _ in range(ADMISSIBLE_HALVINGS):
            solver.update(step)
            ok = admissible()
            restore()
            if ok:
                break
            step *= 0.5
    for _ in range(RESIDUAL_HALVINGS):
        solver.update(step)
        if solver.assemble_residual().norm() < rnorm:
            break
        restore()
        step *= 0.5
    else:
        solver.update(step)
    x0.destroy()
