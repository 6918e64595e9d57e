"""Particle-model benchmarks of [Eischen2000, sec. 4] (helpers, not registered cases; SI units inside).

Each helper returns a dict of the quantities of the seed's tables (in the seed's units, gf and cm, or the
normalized x/L, y/L, z/L) with the theoretical / experimental row, the seed's particle-model row and
percentage errors, and the wall time.
"""
from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse.linalg as spla

from fabricfem.particles import (
    STANDARD_GRAVITY,
    Problem,
    TableTop,
    beam_strip,
    critical_time_step,
    penalty_stiffness,
    rectangular_grid,
    relax_newton,
    simulate,
    table_edge,
    table_top,
)
from fabricfem.particles.integrate import tangent_stiffness
from fabricfem.verify.references import elastica_tip_load

GF = STANDARD_GRAVITY * 1e-3  # one gram-force [N]
CM, MM = 1e-2, 1e-3

# [Eischen2000, sec. 4.3] table: theory and particle-model rows (p [cm], delta_y [cm], R_b [gf], R_c [gf])
OVERHANG_THEORY = {"p": 2.1213, "deflection": 0.0812, "R_b": 0.0135, "R_c": 0.0788}
OVERHANG_SEED_PARTICLE = {"p": 2.2499, "deflection": 0.0966, "R_b": 0.0156, "R_c": 0.0813}
OVERHANG_SEED_PARTICLE_ERROR = {"p": 6.06, "deflection": 18.0, "R_b": 15.52, "R_c": 3.15}  # percent

# [Eischen2000, sec. 4.4] table (experiment and particle model rows)
TABLECLOTH_EXPERIMENT = {"corner x/L": 0.39, "corner y/L": 0.38, "corner z/L": 0.39, "midside y/L": 0.18,
                         "midside z/L": 0.40}
TABLECLOTH_SEED_PARTICLE = {"corner x/L": 0.39, "corner y/L": 0.39, "corner z/L": 0.38, "midside y/L": 0.16,
                            "midside z/L": 0.37}
TABLECLOTH_SEED_FE = {"corner x/L": 0.41, "corner y/L": 0.41, "corner z/L": 0.36, "midside y/L": 0.19,
                      "midside z/L": 0.38}
TABLECLOTH_SEED_PARTICLE_ERROR = {"corner x/L": 0.45, "corner y/L": 3.12, "corner z/L": 1.79, "midside y/L": 7.90,
                                  "midside z/L": 5.34}  # percent


def _percent(value: float, reference: float) -> float:
    return 100.0 * abs(value - reference) / abs(reference)


def particle_tip_loaded_cantilever(lam: float, n: int = 8) -> dict:
    """[Eischen2000, sec. 4.1]: L = 1, EA = 2 sqrt(3) e-3, EI = 2 sqrt(3) e-9 (consistent units), P = lam EI / L^2,
    n particle elements (two lines of particles). The clamp pins the root particles and a ghost column one
    spacing behind them (zero displacement and zero rotation of the first flexion triple).
    Returns tip deflection w/L, shortening u/L and tip rotation [rad] with the elastica values."""
    t0 = time.perf_counter()
    L, EA, EI = 1.0, 2.0 * np.sqrt(3.0) * 1e-3, 2.0 * np.sqrt(3.0) * 1e-9
    b = L / n
    system = beam_strip(n + 1, L + b, EA, EI, 0.0, origin=(-b, 0.0, 0.0))
    tip = system.index(-1, [0, 1])
    P = np.zeros((system.n, 3))
    P[tip, 2] = -lam * EI / L ** 2 / 2.0  # half on each line
    problem = Problem(system, gravity=np.zeros(3), point_forces=P, pinned=system.index([0, 1, 0, 1], [0, 0, 1, 1]))
    res = relax_newton(problem)
    x = res.x
    xt = x[tip].mean(axis=0)
    seg = xt - x[system.index(-2, [0, 1])].mean(axis=0)
    ref = elastica_tip_load(lam)
    out = {"w": -xt[2] / L, "u": 1.0 - xt[0] / L, "rotation": float(np.arctan2(-seg[2], seg[0])),
           "w_ref": ref["w"], "u_ref": ref["u"], "rotation_ref": ref["rotation"], "iterations": res.iterations,
           "wall_s": time.perf_counter() - t0}
    for q in ("w", "u", "rotation"):
        out[f"{q}_error_%"] = _percent(out[q], out[f"{q}_ref"])
    return out


def particle_overhanging_beam(n: int = 24) -> dict:
    """[Eischen2000, sec. 4.3]: L = 6 cm, overhang a = 1.5 cm past a frictionless table edge at x = 0, EA = 2809 gf,
    EI = 0.386 gf cm^2, w = 0.0255 gf/cm, n particle elements (two lines).

    Lift-off length p = x_C - x_B with B the contacting particle nearest to the edge C; deflection = drop of the
    free end; R_c = contact force on the edge particle; R_b = w (a + p) - R_c, the point reaction at B from the
    equilibrium of the part between B and the free end (the same identity holds for the theory row).
    The table edge is rounded to b / 10 (obstacles.TableTop); the left end particles keep x (and one y), which
    only removes the free horizontal sliding of a beam on a frictionless table.
    """
    t0 = time.perf_counter()
    L, a = 6.0 * CM, 1.5 * CM
    EA, EI, w = 2809.0 * GF, 0.386 * GF * CM ** 2, 0.0255 * GF / CM
    system = beam_strip(n, L, EA, EI, w / STANDARD_GRAVITY, origin=(-(L - a), 0.0, 0.0))
    b = system.spacing
    fixed = np.zeros((system.n, 3), dtype=bool)
    fixed[system.index(0, [0, 1]), 0] = True
    fixed[system.index(0, 0), 1] = True
    problem = Problem(system, fixed=fixed,
                      obstacles=(table_edge(0.0, 0.0, penalty_stiffness(system), edge_radius=b / 10.0),))
    res = relax_newton(problem)
    nx = n + 1
    xs = system.positions[:nx, 0]
    fz = problem.contact_forces(res.x)[:, 2]
    force = fz[:nx] + fz[nx:]  # both lines
    iC = int(np.argmin(np.abs(xs)))
    if abs(xs[iC]) > 1e-9 * b:
        raise ValueError(f"n = {n}: no particle on the table edge (a / b must be an integer)")
    iB = int(np.nonzero(force[:iC] > 0)[0].max())
    p = xs[iC] - xs[iB]
    R_c = force[iC]
    values = {"p": p / CM, "deflection": -res.x[nx - 1, 2] / CM, "R_c": R_c / GF, "R_b": (w * (a + p) - R_c) / GF}
    out = {"values": values, "theory": dict(OVERHANG_THEORY), "seed_particle": dict(OVERHANG_SEED_PARTICLE),
           "seed_particle_error_%": dict(OVERHANG_SEED_PARTICLE_ERROR),
           "error_%": {k: _percent(values[k], OVERHANG_THEORY[k]) for k in values},
           "spacing_cm": b / CM, "iterations": res.iterations, "residual": res.residual,
           "total_reaction_gf": float(force.sum() / GF), "weight_gf": w * L / GF, "ndofs": 3 * system.n,
           "wall_s": time.perf_counter() - t0}
    return out


# ---------------------------------------------------------------------------- tablecloth (sec. 4.4)
# [Eischen2000, sec. 4.4] set-up (SI): cloth side, isotropic cotton, weight per area, 8 cm cube (top at z = 0)
CLOTH_SIDE = 20.0 * CM                                                   # L [m]
CLOTH_E, CLOTH_H, CLOTH_NU = 118.1176 * GF / MM ** 2, 0.54229 * MM, 0.3  # Pa, m, -
CLOTH_WEIGHT = 0.2384e-3 * GF / MM ** 2                                  # q [N/m^2]
TABLE_HALF, TABLE_HEIGHT = 4.0 * CM, 8.0 * CM                            # m
# Air drag of a cloth, [Peng2022, eq. 17d] (eta = 0.351 kg/(m^2 s)): force -eta v per area = -(eta / rho) m v.
AIR_DRAG = 0.351                                                         # eta [kg/(m^2 s)]
# Flatness imperfection of the cloth laid on the table before the drop (the same for every run and model):
# a smooth random waviness of 8 plane waves, wavelengths uniform in [2 cm, 20 cm] (grid scale to cloth
# scale), random directions and phases from numpy's default_rng(IMPERFECTION_SEED), shifted and scaled to
# heights in [0, h / 2] above the table top (a cloth laid out by hand is not flatter than half its
# thickness; upward only, so that no point starts inside the table). Chosen before any run was looked at.
IMPERFECTION_SEED, IMPERFECTION_WAVES = 2000, 8
IMPERFECTION_AMPLITUDE = 0.5 * CLOTH_H                                   # m


def flatness_imperfection(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Initial height [m] in [0, h / 2] of the cloth point with reference coordinates (x, y) [m] measured from
    the table centre (module constants IMPERFECTION_*): the same field for the particle and shell models."""
    rng = np.random.default_rng(IMPERFECTION_SEED)
    k = rng.uniform(2.0 * np.pi / (10 * CM), 2.0 * np.pi / (1 * CM), IMPERFECTION_WAVES) / 2.0  # 2 pi / lambda
    angle = rng.uniform(0.0, 2.0 * np.pi, IMPERFECTION_WAVES)
    phase = rng.uniform(0.0, 2.0 * np.pi, IMPERFECTION_WAVES)

    def waves(X, Y):
        X, Y = np.asarray(X, dtype=float)[..., None], np.asarray(Y, dtype=float)[..., None]
        return np.sum(np.cos(k * (np.cos(angle) * X + np.sin(angle) * Y) + phase), axis=-1)

    # range of the field over the cloth on a fine grid (0.1 mm): fixes the shift and scale once
    g = np.linspace(-0.5 * CLOTH_SIDE, 0.5 * CLOTH_SIDE, 401)
    ref = waves(*np.meshgrid(g, g))
    lo, hi = float(ref.min()), float(ref.max())
    return IMPERFECTION_AMPLITUDE * np.clip((waves(x, y) - lo) / (hi - lo), 0.0, 1.0)


def tablecloth_reading(corner: np.ndarray, midside: np.ndarray) -> dict:
    """The seed's table entries from the corner and midside positions [m] (table centre at the origin, top at
    z = 0, midside = middle of the edge y = +L/2): the admissible "floor" reading (see
    fabricfem.verify.drape.reading_admissibility), x/L and z/L horizontal from the table centre (corner x,
    y; midside y), y/L the height above the floor on which the 8 cm cube stands."""
    return {"corner x/L": corner[0] / CLOTH_SIDE, "corner y/L": (TABLE_HEIGHT + corner[2]) / CLOTH_SIDE,
            "corner z/L": corner[1] / CLOTH_SIDE, "midside y/L": (TABLE_HEIGHT + midside[2]) / CLOTH_SIDE,
            "midside z/L": midside[1] / CLOTH_SIDE}


def hem_folds(height: np.ndarray, tolerance: float) -> int:
    """Number of folds of a draped hem: local minima of the hem height along the closed hem (periodic
    sequence, heights [m]) deeper than `tolerance` [m] below the highest point on either side before the
    next lower point (a prominence test, so that node-level noise does not count)."""
    z = np.asarray(height, dtype=float)
    n = len(z)
    if n < 3 or not np.all(np.isfinite(z)):
        raise ValueError("height must be a finite periodic sequence of at least 3 hem points")
    count = 0
    for i in np.flatnonzero((z <= np.roll(z, 1)) & (z < np.roll(z, -1))):  # candidate minima only (a few)
        order = np.roll(z, -i)
        left, right = order[::-1][:-1], order[1:]     # walk away from i both ways around the hem
        ok = True
        for side in (left, right):
            lower = np.flatnonzero(side < z[i])
            span = side[:lower[0]] if len(lower) else side
            ok &= (span.max() if len(span) else z[i]) - z[i] > tolerance
        count += bool(ok)
    return count


def _tablecloth_system(n: int):
    if not (isinstance(n, (int, np.integer)) and n >= 2 and n % 2 == 0
            and abs(n * TABLE_HALF / CLOTH_SIDE - round(n * TABLE_HALF / CLOTH_SIDE)) < 1e-9):
        raise ValueError(f"n must be even with a particle row on the table edges (n = 10, 20, 30, ...), got {n!r}")
    b = CLOTH_SIDE / n
    rho_a = CLOTH_WEIGHT / STANDARD_GRAVITY  # areal mass [kg/m^2]
    return rectangular_grid(n + 1, n + 1, b, b, CLOTH_E, CLOTH_NU, CLOTH_H, rho_a,
                            origin=(-CLOTH_SIDE / 2, -CLOTH_SIDE / 2, 0.0)), b


def _table(system, b: float, factor: float = 100.0) -> tuple:
    """The table (top z = 0, edges rounded to b / 10) and the floor z = -8 cm on which the cube of the
    experiment stands (part of the experiment in the floor reading of the seed's table: a corner of the
    cloth can reach it, the diagonal overhang being 8.49 cm), penalty factor x the stiffest spring."""
    k = penalty_stiffness(system, factor)
    return (table_top(0.0, 0.0, TABLE_HALF, TABLE_HALF, 0.0, k, edge_radius=b / 10.0),
            TableTop(-TABLE_HEIGHT, k, b / 10.0))


def _hem(system) -> np.ndarray:
    """Indices of the boundary particles in order around the grid."""
    nx, ny = system.shape
    ix, iy = np.arange(nx), np.arange(ny)
    return np.concatenate([system.index(ix[:-1], 0), system.index(nx - 1, iy[:-1]),
                           system.index(ix[::-1][:-1], ny - 1), system.index(0, iy[::-1][:-1])])


def lowest_particle_eigenvalues(problem: Problem, x: np.ndarray, count: int = 3) -> np.ndarray:
    """The `count` lowest eigenvalues [N/m] of the exact tangent (compressive geometric stiffness kept) on
    the free coordinates at x, by shift-invert Lanczos below zero: all positive = stable equilibrium."""
    free = problem.free.ravel()
    K = tangent_stiffness(problem, x, definite=False)[free][:, free]
    shift = -1e-3 * float(np.abs(K.diagonal()).max())
    return np.sort(spla.eigsh(K, k=count, sigma=shift, which="LM", return_eigenvectors=False))


def _static_tablecloth_problem(n: int) -> Problem:
    system, b = _tablecloth_system(n)
    fixed = np.zeros((system.n, 3), dtype=bool)
    line = np.arange(n + 1)
    fixed[system.index(n // 2, line), 0] = True
    fixed[system.index(line, n // 2), 1] = True
    return Problem(system, fixed=fixed, obstacles=_table(system, b))


def particle_tablecloth_nodes(n: int = 20, load_steps: int = 5) -> dict:
    """particle_tablecloth without the stability check (for the speed-accuracy benchmark): corner (L/2, L/2)
    and midside (0, L/2) positions [m] (table top at z = 0), hem folds, diagonal asymmetry |x_c - y_c| / L,
    free coordinates, Newton iterations."""
    problem = _static_tablecloth_problem(n)
    res = relax_newton(problem, load_steps=load_steps, max_iterations=400)
    system = problem.system
    corner = res.x[system.index(-1, -1)].copy()
    return {"corner": corner, "midside": res.x[system.index(n // 2, -1)].copy(),
            "folds": hem_folds(res.x[_hem(system), 2], 1e-3 * CLOTH_SIDE),
            "diagonal_asymmetry": abs(corner[0] - corner[1]) / CLOTH_SIDE,
            "ndofs": int(problem.free.sum()), "iterations": res.iterations}


def particle_tablecloth(n: int = 20, load_steps: int = 5) -> dict:
    """[Eischen2000, sec. 4.4] by static relaxation: 20 cm square cloth centred on an 8 cm square frictionless
    table, E = 118.1176 gf/mm^2, weight 0.2384e-3 gf/mm^2, h = 0.54229 mm, nu = 0.3, n x n elements.

    Newton's method from the flat sheet in load_steps equal gravity increments (the drape has several
    equilibria: this is the one reached on that path, the diagonal-symmetric one). The mirror planes x = 0
    and y = 0 are imposed (x fixed on x = 0, y fixed on y = 0), which also removes the free in-plane sliding
    on the frictionless table. The table edge is rounded to b / 10; the floor is 8 cm below the top.
    Values in the seed's floor reading (tablecloth_reading); all lengths / L.
    """
    t0 = time.perf_counter()
    problem = _static_tablecloth_problem(n)
    res = relax_newton(problem, load_steps=load_steps, max_iterations=400)
    return _tablecloth_result(problem, res, t0)


def _tablecloth_result(problem: Problem, res, t0: float, **extra) -> dict:
    system = problem.system
    n = system.shape[0] - 1
    x = res.x
    values = tablecloth_reading(x[system.index(-1, -1)], x[system.index(n // 2, -1)])
    eig = lowest_particle_eigenvalues(problem, x)
    hem = x[_hem(system), 2]
    corners = x[system.index([0, 0, -1, -1], [0, -1, 0, -1]), 2]
    weight = float(-problem.external_forces()[:, 2].sum())
    return dict(extra, reaction_over_weight=float(problem.contact_forces(x)[:, 2].sum()) / weight, values=values,
                experiment=dict(TABLECLOTH_EXPERIMENT),
                seed_particle=dict(TABLECLOTH_SEED_PARTICLE), **{
                    "seed_particle_error_%": dict(TABLECLOTH_SEED_PARTICLE_ERROR),
                    "error_%": {k: _percent(values[k], TABLECLOTH_EXPERIMENT[k]) for k in values}},
                folds=hem_folds(hem, 1e-3 * CLOTH_SIDE), corner_height_spread=float(np.ptp(corners)) / CLOTH_SIDE,
                lowest_eigenvalue=float(eig[0]), iterations=res.iterations, residual=res.residual,
                ndofs=int(problem.free.sum()), positions=x, wall_s=time.perf_counter() - t0)


def particle_tablecloth_drop(n: int = 20, t_end: float = 2.0, penalty_factor_drop: float = 4.0) -> dict:
    """[Eischen2000, sec. 4.4] the way the seed computed it: the cloth FALLS from the (imperfect) flat state and
    settles, then a static Newton polish and a stability check.

    Full n x n grid on the table and the floor (_table), no mirror planes (any fold pattern can form); the
    centre particle keeps x and y and its +x neighbour y (removes the free sliding and spinning on the
    frictionless table; these supports carry no load in equilibrium). Start: flatness_imperfection, at
    rest. Drop: velocity Verlet with the air drag c = eta / rho [Peng2022, eq. 17d] to t_end [s] (default
    2 s: > 3 periods of the slowest pendulum mode of the overhang, 2 pi sqrt(l / g) = 0.5-0.6 s for
    l = 6-8.5 cm, and 1.4 air-drag decay times 1 / c), at 0.9 x the critical step; during the drop the
    contact penalty is penalty_factor_drop x the stiffest spring (4: the step is then set by the springs,
    not by the contact; the equilibrium does not depend on it since the polish uses the standard factor
    100). Polish: relax_newton from the settled state. Stability: the lowest eigenvalues of the exact
    tangent. Returns the values (floor reading), the number of hem folds and
    the corner height spread (0 = the four corners alike), eigenvalue [N/m], wall time [s].
    """
    t0 = time.perf_counter()
    if not (math.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be a positive time [s], got {t_end!r}")
    if not (math.isfinite(penalty_factor_drop) and penalty_factor_drop > 0):
        raise ValueError(f"penalty_factor_drop must be positive, got {penalty_factor_drop!r}")
    system, b = _tablecloth_system(n)
    x0 = system.positions.copy()
    x0[:, 2] += flatness_imperfection(x0[:, 0], x0[:, 1])
    fixed = np.zeros((system.n, 3), dtype=bool)
    fixed[system.index(n // 2, n // 2), :2] = True
    fixed[system.index(n // 2 + 1, n // 2), 1] = True
    rho_a = CLOTH_WEIGHT / STANDARD_GRAVITY
    drop = Problem(system, fixed=fixed, obstacles=_table(system, b, penalty_factor_drop),
                   damping=AIR_DRAG / rho_a)
    dt = 0.9 * critical_time_step(drop)
    steps = int(math.ceil(t_end / dt))
    trajectory = simulate(drop, t_end / steps, steps, x0=x0, record_every=steps)
    static = Problem(system, fixed=fixed, obstacles=_table(system, b))
    res = relax_newton(static, x0=trajectory.x, max_iterations=400)
    return _tablecloth_result(static, res, t0, drop_steps=steps, drop_dt=t_end / steps,
                              kinetic_energy_end=static.kinetic_energy(trajectory.v))
