"""Periodic unit-cell homogenization ([Man2006, sec. 4.2.2, 4.3.2]-4.3.3) against closed forms."""
from __future__ import annotations

import dolfinx.mesh as dmesh
import numpy as np
import ufl
from mpi4py import MPI
from scipy.optimize import brentq

from fabricfem.verify import Timer, case, result
from fabricfem.weave.homogenize import UnitCellProblem, box_periodic_pairs

# A non-symmetric macroscopic deformation gradient with det = 1.146 > 0 (stretch, shear and rotation).
PHI_GENERAL = np.array([[1.20, 0.10, -0.05],
                        [0.03, 0.90, 0.08],
                        [0.02, -0.10, 1.10]])
# An in-plane one for the cell with traction-free top and bottom (det of the 2 x 2 block 1.085).
PHI_IN_PLANE = np.array([[1.15, 0.12, 0.0],
                         [-0.05, 0.95, 0.0],
                         [0.0, 0.0, 1.0]])
MU, LAMBDA = 1.2e6, 1.8e6  # Lame constants [Pa] of the homogeneous cell


def neo_hookean(mu: float, lam: float):
    """psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 [J/m^3] (compressible Neo-Hookean)."""
    def psi(C):
        J = ufl.sqrt(ufl.det(C))
        return mu / 2 * (ufl.tr(C) - 3) - mu * ufl.ln(J) + lam / 2 * ufl.ln(J) ** 2
    return psi


def neo_hookean_S(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Closed form S = mu (1 - C^-1) + lambda ln J C^-1 [Pa] of the same energy, C = F^T F."""
    Cinv = np.linalg.inv(F.T @ F)
    return mu * (np.eye(3) - Cinv) + lam * np.log(np.linalg.det(F)) * Cinv


def free_thickness_stretch(Phi_in_plane: np.ndarray, mu: float, lam: float) -> float:
    """Thickness stretch with S_33 = 0: mu (l^2 - 1) + lambda ln(l J_2) = 0 (monotone in l)."""
    J2 = np.linalg.det(Phi_in_plane[:2, :2])
    return brentq(lambda s: mu * (s ** 2 - 1.0) + lam * np.log(s * J2), 1e-3, 1e3, xtol=1e-15, rtol=1e-15)


def box_cell(n: tuple[int, int, int], size: tuple[float, float, float], comm=MPI.COMM_WORLD) -> dmesh.Mesh:
    return dmesh.create_box(comm, [np.zeros(3), np.array(size, dtype=float)], list(n), dmesh.CellType.hexahedron)


@case("homogenize-homogeneous", mpi=True)
def homogenize_homogeneous() -> list:
    """A 3 x 3 x 3 hexahedral cell of one Neo-Hookean material returns its own S(E).

    (a) periodic in x, y and z under the non-symmetric PHI_GENERAL (2 load steps): the fluctuation
    is zero, so S must equal the closed-form S(Phi) to round-off; tolerance 1e-8 relative to |S|.
    (b) periodic in x and y with traction-free top and bottom under the in-plane PHI_IN_PLANE:
    the fluctuation is u* = (l - 1) z e_z (linear, so exact in Q1) with the thickness stretch l
    from S_33 = 0 (scalar root, scipy brentq); S against the closed form S(Phi + (l - 1) e_z e_z)
    within 1e-8 (Newton stops at |R| <= 1e-10 of the boundary-force scale, far below).
    """
    out = []
    psi = neo_hookean(MU, LAMBDA)
    size = (1e-3, 1e-3, 1e-3)
    with Timer() as timer:
        mesh = box_cell((3, 3, 3), size)
        tags, pairs = box_periodic_pairs(mesh, axes=(0, 1, 2))
        problem = UnitCellProblem(mesh, psi, pairs, facet_tags=tags)
        res = problem.solve(PHI_GENERAL, steps=2)
    S_ref = neo_hookean_S(PHI_GENERAL, MU, LAMBDA)
    scale = np.linalg.norm(S_ref)
    out.append(result("homogenize-homogeneous", "(a) |S - S(Phi)| / |S(Phi)|, periodic x y z",
                      np.linalg.norm(res.S - S_ref) / scale, 0.0, 1e-8, res.ndofs, timer.elapsed, scale=1.0))
    out.append(result("homogenize-homogeneous", "(a) S11 [Pa]", res.S[0, 0], S_ref[0, 0], 1e-8, res.ndofs,
                      timer.elapsed, scale=scale))
    out.append(result("homogenize-homogeneous", "(a) S12 [Pa]", res.S[0, 1], S_ref[0, 1], 1e-8, res.ndofs,
                      timer.elapsed, scale=scale))
    out.append(result("homogenize-homogeneous", "(a) E12 = (Phi^T Phi - 1)_12 / 2", res.E[0, 1],
                      0.5 * (PHI_GENERAL.T @ PHI_GENERAL)[0, 1], 1e-14, res.ndofs, timer.elapsed))

    with Timer() as timer:
        mesh = box_cell((3, 3, 3), size)
        tags, pairs = box_periodic_pairs(mesh, axes=(0, 1))
        problem = UnitCellProblem(mesh, psi, pairs, facet_tags=tags)
        res = problem.solve(PHI_IN_PLANE, steps=2)
    stretch = free_thickness_stretch(PHI_IN_PLANE, MU, LAMBDA)
    F = PHI_IN_PLANE.copy()
    F[2, 2] = stretch
    S_ref = neo_hookean_S(F, MU, LAMBDA)
    scale = np.linalg.norm(S_ref)
    out.append(result("homogenize-homogeneous", "(b) |S - S(Phi, l)| / |S|, free top/bottom",
                      np.linalg.norm(res.S - S_ref) / scale, 0.0, 1e-8, res.ndofs, timer.elapsed, scale=1.0))
    out.append(result("homogenize-homogeneous", "(b) S11 [Pa]", res.S[0, 0], S_ref[0, 0], 1e-8, res.ndofs,
                      timer.elapsed, scale=scale))
    out.append(result("homogenize-homogeneous", "(b) S33 [Pa] (traction-free)", res.S[2, 2], 0.0, 1e-8,
                      res.ndofs, timer.elapsed, scale=scale))
    return out


def laminate_problem(f1: float = 0.4, E1: float = 10e9, E2: float = 1e9, n: tuple[int, int, int] = (5, 2, 2),
                     size: tuple[float, float, float] = (2e-3, 1e-3, 1e-3), comm=MPI.COMM_WORLD) -> UnitCellProblem:
    """Two layers stacked along x (material 1 for x < f1 Lx), Neo-Hookean with nu = 0
    (lambda = 0, mu = E / 2), periodic in x, y and z; f1 * n[0] must be an integer so that
    the interface is a mesh plane."""
    if abs(f1 * n[0] - round(f1 * n[0])) > 1e-12:
        raise ValueError(f"f1 = {f1} must be a multiple of 1 / n[0] = {1 / n[0]:g}")
    mesh = box_cell(n, size, comm)
    tags, pairs = box_periodic_pairs(mesh)
    x_interface = f1 * size[0]
    cells = dmesh.locate_entities(mesh, 3, lambda x: x[0] <= x_interface + 1e-9 * size[0])
    ncells = mesh.topology.index_map(3).size_local + mesh.topology.index_map(3).num_ghosts
    values = np.full(ncells, 2, dtype=np.int32)
    values[cells] = 1
    cell_tags = dmesh.meshtags(mesh, 3, np.arange(ncells, dtype=np.int32), values)
    materials = {1: neo_hookean(E1 / 2, 0.0), 2: neo_hookean(E2 / 2, 0.0)}
    return UnitCellProblem(mesh, materials, pairs, facet_tags=tags, cell_tags=cell_tags)


@case("homogenize-laminate", mpi=True)
def homogenize_laminate(f1: float = 0.4, E1: float = 10e9, E2: float = 1e9, strain: float = 1e-6) -> list:
    """Two-layer periodic laminate, nu = 0: effective modulus S / strain along the layers (y) is the
    Voigt average f1 E1 + f2 E2, across them (x) the Reuss average 1 / (f1 / E1 + f2 / E2).

    Tolerance 1e-4 (tighter than the 1% asked): the exact fluctuation is piecewise linear in x with
    the kink on a mesh plane, so Q1 has no discretisation error; the finite-strain law deviates
    from the linear one by O(strain) = 1e-6 relative; Newton stops at 1e-10 of the force scale.
    """
    f2 = 1.0 - f1
    with Timer() as timer:
        problem = laminate_problem(f1, E1, E2)
        along = problem.solve(np.eye(3) + strain * np.diag([0.0, 1.0, 0.0])).S[1, 1] / strain
        problem.u.x.array[:] = 0.0
        across = problem.solve(np.eye(3) + strain * np.diag([1.0, 0.0, 0.0])).S[0, 0] / strain
    voigt = f1 * E1 + f2 * E2
    reuss = 1.0 / (f1 / E1 + f2 / E2)
    return [result("homogenize-laminate", "S_yy / strain along the layers [Pa] (Voigt)", along, voigt, 1e-4,
                   problem.ndofs, timer.elapsed),
            result("homogenize-laminate", "S_xx / strain across the layers [Pa] (Reuss)", across, reuss, 1e-4,
                   problem.ndofs, timer.elapsed)]
