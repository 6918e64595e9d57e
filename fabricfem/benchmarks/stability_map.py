"""Stability map of the explicit schemes: largest stable time step vs in-plane stiffness and mesh size.

Set-up ([Peng2022, sec. 4.1], "corner kidnapped cloth"): a square cloth of side 0.2 m in the plane z = 0,
pinned (displacements zero, rotations free) at its two corners on y = 0.2 m and released from rest under
gravity (9.80665 m/s^2 along -z). In-plane model of the seed: k = k_weft = k_warp = 2.5 k_shear with k / rho
in {50, 200, 1000, 5000} (m/s)^2, areal density rho = 0.117 kg/m^2, thickness h = 0.001177 m. Mapping:

* shell (fabricfem.shell.ShellModel, Naghdi, Q2 quadrilaterals, central differences with the lumped mass of
  [Man2006, eq. 2.82]): E t = k [N/m], i.e. E1 = E2 = (k / rho) rho / h [Pa], G12 = G13 = E / 2.5, nu12 = 0,
  volumetric density rho / h [kg/m^3]; "membrane" is the same sheet without bending and thickness shear;
* particles (fabricfem.particles.rectangular_grid, velocity Verlet): the same E, nu = 0 and h; the structural
  springs then carry k per unit width, and the shear springs get shear_factor 2 / 2.5 so that their
  constant B' E h / (2 (1 + nu)) = k / 2.5 = k_shear.

n x n cells (elements, or particle-grid cells) with n in {8, 16}. For each case:

* dt_predicted: the critical step of the method's own estimate, 2 / omega_max [Man2006, eq. 2.86]: for the
  shell stability.critical_time_step (eq. 2.87 extended with the Q2 constant and thickness shear), for the
  particles particles.critical_time_step (Gershgorin bound of M^-1 K);
* dt_measured: the largest step for which a run of n_steps steps from rest neither raises DynamicsError /
  DivergenceError nor lets the energy exceed 10 x the scale of the loads' work (both integrators' built-in
  blow-up checks), by bisection to rel_tol (stability.measured_critical_time_step);
* dt_eigen: 2 / omega_max with omega_max the largest eigenfrequency of K vs the lumped mass on the free dofs
  at the reference state (SLEPc for the shell, scipy eigsh for the particles): the linear stability limit of
  central differences / velocity Verlet (undamped), an independent reference for dt_measured;
* dt_eigen_end: the same at the state reached after n_steps at dt_measured. A stretched St. Venant-Kirchhoff
  membrane stiffens (tangent E (3 F^2 - 1) / 2 in 1D), most near the pinned corners, so for soft cloth the
  limit drops during the run and dt_measured depends on the run length (linear springs of the particle
  model do not stiffen along their axis);
* timing: the median wall time per step of `repeats` runs at 0.9 dt_measured, its cost per simulated second
  (wall / dt) and that cost relative to the particle model on the same mesh and k / rho (same process);
* memory: the process's peak resident set size (getrusage ru_maxrss) after each case.

Writes stability_map.csv, stability_map.png and stability_map_memory.csv under `out`. SI units.
"""
from __future__ import annotations

import importlib
import math
import resource
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI

from fabricfem import io
from fabricfem.dynamics import CentralDifference, discrete_max_frequency, measured_critical_time_step
from fabricfem.dynamics import critical_time_step as shell_critical_time_step
from fabricfem.dynamics.explicit import runs_stably
from fabricfem.dynamics.stability import MEMBRANE_KAPPA, min_edge_length, plane_stress_wave_speed
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.particles import (
    DivergenceError,
    Problem,
    critical_time_step,
    rectangular_grid,
    simulate,
    stiffness_matrix,
)
from fabricfem.shell import ShellModel

AREAL_DENSITY = 0.117  # rho [kg/m^2], [Peng2022, sec. 4.1]
THICKNESS = 0.001177  # h [m], [Peng2022, sec. 4.1]
STIFFNESS_OVER_SHEAR = 2.5  # k / k_shear, [Peng2022, sec. 4.1]
SIDE = 0.2  # cloth side [m]
GRAVITY = 9.80665  # [m/s^2]
K_OVER_RHO = (50.0, 200.0, 1000.0, 5000.0)  # [(m/s)^2], [Peng2022, sec. 4.1-4.2] range
MESHES = (8, 16)
METHODS = ("shell", "membrane", "particles")

CSV_COLUMNS = ("method", "k_over_rho", "n", "dt_predicted", "dt_measured", "ratio", "dt_eigen",
               "measured_over_eigen", "dt_eigen_end", "dt_membrane_estimate", "ndofs", "n_steps", "step_wall_s",
               "wall_per_simulated_s", "cost_vs_particles", "rss_hwm_MiB")


@dataclass
class StabilityRow:
    """One case of the map: time steps [s], ratios [-], timings [s], memory [MiB]."""

    method: str
    k_over_rho: float
    n: int
    dt_predicted: float
    dt_measured: float
    ratio: float  # dt_measured / dt_predicted
    dt_eigen: float
    measured_over_eigen: float
    dt_eigen_end: float  # 2 / omega_max at the end of a run of n_steps at dt_measured (deformed state)
    dt_membrane_estimate: float | None  # 2 / omega_membrane of the shell estimate (no thickness shear)
    ndofs: int
    n_steps: int
    step_wall_s: float
    wall_per_simulated_s: float
    cost_vs_particles: float | None
    rss_hwm_MiB: float

    def as_list(self) -> list:
        return ["" if getattr(self, c) is None else getattr(self, c) for c in CSV_COLUMNS]


# ----------------------------------------------------------------------------------------- models
def _check_inputs(k_over_rho: float, n: int):
    if not (isinstance(k_over_rho, (int, float, np.floating)) and math.isfinite(k_over_rho) and k_over_rho > 0):
        raise ValueError(f"k_over_rho must be a positive finite number [(m/s)^2], got {k_over_rho!r}")
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n (cells per side) must be an integer >= 2, got {n!r}")


def youngs_modulus(k_over_rho: float) -> float:
    """E [Pa] with E h = k = (k / rho) rho ([Peng2022]'s areal stiffness k [N/m] on a sheet of thickness h)."""
    return float(k_over_rho) * AREAL_DENSITY / THICKNESS


def shell_fabric(k_over_rho: float):
    """Fabric with E1 = E2 = k / h, G12 = G13 = E / 2.5, nu12 = 0 and areal density 0.117 kg/m^2."""
    _check_inputs(k_over_rho, 2)
    E = youngs_modulus(k_over_rho)
    return Fabric(E1=E, E2=E, G12=E / STIFFNESS_OVER_SHEAR, nu12=0.0, thickness=THICKNESS,
                  density=AREAL_DENSITY / THICKNESS, name=f"seed-002 k/rho = {k_over_rho:g}")


def shell_cloth(k_over_rho: float, n: int, model: str = "naghdi", comm=MPI.COMM_WORLD):
    """Square Q2 sheet (side 0.2 m, n x n elements) pinned at (0, 0.2, 0) and (0.2, 0.2, 0), under gravity."""
    _check_inputs(k_over_rho, n)
    sheet = ShellModel(plate(SIDE, SIDE, n, n, cell="quadrilateral", comm=comm), shell_fabric(k_over_rho),
                       model=model)
    for x_corner in (0.0, SIDE):
        sheet.constrain(lambda x, xc=x_corner: np.isclose(x[0], xc) & np.isclose(x[1], SIDE), u=(0.0, 0.0, 0.0))
    sheet.add_gravity((0.0, 0.0, -GRAVITY))
    sheet.compile()
    return sheet


def particle_cloth(k_over_rho: float, n: int):
    """(n + 1) x (n + 1) particle grid (spacing 0.2 / n m) with the same E, nu = 0, h; k_shear = k / 2.5;
    pinned at the two corners on y = 0.2 m, under gravity."""
    _check_inputs(k_over_rho, n)
    spacing = SIDE / n
    # shear springs: B' E h / (2 (1 + nu)) = k / 2.5 with nu = 0 -> B' = 2 / 2.5 ([Eischen2000, eq. 43], [Peng2022])
    system = rectangular_grid(n + 1, n + 1, spacing, spacing, youngs_modulus(k_over_rho), 0.0, THICKNESS,
                              AREAL_DENSITY, shear_factor=2.0 / STIFFNESS_OVER_SHEAR)
    return Problem(system, gravity=np.array([0.0, 0.0, -GRAVITY]), pinned=system.index([0, -1], [-1, -1]))


# -------------------------------------------------------------------------- stability of one run
def shell_run_is_stable(sheet, dt: float, n_steps: int) -> bool:
    """n_steps central-difference steps from rest; False if stopped by the blow-up check (DynamicsError)."""
    return runs_stably(sheet, dt, n_steps)


def particle_run_is_stable(problem, dt: float, n_steps: int) -> bool:
    """n_steps velocity-Verlet steps from rest; False if stopped as diverged (DivergenceError)."""
    try:
        simulate(problem, dt, n_steps, record_every=max(1, n_steps // 20))  # energy bound default 10
        return True
    except DivergenceError:
        return False


def bracketed_critical_time_step(run_is_stable: Callable[[float], bool], dt_guess: float, rel_tol: float = 0.01,
                                 low: float = 0.8, high: float = 1.6, max_expansions: int = 8) -> float:
    """Largest stable step near dt_guess [s]: widen [low, high] dt_guess by halving / doubling until low is
    stable and high is not, then bisect (stability.measured_critical_time_step). Runs are memoized."""
    if not (math.isfinite(dt_guess) and dt_guess > 0):
        raise ValueError(f"dt_guess must be positive and finite, got {dt_guess!r}")
    cache: dict[float, bool] = {}

    def stable(dt: float) -> bool:
        if dt not in cache:
            cache[dt] = bool(run_is_stable(dt))
        return cache[dt]

    dt_low, dt_high = low * dt_guess, high * dt_guess
    for _ in range(max_expansions):
        if stable(dt_low):
            break
        dt_low, dt_high = 0.5 * dt_low, dt_low
    else:
        raise RuntimeError(f"no stable step found down to {dt_low:.4g} s (guess {dt_guess:.4g} s)")
    for _ in range(max_expansions):
        if not stable(dt_high):
            break
        dt_low, dt_high = dt_high, 2.0 * dt_high
    else:
        raise RuntimeError(f"every step up to {dt_high:.4g} s was stable (guess {dt_guess:.4g} s)")
    return measured_critical_time_step(stable, dt_low, dt_high, rel_tol=rel_tol)


# ------------------------------------------------------------------------- linear stability limits
def shell_eigen_time_step(sheet) -> float:
    """2 / omega_max of K vs M_L at the current state ([Man2006, eq. 2.86] with the discrete omega_max, SLEPc)."""
    return 2.0 / discrete_max_frequency(sheet, iterations=2000)


def shell_membrane_time_step(sheet) -> float:
    """2 / omega_membrane of the shell estimate (eq. 2.87 with the Q2 constant, no thickness shear) [s]."""
    kappa = MEMBRANE_KAPPA[sheet.mesh.ufl_cell().cellname()]
    return 2.0 * min_edge_length(sheet.mesh) / (kappa * plane_stress_wave_speed(sheet.fabric))


def shell_end_state_eigen_time_step(sheet, dt: float, n_steps: int) -> float:
    """2 / omega_max of K(d) vs M_L at the end of n_steps central-difference steps of dt from rest [s]."""
    sheet.w.x.array[:] = 0.0
    integrator = CentralDifference(sheet, dt, force=True)
    try:
        integrator.run(n_steps, output_every=n_steps)  # leaves the final state in sheet.w
        return shell_eigen_time_step(sheet)
    finally:
        integrator.destroy()
        sheet.w.x.array[:] = 0.0


def particle_eigen_time_step(problem, x: np.ndarray | None = None) -> float:
    """2 / omega_max of K(x) vs the particle masses on the free coordinates (scipy eigsh); x defaults to the
    reference positions. The exact Hessian (compressive geometric stiffness included) is used."""

    system = problem.system
    free = problem.free.ravel()
    K = stiffness_matrix(system, system.positions if x is None else x, definite=False)[free][:, free]
    scale = sp.diags(1.0 / np.sqrt(np.repeat(system.mass, 3)[free]))
    lam = float(spla.eigsh(scale @ K @ scale, k=1, which="LA", return_eigenvectors=False)[0])
    if not lam > 0:
        raise RuntimeError(f"largest eigenvalue of M^-1 K is not positive ({lam!r})")
    return 2.0 / math.sqrt(lam)


# ------------------------------------------------------------------------------------ one case
def peak_rss_mib(comm=MPI.COMM_WORLD) -> float:
    """Peak resident set size of this process [MiB] (getrusage ru_maxrss, KiB on Linux), max over ranks."""
    return comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, op=MPI.MAX)


def _median_step_time(run_steps: Callable[[], None], n_steps: int, repeats: int, comm) -> float:
    times = []
    for _ in range(repeats):
        comm.barrier()
        t0 = time.perf_counter()
        run_steps()
        times.append(comm.allreduce(time.perf_counter() - t0, op=MPI.MAX) / n_steps)
    return float(statistics.median(times))


def measure_case(method: str, k_over_rho: float, n: int, n_steps: int = 200, rel_tol: float = 0.01,
                 repeats: int = 3, timing_steps: int = 50, comm=MPI.COMM_WORLD) -> StabilityRow:
    """Predicted, measured and eigenvalue critical steps of one method / stiffness / mesh (see module doc)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    _check_inputs(k_over_rho, n)
    for name, value in (("n_steps", n_steps), ("repeats", repeats), ("timing_steps", timing_steps)):
        if not (isinstance(value, (int, np.integer)) and value >= 1):
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if not (math.isfinite(rel_tol) and 0 < rel_tol < 0.5):
        raise ValueError(f"rel_tol must lie in (0, 0.5), got {rel_tol!r}")
    if method == "particles":
        problem = particle_cloth(k_over_rho, n)
        dt_predicted = critical_time_step(problem)
        dt_eigen = particle_eigen_time_step(problem)
        dt_membrane = None
        ndofs = int(problem.free.sum())
        dt_measured = bracketed_critical_time_step(lambda dt: particle_run_is_stable(problem, dt, n_steps),
                                                   dt_predicted, rel_tol)
        dt_eigen_end = particle_eigen_time_step(problem, simulate(problem, dt_measured, n_steps,
                                                                  record_every=n_steps).x)
        step_wall = _median_step_time(
            lambda: simulate(problem, 0.9 * dt_measured, timing_steps, record_every=timing_steps),
            timing_steps, repeats, comm)
    else:
        sheet = shell_cloth(k_over_rho, n, model="naghdi" if method == "shell" else "membrane", comm=comm)
        dt_predicted = shell_critical_time_step(sheet)
        dt_eigen = shell_eigen_time_step(sheet)
        dt_membrane = shell_membrane_time_step(sheet)
        ndofs = sheet.ndofs
        dt_measured = bracketed_critical_time_step(lambda dt: shell_run_is_stable(sheet, dt, n_steps),
                                                   dt_predicted, rel_tol)
        dt_eigen_end = shell_end_state_eigen_time_step(sheet, dt_measured, n_steps)

        def timed_run():
            sheet.w.x.array[:] = 0.0
            integrator = CentralDifference(sheet, 0.9 * dt_measured, force=True)
            integrator.initialize()
            t0 = time.perf_counter()
            integrator.run(timing_steps, output_every=timing_steps)
            elapsed = time.perf_counter() - t0
            integrator.destroy()
            return elapsed

        step_wall = float(statistics.median(comm.allreduce(timed_run(), op=MPI.MAX) / timing_steps
                                            for _ in range(repeats)))
    values = dict(dt_predicted=dt_predicted, dt_measured=dt_measured, dt_eigen=dt_eigen, dt_eigen_end=dt_eigen_end,
                  step_wall=step_wall)
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0):
            raise RuntimeError(f"{method}, k/rho = {k_over_rho:g}, n = {n}: {name} = {value!r} is not positive")
    return StabilityRow(method, float(k_over_rho), int(n), dt_predicted, dt_measured, dt_measured / dt_predicted,
                        dt_eigen, dt_measured / dt_eigen, dt_eigen_end, dt_membrane, ndofs, int(n_steps), step_wall,
                        step_wall / (0.9 * dt_measured), None, peak_rss_mib(comm))


# ------------------------------------------------------------------------------------ the map
def plot_map(rows: Sequence[StabilityRow], path: Path):
    """log-log dt vs k / rho: predicted steps as lines, measured as markers (rank 0 only)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    colors = {"shell": "tab:blue", "membrane": "tab:green", "particles": "tab:red"}
    markers = {8: "o", 16: "s"}
    styles = {8: "-", 16: "--"}
    fig, ax = plt.subplots(figsize=(10, 5))
    for method in dict.fromkeys(r.method for r in rows):
        for n in sorted({r.n for r in rows if r.method == method}):
            sel = sorted((r for r in rows if r.method == method and r.n == n), key=lambda r: r.k_over_rho)
            k = [r.k_over_rho for r in sel]
            ax.plot(k, [r.dt_predicted for r in sel], styles.get(n, ":"), color=colors[method],
                    label=f"{method} {n}x{n}: predicted")
            ax.plot(k, [r.dt_measured for r in sel], markers.get(n, "^"), color=colors[method], mfc="none",
                    label=f"{method} {n}x{n}: measured")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("k / rho [(m/s)^2]")
    ax.set_ylabel("critical time step [s]")
    ax.set_title("Explicit stability: 0.2 m cloth pinned at two corners, gravity")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def stability_map(out: str | Path = "results/bench", quick: bool = False,
                  k_over_rho: Sequence[float] | None = None, meshes: Sequence[int] | None = None,
                  methods: Sequence[str] = METHODS, n_steps: int | None = None, rel_tol: float = 0.01,
                  repeats: int = 3, comm=MPI.COMM_WORLD, verbose: bool = True) -> list[StabilityRow]:
    """Run the map (see module doc) and write stability_map.csv / .png / _memory.csv under `out`.

    quick: k / rho = 1000 only, the 8 x 8 mesh, 100-step runs (smoke test); explicit arguments override.
    """
    k_values = tuple(k_over_rho) if k_over_rho is not None else ((1000.0,) if quick else K_OVER_RHO)
    mesh_sizes = tuple(meshes) if meshes is not None else ((8,) if quick else MESHES)
    n_steps = n_steps if n_steps is not None else (100 if quick else 200)
    if not (isinstance(n_steps, (int, np.integer)) and n_steps >= 1):
        raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
    if not k_values or not mesh_sizes:
        raise ValueError("k_over_rho and meshes must not be empty")
    for k in k_values:
        _check_inputs(k, 2)
    for n in mesh_sizes:
        _check_inputs(1.0, n)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"methods must be a non-empty subset of {METHODS}, got {tuple(methods)!r}")
    out = Path(out)
    say = (lambda *a: print(*a, flush=True)) if (verbose and comm.rank == 0) else (lambda *a: None)
    if any(m != "particles" for m in methods):
        importlib.import_module("dolfinx")  # the baseline memory includes the FE libraries
    memory = [("before the first case (libraries imported)", peak_rss_mib(comm))]
    rows: list[StabilityRow] = []
    # particles first (the cost baseline); the shell cases in order of size, so the last is the largest
    order = [m for m in ("particles", "membrane", "shell") if m in methods]
    for method in order:
        for n in sorted(mesh_sizes):
            for k in k_values:
                row = measure_case(method, k, n, n_steps=n_steps, rel_tol=rel_tol, repeats=repeats, comm=comm)
                rows.append(row)
                memory.append((f"after {method} n = {n} k/rho = {k:g} ({row.ndofs} dofs)", row.rss_hwm_MiB))
                say(f"{method:>9} k/rho = {k:6g}  n = {n:3d}: dt predicted {row.dt_predicted:.4e} s, measured "
                    f"{row.dt_measured:.4e} s (ratio {row.ratio:.3f}), eigen {row.dt_eigen:.4e} s "
                    f"(measured / eigen {row.measured_over_eigen:.3f}; at the end state {row.dt_eigen_end:.4e} s), "
                    f"{row.step_wall_s * 1e3:.2f} ms/step")
    baseline = {(r.k_over_rho, r.n): r.wall_per_simulated_s for r in rows if r.method == "particles"}
    for r in rows:
        if (r.k_over_rho, r.n) in baseline:
            r.cost_vs_particles = r.wall_per_simulated_s / baseline[(r.k_over_rho, r.n)]
    io.write_csv(out / "stability_map.csv", CSV_COLUMNS, [r.as_list() for r in rows], comm=comm)
    largest = max(rows, key=lambda r: r.ndofs)
    memory.append((f"peak after all cases; largest case {largest.method} n = {largest.n} ({largest.ndofs} dofs)",
                   peak_rss_mib(comm)))
    io.write_csv(out / "stability_map_memory.csv", ("stage", "rss_hwm_MiB"), memory, comm=comm)
    say(f"peak resident memory (ru_maxrss, max over {comm.size} rank(s)): {memory[0][1]:.1f} MiB before the "
        f"first case, {memory[-1][1]:.1f} MiB after the largest ({largest.method}, n = {largest.n}, "
        f"{largest.ndofs} dofs)")
    if comm.rank == 0:
        plot_map(rows, out / "stability_map.png")
    return rows


__all__ = ["AREAL_DENSITY", "CSV_COLUMNS", "K_OVER_RHO", "MESHES", "METHODS", "StabilityRow", "THICKNESS",
           "bracketed_critical_time_step", "measure_case", "particle_cloth", "particle_eigen_time_step",
           "particle_run_is_stable", "peak_rss_mib", "plot_map", "shell_cloth", "shell_eigen_time_step",
           "shell_end_state_eigen_time_step", "shell_fabric", "shell_membrane_time_step", "shell_run_is_stable",
           "stability_map", "youngs_modulus"]
