"""Woven unit cell with yarn-yarn frictional contact ([Man2006, sec. 4.3.2-4.3.5] with sec. 3.4, Box 7).

A UnitCellMesh (meshes.unit_cell: quarter cell = option B, full cell = option A) of separate yarn
bodies is loaded by the macroscopic deformation gradient Phi (y = Phi Y + u*, eq. 4.52) through the
periodic UnitCellProblem (fabricfem.weave.homogenize); the yarns interact by node-to-surface frictional
contact (fabricfem.contact.yarn.YarnContact, symmetrized augmented Lagrangian of [Man2006, Box 7], Coulomb
friction), whose forces and stiffness are added to the MPC-condensed residual and Jacobian. In each
load step Newton solves with fixed multipliers, then Uzawa augmentations follow until the
penetration is below the tolerance (solve_with_contact). Homogenized S by eq. 4.64, E by eq. 4.59.
Units: m, N, Pa.

Rigid modes ([Man2006, sec. 4.3.5]: "rigid body motions are precluded by applying appropriate essential
boundary conditions"; sec. 4.3.2-4.3.3 pins per yarn one translation and the rotation about its own
axis). Each yarn is its own body, so every rigid mode that its periodicity leaves free must be
removed. Here they are removed at points where the weave's symmetry makes the pinned component of
the exact fluctuation vanish, so the pins carry no reaction at the symmetric solution and can stay
for the whole load path (no release when contact takes over):
  * crossing point of the centreline (s = 0, on the vertical C2 axis of the crossing, which maps
    u*(x, y, z) to (-u*_x, -u*_y, u*_z) and is a symmetry of every in-plane Phi): u*_x = u*_y = 0;
  * full cell only (its yarn ends repeat by pure translation, so a yarn can also translate along z
    and rotate about its axis): the top or bottom point of the same section (also on the C2 axis),
    transverse in-plane component = 0 (rotation about the yarn axis), and the centreline point at
    the inflection s = p/2, u*_z = 0 (the glide symmetry (x + p, y, -z) with u*_z -> -u*_z combined
    with the C2 axis makes u*_z vanish there).
In the quarter cell the anti-symmetric repetition (half-period shift with z -> -z and u*_z flipped)
already excludes the z translation and all rotations of each yarn.
The residual at the pins (`pin_reactions`) is reported as a check that they carry no load.

End faces (`end_faces`): "periodic" (default) couples all three components of u* across each
yarn's end faces (quarter cell: the exact anti-symmetric repetition, u*_z flipped). "uz_fixed" is
the thesis' choice (sec. 4.3.5.3: "In both unit cell models, the local vertical displacements on the
end faces of a yarn are restricted"): u*_x, u*_y stay periodic and u*_z = 0 on both end faces (the
vertical displacement is u*_z, since Phi_3a = 0 for the in-plane loads). On the quarter cell this
over-restricts the cross-section at the yarn inflection, which the full cell leaves free to move
vertically ("the quarter model is over-restricted compared to the full model and thus exhibits
stiffer responses"). On the full cell it also removes the z translation, so the pin u*_z = 0 at
s = p/2 is dropped there (that section is free in the thesis' full model).

Materials: the yarns follow the Neo-Hookean + Bonet-Burton law (eqs. 4.66-4.68, forms.yarn) with
the axis A = the centreline tangent (UnitCellMesh.yarn_axis, DG0).

Crushed elements: the contact
pressure at the crossing is smooth over the patch (31 nodes, 0.25-1.3 GPa, mean 0.73 GPa ~ 0.55 E_T
at E11 = 0.105) and flattens the transversely soft yarns; the outer ring of hexahedra of the lower
yarn at the crossing takes the crush (min det F at the Gauss points 0.97, 0.77, 0.60, 0.45, 0.33,
0.23 for E11 = 0.02 ... 0.127). The material stays strongly elliptic there (acoustic tensor >= 0.19
GPa), but the discrete tangent of those elements turns indefinite (softest eigenvalue -6.6e3 N/m
against 1.2e7 N/m), so a full Newton correction is as large as the elements (87 um) and inverts
them (det F < 0 at a Gauss point). The energy uses J = sqrt(det C), blind to the sign of det F, so
an inverted state is not rejected by the energy itself. Hence (1) every Newton update is
backtracked until the smallest det F over the Gauss points stays above half its value at the start
of the iteration (ADMISSIBLE_DET_RATIO: no element inverts or is suddenly crushed), before the usual
residual-decrease test (the predicate `crush_guard` of
fabricfem.solvers.mpc_newton.backtrack), and (2) a load increment that still fails is cut in halves (at most
MAX_CUTS times) and grown back by doubling after each converged sub-increment (`_increment`). The
smallest det F of every converged step is reported (ContactUnitCellStep.min_det_F), and a run that
cannot proceed stops with a SolverError naming the load step, Phi and the most crushed element (the
furthest converged sub-increment is kept as a step). Measured with these changes: the TI biaxial
path goes on to E11 = 0.142 (Phi = 1.133; before: 0.138 periodic, 0.133 with u_z = 0 ends), det F
min = 0.17, and there stops because Newton and the Uzawa updates cycle on stick/slip switches at
~2e-5 of the force scale (above rtol) with a crushed coarse ring layer: a limit of this mesh and
contact discretisation, not of the inversion any more (uniaxial, shear and compression reach their
full paths with the same S as before).

Newton at the crossing: (1) the iterates did not cycle on stick/slip but on the MASTER FACET of 7 slave
nodes pressed 13-19 um into the lower yarn at its vertices (foot point weight 1 on one vertex, or on
an edge next to it): the closest facet changes at every iterate, and from inside the polyhedral
surface the closest point even jumps (one node: between two edges 2.6 um apart, normal turning by
2.3 %); |R| stalls at 1e-3 of the force scale. Remedy: the active-set strategy on the facets
(`active_set`, fabricfem.contact.yarn.solve_with_fixed_sets): fixed facet and triangle plane per
Newton solve, updated from the converged state with a tie tolerance, then a polishing solve on the
unfixed law. (2) With the facets fixed, Newton converged quadratically in most solves, but some
solves then stalled with every backtracking step rejected: the closed-form friction tangent omitted
the rotation of the tangent plane P(n) (a relative error ~ mu); the friction part of the tangent is
now by finite differences too (ContactParameters.consistent_tangent). (3) The remaining failures are
solves whose Newton correction (|du| = 52 um against 87 um elements) is linear only for s < 0.1 of
it: the crushed elements' near-singular tangent. The MPC Newton solver then retries the update with
the shifted matrix J + alpha mean|diag J| I (`damping`, Levenberg-Marquardt style; the residual and
the tolerance are unchanged). Measured with (1)-(3) on the coarse quarter cell, ends u_z = 0: the
path still stops at E11 = 0.1406 (Phi = 1.131875, min det F 0.170): Newton converges, but the [Man2006, Box 7]
augmentations of the next sub-increment stall (penetration 1.2e-6 m and stick slip 1.1e-6 m after 20
Uzawa updates against the tolerance 1.66e-7 m).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Callable

import basix
import dolfinx.fem as fem
import dolfinx_mpc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem.contact.yarn import (
    ContactParameters,
    ContactReport,
    YarnContact,
    solve_with_contact,
    solve_with_fixed_sets,
)
from fabricfem.forms.yarn import yarn_energy
from fabricfem.materials.yarn import YarnMaterial
from fabricfem.meshes.unit_cell import UnitCellMesh
from fabricfem.solvers.newton import SolverError
from fabricfem.weave.homogenize import PeriodicPair, UnitCellProblem, green_lagrange

__all__ = ["ContactUnitCell", "ContactUnitCellStep", "default_contact_parameters", "symmetry_pins",
           "DEFAULT_VOLUME_FRACTION", "DEFAULT_FRICTION", "DeformationCheck", "MAX_CUTS"]

DEFAULT_VOLUME_FRACTION = 0.4  # phi of eq. 4.65 [Man2006, sec. 4.3.5]
END_FACES = ("periodic", "uz_fixed")
DEFAULT_FRICTION = 0.2  # Coulomb coefficient yarn on yarn (assumed; the thesis does not give one for ch. 4)
MAX_CUTS = 5  # a failed load increment is halved at most this many times (smallest sub-increment 1/32)
PRESSURE_RATIO = 1.0  # eps_N h / p_max kept above this (ContactUnitCell._adapt_penalty)
# A Newton update may shrink the smallest det F over the Gauss points to no less than this fraction of
# its value at the start of the iteration: beyond that the linearisation is not trusted (measured at
# E11 = 0.14: the full correction takes the crushed elements from det F = 0.156 to -0.03, 1/32 of it
# leaves 0.156)
ADMISSIBLE_DET_RATIO = 0.5


@dataclass
class ContactUnitCellStep:
    """One converged load step: Phi, E (eq. 4.59) dimensionless, S and P (eq. 4.64) in Pa, contact report
    (None without contact), wall time [s] and the part spent in the contact search/evaluation [s]."""

    Phi: np.ndarray
    E: np.ndarray
    S: np.ndarray
    P: np.ndarray
    newton_iterations: list[int]
    contact: ContactReport | None
    wall_s: float
    contact_s: float
    pin_reaction: float  # largest |residual| at a pin over the force scale (0 = the pin carries no load)
    min_det_F: float = 1.0  # smallest det F over all Gauss points at the converged state (volume ratio)
    sub_increments: int = 1  # converged sub-increments the step took (1 = no cut)

    @property
    def augmentations(self) -> int:
        return 0 if self.contact is None else self.contact.augmentations


def symmetry_pins(cell: UnitCellMesh, end_faces: str = "periodic") -> list[tuple[np.ndarray, tuple[int, ...]]]:
    """Pins (point [m], components) removing each yarn's free rigid modes at symmetry points (module
    docstring; with end_faces = "uz_fixed" the full cell needs no u*_z pin); all points are mesh
    vertices of the O-grid sweep (section centre and the rim points on the principal normal exist
    for every MeshResolution; stations s = 0 and s = p/2 are mesh stations when `along` is even)."""
    if cell.resolution.along % 2:
        raise ValueError(f"cell.resolution.along must be even (a mesh station at the yarn inflection s = p/2), "
                         f"got {cell.resolution.along}")
    pins = []
    for y in cell.yarns:
        centre = y.centre(np.array(0.0))
        pins.append((centre, (0, 1)))
        if cell.option == "full":
            b = y.family.semi_height
            normal = y.normal(np.array(0.0))
            outer = max((centre + b * normal, centre - b * normal), key=lambda p: abs(p[2]))  # away from contact
            pins.append((outer, (1 - y.axis,)))
            if end_faces == "periodic":
                pins.append((y.centre(np.array(0.5 * y.family.half_period)), (2,)))
    return pins


def default_contact_parameters(material: YarnMaterial, cell: UnitCellMesh, penalty_factor: float = 1.0,
                               friction: float = DEFAULT_FRICTION, tolerance_factor: float = 1e-3,
                               max_augmentations: int = 20, smoothing_factor: float = 1.0) -> ContactParameters:
    """eps_N = penalty_factor x E_T / h (E_T transverse Young's modulus of the yarn [Pa], h the
    circumferential facet size of the section [m]); augmentations until the penetration is below
    tolerance_factor x the smaller yarn semi-height (the brief's 1e-3 of the yarn radius); the pressure
    bracket is rounded over smoothing_factor x that tolerance (ContactParameters.smoothing)."""
    E_T = material.engineering_constants().E_T
    families = (cell.weave.warp, cell.weave.weft)
    # ellipse perimeter ~ pi (a + b) over the polygon_vertices facets of the section
    h = min(np.pi * (f.semi_width + f.semi_height) / cell.resolution.polygon_vertices for f in families)
    b = min(f.semi_height for f in families)
    return ContactParameters(penalty=penalty_factor * E_T / h, friction=friction,
                             tolerance=tolerance_factor * b, max_augmentations=max_augmentations,
                             smoothing=smoothing_factor * tolerance_factor * b, consistent_tangent=True)


class _TimedContact:
    """YarnContact wrapper accumulating the wall time of its residual/Jacobian evaluations (search,
    projection, return map, assembly into PETSc)."""

    def __init__(self, contact: YarnContact):
        self.contact = contact
        self.elapsed = 0.0

    def add_residual(self, x, b) -> None:
        t0 = time.perf_counter()
        self.contact.add_residual(x, b)
        self.elapsed += time.perf_counter() - t0

    def add_jacobian(self, x, A) -> None:
        t0 = time.perf_counter()
        self.contact.add_jacobian(x, A)
        self.elapsed += time.perf_counter() - t0


class DeformationCheck:
    """det F = det(Phi + grad u*) at the Gauss points of the residual's quadrature rule (one
    fem.Expression, evaluated on the owned cells; reduced over all ranks).

    Parameters:
        problem: UnitCellProblem (its Phi constant, fluctuation u and mesh)
        degree: quadrature degree of the residual (2 for trilinear hexahedra)
    """

    def __init__(self, problem: UnitCellProblem, degree: int = 2):
        mesh = problem.mesh
        cell_type = basix.cell.string_to_type(mesh.topology.cell_name())
        points, _ = basix.make_quadrature(cell_type, degree)
        self._det = fem.Expression(ufl.det(problem.Phi + ufl.grad(problem.u)), points)
        self.cells = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
        centre = basix.geometry(cell_type).mean(axis=0)[None, :]
        self.centres = fem.Expression(ufl.SpatialCoordinate(mesh), centre).eval(self.cells).reshape(-1, 3)
        self.comm = mesh.comm

    def local(self) -> np.ndarray:
        """det F (owned cells, Gauss points) on this rank."""
        if len(self.cells) == 0:
            return np.ones((0, 1))
        return self._det.eval(self.cells).reshape(len(self.cells), -1)

    def minimum(self) -> float:
        """Smallest det F over all Gauss points of the cell (all ranks; NaN counts as inverted: -inf)."""
        det = self.local()
        value = float(np.nanmin(det, initial=np.inf)) if not np.any(np.isnan(det)) else -np.inf
        return self.comm.allreduce(value, op=MPI.MIN)

    def worst(self) -> tuple[float, np.ndarray]:
        """(smallest det F, reference centre [m] of the element holding it), same on every rank."""
        det = self.local().min(axis=1, initial=np.inf) if len(self.cells) else np.zeros(0)
        k = int(np.argmin(det)) if len(det) else -1
        mine = (float(det[k]), *self.centres[k].tolist()) if k >= 0 else (np.inf, 0.0, 0.0, 0.0)
        best = min(self.comm.allgather(mine))
        return best[0], np.array(best[1:])


def crush_guard(check: DeformationCheck) -> Callable[[], bool]:
    """The line-search predicate of the unit cell (fabricfem.solvers.mpc_newton.backtrack, built at the start
    of each Newton update): the smallest det F over the Gauss points stays above ADMISSIBLE_DET_RATIO x its
    value at the start of the iteration (no inverted, no suddenly crushed element)."""
    floor = ADMISSIBLE_DET_RATIO * max(check.minimum(), 0.0)
    return lambda: check.minimum() > floor


class ContactUnitCell:
    """Periodic woven unit cell of Bonet-Burton yarns with (optional) yarn-yarn frictional contact.

    Parameters:
        cell: UnitCellMesh (meshes.unit_cell.unit_cell), quarter or full, any resolution with even `along`
        material: YarnMaterial (all yarns), e.g. materials_yarn.THESIS_TRANSVERSELY_ISOTROPIC
        contact: ContactParameters, True (default_contact_parameters) or None/False (no contact: the
            yarns pass through each other)
        volume_fraction: phi of eq. 4.65 in (0, 1] (thesis: 0.4)
        rtol: Newton residual tolerance relative to the step's force scale (the norm of the unbalanced
            nodal forces of the step's initial state, tens of N here). Contact on faceted surfaces makes
            the residual only piecewise smooth (active set, foot points changing facets): measured on the
            TI quarter cell, Newton cycles at 2e-6 to 5e-5 of the force scale (1e-6 to 1e-5 of the total
            contact force) beyond E11 = 0.06, so 1e-5 is the tightest tolerance that it reaches; the
            homogenized S is then converged to ~1e-5 relative
        max_it: Newton iterations per solve
        two_pass: contact pairs in both directions (warp nodes on weft facets and weft nodes on warp
            facets): keeps the warp/weft symmetry of a balanced weave and catches the master nodes that
            a one-pass search lets through ([Man2006, Fig. 31]'s undetected penetrations). Off by default:
            with the augmented Lagrangian it over-constrains faceted surfaces (both node sets cannot
            reach zero gap on the other's chords; measured: the Uzawa updates stall at a fixed
            penetration of ~1e-2 of the facet sag)
        end_faces: "periodic" (exact periodicity of u*) or "uz_fixed" ([Man2006, sec. 4.3.5.3]: u*_z = 0 on
            every yarn end face, u*_x, u*_y periodic); see the module docstring
        active_set: Newton solves with the master facets fixed and updated between solves
            (fabricfem.contact.yarn.solve_with_fixed_sets; module docstring);
            False = the closest facet at every evaluation
    """

    def __init__(self, cell: UnitCellMesh, material: YarnMaterial, contact: ContactParameters | bool | None = True,
                 volume_fraction: float = DEFAULT_VOLUME_FRACTION, rtol: float = 1e-5, max_it: int = 25,
                 two_pass: bool = False, end_faces: str = "periodic", active_set: bool = True):
        if not isinstance(cell, UnitCellMesh):
            raise ValueError(f"cell must be a UnitCellMesh, got {type(cell).__name__}")
        if not isinstance(material, YarnMaterial):
            raise ValueError(f"material must be a YarnMaterial, got {type(material).__name__}")
        if not (np.isfinite(volume_fraction) and 0.0 < volume_fraction <= 1.0):
            raise ValueError(f"volume_fraction must lie in (0, 1], got {volume_fraction!r}")
        if end_faces not in END_FACES:
            raise ValueError(f"end_faces must be one of {END_FACES}, got {end_faces!r}")
        self.end_faces = end_faces
        self.active_set = bool(active_set)
        self.cell, self.material, self.comm = cell, material, cell.mesh.comm
        A = cell.yarn_axis

        def psi(C):
            return yarn_energy(C, A, material)  # eqs. 4.66-4.68
        coupled = (0, 1, 2) if end_faces == "periodic" else (0, 1)
        pairs = [PeriodicPair(slave=cell.tag(f"{y.name}_end"), master=cell.tag(f"{y.name}_start"),
                              relation=cell.periodic_relation(y.name),
                              component_scale=(1.0, 1.0, -1.0) if cell.option == "quarter" else (1.0, 1.0, 1.0),
                              components=coupled)
                 for y in cell.yarns]
        fixed = None if end_faces == "periodic" else [
            (cell.tag(f"{y.name}_{side}"), (2,)) for y in cell.yarns for side in ("start", "end")]
        self.problem = UnitCellProblem(cell.mesh, psi, pairs,  # one material: one integral, one JIT form
                                       facet_tags=cell.facet_tags, cell_tags=cell.cell_tags,
                                       volume_fraction=volume_fraction, rtol=rtol, max_it=max_it,
                                       pins=symmetry_pins(cell, end_faces), fixed_facets=fixed)
        newton = self.problem.newton
        newton.line_search = True
        newton.damping = True  # shifted-matrix fallback where the line search fails (crushed elements)
        self.deformation = DeformationCheck(self.problem)
        newton.admissible_step = lambda: crush_guard(self.deformation)
        self.contact: YarnContact | None = None
        self._timed: _TimedContact | None = None
        if contact is True:
            contact = default_contact_parameters(material, cell)
        if contact:
            if not isinstance(contact, ContactParameters):
                raise ValueError("contact must be ContactParameters, True or None")
            warps = [y.name for y in cell.yarns if y.axis == 0]
            wefts = [y.name for y in cell.yarns if y.axis == 1]
            pairs_c = [(cell.tag(f"{w}_surface"), cell.tag(f"{f}_surface")) for w in warps for f in wefts]
            if two_pass:  # weft nodes against warp facets too: no master node can poke through a slave facet
                pairs_c += [(m, s) for s, m in pairs_c]
            self.contact = YarnContact(self.problem.u, cell.facet_tags, pairs_c, contact,
                                       constrained_dofs=newton.constrained_dofs())
            self._timed = _TimedContact(self.contact)
            self._base_penalty = contact.penalty
            self._base_tangential = contact.tangential_penalty
            newton.contact = self._timed
        self.Phi = np.eye(3)
        self.steps: list[ContactUnitCellStep] = []

    @property
    def ndofs(self) -> int:
        return self.problem.ndofs

    def pin_reactions(self, force_scale: float) -> float:
        """Largest |nodal force| [N] that the pins have to supply at the current state (the MPC-condensed
        residual, contact included, at the pinned dofs), over force_scale [N]: ~0 when the symmetry
        argument of the module docstring holds (the pins then only remove the rigid modes)."""
        newton = self.problem.newton
        b = newton.b
        with b.localForm() as b_local:
            b_local.set(0.0)
        dolfinx_mpc.assemble_vector(newton.L, newton.mpc, b=b)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self._timed is not None:
            self.contact.add_residual(newton.u.vector, b)
        owned = newton.mpc.function_space.dofmap.index_map.size_local * 3
        local = 0.0
        for bc in self.problem.pin_bcs:  # not the end-face conditions, which carry load by design
            dofs = bc.dof_indices()[0]
            dofs = dofs[dofs < owned]
            if len(dofs):
                local = max(local, float(np.abs(b.array_r[dofs]).max()))
        return self.comm.allreduce(local, op=MPI.MAX) / force_scale

    def _adapt_penalty(self, boost: float = 1.0) -> None:
        """eps_N = max(eps_N0, PRESSURE_RATIO x p_max / h) x boost (p_max: largest multiplier or pressure
        so far [Pa], h: median master facet edge [m]). The tangent of YarnContact omits the rotation of
        the master facets (a geometric stiffness ~ A p / h per node against the penalty stiffness
        A eps_N); keeping eps_N h / p_max >= PRESSURE_RATIO keeps that omission a small part of the
        tangent, so Newton converges fast (measured: with eps_N h / p ~ 1 the residual decays only
        linearly at a rate ~0.7). Changing eps_N between augmentations is allowed in [Man2006, Box 7] (the
        multipliers, not eps_N, carry the converged pressure)."""
        c = self.contact
        p_max = float(np.max(c.lam_N, initial=0.0))
        if c.state is not None:
            p_max = max(p_max, float(np.max(c.state["pressure"], initial=0.0)))
        penalty = max(self._base_penalty, PRESSURE_RATIO * p_max / c.margin) * boost
        c.params = dataclasses.replace(c.params, penalty=penalty,
                                       tangential_penalty=None if self._base_tangential is None else
                                       self._base_tangential * penalty / self._base_penalty)

    def _contact_step(self, force_scale: float, n: int, Phi_n: np.ndarray) -> ContactReport:
        """[Man2006, Box 7] loop of one load step (Newton with fixed multipliers, Uzawa updates) with the adapted
        penalty; the state is restored on failure so that the caller can cut the increment."""
        c, newton, problem = self.contact, self.problem.newton, self.problem
        saved = (problem.u.x.array.copy(), c.lam_N.copy(), c.lam_T.copy(), c.ref_quad.copy(), c.ref_weights.copy())
        self._adapt_penalty()
        try:
            def solve_newton():
                return newton.solve(force_scale, problem.length_scale)
            if self.active_set:  # fixed facet / friction sets per solve, updated until the true law holds
                def accept() -> bool:
                    return newton.assemble_residual().norm() <= newton.rtol * force_scale
                return solve_with_contact(lambda: solve_with_fixed_sets(solve_newton, c, accept), c, n)
            return solve_with_contact(solve_newton, c, n)
        except SolverError:
            problem.u.x.array[:] = saved[0]
            c.lam_N, c.lam_T, c.ref_quad, c.ref_weights = (a.copy() for a in saved[1:])
            c.state = None
            raise

    def _sub_increment(self, Phi_b: np.ndarray, n: int) -> tuple[ContactReport | None, list[int]]:
        """Solve at Phi_b from the converged state (self.Phi); SolverError on failure with the state
        restored (u*, multipliers and contact references), or if an element ends inverted."""
        problem, newton = self.problem, self.problem.newton
        problem.Phi.value[:] = Phi_b
        force_scale = problem.force_scale()
        self.last_force_scale = force_scale
        saved_u = problem.u.x.array.copy()
        c = self.contact
        saved_contact = None if c is None else (c.lam_N.copy(), c.lam_T.copy(), c.ref_quad.copy(),
                                                c.ref_weights.copy())
        if self.contact is None:
            result = newton.solve(force_scale, problem.length_scale)
            if not result.converged:
                problem.u.x.array[:] = saved_u
                raise SolverError(f"unit cell: Newton {result.reason} after {result.iterations} iterations",
                                  reason=result.reason)
            report, iterations = None, [result.iterations]
        else:
            self.contact.Phi = Phi_b
            report = self._contact_step(force_scale, n, Phi_b)
            iterations = list(report.newton_iterations)
        det_min = self.deformation.minimum()
        if not det_min > 0.0:  # converged onto an inverted element: not a physical state (J = sqrt(det C))
            problem.u.x.array[:] = saved_u
            if c is not None:  # solve_with_contact committed: take the references and multipliers back
                c.lam_N, c.lam_T, c.ref_quad, c.ref_weights = saved_contact
                c.state = None
            raise SolverError(f"unit cell: an element is inverted (det F = {det_min:.3g}) at a converged state",
                              reason="INVERTED_ELEMENT")
        return report, iterations

    def _increment(self, Phi_n: np.ndarray, n: int) -> tuple[ContactReport | None, list[int], int]:
        """Reach Phi_n from self.Phi in adaptive sub-increments: a failed one is halved (at most
        MAX_CUTS times below the whole increment), a converged one is followed by one twice as long
        (up to the rest of the increment). Returns the merged report (summed augmentations, all Newton
        iteration counts, the last sub-increment's forces), the iteration counts and the number of
        converged sub-increments. SolverError naming step n, Phi and the most crushed element if the
        smallest sub-increment fails."""
        start = self.Phi.copy()
        reached, length = 0.0, 1.0
        smallest = 0.5 ** MAX_CUTS
        iterations: list[int] = []
        augmentations, growths, report, parts = 0, 0, None, 0
        while reached < 1.0:
            target = min(1.0, reached + length)
            Phi_b = start + target * (Phi_n - start)
            try:
                report, its = self._sub_increment(Phi_b, n)
            except SolverError as exc:
                self.problem.Phi.value[:] = self.Phi  # back to the converged state (u* restored already)
                if self.contact is not None:
                    self.contact.Phi = self.Phi
                if length <= smallest * (1.0 + 1e-12):
                    det_min, where = self.deformation.worst()
                    raise SolverError(
                        f"{str(exc).split(';')[0]} at Phi = {np.round(Phi_b, 6).tolist()} (load step {n}) after "
                        f"{MAX_CUTS} cuts of the increment (last converged Phi = {np.round(self.Phi, 6).tolist()}; "
                        f"smallest det F there {det_min:.3g} in the element at X = "
                        f"{np.round(where * 1e3, 4).tolist()} mm)", reason=exc.reason) from None
                length *= 0.5
                continue
            iterations += its
            if report is not None:
                augmentations += report.augmentations
                growths += report.penalty_growths
                report.augmentations, report.penalty_growths = augmentations, growths
                report.newton_iterations = list(iterations)
            self._partial = (report, list(iterations), parts + 1)
            self._converged_force_scale = self.last_force_scale
            self.Phi = Phi_b.copy()
            self._u_converged = self.problem.u.x.array.copy()  # read by study_unit_cell.run_case on a stop
            reached, parts = target, parts + 1
            length = min(2.0 * length, 1.0)
        return report, iterations, parts

    def solve(self, Phi, steps: int = 1) -> list[ContactUnitCellStep]:
        """Go from the current Phi to `Phi` in `steps` equal increments (Phi_n = Phi_0 + n/steps (Phi -
        Phi_0)); one ContactUnitCellStep per step (also appended to self.steps). A failed increment
        is cut adaptively (`_increment`, at most MAX_CUTS halvings); SolverError (with the load step,
        the last converged Phi and the most crushed element in the message) if it still fails; the
        furthest converged sub-increment of that step is then kept as the last entry of self.steps (its
        Phi short of the step's target)."""
        Phi = np.asarray(Phi, dtype=float)
        if Phi.shape != (3, 3) or not np.all(np.isfinite(Phi)):
            raise ValueError(f"Phi must be a finite 3 x 3 matrix, got {Phi!r}")
        if isinstance(steps, bool) or int(steps) != steps or steps < 1:
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        Phi0 = self.Phi.copy()
        out = []
        problem = self.problem
        for n in range(1, int(steps) + 1):
            Phi_n = Phi0 + (n / steps) * (Phi - Phi0)
            if np.linalg.det(Phi_n) <= 0:
                raise ValueError(f"Phi: the path reaches det(Phi) <= 0 at step {n}")
            t0 = time.perf_counter()
            c0 = 0.0 if self._timed is None else self._timed.elapsed
            self._u_converged = problem.u.x.array.copy()
            self._partial = None
            try:
                report, iterations, parts = self._increment(Phi_n, n)
            except SolverError:
                if self._partial is not None:  # keep the furthest converged sub-increment as a step
                    self._record(*self._partial, t0, c0)
                raise
            self._record(report, iterations, parts, t0, c0)
            out.append(self.steps[-1])
        return out

    def _record(self, report: ContactReport | None, iterations: list[int], parts: int, t0: float,
                c0: float) -> None:
        """Append the converged state at self.Phi as a ContactUnitCellStep (wall time since t0 [s],
        contact time since the contact timer read c0 [s])."""
        problem = self.problem
        Phi_n = self.Phi.copy()
        force_scale = self._converged_force_scale
        S, P = problem.homogenized_stress()
        if not (np.all(np.isfinite(S)) and np.all(np.isfinite(P))):
            raise SolverError(f"unit cell: non-finite homogenized stress at Phi = {Phi_n.tolist()}")
        reaction = self.pin_reactions(force_scale)
        wall = time.perf_counter() - t0
        c_s = 0.0 if self._timed is None else self._timed.elapsed - c0
        self.steps.append(ContactUnitCellStep(Phi_n, green_lagrange(Phi_n), S, P, iterations, report, wall, c_s,
                                              reaction, self.deformation.minimum(), parts))


def contact_table(steps: list[ContactUnitCellStep]) -> str:
    """Per-step report: E11, E22, E12, S11, S22, S12 [Pa], Newton iterations, augmentations (+ penalty growths
    of solve_with_contact, if any), final penetration [m], normal and tangential contact force [N], active / slipping nodes, smallest det F,
    converged sub-increments and wall time [s] of the step."""
    lines = [f"{'step':>4} {'E11':>8} {'E22':>8} {'E12':>8} {'S11 [Pa]':>11} {'S22 [Pa]':>11} {'S12 [Pa]':>11} "
             f"{'Newton':>12} {'aug':>3} {'penetr. [m]':>11} {'F_N [N]':>10} {'F_T [N]':>10} {'act/slip':>9} "
             f"{'detF min':>8} {'sub':>3} {'wall [s]':>8}"]
    for k, s in enumerate(steps, start=1):
        c = s.contact
        its = ",".join(map(str, s.newton_iterations))
        if c is None:
            tail = f"{'-':>3} {'-':>11} {'-':>10} {'-':>10} {'-':>9}"
        else:
            aug = f"{c.augmentations}" + (f"+{c.penalty_growths}g" if c.penalty_growths else "")
            tail = (f"{aug:>3} {c.max_penetration:>11.3e} {c.normal_force:>10.3e} "
                    f"{c.tangential_force:>10.3e} {f'{c.active}/{c.slipping}':>9}")
        lines.append(f"{k:>4d} {s.E[0, 0]:>8.4f} {s.E[1, 1]:>8.4f} {s.E[0, 1]:>8.4f} {s.S[0, 0]:>11.4e} "
                     f"{s.S[1, 1]:>11.4e} {s.S[0, 1]:>11.4e} {its[:12]:>12} " + tail
                     + f" {s.min_det_F:>8.3f} {s.sub_increments:>3d} {s.wall_s:>8.1f}")
    return "\n".join(lines)
