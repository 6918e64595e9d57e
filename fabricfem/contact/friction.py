"""Regularised Coulomb friction with return mapping ([Man2006, sec. 3.1.3], eqs. 3.46-3.52).

Each contact node keeps a stick point a_i: a material point of the body segment, stored in the
segment's local frame so that it moves rigidly with the body (for a moving segment this integrates the
surface velocity v = v_c + omega x (x - c) of `Ellipsoid.surface_velocity` exactly). The slip since the
last converged step is the tangential part of x_i - a_i, and the tangential penalty eps_T [Pa/m]
regularises the stick condition (eq. 3.50). For a step n -> n+1:

    trial (stick):  t* = t_n - eps_T P (x_{n+1} - x_n - v_body dt) = -eps_T P (x_{n+1} - a)     (eq. 3.51)
    Phi*  = |t*| - mu p                                                                          (eq. 3.51)
    return map:  t = t*                 if Phi* <= 0  (stick)                                    (eq. 3.52)
                 t = mu p t* / |t*|      otherwise    (slip)

with P = I - n n^T. t is the traction [Pa] of the body on the cloth (it opposes the slip). After a
converged step the stick point is moved to a = x + t / eps_T (the slip part of the increment is
dissipated, eq. 3.50), and reset to the node where the node is out of contact.

Consistent tangent (the derivative of t with respect to the node position at fixed n; the normal's
own derivative is neglected as in the normal law):

    stick:  dt/dx = -eps_T P
    slip:   dt/dx = -(mu p eps_T / |t*|) (P - tau tau^T) + mu tau dp/dx,   tau = t* / |t*|,
            dp/dx = -k_N n^T  (penalty / augmented normal law)

The slip tangent is unsymmetric (non-associative flow, sec. 3.1.3.4); the LU solver handles that.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fabricfem.meshes._validate import non_negative


def friction_coefficient(mu: float) -> float:
    """mu >= 0 or ValueError naming `friction`."""
    return non_negative("friction (Coulomb coefficient mu)", mu)


@dataclass
class FrictionState:
    """Result of the return mapping at N nodes.

    Attributes:
        traction: (N, 3) tangential traction t_T [Pa] on the cloth.
        tangent: (N, 3, 3) dt_T/dx [Pa/m].
        slip: (N,) True where the node slides (Phi* > 0 and in contact).
    """

    traction: np.ndarray
    tangent: np.ndarray
    slip: np.ndarray


def return_map(x: np.ndarray, stick_point: np.ndarray, normal: np.ndarray, pressure: np.ndarray,
               mu: float, tangential_penalty: float, normal_penalty: float,
               active: np.ndarray | None = None, slip: np.ndarray | None = None) -> FrictionState:
    """Coulomb return mapping at N nodes (eqs. 3.51-3.52), vectorised.

    Args:
        x: (N, 3) current node positions [m].
        stick_point: (N, 3) stick points a at the current body pose [m].
        normal: (N, 3) unit outward body normals.
        pressure: (N,) contact pressure p [Pa] (>= 0, or of either sign on a fixed active set).
        mu: Coulomb coefficient.
        tangential_penalty: eps_T [Pa/m].
        normal_penalty: k_N [Pa/m] (for dp/dx in the slip tangent).
        active: (N,) bool nodes in contact (default p > 0). On a fixed active set (ContactProblem's
            active-set strategy) an active node may carry p <= 0 during the iterations; its slip limit is
            then mu <p> = 0 (no friction force, no dp/dx term), so friction never pushes along the slip.
        slip: (N,) bool fixed slip set (ContactProblem's active-set strategy): these active nodes take the
            slip branch t = mu <p> t* / |t*| and the other active nodes the stick branch t = t*, whatever
            Phi*; default (None): the return map's choice Phi* > 0.
    """
    N = len(x)
    eye = np.broadcast_to(np.eye(3), (N, 3, 3))
    P = eye - normal[:, :, None] * normal[:, None, :]
    trial = -tangential_penalty * np.einsum("nij,nj->ni", P, x - stick_point)          # eq. 3.51
    norm = np.linalg.norm(trial, axis=1)
    limit = mu * np.maximum(pressure, 0.0)
    active = (pressure > 0.0) if active is None else np.asarray(active, dtype=bool)
    slip = active & ((norm > limit) if slip is None else np.asarray(slip, dtype=bool))  # Phi* > 0
    safe = np.where(norm > 0.0, norm, 1.0)
    tau = trial / safe[:, None]
    traction = np.where(slip[:, None], limit[:, None] * tau, trial)                     # eq. 3.52
    traction[~active] = 0.0
    tangent = -tangential_penalty * P
    compressed = (pressure > 0.0).astype(float)                                           # dp/dx = 0 where p <= 0
    slip_tangent = (-(limit * tangential_penalty / safe)[:, None, None] * (P - tau[:, :, None] * tau[:, None, :])
                    - (mu * normal_penalty * compressed)[:, None, None] * tau[:, :, None] * normal[:, None, :])
    tangent = np.where(slip[:, None, None], slip_tangent, tangent)
    tangent[~active] = 0.0
    return FrictionState(traction, tangent, slip)


def updated_stick_point(x: np.ndarray, traction: np.ndarray, tangential_penalty: float) -> np.ndarray:
    """Stick point after a converged step: a = x + t_T / eps_T (zero traction: a = x)."""
    return x + traction / tangential_penalty
