"""Critical time step of explicit central differences [Man2006, eqs. 2.86-2.87] and a measured check.

Thesis: dt_crit = 2 / omega_max (eq. 2.86), omega_max ~ 2 c / h (eq. 2.87), c = sqrt(E / rho) the bar-wave
speed, h the element size. That estimate is for linear elements and membrane waves only. For the
quadratic elements of ShellModel with the lumped mass of eq. 2.82 two things change (measured on this
code with dense eigenvalue solves of K vs M_L, see tests/test_dynamics.py and the free-vibration case):

* membrane: omega_m = kappa c / h_min with c = sqrt(E_max / (rho (1 - nu12 nu21))) (plane-stress wave)
  and kappa the largest single-element frequency times h / c: 4.90 for the 1D quadratic bar
  (2 sqrt 6), up to 6.0 for a Q2 square and 7.3 for a P2 right triangle (nu in [0, 0.45]); we use 6.1
  and 7.4 (eq. 2.87 has kappa = 2 for linear elements).
* thickness shear: the rotational inertia rho t^3 / 12 against the shear stiffness k G13 t gives
  omega_s = chi sqrt(12 k G13 / rho) / t, far above omega_m for thin shells (h / t > ~ 5). chi = 1.01 for
  Q2 and 1.1 for P2 + bubble triangles (measured 1.0046 and 1.09 at h / t = 20).

* bending: the rotational inertia against the bending tangent at zero curvature D0 (the largest of D11,
  D22 for the linear law; a0 for Kawabata's M = sum a_i K^i; 2 B0 sqrt(kappa0 / eps) for the regularised
  square-root law of [Peng2022], whose exact tangent is infinite at K = 0) gives
  omega_b = chi_b sqrt(12 D0 / (rho t^3)) / h_min; chi_b = 4.9 for Q2 (measured 4.899-4.920 on 6x6 and
  12x12 bending-dominated cloths, the 1D quadratic-element value 2 sqrt 6 = 4.899) and 5.5 for P2 + bubble
  triangles. For linear laws and thin shells omega_b << omega_s; for the square-root law it sets the step
  ([Peng2022] cloth: 7x above the shear-and-membrane estimate).

omega_max = sqrt(omega_m^2 + omega_s^2 + omega_b^2) (Naghdi; shear and bending stiffness act on the same
rotational inertia) or omega_m (membrane). D0 is the fabric's own bending stiffness: with a bending rigidity
given apart from the thickness (Fabric.bending_rigidity B1, B2) it is B, not E t^3 / 12 (the cloth of
scenes/corner_pinned.toml with B = 0.02 N m: omega_b = 1.2e4 rad/s on 2x2 cells, 4.8e4 on 8x8; the discrete
omega_max at rest is 0.90-0.98 of the estimate on 2x2 ... 8x8). The estimate before meshing
(fabricfem.scenes.build.critical_time_step_estimate) is `element_frequency` with the mesh spec's h_min.

Deformed states: the estimate is that of the reference state. Where a point support carries the sheet (a pinned
corner: displacements held, rotations free) the tangent's rotational stiffness at that node grows with the load it
carries (stress resultants times the second variation of the strains), and so does omega_max: measured (SLEPc, the
corner-pinned cloth with B = 0.02 N m, strain limit 0.01) from 0.90 to 1.26 of the estimate on 4x4 cells and from
0.98 to 1.48 on 8x8 by t = 0.6 s, the top mode being the pinned corner's rotations; the same cloth held along an
edge stays at 0.90-0.91. dt_fraction = 0.9 then blows up (4x4 at 0.27 s, 8x8 at 0.17 s); 0.6 runs to 0.6 s
(corner drop -1.026 / -1.005 m on 4x4 / 8x8). Such scenes need dt_fraction <= 0.6, Newmark, or the safe step of
fabricfem.dynamics.safe_step (CentralDifference step_check_every; on by default in dynamic scenes), which tracks
omega_max of the current state and shortens the step (docs/findings/2026-11-27-safe-step.md).

Rotary-inertia scaling (fabricfem.dynamics.mass, factor s >= 1 on the rotational lumped masses): the
thickness-shear frequency is rotational inertia against shear stiffness, so omega_s -> omega_s / sqrt(s),
and omega_max = sqrt(omega_m^2 + omega_s^2 / s). For s >= (omega_s / omega_m)^2 the membrane limit governs. With Rayleigh damping
xi = a / (2 omega) + b omega / 2 the limit shrinks to dt = 2 / omega (sqrt(1 + xi^2) - xi)
(Belytschko, Liu, Moran, Nonlinear Finite Elements, eq. 6.2.x). `discrete_max_frequency` computes the
true omega_max of the assembled system (power iteration with SLEPc) and `measured_critical_time_step`
finds the largest stable step by bisection.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from dolfinx.cpp.mesh import entities_to_geometry
from mpi4py import MPI

from fabricfem.dynamics import eigen_cache
from fabricfem.dynamics.mass import lumped_mass, rotary_scale

MEMBRANE_KAPPA = {"quadrilateral": 6.1, "triangle": 7.4}
THICKNESS_SHEAR_CHI = {"quadrilateral": 1.01, "triangle": 1.1}
BENDING_CHI = {"quadrilateral": 4.95, "triangle": 5.5}


def plane_stress_wave_speed(fabric) -> float:
    """c = sqrt(E_max / (rho (1 - nu12 nu21))) [m/s] ([Man2006, eq. 2.87] has sqrt(E / rho), the nu = 0 value)."""
    rho = float(fabric.density)
    if not rho > 0:
        raise ValueError(f"the wave speed needs a positive fabric density, got {rho!r} kg/m^3")
    return float(np.sqrt(max(fabric.E1, fabric.E2) / (rho * (1.0 - fabric.nu12 * fabric.nu21))))


def min_edge_length(mesh) -> float:
    """Smallest cell edge length h_min [m] over all ranks (straight edges between the end vertices)."""
    mesh.topology.create_entities(1)
    n_edges = mesh.topology.index_map(1).size_local
    nodes = entities_to_geometry(mesh._mesh, 1, np.arange(n_edges, dtype=np.int32), False)
    x = mesh.geometry.x
    local = float(np.linalg.norm(x[nodes[:, 0]] - x[nodes[:, -1]], axis=1).min(initial=np.inf))
    return mesh.comm.allreduce(local, op=MPI.MIN)


def max_frequency_estimate(model, rotary_inertia_scale: float = 1.0) -> float:
    """omega_max^h [rad/s] from mesh size and material (eq. 2.87 extended, see the module docstring), for
    rotational lumped masses scaled by `rotary_inertia_scale` (>= 1): `element_frequency` of the model's fabric,
    cells and smallest edge."""
    return element_frequency(model.fabric, model.mesh.ufl_cell().cellname(), min_edge_length(model.mesh),
                             model.model, getattr(model, "bending_eps", None), rotary_inertia_scale)


def element_frequency(fabric, cell: str, h_min: float, model: str = "naghdi", bending_eps: float | None = None,
                      rotary_inertia_scale: float = 1.0) -> float:
    """omega_max^h [rad/s] of a `model` ("naghdi" or "membrane") of `fabric` on `cell`s (quadrilateral,
    triangle) whose smallest edge is h_min [m] (module docstring): membrane waves [Man2006, eq. 2.87] with the
    element's kappa and, for the shell, thickness shear and bending with the bending tangent D0 of
    `initial_bending_stiffness` (a bending rigidity B given apart from the thickness: B itself), the rotational
    masses scaled by `rotary_inertia_scale` (>= 1)."""
    scale = rotary_scale(rotary_inertia_scale)
    omega_m = MEMBRANE_KAPPA[cell] * plane_stress_wave_speed(fabric) / h_min  # eq. 2.87 with the element's kappa
    if model != "naghdi":
        return float(omega_m)
    omega_s = (THICKNESS_SHEAR_CHI[cell] * np.sqrt(12.0 * fabric.shear_correction * fabric.transverse_shear_modulus
                                                   / fabric.density) / fabric.thickness) / np.sqrt(scale)
    omega_b = (BENDING_CHI[cell] * np.sqrt(12.0 * initial_bending_stiffness(fabric, bending_eps) / fabric.density)
               / fabric.thickness ** 1.5 / h_min) / np.sqrt(scale)
    return float(np.sqrt(omega_m ** 2 + omega_s ** 2 + omega_b ** 2))


def initial_bending_stiffness(fabric, bending_eps: float | None = None) -> float:
    """Bending tangent dm/dK at K = 0 [N m] of the fabric's law (module docstring): D0, the larger of D11, D22 of
    Fabric.bending_matrix for the linear law (B1, B2 when the bending rigidity is given apart from E t^3 / 12);
    bending_eps [1/m]: the square-root law's regularisation (None: ShellModel's default 1e-3 kappa0)."""
    law = fabric.bending_law
    if law is None:
        D = fabric.bending_matrix
        return float(max(D[0, 0], D[1, 1]))
    if hasattr(law, "coefficients"):
        return float(law.coefficients[0])
    eps = 1e-3 * law.kappa0 if bending_eps is None else bending_eps
    return float(2.0 * law.B0 * np.sqrt(law.kappa0 / eps))


def critical_time_step(model, rayleigh: tuple[float, float] = (0.0, 0.0), omega_max: float | None = None,
                       rotary_inertia_scale: float = 1.0, mass_scale: float = 1.0) -> float:
    """dt_crit = 2 / omega_max [Man2006, eq. 2.86], reduced for Rayleigh damping (a [1/s], b [s]); omega_max
    from `max_frequency_estimate(model, rotary_inertia_scale)` unless given, divided by sqrt(mass_scale) for
    lumped masses scaled by mass_scale (the damping C = a M of the physical mass: a / mass_scale on the
    scaled one) [Belytschko2000, ch. 6]."""
    omega = max_frequency_estimate(model, rotary_inertia_scale) if omega_max is None else float(omega_max)
    omega /= np.sqrt(mass_scale)
    a, b = rayleigh
    a = a / mass_scale
    xi = a / (2.0 * omega) + b * omega / 2.0
    return float(2.0 / omega * (np.sqrt(1.0 + xi ** 2) - xi))


def discrete_max_frequency(model, iterations: int = 2000, rtol: float = 1e-4, rotary_inertia_scale: float = 1.0) -> float:
    """Largest omega [rad/s] of K(d) phi = omega^2 M_L phi on the free dofs (current state, lumped mass with the
    rotational entries scaled by `rotary_inertia_scale`), by SLEPc's Krylov-Schur on M^-1/2 K M^-1/2 with a
    32-vector subspace (the largest eigenvalues of a uniform mesh are clustered: one vector converges slowly).
    The Ritz value theta converges from below and stops at a relative residual `rtol`; for a symmetric operator an
    eigenvalue lies within ||r|| = rtol theta of it [Parlett1998, thm. 4.5.1], so theta (1 + rtol) is returned:
    an upper bound of that eigenvalue, the safe side for the critical step. A rerun with the same operator reads
    the eigenvalue from `eigen_cache` (the same value, bit for bit)."""
    from slepc4py import SLEPc  # optional package, loaded only for the eigenvalue estimate

    model.compile()
    K = model.create_matrix()
    model.jacobian(model.w.vector, K)  # Dirichlet rows: identity
    m = lumped_mass(model, rotary_inertia_scale=rotary_inertia_scale)
    # Dirichlet rows get a huge mass so their eigenvalue (1 / m) is ~0 and never the largest
    for bc in model.bcs:
        dofs, n_owned = bc.dof_indices()
        owned = dofs[:n_owned]
        m.getArray()[owned[owned < m.getLocalSize()]] = 1e300
    inv_sqrt = m.copy()
    inv_sqrt.sqrtabs()
    inv_sqrt.reciprocal()
    K.diagonalScale(inv_sqrt, inv_sqrt)  # M^-1/2 K M^-1/2
    subspace = min(32, max(K.getSize()[0] - 1, 1))

    def solve() -> float:
        eps = SLEPc.EPS().create(model.comm)
        eps.setOperators(K)
        eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
        eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
        eps.setDimensions(1, subspace)
        eps.setTolerances(rtol, iterations)
        eps.solve()
        if eps.getConverged() < 1:
            raise RuntimeError("SLEPc did not converge the largest eigenvalue")
        eigenvalue = eps.getEigenvalue(0).real
        eps.destroy()
        return float(eigenvalue)

    settings = f"krylovschur largest_real nev=1 ncv={subspace} rtol={rtol!r} max_it={iterations}"
    value = eigen_cache.largest_eigenvalue(K, settings, model.comm, solve)
    for obj in (K, m, inv_sqrt):
        obj.destroy()
    return float(np.sqrt(value * (1.0 + rtol)))


CRITICAL_STEP_METHODS = ("eigenvalue", "estimate")
# dt / dt_crit by default, per critical-step method: the eigenvalue is exact for the linearised current state, so
# 0.9 leaves 10 % for its change during a run and for damping; the element formula overestimates omega_max (by
# 1.3-1.9 on the garments), so 0.8 of it is far below the limit. Measured: docs/findings/2026-11-26-quadrature-geometry.md.
STEP_SAFETY = {"eigenvalue": 0.9, "estimate": 0.8}


def step_safety(value: float | None, method: str) -> float:
    """The explicit step's fraction of the critical step: `value` if given, else STEP_SAFETY[method]."""
    if method not in STEP_SAFETY:
        raise ValueError(f"critical_step must be one of {CRITICAL_STEP_METHODS}, got {method!r}")
    return STEP_SAFETY[method] if value is None else float(value)


def max_frequency(model, rotary_inertia_scale: float = 1.0, method: str = "eigenvalue") -> float:
    """omega_max [rad/s] of the model in its current state for the critical step [Man2006, eq. 2.86]:
    "eigenvalue" solves for the largest eigenvalue of the assembled system (`discrete_max_frequency`, the
    global estimate of explicit codes [Belytschko2000, ch. 6]); "estimate" is the element formula
    `max_frequency_estimate`, an overestimate (measured in docs/findings/2026-11-26-critical-step.md)."""
    if method == "eigenvalue":
        return discrete_max_frequency(model, rotary_inertia_scale=rotary_inertia_scale)
    if method == "estimate":
        return max_frequency_estimate(model, rotary_inertia_scale)
    raise ValueError(f"critical_step must be one of {CRITICAL_STEP_METHODS}, got {method!r}")


def measured_critical_time_step(run_is_stable: Callable[[float], bool], dt_low: float, dt_high: float,
                                rel_tol: float = 0.01, max_iter: int = 30) -> float:
    """Largest stable time step in [dt_low, dt_high] by bisection.

    `run_is_stable(dt)` runs an explicit simulation with step dt (e.g. force=True, a fixed number of steps)
    and returns False when it blew up. dt_low must be stable, dt_high unstable (ValueError otherwise).
    """
    if not (0 < dt_low < dt_high):
        raise ValueError(f"need 0 < dt_low < dt_high, got dt_low = {dt_low!r}, dt_high = {dt_high!r}")
    if not run_is_stable(dt_low):
        raise ValueError(f"dt_low = {dt_low:.6g} s is not stable")
    if run_is_stable(dt_high):
        raise ValueError(f"dt_high = {dt_high:.6g} s is stable: raise it")
    for _ in range(max_iter):
        if dt_high - dt_low <= rel_tol * dt_low:
            break
        mid = 0.5 * (dt_low + dt_high)
        if run_is_stable(mid):
            dt_low = mid
        else:
            dt_high = mid
    return dt_low


__all__ = ["plane_stress_wave_speed", "min_edge_length", "max_frequency_estimate", "element_frequency",
           "initial_bending_stiffness", "critical_time_step",
           "discrete_max_frequency", "max_frequency", "CRITICAL_STEP_METHODS", "STEP_SAFETY", "step_safety",
           "measured_critical_time_step"]
