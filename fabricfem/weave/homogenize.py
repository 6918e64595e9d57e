"""Periodic unit-cell homogenization at finite strain ([Man2006, sec. 4.2.2] and 4.3.2-4.3.3).

The cell Y (a dolfinx 3D mesh, lengths in m) is loaded by a macroscopic deformation gradient Phi:
the microscopic placement is y = Phi Y + u* (eq. 4.52) with the fluctuation u* periodic between
the given pairs of faces, rigid translations removed by pinning u* = 0 at one vertex, and every
face not in a pair left traction-free (the thesis' top and bottom faces). Equilibrium DIV P = 0
(eqs. 4.57, 4.61) is solved by Newton on dolfinx_mpc assemblers, Phi applied in equal increments
of Phi - 1. The homogenized second Piola-Kirchhoff stress is the volume average (eq. 4.64)

    S = phi / |Y_s| int_{Y_s} F^{-1} P dV,   phi = |Y_s| / |Y|          (eqs. 4.64, 4.65)

where Y_s is the meshed (solid) region and |Y| the volume of the reference bounding box; the
conjugate strain is E = (Phi^T Phi - 1) / 2 (eq. 4.59). Stresses are in Pa.

Rigid motions: the translations are removed by the pin; rotations are not periodic once pairs span
two independent directions, so they are excluded too. With pairs along one direction only, or a
cell of disconnected bodies (yarns without contact), rigid rotations remain and the tangent is
singular: MUMPS then returns one of the equivalent states (seen with a box periodic in x only) or
the solve fails with SolverError; no further rigid modes are removed here.
Pairs are translations (full cell, thesis option A) or general point maps `relation` with a
sign per displacement component, u*_i(x) = s_i u*_i(relation(x)): the anti-symmetric quarter cell
(option B, [Man2006, sec. 4.3.3], Fig. 19) maps its end face by a half-period translation and z -> -z
with s = (1, 1, -1) (UnitCellMesh.periodic_relation gives the map). Non-unit signs are imposed
per component (one geometrical dolfinx_mpc constraint per component and sign).

Material: `psi` is a strain-energy density [J/m^3] given as a UFL callable psi(C) of the right
Cauchy-Green tensor C, or a mapping {cell tag: psi} used with `cell_tags`. Extra fields (a yarn
axis Function, say) enter through closures.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence, Union

import dolfinx.fem as fem
import dolfinx.fem.petsc as fem_petsc
import dolfinx.mesh as dmesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.solvers.mpc_newton import MPCNewtonSolver
from fabricfem.solvers.newton import SolverError
from fabricfem.weave.periodic import (
    GEOMETRIC_TOLERANCE,
    Locator,
    PeriodicPair,
    SlaveFaces,
    allreduce,
    bounding_box,
    periodic_constraint,
    pin_point,
)

StrainEnergy = Callable[[ufl.core.expr.Expr], ufl.core.expr.Expr]


@dataclass
class UnitCellStep:
    """One converged load step: Phi and E dimensionless, S and P in Pa."""

    Phi: np.ndarray
    E: np.ndarray  # eq. 4.59
    S: np.ndarray  # eq. 4.64, homogenized second Piola-Kirchhoff stress
    P: np.ndarray  # phi / |Y_s| int_{Y_s} P dV, homogenized first Piola-Kirchhoff stress
    newton_iterations: int
    residual_norms: list[float] = field(default_factory=list)


@dataclass
class UnitCellResult:
    """The steps of one solve with the cell's phi, |Y_s| and |Y| [m^3], the dofs and the fluctuation u* [m]."""

    steps: list[UnitCellStep]
    volume_fraction: float
    solid_volume: float  # |Y_s| [m^3]
    cell_volume: float  # |Y| [m^3]
    ndofs: int
    fluctuation: fem.Function  # u* at the last step [m]

    @property
    def S(self) -> np.ndarray:
        """The last step's homogenized S [Pa]."""
        return self.steps[-1].S

    @property
    def E(self) -> np.ndarray:
        """The last step's Green-Lagrange strain E."""
        return self.steps[-1].E


def green_lagrange(Phi: np.ndarray) -> np.ndarray:
    """E = (Phi^T Phi - 1) / 2 (eq. 4.59)."""
    Phi = np.asarray(Phi, dtype=float)
    return 0.5 * (Phi.T @ Phi - np.eye(3))


def _check_Phi(Phi) -> np.ndarray:
    """Phi as a finite 3 x 3 array with det > 0, else ValueError."""
    Phi = np.asarray(Phi, dtype=float)
    if Phi.shape != (3, 3) or not np.all(np.isfinite(Phi)):
        raise ValueError(f"Phi must be a finite 3 x 3 deformation gradient, got {Phi!r}")
    det = np.linalg.det(Phi)
    if det <= 0:
        raise ValueError(f"Phi must have det(Phi) > 0 (orientation-preserving), got det = {det:.6g}")
    return Phi


def load_path(Phi, steps: int) -> list[np.ndarray]:
    """Phi_n = 1 + (n / steps)(Phi - 1), n = 1 ... steps; det(1 + t (Phi - 1)) must stay > 0 on the
    whole path t in (0, 1], not only at the steps."""
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    Phi = _check_Phi(Phi)
    H = Phi - np.eye(3)
    # det(1 + t H) = 1 + t tr H + t^2 (tr^2 H - tr H^2) / 2 + t^3 det H
    cubic = [np.linalg.det(H), 0.5 * (np.trace(H) ** 2 - np.trace(H @ H)), np.trace(H), 1.0]
    roots = np.roots(cubic) if np.any(np.abs(cubic[:3]) > 0) else np.array([])
    real = roots[np.abs(roots.imag) <= 1e-6 * max(1.0, np.abs(roots).max(initial=0.0))].real
    if np.any((real > 0) & (real <= 1.0)):
        raise ValueError(f"Phi: the linear load path 1 + t (Phi - 1) reaches det = 0 at t = "
                         f"{real[(real > 0) & (real <= 1)].min():.3g}; apply Phi in several calls through "
                         "intermediate deformations")
    return [np.eye(3) + (n / steps) * H for n in range(1, int(steps) + 1)]


class UnitCellProblem:
    """Finite-strain periodic unit cell; build once, then `solve(Phi, steps)` along load paths.

    Parameters:
        mesh: dolfinx mesh of the solid part of the cell (3D, coordinates in m)
        psi: strain energy psi(C) [J/m^3] (UFL), or {cell tag: psi} together with `cell_tags`
        periodic_pairs: PeriodicPair list (all by facet tag, or all by locator)
        facet_tags: MeshTags of facets, needed for pairs given by tag
        cell_tags: MeshTags of cells, needed when psi is a mapping; Y_s is the union of its tags
        volume_fraction: phi of eq. 4.65 in (0, 1]; None computes |Y_s| / |bounding box of the mesh|
        degree: Lagrange degree of u* (1 or 2)
        quadrature_degree: default 2 * degree
        rtol, stol, max_it: Newton tolerances (see MPCNewtonSolver)
        pins: optional [(point (3,) [m], components), ...]: u*_c = 0 at the mesh vertex `point` for each
            component c in `components` (0, 1, 2), instead of the single fully pinned vertex nearest the
            cell centre. Needed for cells of several bodies (yarns without bonded contact): each body's
            rigid modes left free by the periodicity must be removed (fabricfem.weave.unit_cell pins
            them at points where the weave's symmetry makes that component of u* vanish anyway).
        fixed_facets: optional [(facet tag, components), ...]: u*_c = 0 on every vertex of the tagged
            facets for each c in `components` (e.g. u*_z = 0 on the yarn end faces, [Man2006, sec. 4.3.5.3]);
            a component fixed on a slave face must not be coupled by its PeriodicPair (`components`).
            These conditions are in `bcs` after the pins; `pin_bcs` holds the pins only.
    """

    def __init__(self, mesh: dmesh.Mesh, psi: Union[StrainEnergy, Mapping[int, StrainEnergy]],
                 periodic_pairs: Sequence[PeriodicPair], facet_tags=None, cell_tags=None,
                 volume_fraction: float | None = None, degree: int = 1, quadrature_degree: int | None = None,
                 rtol: float = 1e-10, stol: float = 1e-13, max_it: int = 25,
                 pins: Sequence[tuple[Sequence[float], Sequence[int]]] | None = None,
                 fixed_facets: Sequence[tuple[int, Sequence[int]]] | None = None):
        self._check_arguments(mesh, degree, volume_fraction)
        self.mesh, self.comm = mesh, mesh.comm
        lower, upper = bounding_box(mesh)
        self.length_scale = float(np.linalg.norm(upper - lower))  # cell diagonal [m]
        tol = GEOMETRIC_TOLERANCE * self.length_scale
        materials = self._materials(psi, cell_tags)
        q = 2 * degree if quadrature_degree is None else int(quadrature_degree)
        self.dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags, metadata={"quadrature_degree": q})
        V = fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
        faces = SlaveFaces(mesh, periodic_pairs, facet_tags, tol)
        self._set_conditions(V, faces, pins, fixed_facets, facet_tags, periodic_pairs, 0.5 * (lower + upper), tol)
        self.mpc = periodic_constraint(V, faces, periodic_pairs, facet_tags, self.bcs)
        self.u = fem.Function(self.mpc.function_space, name="fluctuation")  # u* [m]
        self._set_forms(V, materials, q, rtol, stol, max_it)
        self._set_volumes(materials, float(np.prod(upper - lower)), volume_fraction)

    @staticmethod
    def _check_arguments(mesh: dmesh.Mesh, degree: int, volume_fraction: float | None) -> None:
        """ValueError unless the mesh is a 3D volume mesh, degree 1 or 2 and volume_fraction None or in (0, 1]."""
        if mesh.topology.dim != 3 or mesh.geometry.dim != 3:
            raise ValueError("mesh must be a 3D volume mesh")
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree!r}")
        if volume_fraction is not None and not (np.isfinite(volume_fraction) and 0.0 < volume_fraction <= 1.0):
            raise ValueError(f"volume_fraction must lie in (0, 1], got {volume_fraction!r}")

    def _set_conditions(self, V: fem.FunctionSpace, faces: SlaveFaces, pins, fixed_facets, facet_tags,
                        periodic_pairs: Sequence[PeriodicPair], centre: np.ndarray, tol: float) -> None:
        """The Dirichlet conditions: the vertex nearest the cell centre [m] off the slave faces pinned (self.pin),
        or the component pins; then the fixed facets. self.pin_bcs holds the pins only."""
        if pins is None:
            self.pin = pin_point(self.mesh, faces.contains, centre)
            pinned = fem.locate_dofs_geometrical(V, lambda x: np.linalg.norm(x - self.pin[:, None], axis=0) <= tol)
            self.bcs = [fem.dirichletbc(np.zeros(3, dtype=np.float64), pinned, V)]
        else:
            self.pin = None
            self.bcs = self._component_pins(V, pins, faces.contains, tol)
        self.pin_bcs = list(self.bcs)
        if fixed_facets:
            self.bcs += self._facet_conditions(V, fixed_facets, facet_tags, periodic_pairs, faces.coupled)

    def _set_forms(self, V: fem.FunctionSpace, materials: list[tuple[int | None, StrainEnergy]], q: int,
                   rtol: float, stol: float, max_it: int) -> None:
        """Phi (a Constant), the residual (eq. 4.61) with its MPC Newton solver, and the one compiled form of the
        volume integrals of S and P (18 components against a DG0 test function)."""
        mesh = self.mesh
        self.Phi = fem.Constant(mesh, np.eye(3))
        F = self.Phi + ufl.grad(self.u)  # eq. 4.54
        C = F.T * F
        v = ufl.TestFunction(V)
        energy = sum(w(C) * self._dx(tag) for tag, w in materials)
        residual = ufl.derivative(energy, self.u, v)  # eq. 4.61: int P : grad(du*) dV
        self.residual = residual
        self.newton = MPCNewtonSolver(residual, self.u, self.mpc, self.bcs, rtol=rtol, stol=stol, max_it=max_it,
                                      form_compiler_params={"quadrature_degree": q})
        self._plain_residual = self.newton.L
        averages = []
        for tag, w in materials:
            Cv = ufl.variable(C)
            S = ufl.diff(w(Cv), Cv)
            S = S + S.T  # S = 2 dpsi/dC, symmetrized: C is symmetric
            P = F * S
            flat = ufl.as_vector([S[i, j] for i in range(3) for j in range(3)] +
                                 [P[i, j] for i in range(3) for j in range(3)])
            averages.append((flat, tag))
        W = fem.FunctionSpace(mesh, ufl.VectorElement("DG", mesh.ufl_cell(), 0, dim=18))
        t = ufl.TestFunction(W)
        self._stress_form = fem.form(sum(ufl.inner(flat, t) * self._dx(tag) for flat, tag in averages))
        self._stress_vector = fem_petsc.create_vector(self._stress_form)
        self._owned_stress = W.dofmap.index_map.size_local * W.dofmap.index_map_bs

    def _set_volumes(self, materials: list[tuple[int | None, StrainEnergy]], box_volume: float,
                     volume_fraction: float | None) -> None:
        """|Y_s| [m^3] (solid_volume), phi (given, or |Y_s| / box_volume) and |Y| = |Y_s| / phi (cell_volume)."""
        one = fem.Constant(self.mesh, 1.0)
        self.solid_volume = self.comm.allreduce(
            fem.assemble_scalar(fem.form(sum(one * self._dx(tag) for tag, _ in materials))), op=MPI.SUM)
        self.volume_fraction = self.solid_volume / box_volume if volume_fraction is None else float(volume_fraction)
        if not (0.0 < self.volume_fraction <= 1.0 + 1e-12):
            raise ValueError(f"volume_fraction computed from the mesh is {self.volume_fraction:.6g}, outside (0, 1]")
        self.cell_volume = self.solid_volume / self.volume_fraction

    def _component_pins(self, V: fem.FunctionSpace, pins, on_slave_face: Locator, tol: float) -> list:
        """One zero Dirichlet condition per (point, component) of `pins`; ValueError if a point is not a
        mesh vertex, lies on a slave face or a component is not 0, 1 or 2."""
        if len(pins) == 0:
            raise ValueError("pins must hold at least one (point, components) pair, or be None")
        bcs = []
        for point, components in pins:
            point = np.asarray(point, dtype=float)
            if point.shape != (3,) or not np.all(np.isfinite(point)):
                raise ValueError(f"pins: point must be a finite 3-vector, got {point!r}")
            if on_slave_face(point[:, None])[0]:
                raise ValueError(f"pins: point {point.tolist()} lies on a slave face (its dofs are constrained)")
            for c in components:
                if c not in (0, 1, 2):
                    raise ValueError(f"pins: components must be 0, 1 or 2, got {components!r}")
                Vc, _ = V.sub(c).collapse()
                dofs = fem.locate_dofs_geometrical(
                    (V.sub(c), Vc), lambda x, p=point: np.linalg.norm(x - p[:, None], axis=0) <= tol)[0]
                owned = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
                if self.comm.allreduce(int(np.count_nonzero(dofs < owned)), op=MPI.SUM) != 1:
                    raise ValueError(f"pins: point {point.tolist()} is not (exactly one) mesh vertex")
                bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(c)))
        return bcs

    def _facet_conditions(self, V: fem.FunctionSpace, fixed_facets, facet_tags, pairs, coupled) -> list:
        """Zero Dirichlet conditions u*_c = 0 on tagged facets; ValueError for a missing tag, a bad
        component or a component that a periodic pair also couples on that face."""
        if facet_tags is None:
            raise ValueError("fixed_facets needs facet_tags")
        fdim = self.mesh.topology.dim - 1
        bcs = []
        for tag, components in fixed_facets:
            facets = facet_tags.indices[facet_tags.values == int(tag)]
            if self.comm.allreduce(len(facets), op=MPI.SUM) == 0:
                raise ValueError(f"fixed_facets: no facet carries tag {tag!r}")
            for c in components:
                if c not in (0, 1, 2):
                    raise ValueError(f"fixed_facets: components must be 0, 1 or 2, got {components!r}")
                for p, comps in zip(pairs, coupled):
                    if c in comps and int(tag) in (p.slave, p.master):
                        raise ValueError(f"fixed_facets: component {c} on facet tag {tag} is also coupled by a "
                                         "periodic pair; drop it from that pair's components")
                Vc, _ = V.sub(c).collapse()
                dofs = fem.locate_dofs_topological((V.sub(c), Vc), fdim, facets)[0]
                bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(c)))
        return bcs

    def _dx(self, tag: int | None) -> ufl.Measure:
        """The cell measure, restricted to the cell tag when given."""
        return self.dx if tag is None else self.dx(tag)

    @staticmethod
    def _materials(psi, cell_tags) -> list[tuple[int | None, StrainEnergy]]:
        """[(cell tag or None, psi)]: ValueError unless psi is a callable, or a mapping covering every owned cell."""
        if callable(psi):
            return [(None, psi)]
        if not isinstance(psi, Mapping) or not psi:
            raise ValueError("psi must be a callable psi(C) or a non-empty mapping {cell tag: psi}")
        if cell_tags is None:
            raise ValueError("cell_tags are required when psi is a mapping {cell tag: psi}")
        present = set(np.unique(np.concatenate(cell_tags.mesh.comm.allgather(cell_tags.values))).tolist())
        missing = [tag for tag in psi if tag not in present]
        if missing:
            raise ValueError(f"psi: cell tags {missing} do not occur in cell_tags (present: {sorted(present)})")
        for tag, w in psi.items():
            if not callable(w):
                raise ValueError(f"psi[{tag}] must be a callable psi(C)")
        # every owned cell needs an energy, otherwise the tangent is singular there
        mesh = cell_tags.mesh
        owned = mesh.topology.index_map(mesh.topology.dim).size_local
        covered = np.unique(cell_tags.indices[np.isin(cell_tags.values, list(psi)) & (cell_tags.indices < owned)])
        uncovered = mesh.comm.allreduce(owned - len(covered), op=MPI.SUM)
        if uncovered:
            raise ValueError(f"psi: {uncovered} cells carry no tag of psi {sorted(psi)} in cell_tags (no strain "
                             "energy there); mesh only the solid and give every cell a material")
        return list(psi.items())

    @property
    def ndofs(self) -> int:
        """Global number of scalar dofs of u* (MPC slaves included)."""
        return self.newton.ndofs

    def homogenized_stress(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, P) [Pa] at the current state: phi / |Y_s| int_{Y_s} (F^{-1} P, P) dV (eq. 4.64)."""
        b = self._stress_vector
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self._stress_form)
        local = b.array_r[: self._owned_stress].reshape(-1, 18).sum(axis=0)
        total = allreduce(self.comm, local, MPI.SUM)
        scale = self.volume_fraction / self.solid_volume  # eq. 4.64
        return scale * total[:9].reshape(3, 3), scale * total[9:].reshape(3, 3)

    def force_scale(self) -> float:
        """Norm of the nodal forces of the current state without the periodic condensation [N]:
        the boundary forces the periodicity has to balance (zero only for a stress-free state)."""
        b = fem_petsc.assemble_vector(self._plain_residual)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        norm = b.norm()
        b.destroy()
        return float(norm) if norm > 0 else float(np.finfo(float).tiny)

    def solve(self, Phi, steps: int = 1) -> UnitCellResult:
        """Apply Phi in `steps` equal increments of Phi - 1 from the current state of u*
        (zero for a new problem); SolverError if a step does not converge."""
        path = load_path(Phi, steps)
        out = []
        for n, Phi_n in enumerate(path, start=1):
            self.Phi.value[:] = Phi_n
            result = self.newton.solve(self.force_scale(), self.length_scale)
            if not result.converged:
                raise SolverError(f"unit cell: Newton {result.reason} after {result.iterations} iterations at load "
                                  f"step {n}/{steps} (Phi = {Phi_n.tolist()}); residual norms "
                                  f"{[f'{r:.3g}' for r in result.residual_norms]}",
                                  last_converged_load_factor=(n - 1) / steps, reason=result.reason)
            S, P = self.homogenized_stress()
            if not (np.all(np.isfinite(S)) and np.all(np.isfinite(P))):
                raise SolverError(f"unit cell: non-finite homogenized stress at load step {n}/{steps}")
            out.append(UnitCellStep(Phi_n.copy(), green_lagrange(Phi_n), S, P, result.iterations,
                                    result.residual_norms))
        return UnitCellResult(out, self.volume_fraction, self.solid_volume, self.cell_volume, self.ndofs, self.u)


def solve_unit_cell(mesh: dmesh.Mesh, psi: Union[StrainEnergy, Mapping[int, StrainEnergy]], Phi,
                    periodic_pairs: Sequence[PeriodicPair], facet_tags=None, cell_tags=None,
                    volume_fraction: float | None = None, steps: int = 1, degree: int = 1,
                    quadrature_degree: int | None = None) -> UnitCellResult:
    """Homogenized S (eq. 4.64) and P of the unit cell `mesh` under Phi applied in `steps` increments.

    See UnitCellProblem for the parameters; returns a UnitCellResult with one UnitCellStep per step.
    """
    load_path(Phi, steps)  # validate before the (expensive) set-up
    problem = UnitCellProblem(mesh, psi, periodic_pairs, facet_tags=facet_tags, cell_tags=cell_tags,
                              volume_fraction=volume_fraction, degree=degree, quadrature_degree=quadrature_degree)
    return problem.solve(Phi, steps)


def box_periodic_pairs(mesh: dmesh.Mesh, axes: Sequence[int] = (0, 1, 2)):
    """Facet tags of an axis-aligned box mesh (faces min/max of axis a tagged 2a+1 / 2a+2) and the
    PeriodicPairs (slave = max face, master = min face) along `axes`."""
    lower, upper = bounding_box(mesh)
    tol = GEOMETRIC_TOLERANCE * float(np.linalg.norm(upper - lower))
    fdim = mesh.topology.dim - 1
    indices, values = [], []
    for axis in range(3):
        for side, coordinate in ((1, lower[axis]), (2, upper[axis])):
            facets = dmesh.locate_entities_boundary(mesh, fdim, lambda x, a=axis, c=coordinate: np.abs(x[a] - c) <= tol)
            indices.append(facets)
            values.append(np.full(len(facets), 2 * axis + side, dtype=np.int32))
    indices, values = np.concatenate(indices), np.concatenate(values)
    order = np.argsort(indices, kind="stable")
    tags = dmesh.meshtags(mesh, fdim, indices[order].astype(np.int32), values[order])
    pairs = [PeriodicPair(slave=2 * a + 2, master=2 * a + 1) for a in axes]
    return tags, pairs
