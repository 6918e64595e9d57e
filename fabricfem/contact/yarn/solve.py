"""The outer loops of yarn contact for one load step: Uzawa augmentation with penalty growth ([Man2006, Box 7]
step 3) around Newton solves (`solve_with_contact`), and the active-set strategy on the master facets
(`solve_with_fixed_sets`), with the step's `ContactReport`. Units: m, N.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from fabricfem.contact.yarn.geometry import triangle_of
from fabricfem.contact.yarn.term import YarnContact
from fabricfem.solvers.newton import NewtonResult, SolverError

__all__ = ["ContactReport", "MAX_SET_UPDATES", "WEIGHT_SLACK", "solve_with_contact", "solve_with_fixed_sets"]


@dataclass
class ContactReport:
    """Contact summary of one load step (forces in N on the slave bodies, lengths in m)."""

    augmentations: int
    max_penetration: float
    max_stick_slip: float
    force: np.ndarray  # total contact force on the slave yarns (3,) [N]
    normal_force: float  # sum of A_s p_s [N]
    tangential_force: float  # |sum of A_s t_T| [N]
    active: int
    slipping: int
    newton_iterations: list[int] = field(default_factory=list)
    dropped_active: int = 0
    penalty_growths: int = 0  # times eps_N, eps_T were raised by penalty_growth in this step (solve_with_contact)


MAX_SET_UPDATES = 20  # updates of the fixed sets in one solve_with_fixed_sets
# a fixed facet is kept only while the foot point on its (extended) triangle plane has all weights >= -this:
# at most 5 % of the facet beyond its edge, so the master forces stay on the facet's own nodes
WEIGHT_SLACK = 0.05


def solve_with_fixed_sets(solve_newton: Callable[[], NewtonResult], contact: YarnContact, accept: Callable[[], bool],
                          max_updates: int = MAX_SET_UPDATES) -> NewtonResult:
    """Newton with an active-set strategy on the master facets (cf. fabricfem.contact.problem).

    On a faceted master surface the closest facet of a slave node switches where its foot point reaches
    a facet edge or vertex: the contact forces are only piecewise smooth there, and from inside the
    master (a penetrated node) the closest-point map is even discontinuous (the medial axis of the
    polyhedral surface runs through its vertices and edges). Measured on the TI unit cell (E11 0.127 ->
    0.145, first augmentation): 7 slave nodes pressed 13-19 um into the master at its vertices change
    facet at every iterate (one foot point jumping between two edges 2.6 um apart, normal turning by
    2.3 %, distance changing by 7e-8 m) and |R| stalls at 1e-3 of the force scale for 25 iterations.

    Rule: each Newton solve keeps every active slave on a fixed facet, projected onto the plane of a
    fixed triangle of it (`YarnContact.freeze`; unclamped, so the law is smooth in u and the
    finite-difference tangent is consistent with it). From the converged state the set is updated and
    the solve repeated until it no longer changes:
      * a node keeps its facet while the foot point on the plane is a closest point within the
        penetration tolerance (distance <= closest distance + contact.params.tolerance, the accuracy to
        which the augmented Lagrangian resolves the gap anyway) and lies on the facet up to WEIGHT_SLACK;
        otherwise, and for a newly active node, the closest facet and its triangle are taken.
    The friction branch is NOT fixed: the Coulomb test |t*| > mu lambda_N is applied at every evaluation
    (fixing it was tried: a node held on the slip branch while |t*| < mu lambda_N keeps a traction of
    full size along t* / |t*| with a tangent ~ 1 / |t*|, and Newton then stalled at 0.2 of the force
    scale on the crossed cylinders of fabricfem.verify.yarn_contact, where the free branch converges).
    A converged state is accepted at once when the residual of the unfixed law passes `accept()`. When
    the set does not change any more, Newton on the unfixed law is tried from there (`solve_newton` with
    the contact unfrozen: it converges in a few iterations where that law is smooth near the solution,
    and then gives the same state on every partition up to round-off, which the tie rule alone does
    not: measured 5e-6 relative in S between 2 ranks and serial); if it fails, the fixed-set state is
    restored and accepted: an equilibrium (|R| below the Newton tolerance) of the law with every foot
    point closest within the tolerance and every node on its Coulomb branch.

    solve_newton() -> NewtonResult; accept() -> bool, called with the contact unfrozen (it must evaluate
    the residual, e.g. |R| <= rtol force_scale). Returns a NewtonResult (iterations summed over the
    solves; reason DIVERGED_ACTIVE_SET if the set still changes after max_updates updates). The contact
    is left unfrozen; contact.set_updates lists the number of slaves whose facet changed at each update,
    contact.accepted_sets = (facet, triangle, why) the set of the accepted state."""
    iterations, norms = 0, []
    contact.set_updates = []
    try:
        contact.freeze()
        for _ in range(max_updates + 1):
            facet, tri = contact.frozen_facet.copy(), contact.frozen_tri.copy()
            result = solve_newton()
            iterations += result.iterations
            norms += list(result.residual_norms)
            if not result.converged:
                return NewtonResult(False, iterations, result.reason, norms)
            fixed = contact.evaluate()  # the fixed-set law at the converged state
            contact.unfreeze()
            free = contact.evaluate()   # closest-point projection
            act = free["active"] | fixed["active"]
            keep = (act & (facet >= 0) & (fixed["dist"] <= free["dist"] + contact.params.tolerance)
                    & (fixed["weights"].min(axis=1) >= -WEIGHT_SLACK))
            new_facet = np.where(keep, facet, np.where(free["active"], free["facet"], -1))
            new_tri = np.where(keep, tri, triangle_of(free["weights"]))
            changed = act & ((new_facet != facet) | ((new_tri != tri) & (new_facet >= 0)))
            if accept():
                contact.accepted_sets = (facet, tri, "unfixed residual")
                return NewtonResult(True, iterations, result.reason, norms)
            if not changed.any():
                # polish: Newton on the unfixed law from here (a few iterations where it is smooth, and the same
                # state on every partition up to round-off); if it fails, the fixed-set equilibrium stands
                saved = contact.u.x.array.copy()
                polish = solve_newton()
                iterations += polish.iterations
                norms += list(polish.residual_norms)
                if polish.converged:
                    contact.accepted_sets = (facet, tri, "unfixed law (polished)")
                    return NewtonResult(True, iterations, polish.reason, norms)
                contact.u.x.array[:] = saved
                contact.accepted_sets = (facet, tri, "set unchanged")
                return NewtonResult(True, iterations, result.reason, norms)
            contact.set_updates.append(int(changed.sum()))
            contact.freeze(new_facet, new_tri)
        return NewtonResult(False, iterations, "DIVERGED_ACTIVE_SET", norms)
    finally:
        contact.unfreeze()


def solve_with_contact(solve_newton: Callable[[], NewtonResult], contact: YarnContact, step: int = 0) -> ContactReport:
    """[Man2006, Box 7] outer loop for one load step: Newton solve with fixed multipliers (`solve_newton()` returns a
    NewtonResult), then Uzawa augmentation until the penetration and stick slip are below the tolerance.
    Raises SolverError if Newton fails or the augmentations do not converge.

    Penalty growth (the method of multipliers with increasing penalty, Bertsekas 1982, sec. 2.2): on a convex
    problem the Uzawa update contracts for any eps_N, but where the tangent is indefinite (the crushed crossing
    of the TI unit cell) the violation can grow at every update (measured: x1.07-1.15 per update for 15
    updates, from 1.1e-7 m to 8.6e-7 m, at E11 = 0.141 of the biaxial path). When max(penetration, stick slip)
    has grown in two successive augmentations, eps_N and eps_T are multiplied by `penalty_growth` before the
    next update ([Man2006, Box 7] allows eps to change between augmentations: the multipliers carry the pressure)."""
    p_ = contact.params
    iterations, violations, growths = [], [], 0
    for k in range(p_.max_augmentations + 1):
        result = solve_newton()
        iterations.append(result.iterations)
        if not result.converged:
            raise SolverError(f"yarn contact: Newton {result.reason} after {result.iterations} iterations in "
                              f"augmentation {k} of load step {step}; residual norms "
                              f"{[f'{r:.3g}' for r in result.residual_norms]}", reason=result.reason)
        pen, slip = contact.violation()
        if not p_.augmented or (pen <= p_.tolerance and slip <= p_.tolerance):
            break
        if k == p_.max_augmentations:
            raise SolverError(f"yarn contact: penetration {pen:.3g} m / stick slip {slip:.3g} m still above the "
                              f"tolerance {p_.tolerance:.3g} m after {k} augmentations at load step {step}",
                              reason="DIVERGED_AUGMENTATION")
        violations.append(max(pen, slip))
        if p_.penalty_growth > 1.0 and len(violations) >= 3 and violations[-1] > violations[-2] > violations[-3]:
            q = contact.params
            contact.params = dataclasses.replace(q, penalty=q.penalty * p_.penalty_growth, tangential_penalty=(
                None if q.tangential_penalty is None else q.tangential_penalty * p_.penalty_growth))
            growths += 1
            violations.clear()
        contact.augment()
    total, fN, fT, active, slipping = contact.totals()
    report = ContactReport(augmentations=k, max_penetration=pen, max_stick_slip=slip, force=total,
                           normal_force=fN, tangential_force=fT, active=active, slipping=slipping,
                           newton_iterations=iterations, dropped_active=contact.dropped_active,
                           penalty_growths=growths)
    contact.commit()
    return report
