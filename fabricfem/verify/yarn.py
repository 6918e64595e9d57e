"""Yarn law [Man2006, sec. 4.3.4]: UFL stress against eq. 4.69 and finite differences; engineering constants
recovered by finite-element tests on a block."""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from dolfinx.nls.petsc import NewtonSolver
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.forms import yarn as yarn_forms
from fabricfem.materials.yarn import THESIS_TRANSVERSELY_ISOTROPIC, EngineeringConstants, YarnMaterial, unit_axis
from fabricfem.verify import Timer, case, result

REFERENCE_POINT = np.array([[0.25, 0.25, 0.25]])  # any point of the reference tetrahedron (fields are constant)


def random_deformations(n: int, seed: int = 20060101, spread: float = 0.3, min_det: float = 0.5):
    """n random deformation gradients I + spread * N(0, 1) with det F >= min_det, and n random unit axes."""
    rng = np.random.default_rng(seed)
    Fs = []
    while len(Fs) < n:
        F = np.eye(3) + spread * rng.standard_normal((3, 3))
        if np.linalg.det(F) >= min_det:
            Fs.append(F)
    A = rng.standard_normal((n, 3))
    return np.array(Fs), A / np.linalg.norm(A, axis=1, keepdims=True)


class PointwiseYarnLaw:
    """The UFL yarn law evaluated at one point with dolfinx Expressions (one-cell mesh, constant fields)."""

    def __init__(self, material: YarnMaterial):
        domain = dmesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
        self.F = fem.Constant(domain, np.eye(3))
        self.C = fem.Constant(domain, np.eye(3))
        self.A = fem.Constant(domain, np.array([1.0, 0.0, 0.0]))
        p = material
        self._stress = fem.Expression(yarn_forms.yarn_stress(self.F, self.A, p), REFERENCE_POINT)
        self._closed = fem.Expression(yarn_forms.closed_form_stress(self.F.T * self.F, self.A, p.lmbda, p.mu,
                                                                    p.alpha, p.beta, p.gamma), REFERENCE_POINT)
        self._energy = fem.Expression(yarn_forms.yarn_energy(self.C, self.A, p), REFERENCE_POINT)
        self._cell = np.array([0], dtype=np.int32)

    def _set(self, constant: fem.Constant, value) -> None:
        constant.value[...] = value

    def stress(self, F: np.ndarray, A: np.ndarray) -> np.ndarray:
        """S = 2 dpsi/dC by UFL automatic differentiation [Pa]."""
        self._set(self.F, F)
        self._set(self.A, unit_axis(A))
        return self._stress.eval(self._cell).reshape(3, 3)

    def closed_form(self, F: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Eq. 4.69 written out in UFL [Pa]."""
        self._set(self.F, F)
        self._set(self.A, unit_axis(A))
        return self._closed.eval(self._cell).reshape(3, 3)

    def energy(self, C: np.ndarray, A: np.ndarray) -> float:
        """psi(C) [Pa] (C need not be exactly F^T F: used for finite differences)."""
        self._set(self.C, C)
        self._set(self.A, unit_axis(A))
        return float(self._energy.eval(self._cell)[0, 0])

    def finite_difference_stress(self, F: np.ndarray, A: np.ndarray, h: float) -> np.ndarray:
        """S_IJ = 2 dpsi/dC_IJ by central differences of the energy along symmetric directions of C.

        For I != J the symmetric direction e_I e_J + e_J e_I changes both C_IJ and C_JI, so its
        directional derivative is already 2 dpsi/dC_IJ; for I = J it is dpsi/dC_II."""
        C0 = F.T @ F
        S = np.zeros((3, 3))
        for i in range(3):
            for j in range(i, 3):
                dC = np.zeros((3, 3))
                dC[i, j] = dC[j, i] = 1.0
                dpsi = (self.energy(C0 + h * dC, A) - self.energy(C0 - h * dC, A)) / (2.0 * h)
                S[i, j] = S[j, i] = 2.0 * dpsi if i == j else dpsi
        return S


@case("bonet-burton-stress")
def bonet_burton_stress(n_samples: int = 6, h: float = 1e-5) -> list:
    """UFL S = 2 dpsi/dC of eqs. 4.66-4.68 against eq. 4.69 (numpy and UFL) and against central differences
    of the energy, for random F (det F >= 0.5) and random unit axes, thesis parameters (sec. 4.3.5.2).

    Tolerances, relative to the Frobenius norm of S:
    - eq. 4.69: both sides evaluate algebraically equal expressions in double precision; round-off of a few
      dozen operations on terms at most ~10 |S| is < 1e-13, so 1e-10 (any formula error is O(1)).
    - finite differences: central-difference error = truncation h^2 |psi'''| / 6 + round-off eps |psi| / h;
      with C = O(1), |psi| ~ |S| and |psi'''| ~ 10 |S| this is ~1e-10 |S| at h = 1e-5, so 1e-8 leaves 100x.
    """
    name = "bonet-burton-stress"
    material = THESIS_TRANSVERSELY_ISOTROPIC
    with Timer() as timer:
        law = PointwiseYarnLaw(material)
        Fs, As = random_deformations(n_samples)
        err_numpy, err_ufl_closed, err_fd = 0.0, 0.0, 0.0
        reference = material.stress(Fs, As)  # eq. 4.69 vectorised in numpy
        for F, A, S_ref in zip(Fs, As, reference):
            S = law.stress(F, A)
            scale = np.linalg.norm(S_ref)
            err_numpy = max(err_numpy, np.linalg.norm(S - S_ref) / scale)
            err_ufl_closed = max(err_ufl_closed, np.linalg.norm(S - law.closed_form(F, A)) / scale)
            err_fd = max(err_fd, np.linalg.norm(S - law.finite_difference_stress(F, A, h)) / scale)
        S_identity = law.stress(np.eye(3), As[0])
    out = [result(name, f"max |S_ufl - S_eq4.69(numpy)| / |S| over {n_samples} random F", err_numpy, 0.0, 1e-10,
                  0, timer.elapsed, scale=1.0),
           result(name, f"max |S_ufl - S_eq4.69(UFL)| / |S| over {n_samples} random F", err_ufl_closed, 0.0, 1e-10,
                  0, timer.elapsed, scale=1.0),
           result(name, f"max |S_ufl - S_FD| / |S| over {n_samples} random F (h = {h:g})", err_fd, 0.0, 1e-8, 0,
                  timer.elapsed, scale=1.0),
           # S(I) is a sum of terms that vanish exactly except through |A|^2 - 1 ~ 1e-16 (times gamma)
           result(name, "|S(F = I)| / gamma", np.linalg.norm(S_identity) / material.gamma, 0.0, 1e-12, 0,
                  timer.elapsed, scale=1.0)]
    return out


class YarnBlock:
    """Unit cube [0, 1]^3 m of yarn material (P1 tetrahedra), total Lagrangian, residual int P : grad v dX.

    P1 represents homogeneous deformations exactly, so the tests below have the exact homogeneous
    solution whatever the mesh; the mesh is kept small (n^3 cubes x 6 tetrahedra).
    """

    def __init__(self, material: YarnMaterial, axis=(1.0, 0.0, 0.0), n: int = 2, comm=MPI.COMM_WORLD):
        self.mesh = dmesh.create_unit_cube(comm, n, n, n)
        self.V = fem.VectorFunctionSpace(self.mesh, ("Lagrange", 1))
        self.u = fem.Function(self.V)
        v = ufl.TestFunction(self.V)
        F = ufl.Identity(3) + ufl.grad(self.u)
        A = fem.Constant(self.mesh, unit_axis(axis))
        self.P = F * yarn_forms.yarn_stress(F, A, material)
        dx = ufl.dx(domain=self.mesh, metadata={"quadrature_degree": 1})  # P1: the integrand is cellwise constant
        self.residual = ufl.inner(self.P, ufl.grad(v)) * dx
        self._residual_form = fem.form(self.residual)
        self._grad_forms = [[fem.form(ufl.grad(self.u)[i, j] * dx) for j in range(3)] for i in range(3)]
        self.fdim = self.mesh.topology.dim - 1
        self.ndofs = self.V.dofmap.index_map.size_global * self.V.dofmap.index_map_bs

    def face(self, axis: int, value: float) -> np.ndarray:
        return dmesh.locate_entities_boundary(self.mesh, self.fdim, lambda x: np.isclose(x[axis], value))

    def bc(self, component: int, facets: np.ndarray, value: float) -> fem.DirichletBCMetaClass:
        dofs = fem.locate_dofs_topological(self.V.sub(component), self.fdim, facets)
        return fem.dirichletbc(PETSc.ScalarType(value), dofs, self.V.sub(component))

    def solve(self, bcs: list) -> int:
        """Newton from u = 0 (LU); returns the iteration count or raises RuntimeError."""
        self.u.x.array[:] = 0.0
        problem = fem_petsc.NonlinearProblem(self.residual, self.u, bcs,
                                             form_compiler_params={"quadrature_degree": 1})
        solver = NewtonSolver(self.mesh.comm, problem)
        # Incremental criterion, relative to the first increment. At strains ~1e-6 the residual carries
        # round-off ~1e-10 of itself (cancellation in I - C^-1 and J - 1), so Newton stalls near 1e-11;
        # 1e-8 is reached in 3 iterations and moves the measured moduli by < 1e-8 relative.
        solver.convergence_criterion = "incremental"
        solver.rtol, solver.atol, solver.max_it = 1e-8, 1e-30, 10
        ksp = solver.krylov_solver
        ksp.setType("preonly")
        ksp.getPC().setType("lu")
        ksp.getPC().setFactorSolverType("mumps")
        iterations, converged = solver.solve(self.u)
        if not converged:
            raise RuntimeError(f"yarn block: Newton did not converge in {iterations} iterations")
        return iterations

    def mean_displacement_gradient(self) -> np.ndarray:
        """Volume average of grad u over the unit cube (= grad u for a homogeneous deformation)."""
        return np.array([[self.mesh.comm.allreduce(fem.assemble_scalar(f), op=MPI.SUM) for f in row]
                         for row in self._grad_forms])

    def reaction(self, component: int, facets: np.ndarray) -> float:
        """Total force [N] in `component` on the nodes of `facets`: the residual there (nodal reactions)."""
        b = fem_petsc.assemble_vector(self._residual_form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dofs = fem.locate_dofs_topological(self.V.sub(component), self.fdim, facets)
        owned = dofs[dofs < self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs]
        total = float(b.array[owned].sum())
        b.destroy()
        return self.mesh.comm.allreduce(total, op=MPI.SUM)

    def uniaxial(self, direction: int, strain: float) -> tuple[float, np.ndarray]:
        """Uniaxial stress along `direction`: symmetry rollers on the three faces x_i = 0, end face
        x_direction = 1 displaced by `strain`, other faces free. Returns (nominal stress [Pa], mean grad u)."""
        end = self.face(direction, 1.0)
        bcs = [self.bc(i, self.face(i, 0.0), 0.0) for i in range(3)] + [self.bc(direction, end, strain)]
        self.solve(bcs)
        return self.reaction(direction, end), self.mean_displacement_gradient()  # unit end face area

    def simple_shear(self, i: int, j: int, shear: float) -> tuple[float, np.ndarray]:
        """u = shear x_j e_i on the whole boundary (interior nodes solved). Returns (force in i on the face
        x_j = 1 [N] = nominal shear stress P_ij [Pa] on the unit face, mean grad u)."""
        facets = dmesh.locate_entities_boundary(self.mesh, self.fdim, lambda x: np.full(x.shape[1], True))
        prescribed = fem.Function(self.V)
        prescribed.interpolate(lambda x: np.stack([shear * x[j] if k == i else 0.0 * x[0] for k in range(3)]))
        bcs = [fem.dirichletbc(prescribed, fem.locate_dofs_topological(self.V, self.fdim, facets))]
        self.solve(bcs)
        return self.reaction(i, self.face(j, 1.0)), self.mean_displacement_gradient()


@case("bonet-burton-constants", mpi=True)
def bonet_burton_constants(strain: float = 1e-6, n: int = 2) -> list:
    """Small-strain tests on a finite-element block of the yarn law with parameters converted from
    E_L = 100, E_T = 10, G_LT = 5 GPa, nu_LT = nu_TT = 0.3 (yarn axis along x) recover those constants.

    Tolerance 1e-4 relative: at strain 1e-6 the nonlinear terms of the law (and the difference between
    nominal and true stress or engineering and Green strain) are O(strain) times stiffness ratios
    C_ij / E <= 20, i.e. < 2e-5; the exact homogeneous solution is in the P1 space. (Measured: the errors
    scale linearly with the strain, 1.3e-6 on E_L at strain 1e-6, so they are the nonlinearity, not the map.)
    The stress at F = I must vanish (round-off only: 1e-12 of E_L).
    """
    name = "bonet-burton-constants"
    target = EngineeringConstants(E_L=100e9, E_T=10e9, G_LT=5e9, nu_LT=0.3, nu_TT=0.3)
    material = YarnMaterial.from_engineering_constants(target.E_L, target.E_T, target.G_LT, target.nu_LT,
                                                       target.nu_TT)
    with Timer() as timer:
        block = YarnBlock(material, n=n)
        stress_at_rest = block.reaction(0, block.face(0, 1.0))
        P_L, H_L = block.uniaxial(0, strain)
        P_T, H_T = block.uniaxial(1, strain)
        P_LT, H_LT = block.simple_shear(0, 1, strain)
    E_L = P_L / H_L[0, 0]
    nu_LT = -0.5 * (H_L[1, 1] + H_L[2, 2]) / H_L[0, 0]
    E_T = P_T / H_T[1, 1]
    nu_TT = -H_T[2, 2] / H_T[1, 1]
    nu_TL = -H_T[0, 0] / H_T[1, 1]
    G_LT = P_LT / (H_LT[0, 1] + H_LT[1, 0])
    nd, t = block.ndofs, timer.elapsed
    return [result(name, "E_L [Pa] (uniaxial along the axis)", E_L, target.E_L, 1e-4, nd, t),
            result(name, "nu_LT (uniaxial along the axis)", nu_LT, target.nu_LT, 1e-4, nd, t),
            result(name, "E_T [Pa] (uniaxial across the axis)", E_T, target.E_T, 1e-4, nd, t),
            result(name, "nu_TT (uniaxial across the axis)", nu_TT, target.nu_TT, 1e-4, nd, t),
            result(name, "nu_TL = nu_LT E_T / E_L (uniaxial across the axis)", nu_TL, target.nu_TL, 1e-4, nd, t),
            result(name, "G_LT [Pa] (simple shear in the axial plane)", G_LT, target.G_LT, 1e-4, nd, t),
            result(name, "reaction at F = I / E_L [m^2]", abs(stress_at_rest) / target.E_L, 0.0, 1e-12, nd, t,
                   scale=1.0)]
