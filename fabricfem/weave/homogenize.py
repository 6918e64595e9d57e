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

import dolfinx.cpp as _cpp
import dolfinx.fem as fem
import dolfinx.fem.petsc as fem_petsc
import dolfinx.mesh as dmesh
import dolfinx_mpc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.solvers.mpc_newton import MPCNewtonSolver
from fabricfem.solvers.newton import SolverError

StrainEnergy = Callable[[ufl.core.expr.Expr], ufl.core.expr.Expr]
Locator = Callable[[np.ndarray], np.ndarray]

GEOMETRIC_TOLERANCE = 1e-8  # relative to the cell diagonal: points closer than this coincide


@dataclass(frozen=True)
class PeriodicPair:
    """Two opposite faces with u*_i(x) = s_i u*_i(m(x)) for x on the slave face, where the master
    point is m(x) = x - translation or m(x) = relation(x), and s = component_scale.

    `slave` and `master` are facet-tag values (with `facet_tags` given to the problem) or,
    for geometric pairs, `slave` is a locator x (3, n) -> bool (n,) and `translation` or
    `relation` is required. `translation` [m] is the vector from the master face to the slave face;
    with tags it defaults to the difference of the faces' vertex centroids (exact for meshes whose
    opposite faces match, which dolfinx_mpc does not otherwise require). `relation` x (3, n) ->
    (3, n) [m] is a general point map from the slave face onto the master face (e.g.
    UnitCellMesh.periodic_relation(name) of the quarter cell: half-period shift and z -> -z);
    give either `relation` or `translation`. `component_scale` (s_x, s_y, s_z), non-zero and
    dimensionless, is (1, 1, -1) for the anti-symmetric quarter cell [Man2006, sec. 4.3.3].
    `components` lists the displacement components (0, 1, 2) that are coupled; the others are left
    free by this pair (e.g. u*_z when it is prescribed on both faces by `fixed_facets`, the thesis'
    end-face condition of sec. 4.3.5.3).
    """

    slave: int | Locator
    master: int | None = None
    translation: Sequence[float] | None = None
    relation: Callable[[np.ndarray], np.ndarray] | None = None
    component_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    components: tuple[int, ...] = (0, 1, 2)


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
    steps: list[UnitCellStep]
    volume_fraction: float
    solid_volume: float  # |Y_s| [m^3]
    cell_volume: float  # |Y| [m^3]
    ndofs: int
    fluctuation: fem.Function  # u* at the last step [m]

    @property
    def S(self) -> np.ndarray:
        return self.steps[-1].S

    @property
    def E(self) -> np.ndarray:
        return self.steps[-1].E


def green_lagrange(Phi: np.ndarray) -> np.ndarray:
    """E = (Phi^T Phi - 1) / 2 (eq. 4.59)."""
    Phi = np.asarray(Phi, dtype=float)
    return 0.5 * (Phi.T @ Phi - np.eye(3))


def _check_Phi(Phi) -> np.ndarray:
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


def _facet_vertex_coordinates(mesh: dmesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """Coordinates (n, 3) of the vertices of the given facets, gathered from all ranks, each vertex
    once (by global index), so that every rank sees the same complete face."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, 0)
    f2v = mesh.topology.connectivity(tdim - 1, 0)
    per_facet = f2v.offsets[1] - f2v.offsets[0]  # one facet type per mesh
    verts = np.unique(f2v.array.reshape(-1, per_facet)[facets].ravel()).astype(np.int32)
    nodes = _cpp.mesh.entities_to_geometry(mesh._mesh, 0, verts, False).ravel()
    global_ids = mesh.topology.index_map(0).local_to_global(verts)
    ids = np.concatenate(mesh.comm.allgather(np.asarray(global_ids, dtype=np.int64)))
    x = np.concatenate(mesh.comm.allgather(mesh.geometry.x[nodes]))
    return x[np.unique(ids, return_index=True)[1]]


@dataclass(frozen=True)
class _Face:
    """A planar face: centroid c, unit normal n and bounding box, for geometric membership tests."""

    centroid: np.ndarray
    normal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tolerance: float

    def contains(self, x: np.ndarray) -> np.ndarray:
        on_plane = np.abs(self.normal @ (x - self.centroid[:, None])) <= self.tolerance
        inside = np.all((x >= self.lower[:, None] - self.tolerance) & (x <= self.upper[:, None] + self.tolerance),
                        axis=0)
        return on_plane & inside


def _tagged_face(mesh: dmesh.Mesh, facet_tags, tag: int, tolerance: float) -> _Face:
    """Fit the plane of the facets tagged `tag` (same result on all ranks); ValueError if missing or
    not planar."""
    x = _facet_vertex_coordinates(mesh, facet_tags.indices[facet_tags.values == tag])
    if len(x) < 3:
        raise ValueError(f"periodic_pairs: facet tag {tag} marks no face of the mesh (found {len(x)} vertices)")
    centroid = x.mean(axis=0)
    d = x - centroid
    normal = np.linalg.eigh(d.T @ d)[1][:, 0]  # direction of least spread
    offplane = float(np.abs(d @ normal).max())
    if offplane > tolerance:
        raise ValueError(f"periodic_pairs: the face with facet tag {tag} is not planar "
                         f"(vertices up to {offplane:.3g} m off its mean plane)")
    return _Face(centroid, normal, x.min(axis=0), x.max(axis=0), tolerance)


def _allreduce(comm: MPI.Comm, a: np.ndarray, op: MPI.Op) -> np.ndarray:
    """Element-wise reduction of a float array over `comm` (the pickle path cannot MIN/MAX arrays)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty_like(a)
    comm.Allreduce(a, out, op=op)
    return out


def _bounding_box(mesh: dmesh.Mesh) -> tuple[np.ndarray, np.ndarray]:
    x = mesh.geometry.x
    lower = x.min(axis=0) if len(x) else np.full(3, np.inf)
    upper = x.max(axis=0) if len(x) else np.full(3, -np.inf)
    return _allreduce(mesh.comm, lower, MPI.MIN), _allreduce(mesh.comm, upper, MPI.MAX)


def _pin_point(mesh: dmesh.Mesh, excluded: Callable[[np.ndarray], np.ndarray], target: np.ndarray) -> np.ndarray:
    """The mesh vertex nearest `target` that no slave face contains (same choice on every rank)."""
    nv = mesh.topology.index_map(0).size_local
    nodes = _cpp.mesh.entities_to_geometry(mesh._mesh, 0, np.arange(nv, dtype=np.int32), False).ravel()
    x = mesh.geometry.x[nodes]
    x = x[~excluded(x.T)] if len(x) else x
    if len(x):
        dist = np.linalg.norm(x - target, axis=1)
        # ties broken by coordinates so that every partition picks the same vertex
        best = x[np.lexsort((x[:, 2], x[:, 1], x[:, 0], np.round(dist, 12)))[0]]
        candidate = (round(float(np.linalg.norm(best - target)), 12), *best.tolist())
    else:
        candidate = (np.inf, 0.0, 0.0, 0.0)
    winner = min(mesh.comm.allgather(candidate))
    if not np.isfinite(winner[0]):
        raise ValueError("periodic_pairs: every vertex lies on a slave face; no point left to pin")
    return np.array(winner[1:])


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
        if mesh.topology.dim != 3 or mesh.geometry.dim != 3:
            raise ValueError("mesh must be a 3D volume mesh")
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree!r}")
        if volume_fraction is not None and not (np.isfinite(volume_fraction) and 0.0 < volume_fraction <= 1.0):
            raise ValueError(f"volume_fraction must lie in (0, 1], got {volume_fraction!r}")
        self.mesh, self.comm = mesh, mesh.comm
        lower, upper = _bounding_box(mesh)
        self.length_scale = float(np.linalg.norm(upper - lower))  # cell diagonal [m]
        tol = GEOMETRIC_TOLERANCE * self.length_scale

        materials = self._materials(psi, cell_tags)
        q = 2 * degree if quadrature_degree is None else int(quadrature_degree)
        self.dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags, metadata={"quadrature_degree": q})

        V = fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
        slave_faces, maps, scales = self._pairs(periodic_pairs, facet_tags, tol)
        coupled = [tuple(sorted(set(int(c) for c in p.components))) for p in periodic_pairs]
        for comps in coupled:
            if not comps or any(c not in (0, 1, 2) for c in comps):
                raise ValueError(f"periodic_pairs: components must be a non-empty subset of (0, 1, 2), got {comps!r}")

        def on_slave_face(x: np.ndarray) -> np.ndarray:
            hit = np.zeros(x.shape[1], dtype=bool)
            for face in slave_faces:
                hit |= face(x)
            return hit

        def chain(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # A point on several slave faces (edge, corner) is mapped by each pair in turn, until it
            # lies on no slave face (no chained constraints); its sign is the product of the pairs'.
            out, sign = np.array(x, dtype=np.float64, copy=True), np.ones((3, x.shape[1]))
            for _ in range(2 * len(slave_faces) + 1):
                moved = False
                for face, point_map, s in zip(slave_faces, maps, scales):
                    hit = face(out)
                    if np.any(hit):
                        out[:, hit] = point_map(out[:, hit])
                        sign[:, hit] *= s[:, None]
                        moved = True
                if not moved:
                    return out, sign
            raise ValueError("periodic_pairs: the maps send slave points back onto slave faces (cycle); "
                             "each pair must map its slave face onto a master face")

        if pins is None:
            self.pin = _pin_point(mesh, on_slave_face, 0.5 * (lower + upper))
            pinned = fem.locate_dofs_geometrical(V, lambda x: np.linalg.norm(x - self.pin[:, None], axis=0) <= tol)
            self.bcs = [fem.dirichletbc(np.zeros(3, dtype=np.float64), pinned, V)]
        else:
            self.pin = None
            self.bcs = self._component_pins(V, pins, on_slave_face, tol)
        self.pin_bcs = list(self.bcs)
        if fixed_facets:
            self.bcs += self._facet_conditions(V, fixed_facets, facet_tags, periodic_pairs, coupled)

        mpc = dolfinx_mpc.MultiPointConstraint(V)
        if all(np.all(s == 1.0) for s in scales) and all(c == (0, 1, 2) for c in coupled):
            def to_master(x: np.ndarray) -> np.ndarray:
                return chain(x)[0]
            if isinstance(periodic_pairs[0].slave, (int, np.integer)):
                slave_facets = np.unique(np.concatenate(
                    [facet_tags.indices[facet_tags.values == p.slave] for p in periodic_pairs]))
                all_slaves = dmesh.meshtags(mesh, mesh.topology.dim - 1, slave_facets.astype(np.int32), 1)
                mpc.create_periodic_constraint_topological(V, all_slaves, 1, to_master, self.bcs)
            else:
                mpc.create_periodic_constraint_geometrical(V, on_slave_face, to_master, self.bcs)
        else:
            # one constraint u*_c(x) = s u*_c(m(x)) per component c and per sign s occurring at the
            # slave points (products over the pairs meeting at an edge or corner)
            signs = {1.0}
            for s in scales:
                signs |= {round(float(a * b), 12) for a in signs for b in s}
            for c in range(3):
                faces_c = [face for face, comps in zip(slave_faces, coupled) if c in comps]
                if not faces_c:
                    continue

                def on_slave_face_c(x: np.ndarray, faces_c=faces_c) -> np.ndarray:
                    hit = np.zeros(x.shape[1], dtype=bool)
                    for face in faces_c:
                        hit |= face(x)
                    return hit
                for value in sorted(signs):
                    def indicator(x: np.ndarray, c: int = c, value: float = value,
                                  on_face: Locator = on_slave_face_c) -> np.ndarray:
                        hit = on_face(x)
                        sign = np.zeros(x.shape[1])
                        if np.any(hit):
                            sign[hit] = chain(x[:, hit])[1][c]
                        return hit & np.isclose(sign, value, rtol=0, atol=1e-12)
                    mpc.create_periodic_constraint_geometrical(V.sub(c), indicator, lambda x: chain(x)[0],
                                                               self.bcs, scale=value)
        mpc.finalize()
        self.mpc = mpc
        self.u = fem.Function(mpc.function_space, name="fluctuation")  # u* [m]

        self.Phi = fem.Constant(mesh, np.eye(3))
        F = self.Phi + ufl.grad(self.u)  # eq. 4.54
        C = F.T * F
        v = ufl.TestFunction(V)
        energy = sum(w(C) * self._dx(tag) for tag, w in materials)
        residual = ufl.derivative(energy, self.u, v)  # eq. 4.61: int P : grad(du*) dV
        self.residual = residual
        self.newton = MPCNewtonSolver(residual, self.u, mpc, self.bcs, rtol=rtol, stol=stol, max_it=max_it,
                                      form_compiler_params={"quadrature_degree": q})
        self._plain_residual = self.newton.L

        # Volume integrals of S and P (18 components) against a DG0 test function: one compiled form.
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

        one = fem.Constant(mesh, 1.0)
        self.solid_volume = self.comm.allreduce(
            fem.assemble_scalar(fem.form(sum(one * self._dx(tag) for tag, _ in materials))), op=MPI.SUM)
        box_volume = float(np.prod(upper - lower))
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
        return self.dx if tag is None else self.dx(tag)

    @staticmethod
    def _materials(psi, cell_tags) -> list[tuple[int | None, StrainEnergy]]:
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

    def _pairs(self, pairs, facet_tags, tol) -> tuple[list[Locator], list[Callable], list[np.ndarray]]:
        """Slave-face locators, slave -> master point maps and component signs of the pairs."""
        if not pairs:
            raise ValueError("periodic_pairs must contain at least one PeriodicPair")
        by_tag = [isinstance(p.slave, (int, np.integer)) for p in pairs]
        if any(by_tag) and not all(by_tag):
            raise ValueError("periodic_pairs must be all by facet tag or all by locator, not mixed")
        faces, maps, scales = [], [], []
        for p in pairs:
            if p.relation is not None and p.translation is not None:
                raise ValueError("periodic_pairs: give either a relation or a translation, not both")
            if p.relation is not None and not callable(p.relation):
                raise ValueError(f"periodic_pairs: relation must be a callable x (3, n) -> (3, n), got {p.relation!r}")
            scale = np.asarray(p.component_scale, dtype=float)
            if scale.shape != (3,) or not np.all(np.isfinite(scale)) or np.any(scale == 0.0):
                raise ValueError(f"periodic_pairs: component_scale must be three finite non-zero numbers, "
                                 f"got {p.component_scale!r}")
            if by_tag[0]:
                if facet_tags is None:
                    raise ValueError("facet_tags are required for periodic_pairs given by tag")
                slave = _tagged_face(self.mesh, facet_tags, int(p.slave), tol)
                if p.translation is None and p.relation is None:
                    if p.master is None:
                        raise ValueError(f"periodic_pairs: pair with slave tag {p.slave} needs a master tag, "
                                         "a translation or a relation")
                    master = _tagged_face(self.mesh, facet_tags, int(p.master), tol)
                    t = slave.centroid - master.centroid
                else:
                    t = None if p.translation is None else np.asarray(p.translation, dtype=float)
                faces.append(slave.contains)
            else:
                if not callable(p.slave) or (p.translation is None and p.relation is None):
                    raise ValueError("periodic_pairs: a pair given by locator needs a callable slave and a "
                                     "translation or a relation")
                faces.append(p.slave)
                t = None if p.translation is None else np.asarray(p.translation, dtype=float)
            if p.relation is not None:
                maps.append(lambda x, r=p.relation: np.asarray(r(x), dtype=np.float64).reshape(3, -1))
            else:
                if t.shape != (3,) or not np.all(np.isfinite(t)) or np.linalg.norm(t) <= tol:
                    raise ValueError(f"periodic_pairs: translation must be a non-zero finite 3-vector, got {t!r}")
                maps.append(lambda x, t=t: x - t[:, None])
            scales.append(scale)
        return faces, maps, scales

    @property
    def ndofs(self) -> int:
        return self.newton.ndofs

    def homogenized_stress(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, P) [Pa] at the current state: phi / |Y_s| int_{Y_s} (F^{-1} P, P) dV (eq. 4.64)."""
        b = self._stress_vector
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self._stress_form)
        local = b.array_r[: self._owned_stress].reshape(-1, 18).sum(axis=0)
        total = _allreduce(self.comm, local, MPI.SUM)
        scale = self.volume_fraction / self.solid_volume  # eq. 4.64
        return scale * total[:9].reshape(3, 3), scale * total[9:].reshape(3, 3)

    def _force_scale(self) -> float:
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
            result = self.newton.solve(self._force_scale(), self.length_scale)
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
    lower, upper = _bounding_box(mesh)
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
