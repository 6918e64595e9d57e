"""Compression garments: putting a garment on by growing the body inside it, and Laplace's law.

Donning (`don`): the garment is meshed at its relaxed size (a tube of radius R0 smaller than the limb,
say); the body segments start with their transverse radii (r2, r3, across the long axis e1 of
fabricfem.body.pose) scaled by `start`, so that they fit inside, and grow to full size in `steps`
quasi-static increments, each solved by the augmented Lagrangian (ContactProblem.solve_augmented) to a
penetration below `tolerance`. With friction the end state depends on this path; frictionless contact
(the default of the scenes here) gives the state that a garment relaxed by wear settles to.

Laplace's law (`laplace_pressure`): a tube of relaxed radius R0 on a cylinder of radius r is stretched
uniformly, lambda_h = r / R0 around, and presses on it with

    p = T / r                                        (Laplace's law for a cylindrical membrane)
    T = t lambda_h S_hh / lambda_a                   (hoop force per unit deformed length [N/m], P = F S)
    S_hh = Q22 E_hh,  E_hh = (lambda_h^2 - 1) / 2    (axial stretch held, lambda_a = 1)
    S_hh = E2 E_hh,   E_aa = -nu21 E_hh              (axial force free, S_aa = 0)

for the orthotropic St. Venant-Kirchhoff fabric with the weft (E2) around the tube (meshes.tube) and the
contact on the mid-surface. Pressures are in Pa (1 mmHg = 133.322 Pa, the unit of compression classes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes._validate import choice, count, positive
from fabricfem.solvers.newton import NewtonSolver, SolverError

PA_PER_MMHG = 133.322387415      # Pa


@dataclass
class LaplaceSolution:
    pressure: float        # p [Pa] on the body
    tension: float         # T [N/m] hoop force per unit deformed axial length
    hoop_stretch: float    # lambda_h
    axial_stretch: float   # lambda_a


def laplace_pressure(fabric: Fabric, relaxed_radius: float, radius: float, axial: str = "held") -> LaplaceSolution:
    """Uniform state of a tube of relaxed radius R0 [m] on a cylinder of radius r [m] (module docstring);
    `axial` = "held" (lambda_a = 1) or "free" (no axial force)."""
    R0 = positive("relaxed_radius", relaxed_radius)
    r = positive("radius", radius)
    choice("axial", axial, ("held", "free"))
    Q = fabric.plane_stress_matrix
    lam_h = r / R0
    E_hh = 0.5 * (lam_h ** 2 - 1.0)
    if axial == "held":
        S_hh, lam_a = Q[1, 1] * E_hh, 1.0
    else:
        S_hh, lam_a = fabric.E2 * E_hh, math.sqrt(1.0 - 2.0 * fabric.nu21 * E_hh)
    T = fabric.thickness * lam_h * S_hh / lam_a
    return LaplaceSolution(pressure=T / r, tension=T, hoop_stretch=lam_h, axial_stretch=lam_a)


def grown(segment: Ellipsoid, factor: float) -> Ellipsoid:
    """The segment with its transverse radii r2, r3 scaled by `factor` (long axis e1 unchanged)."""
    return Ellipsoid(segment.center, segment.rotation, segment.radii * np.array([1.0, factor, factor]))


@dataclass
class DonningStep:
    factor: float              # transverse radius scale of the body
    augmentations: int
    newton_iterations: int
    max_penetration: float     # m


def don(problem: ContactProblem, segments: Sequence[Ellipsoid], start: float, steps: int = 10,
        tolerance: float = 1e-7, solver: NewtonSolver | None = None,
        on_step: Callable[[DonningStep], None] | None = None) -> list[DonningStep]:
    """Grow `segments` from `start` x their transverse radii to full size in `steps` equal increments
    (module docstring). `problem` must use method="augmented". On a failed increment the model is put
    back to the last converged state and SolverError names the growth factors reached and tried."""
    if not (isinstance(start, (int, float)) and 0.0 < start <= 1.0):
        raise ValueError(f"start must lie in (0, 1], got {start!r}")
    steps = count("steps", steps)
    solver = solver or NewtonSolver(problem)
    history: list[DonningStep] = []
    reached = start
    for k in range(1, steps + 1):
        factor = start + (1.0 - start) * k / steps
        last_good = problem.model.w.x.array.copy()
        multipliers = problem.multiplier.copy()
        problem.set_obstacles([grown(e, factor) for e in segments])
        try:
            report = problem.solve_augmented(solver, tolerance=tolerance)
        except SolverError as err:
            problem.model.w.x.array[:] = last_good
            problem.multiplier[:] = multipliers
            problem.set_obstacles([grown(e, reached) for e in segments])
            raise SolverError(f"donning: body grown to {reached:.4g} of its size; the increment to {factor:.4g} "
                              f"failed ({err}); the model holds the state at {reached:.4g}",
                              reason=getattr(err, "reason", "")) from err
        problem.after_converged_step()
        reached = factor
        history.append(DonningStep(factor, report.augmentations, sum(report.newton_iterations),
                                   report.max_penetration))
        if on_step is not None:
            on_step(history[-1])
    return history
