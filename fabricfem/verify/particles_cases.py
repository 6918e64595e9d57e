"""Particle-model benchmarks of seed 001 sec. 4 (helpers, not registered cases; SI units inside).

Each helper returns a dict of the quantities of the seed's tables (in the seed's units, gf and cm, or the
normalized x/L, y/L, z/L) with the theoretical / experimental row, the seed's particle-model row and
percentage errors, and the wall time.
"""
from __future__ import annotations

import time

import numpy as np

from fabricfem.particles import (STANDARD_GRAVITY, Problem, beam_strip, penalty_stiffness, rectangular_grid,
                                 relax_newton, table_edge, table_top)
from fabricfem.verify.references import elastica_tip_load

GF = STANDARD_GRAVITY * 1e-3  # one gram-force [N]
CM, MM = 1e-2, 1e-3

# Seed 001 sec. 4.3 table: theory and particle-model rows (p [cm], delta_y [cm], R_b [gf], R_c [gf])
OVERHANG_THEORY = {"p": 2.1213, "deflection": 0.0812, "R_b": 0.0135, "R_c": 0.0788}
OVERHANG_SEED_PARTICLE = {"p": 2.2499, "deflection": 0.0966, "R_b": 0.0156, "R_c": 0.0813}
OVERHANG_SEED_PARTICLE_ERROR = {"p": 6.06, "deflection": 18.0, "R_b": 15.52, "R_c": 3.15}  # percent

# Seed 001 sec. 4.4 table (experiment and particle model rows)
TABLECLOTH_EXPERIMENT = {"corner x/L": 0.39, "corner y/L": 0.38, "corner z/L": 0.39, "midside y/L": 0.18,
                         "midside z/L": 0.40}
TABLECLOTH_SEED_PARTICLE = {"corner x/L": 0.39, "corner y/L": 0.39, "corner z/L": 0.38, "midside y/L": 0.16,
                            "midside z/L": 0.37}
TABLECLOTH_SEED_PARTICLE_ERROR = {"corner x/L": 0.45, "corner y/L": 3.12, "corner z/L": 1.79, "midside y/L": 7.90,
                                  "midside z/L": 5.34}  # percent


def _percent(value: float, reference: float) -> float:
    return 100.0 * abs(value - reference) / abs(reference)


def particle_tip_loaded_cantilever(lam: float, n: int = 8) -> dict:
    """Seed 001 sec. 4.1: L = 1, EA = 2 sqrt(3) e-3, EI = 2 sqrt(3) e-9 (consistent units), P = lam EI / L^2,
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
    """Seed 001 sec. 4.3: L = 6 cm, overhang a = 1.5 cm past a frictionless table edge at x = 0, EA = 2809 gf,
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


def particle_tablecloth(n: int = 20, load_steps: int = 5) -> dict:
    """Seed 001 sec. 4.4: 20 cm square cloth centred on an 8 cm square frictionless table, E = 118.1176 gf/mm^2,
    weight 0.2384e-3 gf/mm^2, h = 0.54229 mm, nu = 0.3, n x n elements, solved to static equilibrium.

    Reading of the seed's table: its Fig. 23 shows the hem "projected on the xz plane", so y is vertical and
    x, z are horizontal, measured from the table centre (the corner has x/L ~ z/L by symmetry; the midside
    node, middle of an edge, is reported by its vertical y/L and its horizontal distance z/L). The seed does
    not say where y is measured from, so two readings are returned: "values" with y the drop below the table
    top, and "values_floor" with y the height above the floor on which the 8 cm cube of the experiment
    stands (table top at y/L = 0.4). (With the experimental corner, the first reading puts the corner
    9.3 cm from the table corner although only 8.49 cm of cloth lie between them; the second is feasible.)
    All lengths are normalized by L = 20 cm. The mirror planes x = 0 and
    y = 0 of the problem are imposed (x fixed on x = 0, y fixed on y = 0), which also removes the free in-plane
    sliding on the frictionless table. The table edge is rounded to b / 10. Newton's method from the flat
    sheet in load_steps equal gravity increments; the drape has several equilibria and this is the one
    reached on that path.
    """
    t0 = time.perf_counter()
    Lc = 20.0 * CM
    E, h, nu = 118.1176 * GF / MM ** 2, 0.54229 * MM, 0.3
    rho_a = 0.2384e-3 * GF / MM ** 2 / STANDARD_GRAVITY  # areal mass [kg/m^2]
    table_half, table_height = 4.0 * CM, 8.0 * CM
    b = Lc / n
    system = rectangular_grid(n + 1, n + 1, b, b, E, nu, h, rho_a, origin=(-Lc / 2, -Lc / 2, 0.0))
    if n % 2:
        raise ValueError(f"n must be even (a particle row on each mirror plane), got {n}")
    fixed = np.zeros((system.n, 3), dtype=bool)
    line = np.arange(n + 1)
    fixed[system.index(n // 2, line), 0] = True
    fixed[system.index(line, n // 2), 1] = True
    problem = Problem(system, fixed=fixed, obstacles=(
        table_top(0.0, 0.0, table_half, table_half, 0.0, penalty_stiffness(system), edge_radius=b / 10.0),))
    res = relax_newton(problem, load_steps=load_steps, max_iterations=400)
    x = res.x
    corner = x[system.index(-1, -1)]
    midside = x[system.index(n // 2, -1)]  # middle of the edge y = +L/2
    values = {"corner x/L": corner[0] / Lc, "corner y/L": -corner[2] / Lc, "corner z/L": corner[1] / Lc,
              "midside y/L": -midside[2] / Lc, "midside z/L": midside[1] / Lc}
    values_floor = dict(values)
    values_floor["corner y/L"] = (table_height + corner[2]) / Lc
    values_floor["midside y/L"] = (table_height + midside[2]) / Lc
    return {"values": values, "values_floor": values_floor, "experiment": dict(TABLECLOTH_EXPERIMENT),
            "error_floor_%": {k: _percent(values_floor[k], TABLECLOTH_EXPERIMENT[k]) for k in values},
            "seed_particle": dict(TABLECLOTH_SEED_PARTICLE),
            "seed_particle_error_%": dict(TABLECLOTH_SEED_PARTICLE_ERROR),
            "error_%": {k: _percent(values[k], TABLECLOTH_EXPERIMENT[k]) for k in values},
            "iterations": res.iterations, "residual": res.residual, "ndofs": 3 * system.n, "positions": x,
            "wall_s": time.perf_counter() - t0}
