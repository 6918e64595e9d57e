"""Speed versus accuracy of the cloth methods: error of a dynamic quantity against wall time.

Problem ("corner-pinned"; [Peng2022, sec. 4.1] parameters, the set-up of fabricfem.verify.strain_limit): a square
cloth of side L = 1 m in the plane z = 0, pinned at the corners (0, 0, 0) and (0, L, 0), released from rest
under gravity g = 9.81 m/s^2 along -z with the air drag eta = 0.351 kg/(m^2 s) of [Peng2022, eq. 17d];
rho = 0.117 kg/m^2, h = 0.001177 m, k = k_warp = k_weft = 2.5 k_shear with k / rho = 1000 (m/s)^2, nu = 0.
Quantity of interest: the displacement u_c of the free corner (L, L, 0) at t_end = 0.6 s (the time of the
seed's Table 1); the error of a run is |u_c - u_c,ref| / |u_c,ref| (relative, Euclidean).

Methods (all start from rest, flat; one resolution = one mesh size n x n cells and one time step):

* "particles": the seed-001 particle grid (fabricfem.particles.rectangular_grid, (n+1)^2 particles, E h = k,
  nu = 0, shear springs B' = 2 / 2.5 so that B' E h / 2 = k_shear, flexion springs with E h^3 / 12) and
  velocity Verlet (fabricfem.particles.simulate) at 0.9 x its Gershgorin critical step; the drag
  -eta v per area is the mass-proportional damping c = eta / rho [1/s] (force -c m v, m = rho x area);
* "explicit": the membrane model (fabricfem.shell.ShellModel(model="membrane"), Q2 quadrilaterals) with
  central differences and the lumped mass of [Man2006, eq. 2.82] (fabricfem.dynamics.CentralDifference) at
  0.9 x the critical step of fabricfem.dynamics.critical_time_step;
* "implicit": the same membrane with implicit Newmark, trapezoidal rule (beta = 1/4, gamma = 1/2, consistent
  mass; fabricfem.dynamics.NewmarkIntegrator), mesh and step refined together (n, dt) = (4, 0.02 s),
  (8, 0.01 s), (16, 0.005 s);
* "implicit+SL": "implicit" with the continuum strain limiting of [Peng2022, sec. 3] after every step
  (fabricfem.dynamics.strain_limit.FastProjection + attach; warp / weft Green strain limit 0.01, the seed's
  case (a), projection tolerance 1e-4 as in the verification case). With k / rho = 1000 the free swing
  strains the cloth up to ~0.01 near the pins, so the limit is active and changes the answer: its error
  against the unconstrained reference contains that modelling change.

Why the membrane and not the Naghdi shell for every finite-element variant: explicitly the Naghdi shell's step
is limited by thickness shear against the rotational inertia rho t^3 / 12 (fabricfem.dynamics.stability:
~1e-5 s here, 6e4 steps to 0.6 s), and the verification case of [Peng2022, sec. 4.1] (fabricfem.verify.
strain_limit) documents Newton divergence of the implicit shell with the projection. The benchmark compares
the cost and accuracy of the METHODS on one continuum model; the bending rigidity (B0 ~ 1e-5 N m here) only
shapes folds. The particle model's flexion springs keep that small bending stiffness (it is how the seed-001
model is built); its structural + diagonal springs do not reproduce the membrane's continuum exactly (the
diagonal springs add stretch stiffness and a Poisson coupling), so its error levels off at the model
difference instead of going to zero.

Reference: the implicit membrane on the finest mesh and smallest step afforded, (n, dt) = (32, 0.0025 s);
its convergence is shown by the difference to the next coarser reference level (16, 0.005 s), printed and
written to speed_accuracy_reference.csv. If the discretization error falls by a factor r >= 2 per level
(trapezoidal rule second order in dt; Q2 at least second order in h), the reference's own error is at most
that difference / (r - 1).

Timings: wall_s is the median of `repeats` runs of the time integration from rest to t_end (integrator set-up
included; mesh, forms, FFCx compilation and the critical-step estimate excluded), maximum over MPI ranks;
wall_vs_baseline divides it by the coarsest particle run measured in the same process (the machine is shared,
so only ratios within one run are meaningful). The particle model is serial numpy (each rank repeats it).

Conclusion for a target accuracy (1 %, 10 %): for each method the cheapest MEASURED run whose error is at
most the target (no interpolation, no extrapolation); the cheapest method wins, and its advantage is the
ratio of the next best method's cheapest qualifying wall time to its own.

Writes speed_accuracy.csv, speed_accuracy_reference.csv and speed_accuracy.png under `out`. SI units.

Second problem ("tablecloth", bench 2): the static drape of [Eischen2000, sec. 4.4], in
fabricfem.benchmarks.speed_accuracy_tablecloth; `speed_accuracy` runs either or both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.benchmarks.cheapest_run import TARGETS, Conclusion, cheapest_meeting, printer, set_baseline, timed
from fabricfem.benchmarks.speed_accuracy_tablecloth import (
    DRAPE_CSV_COLUMNS,
    DRAPE_FULL,
    DRAPE_METHODS,
    DRAPE_QUICK,
    DrapePlan,
    DrapeRow,
    plot_drape,
    run_drape_particles,
    run_drape_shell,
    same_branch,
    tablecloth_benchmark,
)
from fabricfem.dynamics import CentralDifference, NewmarkIntegrator
from fabricfem.dynamics import critical_time_step as shell_critical_time_step
from fabricfem.dynamics.strain_limit import FastProjection, attach
from fabricfem.particles import Problem, critical_time_step, rectangular_grid, simulate
from fabricfem.verify.strain_limit import corner_pinned_cloth

PROBLEM = "corner-pinned"
K_OVER_RHO = 1000.0  # k / rho [(m/s)^2], [Peng2022, sec. 4.1-4.2] range
AREAL_DENSITY = 0.117  # rho [kg/m^2], [Peng2022, sec. 4.1]
THICKNESS = 0.001177  # h [m], [Peng2022, sec. 4.1]
AIR_DRAG = 0.351  # eta [kg/(m^2 s)], [Peng2022, sec. 4.1] (eq. 17d)
STIFFNESS_OVER_SHEAR = 2.5  # k / k_shear, [Peng2022, sec. 4.1]
SIDE = 1.0  # L [m], as fabricfem.verify.strain_limit (the seed gives no size; see there)
GRAVITY = 9.81  # [m/s^2], as fabricfem.verify.strain_limit.corner_pinned_cloth
STRAIN_LIMIT = 0.01  # warp / weft Green strain limit [-], [Peng2022] case (a)
PROJECTION_TOL = 1e-4  # max violation accepted by the fast projection [-], as the verification case
EXPLICIT_SAFETY = 0.9  # dt = 0.9 x the method's critical step estimate
# Newton: up to 60 iterations per implicit step. The default 25 was exceeded by the strain-limited run at
# (n, dt) = (16, 0.005 s) at t = 0.56 s (28 needed, measured): the projection's velocity jump v += Delta q / dt
# puts the next step's predictor far from its solution. Converged steps are the same with either limit.
NEWTON_OPTIONS = {"snes_max_it": 60}
METHODS = ("particles", "explicit", "implicit", "implicit+SL")

CSV_COLUMNS = ("problem", "method", "resolution", "dt", "n_steps", "ndofs", "wall_s", "wall_vs_baseline", "error",
               "u_x", "u_y", "u_z")


@dataclass(frozen=True)
class Plan:
    """Resolutions of one benchmark run: cells per side for the explicit methods, (cells, dt [s]) for the
    implicit ones and the two reference levels (finest first), the end time [s] and the timing repeats."""

    t_end: float
    particles: tuple[int, ...]
    explicit: tuple[int, ...]
    implicit: tuple[tuple[int, float], ...]
    reference: tuple[int, float]
    reference_coarser: tuple[int, float]
    repeats: int


FULL = Plan(t_end=0.6, particles=(8, 16, 32, 64), explicit=(4, 8, 16), implicit=((4, 0.02), (8, 0.01), (16, 0.005)),
            reference=(32, 0.0025), reference_coarser=(16, 0.005), repeats=3)
# quick: half the swing (t_end 0.3 s), two levels per method, one timing, reference one level coarser
QUICK = Plan(t_end=0.3, particles=(4, 8), explicit=(4, 8), implicit=((4, 0.02), (8, 0.01)),
             reference=(16, 0.005), reference_coarser=(8, 0.01), repeats=1)


@dataclass
class SpeedRow:
    """One run: resolution, time step [s], cost [s] and the corner displacement [m] with its relative error."""

    problem: str
    method: str
    resolution: str
    dt: float
    n_steps: int
    ndofs: int
    wall_s: float
    wall_vs_baseline: float | None
    error: float | None
    u: np.ndarray  # free-corner displacement at t_end [m]
    cells: int = 0  # n of the n x n mesh / particle grid

    def as_list(self) -> list:
        """The CSV row (CSV_COLUMNS); "" for a missing ratio or error."""
        return [self.problem, self.method, self.resolution, self.dt, self.n_steps, self.ndofs, self.wall_s,
                "" if self.wall_vs_baseline is None else self.wall_vs_baseline,
                "" if self.error is None else self.error, *map(float, self.u)]


@dataclass
class Reference:
    """The reference corner displacement [m] and its convergence check against the next coarser level."""

    u: np.ndarray
    level: tuple[int, float]
    u_coarser: np.ndarray
    level_coarser: tuple[int, float]
    wall_s: float
    ndofs: int

    @property
    def level_difference(self) -> float:
        """|u_coarser - u| / |u| [-]: the coarser level's error, an upper estimate of the reference's."""
        return float(np.linalg.norm(self.u_coarser - self.u) / np.linalg.norm(self.u))


# ----------------------------------------------------------------------------------------- models
def _check_cells(n) -> int:
    """n (cells per side) as an int >= 2, else ValueError."""
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n (cells per side) must be an integer >= 2, got {n!r}")
    return int(n)


def _check_time(name: str, value) -> float:
    """A positive finite time [s] as float, else ValueError naming `name`."""
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite time [s], got {value!r}")
    return float(value)


def membrane_cloth(n: int, comm=MPI.COMM_WORLD):
    """The corner-pinned membrane cloth, n x n Q2 quadrilaterals (fabricfem.verify.strain_limit)."""
    return corner_pinned_cloth(K_OVER_RHO, _check_cells(n), size=SIDE, comm=comm)


def particle_cloth(n: int):
    """(n + 1) x (n + 1) particle grid of the same cloth: E h = k, nu = 0, k_shear = k / 2.5, drag eta / rho,
    pinned at (0, 0, 0) and (0, L, 0), gravity -z. Returns (Problem, index of the free corner (L, L))."""
    n = _check_cells(n)
    spacing = SIDE / n
    E = K_OVER_RHO * AREAL_DENSITY / THICKNESS  # E h = k = (k / rho) rho [N/m]
    # shear springs: B' E h / (2 (1 + nu)) = k / 2.5 with nu = 0 -> B' = 2 / 2.5 [Eischen2000, eq. 43]
    system = rectangular_grid(n + 1, n + 1, spacing, spacing, E, 0.0, THICKNESS, AREAL_DENSITY,
                              shear_factor=2.0 / STIFFNESS_OVER_SHEAR)
    problem = Problem(system, gravity=np.array([0.0, 0.0, -GRAVITY]), pinned=system.index([0, 0], [0, -1]),
                      damping=AIR_DRAG / AREAL_DENSITY)  # -eta v per area = -(eta / rho) m v
    return problem, int(system.index(-1, -1))


def free_corner(model) -> np.ndarray:
    """Displacement of the node at (L, L, 0) [m] (same on all ranks)."""
    return model.node_value((SIDE, SIDE, 0.0))


# ------------------------------------------------------------------------------------- one run
def _steps(t_end: float, dt_max: float) -> tuple[int, float]:
    """Smallest number of equal steps to t_end with dt <= dt_max."""
    n_steps = int(math.ceil(t_end / dt_max - 1e-12))
    return n_steps, t_end / n_steps


def _checked(u: np.ndarray, what: str) -> np.ndarray:
    """u [m] if finite, else RuntimeError naming `what`."""
    if not np.all(np.isfinite(u)):
        raise RuntimeError(f"{what}: non-finite corner displacement {u!r}")
    return u


def run_particles(n: int, t_end: float, repeats: int = 3, comm=MPI.COMM_WORLD) -> SpeedRow:
    """Velocity Verlet on the n x n-cell particle grid at 0.9 x its Gershgorin critical step."""
    problem, corner = particle_cloth(n)
    n_steps, dt = _steps(t_end, EXPLICIT_SAFETY * critical_time_step(problem))
    x0 = problem.system.positions[corner].copy()

    def run() -> np.ndarray:
        trajectory = simulate(problem, dt, n_steps, record_every=n_steps)
        return trajectory.x[corner] - x0

    wall, u = timed(run, repeats, comm)
    return SpeedRow(PROBLEM, "particles", f"n={n}", dt, n_steps, int(problem.free.sum()), wall, None, None,
                    _checked(u, f"particles n = {n}"), n)


def run_explicit(n: int, t_end: float, repeats: int = 3, comm=MPI.COMM_WORLD) -> SpeedRow:
    """Central differences with lumped mass on the n x n Q2 membrane at 0.9 x the critical step."""
    model = membrane_cloth(n, comm)
    n_steps, dt = _steps(t_end, EXPLICIT_SAFETY * shell_critical_time_step(model))

    def run() -> np.ndarray:
        model.w.x.array[:] = 0.0
        integrator = CentralDifference(model, dt, air_drag=AIR_DRAG)
        try:
            integrator.run(n_steps, output_every=n_steps)
        finally:
            integrator.destroy()
        return free_corner(model)

    wall, u = timed(run, repeats, comm)
    return SpeedRow(PROBLEM, "explicit", f"n={n}", dt, n_steps, model.ndofs, wall, None, None,
                    _checked(u, f"explicit n = {n}"), n)


def run_implicit(n: int, dt: float, t_end: float, strain_limit: float | None = None, repeats: int = 3,
                 comm=MPI.COMM_WORLD, model=None) -> SpeedRow:
    """Trapezoidal Newmark (consistent mass) on the n x n Q2 membrane with step dt (the largest step <= dt
    dividing t_end); with strain_limit, FastProjection after each step [Peng2022, eqs. 33-36]."""
    _check_time("dt", dt)
    if strain_limit is not None:
        _check_time("strain_limit", strain_limit)  # a positive finite number (dimensionless)
    model = membrane_cloth(n, comm) if model is None else model
    n_steps, dt = _steps(t_end, dt)

    def run() -> np.ndarray:
        model.w.x.array[:] = 0.0
        integrator = NewmarkIntegrator(model, dt, beta=0.25, gamma=0.5, air_drag=AIR_DRAG,
                                       newton_options=NEWTON_OPTIONS)
        projection = None
        try:
            if strain_limit is not None:
                projection = FastProjection(model, strain_limit, tol=PROJECTION_TOL)
                attach(projection, integrator)
            integrator.run(n_steps, output_every=n_steps)
        finally:
            integrator.destroy()
            if projection is not None:
                projection.destroy()
        return free_corner(model)

    method = "implicit" if strain_limit is None else "implicit+SL"
    wall, u = timed(run, repeats, comm)
    return SpeedRow(PROBLEM, method, f"n={n}, dt={dt:g}", dt, n_steps, model.ndofs, wall, None, None,
                    _checked(u, f"{method} n = {n}, dt = {dt:g} s"), n)


def reference_solution(plan: Plan, comm=MPI.COMM_WORLD, say: Callable[..., None] = lambda *a: None,
                       coarser: np.ndarray | None = None) -> Reference:
    """Implicit membrane at plan.reference and at plan.reference_coarser (one run each; `coarser` [m]: the
    corner displacement of the coarser level if already computed, e.g. as a measured implicit run)."""
    fine = run_implicit(*plan.reference, plan.t_end, repeats=1, comm=comm)
    say(f"reference (implicit membrane, {fine.resolution}): u_corner = {np.array2string(fine.u, precision=5)} m, "
        f"{fine.wall_s:.1f} s")
    if coarser is None:
        coarser = run_implicit(*plan.reference_coarser, plan.t_end, repeats=1, comm=comm).u
    ref = Reference(fine.u, plan.reference, np.asarray(coarser, dtype=float), plan.reference_coarser, fine.wall_s,
                    fine.ndofs)
    say(f"next coarser reference level (n={ref.level_coarser[0]}, dt={ref.level_coarser[1]:g}): u_corner = "
        f"{np.array2string(ref.u_coarser, precision=5)} m, relative difference {ref.level_difference:.3e}")
    return ref


# ---------------------------------------------------------------------------------------- plot
def plot_speed_accuracy(rows: Sequence[SpeedRow], reference: Reference, path: Path, t_end: float):
    """log-log error vs wall time, one line per method (rank 0 only)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    colors = {"particles": "tab:red", "explicit": "tab:green", "implicit": "tab:blue", "implicit+SL": "tab:purple"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for method in dict.fromkeys(r.method for r in rows):
        sel = sorted((r for r in rows if r.method == method), key=lambda r: r.wall_s)
        ax.plot([r.wall_s for r in sel], [r.error for r in sel], "o-", color=colors.get(method), label=method)
        for r in sel:
            ax.annotate(r.resolution.replace(", ", "\n"), (r.wall_s, r.error), fontsize=6, xytext=(3, 3),
                        textcoords="offset points")
    for target in TARGETS:
        ax.axhline(target, color="grey", ls="--", lw=0.8)
    ax.axhline(reference.level_difference, color="black", ls=":", lw=0.8,
               label=f"reference level difference ({reference.level_difference:.1e})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s] (median)")
    ax.set_ylabel("relative error of the free-corner displacement")
    ax.set_title(f"Corner-pinned cloth, k/rho = {K_OVER_RHO:g} (m/s)^2, t = {t_end:g} s")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------------------------- benchmark
def corner_pinned_benchmark(out: str | Path = "results/bench", quick: bool = False, methods: Sequence[str] = METHODS,
                            plan: Plan | None = None, comm=MPI.COMM_WORLD, verbose: bool = True) -> dict:
    """The corner-pinned benchmark (module doc); write speed_accuracy.csv / _reference.csv / .png under `out`.

    quick: QUICK plan (t_end 0.3 s, two levels per method, one timing, reference (16, 0.005 s)), else FULL;
    an explicit `plan` overrides both. Returns {"rows", "reference", "conclusions", "baseline_s"}.
    """
    plan = plan if plan is not None else (QUICK if quick else FULL)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"methods must be a non-empty subset of {METHODS}, got {tuple(methods)!r}")
    _check_time("plan.t_end", plan.t_end)
    if not (isinstance(plan.repeats, (int, np.integer)) and plan.repeats >= 1):
        raise ValueError(f"plan.repeats must be a positive integer, got {plan.repeats!r}")
    for n in (*plan.particles, *plan.explicit, *(n for n, _ in plan.implicit), plan.reference[0],
              plan.reference_coarser[0]):
        _check_cells(n)
    for _, dt in (*plan.implicit, plan.reference, plan.reference_coarser):
        _check_time("plan dt", dt)
    out = Path(out)
    say = printer(verbose, comm)
    rows: list[SpeedRow] = []
    runs: list[Callable[[], SpeedRow]] = []
    if "particles" in methods:
        runs += [lambda n=n: run_particles(n, plan.t_end, plan.repeats, comm) for n in plan.particles]
    if "explicit" in methods:
        runs += [lambda n=n: run_explicit(n, plan.t_end, plan.repeats, comm) for n in plan.explicit]
    for method, limit in (("implicit", None), ("implicit+SL", STRAIN_LIMIT)):
        if method in methods:
            runs += [lambda n=n, dt=dt, limit=limit: run_implicit(n, dt, plan.t_end, limit, plan.repeats, comm)
                     for n, dt in plan.implicit]
    for run in runs:
        row = run()
        rows.append(row)
        say(f"{row.method:>12} {row.resolution:<16} dt = {row.dt:.3e} s, {row.n_steps:5d} steps, {row.ndofs:6d} dofs: "
            f"{row.wall_s:8.3f} s, u_corner = {np.array2string(row.u, precision=5)} m")
    # the coarser reference level is usually a measured implicit run: reuse it
    same = [r for r in rows if r.method == "implicit" and (r.cells, r.dt)
            == (plan.reference_coarser[0], _steps(plan.t_end, plan.reference_coarser[1])[1])]
    reference = reference_solution(plan, comm, say, coarser=same[0].u if same else None)
    for row in rows:
        row.error = float(np.linalg.norm(row.u - reference.u) / np.linalg.norm(reference.u))
        say(f"{row.method:>12} {row.resolution:<16} error {row.error:.3e}")
    # baseline: the coarsest particle run (or, without particles, the cheapest run)
    baseline = set_baseline(rows, "particles")
    conclusions = [cheapest_meeting(rows, target) for target in TARGETS]

    io.write_csv(out / "speed_accuracy.csv", CSV_COLUMNS, [r.as_list() for r in rows], comm=comm)
    io.write_csv(out / "speed_accuracy_reference.csv",
                 ("level", "n", "dt", "u_x", "u_y", "u_z", "relative_difference_to_reference"),
                 [("reference", *reference.level, *map(float, reference.u), 0.0),
                  ("next coarser", *reference.level_coarser, *map(float, reference.u_coarser),
                   reference.level_difference)], comm=comm)
    if comm.rank == 0:
        plot_speed_accuracy(rows, reference, out / "speed_accuracy.png", plan.t_end)
    say(f"baseline: {baseline.method} {baseline.resolution}, {baseline.wall_s:.4g} s; wall_vs_baseline in the CSV")
    for c in conclusions:
        say(c.sentence())
    return {"rows": rows, "reference": reference, "conclusions": conclusions, "baseline_s": baseline.wall_s}


BENCHMARKS = ("corner-pinned", "tablecloth")


def speed_accuracy(out: str | Path = "results/bench", quick: bool = False, methods: Sequence[str] = METHODS,
                   plan: Plan | None = None, comm=MPI.COMM_WORLD, verbose: bool = True,
                   problems: Sequence[str] = BENCHMARKS, drape_plan: DrapePlan | None = None) -> dict:
    """Run the benchmarks named in `problems` (module doc): "corner-pinned" (corner_pinned_benchmark, with
    `methods` and `plan`) and "tablecloth" (tablecloth_benchmark, with `drape_plan`); both write under `out`.
    Returns the corner-pinned result dict (keys rows, reference, conclusions, baseline_s) with the tablecloth
    one under the key "tablecloth"."""
    unknown = [p for p in problems if p not in BENCHMARKS]
    if unknown or not problems:
        raise ValueError(f"problems must be a non-empty subset of {BENCHMARKS}, got {tuple(problems)!r}")
    result: dict = {}
    if "corner-pinned" in problems:
        result.update(corner_pinned_benchmark(out, quick, methods, plan, comm, verbose))
    if "tablecloth" in problems:
        result["tablecloth"] = tablecloth_benchmark(out, quick, drape_plan, comm, verbose)
    return result


__all__ = ["AIR_DRAG", "CSV_COLUMNS", "Conclusion", "FULL", "K_OVER_RHO", "METHODS", "Plan", "QUICK", "Reference",
           "SpeedRow", "STRAIN_LIMIT", "TARGETS", "cheapest_meeting", "free_corner", "membrane_cloth",
           "particle_cloth", "plot_speed_accuracy", "reference_solution", "run_explicit", "run_implicit",
           "run_particles", "speed_accuracy",
           # the tablecloth benchmark's names, importable from here too (fabricfem.benchmarks.speed_accuracy_tablecloth)
           "BENCHMARKS", "DRAPE_CSV_COLUMNS", "DRAPE_FULL", "DRAPE_METHODS", "DRAPE_QUICK", "DrapePlan", "DrapeRow",
           "corner_pinned_benchmark", "plot_drape", "run_drape_particles", "run_drape_shell", "same_branch",
           "tablecloth_benchmark"]
