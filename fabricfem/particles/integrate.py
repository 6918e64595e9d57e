"""Dynamics and statics of a particle cloth: velocity Verlet with Provot's strain limit, and static
relaxation ([Eischen2000, sec. 3.2-3.3]; [Man2006, sec. 2.1.1.1]). SI units: m, kg, s, N, J.

Equation of motion [Eischen2000, eq. 50]: m dv/dt = W + F_ext + F_stretch + F_shear + F_bend - c m v, where
W = m g is gravity, F_ext are point loads and obstacle contact forces and c [1/s] a mass-proportional
viscous damping. Pinned particles keep their positions and have zero velocity.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fabricfem.particles.obstacles import TableTop
from fabricfem.particles.springs import (
    ParticleSystem,
    SpringSet,
    elastic_energy,
    internal_forces,
    scatter_add,
    stiffness_matrix,
)

STANDARD_GRAVITY = 9.80665  # m/s^2


class DivergenceError(RuntimeError):
    """An explicit run blew up (non-finite state or energy growth) or a relaxation did not converge."""


@dataclass
class Problem:
    """A particle system with its loads and supports.

    gravity [m/s^2] (3-vector), point_forces [N] (n, 3) or None, pinned: indices of fixed particles,
    fixed: optional (n, 3) boolean mask of single fixed coordinates (e.g. the x and y of one particle on a
    frictionless table, whose vertical reactions leave horizontal translation free), obstacles: penalty planes
    (obstacles.TableTop), damping c [1/s] (force -c m v).
    """

    system: ParticleSystem
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -STANDARD_GRAVITY]))
    point_forces: np.ndarray | None = None
    pinned: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    fixed: np.ndarray | None = None
    obstacles: tuple[TableTop, ...] = ()
    damping: float = 0.0

    def __post_init__(self):
        n = self.system.n
        self.gravity = np.asarray(self.gravity, dtype=float)
        if self.gravity.shape != (3,) or not np.all(np.isfinite(self.gravity)):
            raise ValueError("gravity must be a finite 3-vector [m/s^2]")
        if self.point_forces is not None:
            self.point_forces = np.asarray(self.point_forces, dtype=float)
            if self.point_forces.shape != (n, 3) or not np.all(np.isfinite(self.point_forces)):
                raise ValueError(f"point_forces must be a finite array of shape ({n}, 3) [N]")
        self.pinned = np.unique(np.asarray(self.pinned, dtype=int).ravel())
        if len(self.pinned) and (self.pinned.min() < 0 or self.pinned.max() >= n):
            raise ValueError(f"pinned indices must lie in [0, {n})")
        if self.fixed is not None:
            self.fixed = np.asarray(self.fixed, dtype=bool)
            if self.fixed.shape != (n, 3):
                raise ValueError(f"fixed must be a boolean mask of shape ({n}, 3)")
        if not (math.isfinite(self.damping) and self.damping >= 0):
            raise ValueError(f"damping must be >= 0 [1/s], got {self.damping!r}")
        self.obstacles = tuple(self.obstacles)

    @property
    def movable(self) -> np.ndarray:
        """Boolean mask of particles that are not pinned."""
        mask = np.ones(self.system.n, dtype=bool)
        mask[self.pinned] = False
        return mask

    @property
    def free(self) -> np.ndarray:
        """Boolean (n, 3) mask of free coordinates (not pinned, not fixed)."""
        mask = np.repeat(self.movable[:, None], 3, axis=1)
        if self.fixed is not None:
            mask &= ~self.fixed
        return mask

    def external_forces(self, load_factor: float = 1.0) -> np.ndarray:
        """Gravity W = m g plus point loads, times the load factor [N]."""
        f = self.system.mass[:, None] * self.gravity[None, :]
        if self.point_forces is not None:
            f = f + self.point_forces
        return load_factor * f

    def contact_forces(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros_like(x)
        for ob in self.obstacles:
            f += ob.forces(x)
        return f

    def forces(self, x: np.ndarray, load_factor: float = 1.0) -> np.ndarray:
        """Resultant conservative force on every particle (eq. 48 without seams), pinned ones included [N]."""
        return internal_forces(self.system, x) + self.external_forces(load_factor) + self.contact_forces(x)

    def potential_energy(self, x: np.ndarray, load_factor: float = 1.0) -> float:
        """Elastic + penalty energy minus the work of the (dead) external loads [J]."""
        return (elastic_energy(self.system, x) + sum(ob.energy(x) for ob in self.obstacles)
                - float(np.sum(self.external_forces(load_factor) * x)))

    def kinetic_energy(self, v: np.ndarray) -> float:
        return float(0.5 * np.sum(self.system.mass[:, None] * v ** 2))

    def force_scale(self) -> float:
        """Largest external force on one particle [N] (1 N if there is none): the scale of residuals."""
        f = np.abs(self.external_forces()).max()
        return float(f) if f > 0 else 1.0


# ---------------------------------------------------------------------------------------------
# Provot's strain limit


def strains(x: np.ndarray, springs: tuple[SpringSet, ...]) -> np.ndarray:
    """Engineering strain l / l0 - 1 of every spring of the given sets."""
    return np.concatenate([np.linalg.norm(x[s.j] - x[s.i], axis=1) / s.rest_length - 1.0 for s in springs])


def provot_correction(x: np.ndarray, springs: tuple[SpringSet, ...], tau: float, movable: np.ndarray,
                      tolerance: float = 1e-4, max_iterations: int = 200) -> tuple[np.ndarray, int]:
    """Provot (1995) deformation constraint: shorten every spring longer than (1 + tau) l0 back to (1 + tau) l0
    by moving its end particles towards each other (half each, all of it onto the free end if the other is
    pinned). Corrections of one sweep are computed for all springs at once and averaged per particle (Jacobi);
    sweeps repeat until max strain <= tau + tolerance. Returns the corrected positions and the sweep count.
    Raises DivergenceError if max_iterations sweeps do not suffice.
    """
    if not (math.isfinite(tau) and tau >= 0):
        raise ValueError(f"tau must be >= 0, got {tau!r}")
    i = np.concatenate([s.i for s in springs])
    j = np.concatenate([s.j for s in springs])
    l0 = np.concatenate([s.rest_length for s in springs])
    wi, wj = movable[i].astype(float), movable[j].astype(float)
    share = wi + wj
    active = share > 0
    i, j, l0, wi, wj, share = i[active], j[active], l0[active], wi[active], wj[active], share[active]
    x = x.copy()
    n = len(x)
    for sweep in range(max_iterations + 1):
        d = x[j] - x[i]
        length = np.linalg.norm(d, axis=1)
        over = length > (1.0 + tau + tolerance) * l0
        if not np.any(over):
            return x, sweep
        if sweep == max_iterations:
            break
        d, length = d[over], length[over]
        corr = ((length - (1.0 + tau) * l0[over]) / (length * share[over]))[:, None] * d
        delta = np.zeros_like(x)
        count = np.zeros(n)
        scatter_add(delta, i[over], wi[over, None] * corr)
        scatter_add(delta, j[over], -wj[over, None] * corr)
        count += np.bincount(i[over], weights=wi[over], minlength=n)
        count += np.bincount(j[over], weights=wj[over], minlength=n)
        x += delta / np.maximum(count, 1.0)[:, None]
    raise DivergenceError(f"Provot correction: strain still above tau + tolerance after {max_iterations} sweeps "
                          f"(max strain {np.max(strains(x, springs)):.4g}, tau = {tau})")


# ---------------------------------------------------------------------------------------------
# Explicit dynamics


@dataclass
class Trajectory:
    """Result of `simulate`: final state and per-record time series."""

    x: np.ndarray
    v: np.ndarray
    times: np.ndarray
    energy: np.ndarray  # kinetic + potential [J]
    max_strain: np.ndarray  # largest strain of the strain-limited sets (structural if none)
    positions: np.ndarray  # recorded positions, (records, n, 3)
    provot_sweeps: int = 0


def _initial_state(problem: Problem, x0: np.ndarray | None, v0: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Copies of the start positions [m] (default the reference ones) and velocities [m/s] (default 0), zero on
    the particles that are not free; ValueError on a non-positive movable mass or wrong shapes."""
    sys_ = problem.system
    if np.any(sys_.mass[problem.movable] <= 0):
        raise ValueError("every movable particle needs a positive mass for explicit dynamics")
    x = (sys_.positions if x0 is None else np.asarray(x0, dtype=float)).copy()
    v = np.zeros_like(x) if v0 is None else np.asarray(v0, dtype=float).copy()
    if x.shape != (sys_.n, 3) or v.shape != (sys_.n, 3):
        raise ValueError(f"x0 and v0 must have shape ({sys_.n}, 3)")
    v[~problem.free] = 0.0
    return x, v


def _energy_bound(problem: Problem, E0: float, v: np.ndarray, energy_growth: float) -> float:
    """Blow-up bound [J] of the total energy: E_0 + energy_growth (|E_0| + E_scale + kinetic energy of v), E_scale =
    (m_total |g| + sum |point loads|) diag, diag the size of the reference configuration [m] (or the spacing)."""
    sys_ = problem.system
    diag = float(np.linalg.norm(np.ptp(sys_.positions, axis=0))) or sys_.spacing
    scale_loads = float(np.sum(sys_.mass) * np.linalg.norm(problem.gravity))
    if problem.point_forces is not None:
        scale_loads += float(np.sum(np.linalg.norm(problem.point_forces, axis=1)))
    return E0 + energy_growth * (abs(E0) + scale_loads * diag + problem.kinetic_energy(v))


def simulate(problem: Problem, dt: float, n_steps: int, x0: np.ndarray | None = None, v0: np.ndarray | None = None,
             strain_limit: float | None = None, limited_sets: tuple[str, ...] = ("structural", "shear"),
             record_every: int = 1, energy_growth: float = 10.0, strain_limit_sweeps: int = 2000) -> Trajectory:
    """Velocity Verlet (kick-drift-kick, symplectic and second order without damping):

        v_{n+1/2} = v_n + dt/2 a(x_n, v_n),  x_{n+1} = x_n + dt v_{n+1/2},  v_{n+1} = v_{n+1/2} + dt/2 a(x_{n+1}, v_{n+1/2})

    with a = (F(x) - c m v) / m (damping taken with the velocity at the start of each half kick). If
    strain_limit = tau is given, Provot's correction is applied to the springs of `limited_sets` after each
    drift (at most strain_limit_sweeps Jacobi sweeps, see provot_correction), and the velocities take up the
    position change (v += dx_corr / dt).

    Blow-up detection: a non-finite state, or a total energy above E_0 + energy_growth * E_scale with
    E_scale = |E_0| + m_total |g| diag + |point loads| diag (diag = size of the reference configuration),
    raises DivergenceError naming the step.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive and finite, got {dt!r}")
    if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 0):
        raise ValueError(f"n_steps must be an integer >= 0, got {n_steps!r}")
    if not (isinstance(record_every, (int, np.integer)) and record_every >= 1):
        raise ValueError(f"record_every must be an integer >= 1, got {record_every!r}")
    sys_ = problem.system
    m = sys_.mass
    x, v = _initial_state(problem, x0, v0)
    movable = problem.movable
    free = problem.free
    limited = tuple(s for s in sys_.springs if s.name in limited_sets) if strain_limit is not None else ()
    if strain_limit is not None and not limited:
        raise ValueError(f"limited_sets {limited_sets} match no spring set of the system")
    monitored = limited or sys_.springs[:1]
    c = problem.damping
    inv_m = np.where(free, (1.0 / np.where(m > 0, m, 1.0))[:, None], 0.0)

    def accel(x_, v_):
        return (problem.forces(x_) - c * m[:, None] * v_) * inv_m

    def total_energy(x_, v_):
        return problem.kinetic_energy(v_) + problem.potential_energy(x_)

    E_bound = _energy_bound(problem, total_energy(x, v), v, energy_growth)

    times, energies, max_strain, positions = [], [], [], []

    def record(step):
        times.append(step * dt)
        energies.append(total_energy(x, v))
        max_strain.append(float(np.max(strains(x, monitored))))
        positions.append(x.copy())

    record(0)
    sweeps = 0
    a = accel(x, v)
    for step in range(1, n_steps + 1):
        v_half = v + 0.5 * dt * a
        x_new = x + dt * v_half
        if limited:
            x_lim, k = provot_correction(x_new, limited, strain_limit, movable, max_iterations=strain_limit_sweeps)
            x_lim = np.where(free, x_lim, x_new)
            sweeps += k
            v_half = v_half + (x_lim - x_new) * free / dt
            x_new = x_lim
        x = x_new
        a = accel(x, v_half)
        v = v_half + 0.5 * dt * a
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
            raise DivergenceError(f"explicit integration blew up at step {step} (t = {step * dt:.4g} s): "
                                  f"non-finite positions/velocities; reduce dt = {dt:g} s")
        if step % record_every == 0 or step == n_steps:
            record(step)
            if energies[-1] > E_bound:
                raise DivergenceError(
                    f"explicit integration blew up at step {step} (t = {step * dt:.4g} s): energy "
                    f"{energies[-1]:.4g} J exceeds the bound {E_bound:.4g} J; reduce dt = {dt:g} s")
    return Trajectory(x, v, np.array(times), np.array(energies), np.array(max_strain), np.array(positions), sweeps)


def critical_time_step(problem: Problem) -> float:
    """Stability limit of the undamped explicit scheme, dt_c = 2 / omega_max, with omega_max^2 bounded by the
    Gershgorin bound of M^-1 K at the reference configuration (springs, flexion and penalty). A lower bound of
    the true limit, so dt = 0.5 dt_c is safe in the small-strain regime."""
    sys_ = problem.system
    K = _tangent(problem, sys_.positions)
    row = np.asarray(abs(K).sum(axis=1)).ravel()
    m3 = np.repeat(np.where(sys_.mass > 0, sys_.mass, np.inf), 3)
    free = problem.free.ravel()
    omega2 = np.max(row[free] / m3[free])
    return 2.0 / math.sqrt(omega2)


# ---------------------------------------------------------------------------------------------
# Static relaxation


@dataclass
class StaticResult:
    x: np.ndarray
    iterations: int
    residual: float  # max |resultant force| on a free particle / force scale
    history: list = field(default_factory=list)  # (load factor, iterations) per load step


def tangent_stiffness(problem: Problem, x: np.ndarray, definite: bool = True) -> sp.csr_matrix:
    """Tangent stiffness [N/m] (3n x 3n, dof 3 k + c) of springs, flexion and penalty contact at x;
    definite=True clips the compressive geometric stiffness of the springs (stiffness_matrix)."""
    return _tangent(problem, x, definite)


def _tangent(problem: Problem, x: np.ndarray, definite: bool = True) -> sp.csr_matrix:
    K = stiffness_matrix(problem.system, x, definite)
    if problem.obstacles:
        blocks = sum(ob.stiffness_blocks(x) for ob in problem.obstacles)
        K = K + sp.block_diag(list(blocks), format="csr")
    return K.tocsr()


def relax_seed(problem: Problem, x0: np.ndarray | None = None, momentum: float = 0.9, c_disp: float | None = None,
               tol: float = 1e-8, max_iterations: int = 200_000) -> StaticResult:
    """[Eischen2000, sec. 3.2.3]: each node moves along its resultant force, Disp^k = C_disp F^k, with
    F^k = W + F_int + F_ext + C_acc Disp^{k-1} (eq. 49, the 'acceleration' pseudo-load).

    C_disp [m/N] defaults to 1 / (Gershgorin bound of the tangent stiffness at x0), which makes the plain
    iteration a stable gradient descent; C_acc = momentum / C_disp [N/m] (momentum in [0, 1): a heavy-ball
    iteration). Stops when max |resultant on a free particle| <= tol * force_scale AND the seed's own
    criterion max |Disp| < b / 10000 holds. Raises DivergenceError if it does not converge.
    """
    if not (0.0 <= momentum < 1.0):
        raise ValueError(f"momentum must lie in [0, 1), got {momentum!r}")
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be > 0, got {tol!r}")
    x = (problem.system.positions if x0 is None else np.asarray(x0, dtype=float)).copy()
    if c_disp is None:
        K = _tangent(problem, x)
        c_disp = 1.0 / float(np.max(np.asarray(abs(K).sum(axis=1)).ravel()))
    elif not (math.isfinite(c_disp) and c_disp > 0):
        raise ValueError(f"c_disp must be > 0 [m/N], got {c_disp!r}")
    c_acc = momentum / c_disp
    eps = problem.system.spacing / 10000.0
    movable = problem.free
    scale = problem.force_scale()
    disp = np.zeros_like(x)
    for k in range(1, max_iterations + 1):
        F = problem.forces(x) * movable
        res = float(np.max(np.abs(F))) / scale
        if not math.isfinite(res):
            raise DivergenceError(f"relax_seed: non-finite force at iteration {k}")
        if res <= tol and np.max(np.abs(disp)) < eps:
            return StaticResult(x, k - 1, res)
        disp = c_disp * (F + c_acc * disp)
        x = x + disp
    raise DivergenceError(f"relax_seed did not converge in {max_iterations} iterations (residual {res:.3g})")


def relax_newton(problem: Problem, x0: np.ndarray | None = None, tol: float = 1e-9, load_steps: int = 1,
                 max_iterations: int = 200, max_step: float | None = None, definite: bool = False) -> StaticResult:
    """Static equilibrium [Eischen2000, eq. 48] by Newton's method on the resultant forces.

    Each load step (load factor i / load_steps on gravity and point loads) solves (K + mu D) dx = F with the
    sparse tangent K (springs with compressive geometric stiffness clipped, flexion Hessian, penalty); D is the
    diagonal of K and mu >= 0 a Levenberg-Marquardt shift raised when the step is not a descent direction or
    the backtracking line search on the total potential energy fails, lowered after success.
    Converged when max |resultant on a free particle| <= tol * force_scale (tol raised to the rounding floor
    1000 eps k_max |x| / force_scale if larger). Each iteration moves no particle by more than max_step
    (default half the spacing), a trust region that keeps the linearized step from stretching the stiff
    springs of a rotating, nearly inextensible cloth. definite=False uses the exact spring Hessian (with
    compressive geometric stiffness). Raises DivergenceError if it does not converge.
    """
    if not (isinstance(load_steps, (int, np.integer)) and load_steps >= 1):
        raise ValueError(f"load_steps must be an integer >= 1, got {load_steps!r}")
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be > 0, got {tol!r}")
    x = (problem.system.positions if x0 is None else np.asarray(x0, dtype=float)).copy()
    free = problem.free.ravel()
    scale = problem.force_scale()
    max_step = 0.5 * problem.system.spacing if max_step is None else max_step
    if not (math.isfinite(max_step) and max_step > 0):
        raise ValueError(f"max_step must be > 0 [m], got {max_step!r}")
    # Forces are differences of spring forces k (l - l0) computed from coordinates of size |x|: below about
    # 1000 eps k_max |x| / force_scale the residual is rounding noise, so the tolerance is not set below it.
    k_max = max([float(np.max(s.stiffness)) for s in problem.system.springs]
                + [ob.stiffness for ob in problem.obstacles])
    tol = max(tol, 1e3 * np.finfo(float).eps * k_max * float(np.max(np.abs(x))) / scale)
    total, history = 0, []
    res = float("nan")
    for step in range(1, load_steps + 1):
        lf = step / load_steps
        mu = 0.0
        for it in range(max_iterations + 1):
            F = problem.forces(x, lf).ravel()[free]
            res = float(np.max(np.abs(F))) / scale if F.size else 0.0
            if not math.isfinite(res):
                raise DivergenceError(f"relax_newton: non-finite force (load factor {lf:g}, iteration {it})")
            if res <= tol:
                break
            if it == max_iterations:
                raise DivergenceError(f"relax_newton: no convergence in {max_iterations} iterations at load "
                                      f"factor {lf:g} (residual {res:.3g} of the force scale)")
            K = _tangent(problem, x, definite)[free][:, free]
            D = sp.diags(np.maximum(K.diagonal(), 1e-300))
            Pi0 = problem.potential_energy(x, lf)
            accepted = False
            for _ in range(30):
                A = (K + mu * D).tocsc() if mu > 0 else K.tocsc()
                try:
                    with warnings.catch_warnings():  # a singular K shows up as a non-finite p: raise mu
                        warnings.simplefilter("ignore", spla.MatrixRankWarning)
                        p = spla.spsolve(A, F)
                except RuntimeError:  # exactly singular factor
                    p = np.full_like(F, np.nan)
                slope = float(F @ p)
                if np.all(np.isfinite(p)) and slope > 0:
                    # trust region: no particle moves more than max_step per iteration
                    alpha = min(1.0, max_step / float(np.max(np.abs(p))))
                    for _ in range(20):
                        xt = x.copy()
                        xt.ravel()[free] += alpha * p
                        Pi = problem.potential_energy(xt, lf)
                        Ft = problem.forces(xt, lf).ravel()[free]
                        if (Pi <= Pi0 - 1e-4 * alpha * slope
                                or np.max(np.abs(Ft)) < (1.0 - 1e-4 * alpha) * np.max(np.abs(F))):
                            accepted = True
                            break
                        alpha *= 0.5
                if accepted:
                    break
                mu = max(1e-6, 10.0 * mu)
            if not accepted:
                raise DivergenceError(f"relax_newton: line search failed at load factor {lf:g}, iteration {it}")
            x = xt
            mu = 0.0 if mu < 1e-5 else 0.1 * mu
            total += 1
        history.append((lf, it))
    return StaticResult(x, total, res, history)
