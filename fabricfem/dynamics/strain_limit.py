"""Continuum strain limiting by fast projection ([Peng2022, sec. 3], eqs. 20-37; Goldenthal et al. 2007).

After an unconstrained time step the candidate configuration q~ is corrected, q = q~ + Delta q, so that the
warp and weft Green strains do not exceed a limit. With the constraints C(q) and the lumped mass M, each
fast-projection iteration j solves the symmetric positive definite system

    h^2 dC M^-1 dC^T dlambda = C^[j]                                           [Peng2022, eq. 33]
    Delta q^[j+1] = Delta q^[j] - h^2 M^-1 dC^T dlambda                         [Peng2022, eq. 34]

until max C < tol. h^2 cancels from Delta q; it only scales the multipliers lambda [J] (eq. 37).

Sampling points [Peng2022, sec. 3.4]: the mesh vertices, two constraints each,

    C_i = [E_warp,i - limit, E_weft,i - limit]                                  [Peng2022, eq. 36]

an inequality: only the rows with C_i > 0, or already active earlier in the same projection, are enforced
(active set). Why vertices and how the vertex strain is measured:

* The seed allows at most two constraints per sampling point and about one sampling point per control point
  (its knot-mesh vertices): more constraints than the in-plane dofs can carry lock the sheet.
  With Q2 / P2 fields there are four (Q2) or about four (P2) displacement nodes per vertex, so sampling all
  nodes would give 2 constraints per node = as many as the in-plane dofs (locked and rank deficient: the
  strains E_warp at all nodes of a row of nodes cannot change a shear u_x = f(y)); the vertices give 2 per 4
  nodes.
* The strain at vertex i is the patch average with the vertex's P1 / Q1 hat function phi_i,

      E_i = int phi_i E dA / int phi_i dA,   a_i = int phi_i dA (nodal area, eq. 37),

  assembled by FFCx as a vector on a [P1]^2 space, and dC/dq is the UFL derivative of that form (a
  rectangular [P1]^2 x W PETSc matrix). Sampling the pointwise strain at the vertex instead (average of the
  cell values there) leaves the quadratic midside nodes unconstrained and the minimum-mass correction moves
  them in an hourglass pattern (measured on a 1D P2 bar: a uniformly over-stretched bar was projected to a
  zig-zag with amplitude ~ the correction itself); with the hat-function weights the same bar (and the Q2
  strip of tests/test_strain_limit.py) is projected to the exact uniformly scaled configuration.
  The weighted average over the patch is the "integration version" of the constraint that sec. 3.5 of the
  seed names as the cure of its checkerboard multipliers; its bandwidth is that of the vertex patch.

Only the displacement part of ShellModel.w moves (M^-1 is zero on rotations and Dirichlet rows); after
a time step the velocity is corrected by v += Delta q / h (Goldenthal et al.) and the acceleration is
re-evaluated at the projected state (`project_step`, `attach`). SI units: strains [-], lambda [J].
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import basix
import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.mass import lumped_mass
from fabricfem.forms import shell as shell_forms


class StrainLimitError(RuntimeError):
    """The fast projection did not reach the strain limit within max_iterations."""


@dataclass
class ProjectionResult:
    """Outcome of one projection: iterations, max violation max_i C_i before each iteration and at the end."""
    iterations: int
    violations: list[float] = field(default_factory=list)
    active: int = 0  # number of active constraints at the end (global)
    correction_norm: float = 0.0  # |Delta q| (Euclidean over the displacement dofs) [m]

    @property
    def initial_violation(self) -> float:
        return self.violations[0] if self.violations else 0.0

    @property
    def final_violation(self) -> float:
        return self.violations[-1] if self.violations else 0.0


def _finite_positive(name: str, value) -> float:
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


class FastProjection:
    """Warp/weft Green-strain limiting of a ShellModel by the continuum fast projection [Peng2022, sec. 3].

    Args:
        model: a ShellModel ("naghdi" or "membrane") with a positive fabric density.
        strain_limit: largest Green strain E_warp, E_weft allowed [-] (e.g. 0.01).
        tol: the projection stops when max_i C_i < tol (strain units) [-].
        max_iterations: more iterations raise StrainLimitError.
        ksp_rtol: relative tolerance of the CG + Jacobi solve of eq. 33.
        quadrature_degree: of the patch-averaged strain form.
    """

    def __init__(self, model, strain_limit: float, tol: float = 1e-6, max_iterations: int = 30,
                 ksp_rtol: float = 1e-12, quadrature_degree: int = 4):
        self.strain_limit = _finite_positive("strain_limit", strain_limit)
        self.tol = _finite_positive("tol", tol)
        if not (isinstance(max_iterations, (int, np.integer)) and max_iterations >= 1):
            raise ValueError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        self.max_iterations = int(max_iterations)
        self.model = model
        model.compile()
        mesh = model.mesh
        self.comm = mesh.comm
        # constraint space: two values (warp, weft) per mesh vertex
        self.Q = fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=2)
        mu = ufl.TestFunction(self.Q)
        dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": int(quadrature_degree)})
        strains = self.strain_expressions(model)
        self.limit = fem.Constant(mesh, PETSc.ScalarType(self.strain_limit))
        C_form = ((strains[0] - self.limit) * mu[0] + (strains[1] - self.limit) * mu[1]) * dx
        self._C_form = fem.form(C_form)
        self._G_form = fem.form(ufl.derivative(C_form, model.w, model.w_trial))
        self._area_form = fem.form((mu[0] + mu[1]) * dx)
        self._quadrature_degree = int(quadrature_degree)
        # (E_warp, E_weft) at the strain form's quadrature points, built at the first `point_strain_max`
        self._point_strains: fem.Expression | None = None
        # nodal areas a_i = int phi_i dA (eq. 37), ghosted like C
        self.area = fem_petsc.assemble_vector(self._area_form)
        self.area.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.inv_area = self.area.copy()
        self.inv_area.reciprocal()
        self.C = fem_petsc.create_vector(self._C_form)
        self.G = fem_petsc.create_matrix(self._G_form)
        self.multipliers = self.C.duplicate()  # accumulated lambda of eq. 33 [J] (needs dt)
        self.multipliers.set(0.0)
        self.minv = self._inverse_mass()
        self.ksp = PETSc.KSP().create(self.comm)
        self.ksp.setType("cg")
        self.ksp.getPC().setType("jacobi")
        self.ksp.setTolerances(rtol=float(ksp_rtol), atol=1e-300, max_it=10000)
        self._dq = model.create_vector()

    # ---------------------------------------------------------------- forms
    @staticmethod
    def strain_expressions(model):
        """UFL (E_warp, E_weft): Green strain along the reference warp t1 and weft t2 [Peng2022, eq. 3b]."""
        u = ufl.split(model.w)[0] if model.model == "naghdi" else model.w
        F0 = ufl.grad(model.phi0)
        F = F0 + ufl.grad(u)
        e1, e2 = shell_forms.material_frame(F0, model.t1, model.t2)
        E = shell_forms.membrane_strain(F, F0)
        return ufl.dot(e1, E * e1), ufl.dot(e2, E * e2)

    def _inverse_mass(self) -> PETSc.Vec:
        """M^-1 of the lumped mass on free displacement dofs, 0 on rotations and Dirichlet rows [1/kg]."""
        m = lumped_mass(self.model, translational=True, rotational=False)
        n_local = m.getLocalSize()
        with m.localForm() as local:
            a = local.array
            inv = np.zeros_like(a)
            inv[a > 0] = 1.0 / a[a > 0]
            a[:] = inv
        array = m.getArray()
        for bc in self.model.bcs:
            dofs, n_owned = bc.dof_indices()
            owned = dofs[:n_owned]
            array[owned[owned < n_local]] = 0.0
        m.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return m

    # ------------------------------------------------------------ constraints
    def _assemble_constraints(self):
        """C_i = int phi_i (E - limit) dA / a_i (owned entries; eq. 36)."""
        with self.C.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(self.C, self._C_form)
        self.C.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.C.pointwiseMult(self.C, self.inv_area)

    def _assemble_gradient(self):
        """dC/dq: rows (vertex, warp/weft), columns W dofs [1/m]."""
        self.G.zeroEntries()
        fem_petsc.assemble_matrix(self.G, self._G_form)
        self.G.assemble()
        self.G.diagonalScale(L=self.inv_area)

    def _sync(self):
        self.model.w.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def vertex_strains(self) -> np.ndarray:
        """Patch-averaged (E_warp, E_weft) at the owned vertices of this rank, shape (n_owned, 2) [-]."""
        self._sync()
        self._assemble_constraints()
        return self.C.getArray(readonly=True).reshape(-1, 2) + self.strain_limit

    def strain_summary(self) -> dict[str, float]:
        """Max and area-weighted mean of the vertex E_warp, E_weft over all ranks [-].

        The mean is sum_i a_i E_i / sum_i a_i = int E dA / A (the hat functions sum to 1)."""
        E = self.vertex_strains()
        a = self.area.getArray(readonly=True).reshape(-1, 2)[:, 0]
        out = {}
        for k, name in enumerate(("warp", "weft")):
            out[f"max_{name}"] = self.comm.allreduce(float(E[:, k].max(initial=-np.inf)), op=MPI.MAX)
            num = self.comm.allreduce(float(a @ E[:, k]))
            out[f"mean_{name}"] = num / self.comm.allreduce(float(a.sum()))
        return out

    def point_strain_max(self) -> float:
        """The largest E_warp or E_weft at the quadrature points (the strain form's degree) of the owned cells, over
        all ranks [-]. Unlike the vertex strains, which average over the vertex's patch of cells (2 h across), it
        sees a strain concentrated in one cell."""
        self._sync()
        mesh = self.model.mesh
        if self._point_strains is None:
            cell = basix.cell.string_to_type(mesh.ufl_cell().cellname())
            points, _ = basix.make_quadrature(cell, self._quadrature_degree)
            self._point_strains = fem.Expression(ufl.as_vector(self.strain_expressions(self.model)), points)
        owned = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
        values = self._point_strains.eval(owned)
        return self.comm.allreduce(float(values.max(initial=-np.inf)), op=MPI.MAX)

    def max_violation(self) -> float:
        """max_i C_i over all ranks (<= 0 inside the limit) [-]."""
        self._sync()
        self._assemble_constraints()
        return self._global_max()

    def _global_max(self) -> float:
        local = self.C.getArray(readonly=True)
        value = self.comm.allreduce(float(local.max(initial=-np.inf)), op=MPI.MAX)
        if not math.isfinite(value):
            raise StrainLimitError(f"non-finite strain in the fast projection (max C = {value})")
        return value

    # -------------------------------------------------------------- project
    def project(self, dt: float = 1.0) -> ProjectionResult:
        """Project model.w (displacements only) onto {E_warp, E_weft <= limit} in place (eqs. 33-34).

        dt [s] is the time step h of eq. 33; it only scales the stored multipliers (self.multipliers, [J]).
        Returns the iterations and the max violation per iteration. Raises StrainLimitError when max C
        is still >= tol after max_iterations (or a solve fails)."""
        h = _finite_positive("dt", dt)
        self.multipliers.set(0.0)
        w = self.model.w.vector
        w.copy(self._dq)
        self._sync()
        self._assemble_constraints()
        violation = self._global_max()
        result = ProjectionResult(iterations=0, violations=[violation])
        sticky = np.zeros(self.C.getLocalSize(), dtype=bool)
        r0, _ = self.C.getOwnershipRange()
        while violation >= self.tol:
            if result.iterations >= self.max_iterations:
                raise StrainLimitError(
                    f"fast projection: max strain violation {violation:.3g} >= tol = {self.tol:.3g} after "
                    f"{self.max_iterations} iterations (limit {self.strain_limit:g}; history "
                    f"{[f'{v:.2e}' for v in result.violations]})")
            c = self.C.getArray(readonly=True)
            sticky |= c > 0.0
            rows = PETSc.IS().createGeneral((np.flatnonzero(sticky) + r0).astype(PETSc.IntType), comm=self.comm)
            self._assemble_gradient()
            c0, c1 = self.G.getOwnershipRangeColumn()
            cols = PETSc.IS().createStride(c1 - c0, first=c0, step=1, comm=self.comm)
            GA = self.G.createSubMatrix(rows, cols)
            B = GA.copy()
            B.diagonalScale(R=self.minv)  # G_A M^-1
            S = B.matTransposeMult(GA)  # G_A M^-1 G_A^T (eq. 33 without h^2)
            rhs, dmu = S.createVecLeft(), S.createVecLeft()
            rhs.getArray()[:] = c[sticky]
            self.ksp.reset()  # the active set (hence the size of S) changes between iterations
            self.ksp.setOperators(S)
            self.ksp.solve(rhs, dmu)
            if self.ksp.getConvergedReason() <= 0:
                raise StrainLimitError(f"fast projection: CG on eq. 33 failed (reason "
                                       f"{self.ksp.getConvergedReason()}, {self.ksp.getIterationNumber()} its)")
            step = B.createVecRight()
            B.multTranspose(dmu, step)  # M^-1 G_A^T dmu
            w.axpy(-1.0, step)  # eq. 34, dlambda = dmu / h^2
            self.multipliers.getArray()[sticky] += dmu.getArray(readonly=True) / h ** 2
            for obj in (rows, cols, GA, B, S, rhs, dmu, step):
                obj.destroy()
            self._sync()
            self._assemble_constraints()
            violation = self._global_max()
            result.iterations += 1
            result.violations.append(violation)
        self._dq.aypx(-1.0, w)  # Delta q = w - w~
        result.active = int(self.comm.allreduce(int(sticky.sum())))
        result.correction_norm = float(self._dq.norm())
        return result

    @property
    def correction(self) -> PETSc.Vec:
        """Delta q of the last projection (displacement dofs of W) [m]."""
        return self._dq

    def constraint_stress_resultant(self) -> np.ndarray:
        """lambda_i / a_i of eq. 37 at the owned vertices, (n_owned, 2) (warp, weft) [N/m]: the membrane
        force the constraints carried in the last projection (add S(E_i) t for the reconstructed stress)."""
        return (self.multipliers.getArray(readonly=True) * self.inv_area.getArray(readonly=True)).reshape(-1, 2)

    def destroy(self):
        for obj in (self.area, self.inv_area, self.C, self.G, self.multipliers, self.minv, self.ksp, self._dq):
            obj.destroy()


def project_step(projection: FastProjection, integrator) -> ProjectionResult:
    """Strain-limit the state of a TimeIntegrator (CentralDifference or NewmarkIntegrator) after a step.

    d += Delta q, v += Delta q / dt (Goldenthal et al.). CentralDifference: the end-of-step acceleration is
    re-evaluated at the projected state, (M_L + dt/2 C_L) a = lambda F - f_int(d) - C v~ with v~ = v - dt/2 a_old
    and v = v~ + dt/2 a ([Man2006, eq. 2.84], the step's own update). Newmark: a is kept. Re-evaluating it from
    the equation of motion, M a = lambda F - f_int(d) - C v, puts the unresolved stiff modes of the implicit
    step into a (the rotational inertia rho t^3/12 is tiny): measured on the corner-pinned cloth, a 2e-4 m
    correction gave a next-step Newton residual 4000 x the usual and divergence.
    """
    model = integrator.model
    integrator.d.copy(model.w.vector)
    result = projection.project(integrator.dt)
    if result.iterations == 0:
        return result
    model.w.vector.copy(integrator.d)
    dq = projection.correction
    integrator.v.axpy(1.0 / integrator.dt, dq)
    if not isinstance(integrator, CentralDifference):
        return result
    rhs = integrator.d.duplicate()
    integrator.system.internal_force(integrator.d, rhs)   # the shell + its terms (e.g. obstacle contact)
    rhs.scale(-1.0)
    rhs.axpy(float(model.load_factor.value), model.F_ref)
    cv = integrator.d.duplicate()
    v_pred = integrator.v.copy()
    v_pred.axpy(-0.5 * integrator.dt, integrator.a)
    if integrator.ops.has_damping:
        integrator.ops.damping_action(v_pred, cv)
        rhs.axpy(-1.0, cv)
    integrator.zero_bc_rows(rhs)
    integrator.a.pointwiseDivide(rhs, integrator.denominator)
    bc_v = integrator.v.getArray(readonly=True)[integrator.bc_rows].copy()
    v_pred.copy(integrator.v)
    integrator.v.axpy(0.5 * integrator.dt, integrator.a)
    integrator.v.getArray()[integrator.bc_rows] = bc_v
    v_pred.destroy()
    rhs.destroy()
    cv.destroy()
    return result


def attach(projection: FastProjection, integrator) -> list[ProjectionResult]:
    """Make every `integrator.step()` (hence `integrator.run`) end with `project_step`.

    The integrators have no post-step callback: the instance's step method is wrapped. Returns the list
    the ProjectionResult of every step is appended to."""
    log: list[ProjectionResult] = []
    unconstrained_step = integrator.step

    def step() -> int:
        iterations = unconstrained_step()
        log.append(project_step(projection, integrator))
        return iterations

    integrator.step = step
    return log


__all__ = ["FastProjection", "ProjectionResult", "StrainLimitError", "attach", "project_step"]
