"""Forward-increment Lagrange multiplier contact for explicit time stepping (thesis sec. 3.3.2-3.3.3, Box 5).

In a central-difference step the trial positions x* of the next step are computed without contact. A
node that penetrates a body segment is projected back onto the surface along the gradient of the
segment's implicit function at x* (thesis Box 5: "the gradient at the penetrating trial position is
chosen as the projection direction"), and the correction gives the multiplier:

    d^c = proj(x*) - x*,   a^c = d^c / dt^2,   lambda = -M a^c                             (Box 5, step i)
    a^{n+1} = a* + a^c,    v^{n+1} = v* + dt/2 a^c                                          (Box 5, step j)

so that the next predictor d^{n+2} = d^{n+1} + dt v^{n+1} + dt^2/2 a^{n+1} = proj(x*) lies on the surface.
The functions act on numpy arrays of nodal positions [m], velocities [m/s], accelerations [m/s^2] and
lumped masses [kg] (shape (N,) or (N, 3)), so an explicit shell integrator can call them on its
translational dofs. f_c = M a^c = -lambda [N] is the contact force on the cloth.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.nodal import positive_parameter

MAX_PROJECTION_PASSES = 8
INSIDE_TOLERANCE = 1e-12   # relative to the smallest radius: rounding of a projected point is not "inside"


def _points(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (the explicit step diverged?)")
    return arr


def _masses(masses, n: int) -> np.ndarray:
    m = np.asarray(masses, dtype=float)
    if m.shape == (n,):
        m = np.repeat(m[:, None], 3, axis=1)
    if m.shape != (n, 3) or not np.all(np.isfinite(m)) or np.any(m <= 0.0):
        raise ValueError(f"masses must be positive with shape ({n},) or ({n}, 3), got shape {m.shape}")
    return m


def project_along_gradient(x, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """Move the points inside any ellipsoid onto its surface along grad f at the point (Box 5).

    The ray x + s grad f / |grad f| is intersected with the surface (`Ellipsoid.gap` with one cast);
    a point inside two overlapping segments is projected out of the deeper one first and re-checked
    (at most MAX_PROJECTION_PASSES passes). Returns (projected points (N, 3), moved mask (N,)).
    """
    x = _points("x", x)
    out = x.copy()
    moved = np.zeros(len(x), dtype=bool)
    for _ in range(MAX_PROJECTION_PASSES):
        gaps = np.stack([e.gap(out, ray_casts=1)[0] for e in ellipsoids]) if len(out) else np.zeros((1, 0))
        deepest = np.argmin(gaps, axis=0)
        g = gaps[deepest, np.arange(len(out))]
        scale = np.array([e.radii.min() for e in ellipsoids])[deepest] if len(out) else np.zeros(0)
        inside = g < -INSIDE_TOLERANCE * scale
        if not inside.any():
            return out, moved
        for k, e in enumerate(ellipsoids):  # loop over the few segments, vectorised over the points
            mask = inside & (deepest == k)
            if mask.any():
                direction = e.normal(out[mask])          # grad f / |grad f| at the trial point
                out[mask] = out[mask] - g[mask, None] * direction
        moved |= inside
    raise ValueError("ellipsoids: points remain inside after repeated projections (overlapping segments "
                     "trap them); refine the time step")


@dataclass
class ExplicitContact:
    """Correction of one explicit step (Box 5, step i).

    Attributes:
        position: (N, 3) corrected positions proj(x*) [m].
        correction: (N, 3) d^c [m].
        acceleration: (N, 3) a^c [m/s^2].
        force: (N, 3) contact force on the nodes f_c = M a^c [N].
        multiplier: (N, 3) lambda = -M a^c [N] (thesis sign).
        active: (N,) nodes that were projected.
    """

    position: np.ndarray
    correction: np.ndarray
    acceleration: np.ndarray
    force: np.ndarray
    multiplier: np.ndarray
    active: np.ndarray


def forward_increment_correction(x_trial, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> ExplicitContact:
    """Box 5 step i: project penetrating trial positions and return the multipliers."""
    dt = positive_parameter("dt", dt)
    x_trial = _points("x_trial", x_trial)
    m = _masses(masses, len(x_trial))
    projected, active = project_along_gradient(x_trial, ellipsoids)
    d_c = projected - x_trial
    a_c = d_c / dt ** 2
    force = m * a_c
    return ExplicitContact(projected, d_c, a_c, force, -force, active)


def box5_step(x, v, a, masses, dt: float, acceleration: Callable[[np.ndarray, float], np.ndarray],
              t: float, ellipsoids_at: Callable[[float], Sequence[Ellipsoid]]):
    """One step n -> n+1 of Box 5 for point masses (positions x = X + d).

    Args:
        x, v, a: (N, 3) state at t^n; x must be admissible.
        masses: lumped masses [kg], (N,) or (N, 3).
        dt: time step [s].
        acceleration: a*(x, t) = M^-1 (f_ext(t) - f_int(x)) [m/s^2] without contact.
        t: time t^n [s].
        ellipsoids_at: body segments posed at a given time.

    Returns:
        (x^{n+1}, v^{n+1}, a^{n+1}, ExplicitContact of the step).
    """
    dt = positive_parameter("dt", dt)
    x, v, a = _points("x", x), _points("v", v), _points("a", a)
    v_star = v + 0.5 * dt * a                               # Box 5 f
    x_next = x + dt * v + 0.5 * dt ** 2 * a                 # Box 5 f
    a_star = np.asarray(acceleration(x_next, t + dt), dtype=float)   # Box 5 g
    v_star = v_star + 0.5 * dt * a_star                     # Box 5 h
    x_trial = x_next + dt * v_star + 0.5 * dt ** 2 * a_star  # Box 5 i: trial for n+2
    contact = forward_increment_correction(x_trial, masses, dt, ellipsoids_at(t + 2.0 * dt))
    a_next = a_star + contact.acceleration                  # Box 5 j
    v_next = v_star + 0.5 * dt * contact.acceleration
    return x_next, v_next, a_next, contact


def initial_state(x, v, a_free, masses, dt: float, ellipsoids: Sequence[Ellipsoid]) -> tuple[np.ndarray, np.ndarray]:
    """(v^0, a^0) of Box 5 step 1 for nodes that may start in contact: the first predictor
    x + dt v + dt^2/2 a is corrected as in step j (a^0 = a* + a^c, v^0 = v + dt/2 a^c), so that it lands
    on the surface instead of inside."""
    a_free = _points("a_free", a_free)
    v = _points("v", v)
    trial = _points("x", x) + dt * v + 0.5 * dt ** 2 * a_free
    a_c = forward_increment_correction(trial, masses, dt, ellipsoids).acceleration
    return v + 0.5 * dt * a_c, a_free + a_c
