"""The cloth's kinetic energy relative to its wearer: the energy of the garment's own motion, which the verdict's
kinetic / strain energy check asks about (a garment that moves with a walking body carries that body's kinetic
energy, which says nothing about the garment flapping).

    K_rel = 1/2 sum_i m_i |v_i - v_b(x_i)|^2,   v_b(x) = v_k + omega_k x (x - c_k)

over the cloth's translational dofs (lumped masses m_i [kg], velocities v_i [m/s] at positions x_i [m]), with
v_b the rigid velocity of the body segment k nearest to the node (smallest normalised radius; centre c_k [m],
velocity v_k [m/s], angular velocity omega_k [rad/s], fabricfem.body.pose.Body.velocities). J.
"""
from __future__ import annotations

import math

import numpy as np

from fabricfem.contact.projection import normalised_radii


def body_relative_energy(mass: np.ndarray, velocity: np.ndarray, position: np.ndarray, centre: np.ndarray,
                         linear: np.ndarray, angular: np.ndarray, nearest: np.ndarray) -> float:
    """K_rel [J] (module docstring) of nodes with masses `mass` (n, 3) [kg], velocities and positions (n, 3),
    the segments' centres, velocities and angular velocities (K, 3) and each node's nearest segment (n,)."""
    body = linear[nearest] + np.cross(angular[nearest], position - centre[nearest])
    return 0.5 * float(np.sum(mass * (velocity - body) ** 2))


def relative_kinetic_energy(integrator, contact, t: float) -> float:
    """K_rel [J] of the garment of an explicit run at time t [s], summed over the ranks: the integrator's lumped
    mass and velocity, the contact's cloth nodes and posed body, whose velocities are taken at t clamped to its
    motion's time range (nan without a lumped mass)."""
    diagonal = getattr(integrator.ops, "mass_diag", None)
    if diagonal is None:
        return math.nan
    rows = contact.dofs
    position = contact.reference + integrator.d.getArray(readonly=True)[rows]
    ellipsoids = contact.body_at(t)
    start, end = contact.body.kinematics.time_range
    velocities = contact.body.velocities(min(max(t, start), end))     # a last record may lie past the motion's end
    names = list(contact.body.segments)
    local = 0.0
    if len(rows):
        nearest = np.argmin(normalised_radii(position, ellipsoids), axis=0)
        local = body_relative_energy(diagonal.getArray(readonly=True)[rows],
                                     integrator.v.getArray(readonly=True)[rows], position,
                                     np.array([e.center for e in ellipsoids]),
                                     np.array([velocities[n][0] for n in names]),
                                     np.array([velocities[n][1] for n in names]), nearest)
    return float(contact.comm.allreduce(local))
