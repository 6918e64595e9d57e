"""Speed versus accuracy of the cloth methods, second problem ("tablecloth", bench 2; the first, the corner-pinned
cloth, is fabricfem.benchmarks.speed_accuracy, which runs both): the static drape of [Eischen2000, sec. 4.4] (20 cm
cotton cloth on an 8 cm square frictionless table, fabricfem.verify.drape / particles_cases) on ONE well-defined
equilibrium: the diagonal-symmetric branch reached by static load stepping from the flat sheet with the mirror
planes x = 0, y = 0 imposed and no imperfection (the drape has several equilibria: the dynamic drops of the verification
case tablecloth-drop reach other, folded ones, so their positions against this reference would measure the
branch, not the discretization; they are not in this benchmark). Methods:

* "particles static": the seed-001 particle grid n x n over the whole cloth (n = 10, 20, 30; the seed's grid
  is 20), Newton relaxation in 5 load steps (particles_cases.particle_tablecloth_nodes);
* "shell static": the Naghdi shell, quarter model n x n Q2 quadrilaterals (n = 5, 10, 15, i.e. 10, 20, 30
  element rows across the cloth), Newton with adaptive load steps (drape.fe_tablecloth_nodes).

Reference: the shell on the quarter mesh n = 30 (60 x 60 across the cloth); its convergence is shown by the
error of the finest measured shell mesh (n = 15), printed and drawn in the plot. Error of a run:
max(|x_corner - x_corner,ref|, |x_midside - x_midside,ref|) / L with the corner (L/2, L/2) and the midside
(0, L/2) of the reference configuration. Time: median of `repeats` solves including the set-up (mesh, forms,
contact; FFCx compilation is cached after the first call), ratios against the coarsest particle run of the
same process. Conclusions as for the corner-pinned cloth. Writes speed_accuracy_tablecloth.csv (the last
row is the reference) and speed_accuracy_tablecloth.png. SI units.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.benchmarks.cheapest_run import TARGETS, cheapest_meeting, printer, set_baseline, timed
from fabricfem.verify.drape import CLOTH_L, fe_tablecloth_nodes
from fabricfem.verify.particles_cases import particle_tablecloth_nodes

__all__ = ["BRANCH_ASYMMETRY", "DRAPE_CSV_COLUMNS", "DRAPE_FULL", "DRAPE_METHODS", "DRAPE_PROBLEM", "DRAPE_QUICK",
           "DrapePlan", "DrapeRow", "plot_drape", "run_drape_particles", "run_drape_shell", "same_branch",
           "tablecloth_benchmark"]

DRAPE_PROBLEM = "tablecloth"
DRAPE_METHODS = ("particles static", "shell static")
DRAPE_CSV_COLUMNS = ("problem", "method", "resolution", "grid", "iterations", "ndofs", "wall_s", "wall_vs_baseline",
                     "error", "folds", "diagonal_asymmetry", "same_branch", "corner_x", "corner_y", "corner_z",
                     "midside_x", "midside_y", "midside_z")


@dataclass(frozen=True)
class DrapePlan:
    """Resolutions of the tablecloth benchmark: particle grids n x n over the whole cloth (n a multiple of
    10: particle rows on the table edges and the mirror lines), shell quarter meshes n x n Q2 quadrilaterals
    (n a multiple of 5: nodes on the table edge; n quads on the quarter = a 2n x 2n grid of the cloth), the
    reference shell mesh and the timing repeats."""

    particles: tuple[int, ...]
    shell: tuple[int, ...]
    reference: int
    repeats: int


DRAPE_FULL = DrapePlan(particles=(10, 20, 30), shell=(5, 10, 15), reference=30, repeats=3)
DRAPE_QUICK = DrapePlan(particles=(10,), shell=(5,), reference=10, repeats=1)


@dataclass
class DrapeRow:
    """One static drape solve: corner (L/2, L/2) and midside (0, L/2) positions [m] (table top z = 0) and
    error = max of their distances to the reference, / L."""

    problem: str
    method: str
    resolution: str
    grid: int  # nodes per side of the whole cloth minus one (the seed's "20 x 20 grid" is 20)
    iterations: int
    ndofs: int
    wall_s: float
    wall_vs_baseline: float | None
    error: float | None
    corner: np.ndarray
    midside: np.ndarray
    folds: int = 0
    diagonal_asymmetry: float = 0.0
    same_branch: bool | None = None

    def as_list(self) -> list:
        """The CSV row (DRAPE_CSV_COLUMNS); "" for a missing ratio, error or branch test."""
        return [self.problem, self.method, self.resolution, self.grid, self.iterations, self.ndofs, self.wall_s,
                "" if self.wall_vs_baseline is None else self.wall_vs_baseline,
                "" if self.error is None else self.error, self.folds, self.diagonal_asymmetry,
                "" if self.same_branch is None else int(self.same_branch),
                *map(float, self.corner), *map(float, self.midside)]


BRANCH_ASYMMETRY = 0.01  # |x_c - y_c| / L above which a corner has left the diagonal (1 % of L = 2 mm)


def same_branch(row: DrapeRow, reference: DrapeRow) -> bool:
    """A run is on the reference's equilibrium branch when its hem has the same number of folds and its
    corner is on the same side of the diagonal-symmetry test (asymmetry below or above BRANCH_ASYMMETRY).
    The symmetric static branch is unstable from the first load steps on (lowest tangent eigenvalue < 0
    already at 2 % of the weight, measured on the 5 x 5 and 10 x 10 quarter meshes), so different meshes
    can leave it at different loads; comparing positions across branches would measure the branch."""
    return (row.folds == reference.folds
            and (row.diagonal_asymmetry > BRANCH_ASYMMETRY) == (reference.diagonal_asymmetry > BRANCH_ASYMMETRY))


def _check_drape_plan(plan: DrapePlan) -> None:
    """ValueError unless the particle grids are multiples of 10, the shell meshes of 5 and repeats >= 1."""
    for n in plan.particles:
        if not (isinstance(n, (int, np.integer)) and n >= 10 and n % 10 == 0):
            raise ValueError(f"plan.particles: n must be a multiple of 10, got {n!r}")
    for n in (*plan.shell, plan.reference):
        if not (isinstance(n, (int, np.integer)) and n >= 5 and n % 5 == 0):
            raise ValueError(f"plan.shell / plan.reference: n must be a multiple of 5, got {n!r}")
    if not (isinstance(plan.repeats, (int, np.integer)) and plan.repeats >= 1):
        raise ValueError(f"plan.repeats must be a positive integer, got {plan.repeats!r}")


def run_drape_particles(n: int, repeats: int = 3, comm=MPI.COMM_WORLD) -> DrapeRow:
    """Particle model, static relaxation (Newton from the flat sheet, 5 load steps, mirror planes):
    fabricfem.verify.particles_cases.particle_tablecloth_nodes (set-up included in the time)."""
    wall, r = timed(lambda: particle_tablecloth_nodes(n), repeats, comm)
    return DrapeRow(DRAPE_PROBLEM, "particles static", f"particles n={n}", n, r["iterations"], r["ndofs"], wall, None,
                    None, r["corner"], r["midside"], r["folds"], r["diagonal_asymmetry"])


def run_drape_shell(n: int, repeats: int = 3, comm=MPI.COMM_WORLD) -> DrapeRow:
    """Naghdi shell, static Newton with adaptive load steps on the weight (quarter model, mirror planes, no
    imperfection): fabricfem.verify.drape.fe_tablecloth_nodes (mesh, forms and contact set-up included in
    the time, FFCx compilation cached after the first call)."""
    wall, r = timed(lambda: fe_tablecloth_nodes(n, comm=comm), repeats, comm)
    return DrapeRow(DRAPE_PROBLEM, "shell static", f"shell quarter n={n}", 2 * n, r["iterations"], r["ndofs"], wall,
                    None, None, r["corner"], r["midside"], r["folds"], r["diagonal_asymmetry"])


def plot_drape(rows: Sequence[DrapeRow], reference_difference: float, path: Path):
    """log-log error vs wall time of the tablecloth benchmark (rank 0 only)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    colors = {"particles static": "tab:red", "shell static": "tab:blue"}
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for method in dict.fromkeys(r.method for r in rows):
        sel = sorted((r for r in rows if r.method == method), key=lambda r: r.ndofs)  # in order of refinement
        ax.plot([r.wall_s for r in sel], [r.error for r in sel], "-", color=colors.get(method), label=method)
        for r in sel:
            ax.plot(r.wall_s, r.error, "o", color=colors.get(method),
                    mfc=colors.get(method) if r.same_branch else "none")
            ax.annotate(f"{r.grid}x{r.grid}", (r.wall_s, r.error), fontsize=6, xytext=(3, 3),
                        textcoords="offset points")
    for target in TARGETS:
        ax.axhline(target, color="grey", ls="--", lw=0.8)
    if reference_difference > 0:
        ax.axhline(reference_difference, color="black", ls=":", lw=0.8,
                   label=f"finest measured shell vs reference ({reference_difference:.1e})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s] (median)")
    ax.set_ylabel("max(|corner - ref|, |midside - ref|) / L")
    ax.set_title("Tablecloth drape [Eischen2000, sec. 4.4], static load path; open marks: other branch")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def tablecloth_benchmark(out: str | Path = "results/bench", quick: bool = False, plan: DrapePlan | None = None,
                         comm=MPI.COMM_WORLD, verbose: bool = True) -> dict:
    """The tablecloth benchmark (module doc); writes speed_accuracy_tablecloth.csv and .png under `out`.
    Returns {"rows", "reference", "reference_difference", "conclusions", "baseline_s"}."""
    plan = plan if plan is not None else (DRAPE_QUICK if quick else DRAPE_FULL)
    _check_drape_plan(plan)
    out = Path(out)
    say = printer(verbose, comm)
    rows: list[DrapeRow] = []
    for n in plan.particles:
        rows.append(run_drape_particles(n, plan.repeats, comm))
    for n in plan.shell:
        rows.append(run_drape_shell(n, plan.repeats, comm))
    for r in rows:
        say(f"{r.method:>16} {r.resolution:<20} {r.ndofs:6d} dofs, {r.iterations:4d} Newton it.: {r.wall_s:8.3f} s, "
            f"corner {np.array2string(r.corner / CLOTH_L, precision=4)} L, midside "
            f"{np.array2string(r.midside / CLOTH_L, precision=4)} L")
    t0 = time.perf_counter()
    ref = fe_tablecloth_nodes(plan.reference, comm=comm)
    reference = DrapeRow(DRAPE_PROBLEM, "reference (shell static)", f"shell quarter n={plan.reference}",
                         2 * plan.reference, ref["iterations"], ref["ndofs"], time.perf_counter() - t0, None, 0.0,
                         ref["corner"], ref["midside"], ref["folds"], ref["diagonal_asymmetry"], True)
    say(f"reference (shell static, quarter n={plan.reference}): corner "
        f"{np.array2string(reference.corner / CLOTH_L, precision=4)} L, midside "
        f"{np.array2string(reference.midside / CLOTH_L, precision=4)} L, {reference.wall_s:.1f} s")
    for r in rows:
        r.error = float(max(np.linalg.norm(r.corner - reference.corner),
                            np.linalg.norm(r.midside - reference.midside)) / CLOTH_L)
        r.same_branch = same_branch(r, reference)
        say(f"{r.method:>16} {r.resolution:<20} error {r.error:.3e}, {r.folds} folds, diagonal asymmetry "
            f"{r.diagonal_asymmetry:.2e}: {'same branch' if r.same_branch else 'OTHER BRANCH'} as the reference")
    shells = [r for r in rows if r.method == "shell static"]
    reference_difference = max(shells, key=lambda r: r.ndofs).error if shells else 0.0
    baseline = set_baseline(rows, "particles static")
    conclusions = [cheapest_meeting([r for r in rows if r.same_branch], target) for target in TARGETS]
    io.write_csv(out / "speed_accuracy_tablecloth.csv", DRAPE_CSV_COLUMNS,
                 [r.as_list() for r in rows] + [reference.as_list()], comm=comm)
    if comm.rank == 0:
        plot_drape(rows, reference_difference, out / "speed_accuracy_tablecloth.png")
    say(f"tablecloth baseline: {baseline.method} {baseline.resolution}, {baseline.wall_s:.4g} s")
    for c in conclusions:
        say("tablecloth " + c.sentence())
    return {"rows": rows, "reference": reference, "reference_difference": reference_difference,
            "conclusions": conclusions, "baseline_s": baseline.wall_s}
