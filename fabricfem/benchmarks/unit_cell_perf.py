"""Cost of the contact unit cell: `fabricfem bench unit-cell`.

For the quarter and full cells, coarse and fine meshes, transversely isotropic yarns with contact
under biaxial extension (the first steps, Phi11 = Phi22 = 1 + 0.02 n: the contact is established in
the first step): wall time per load increment and per augmentation (= per Newton solve with fixed
multipliers), the share spent in the contact operator (search, projection, return map, assembly
into PETSc), Newton iterations, peak memory (resource.getrusage ru_maxrss, kB on Linux, of this
process), medians over `repeats` runs (default: 3 on the coarse cells, 1 on the fine ones), and the
time per increment as a ratio against the coarse quarter cell measured in the same run
(step_over_baseline). Writes unit_cell_perf.csv / .png and prints the FE2 costing (a unit cell at
every shell quadrature point) from the measured figures.
"""
from __future__ import annotations

import os
import resource
import time

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.materials.yarn import THESIS_TRANSVERSELY_ISOTROPIC
from fabricfem.meshes.unit_cell import unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.solvers.newton import SolverError
from fabricfem.weave.unit_cell import ContactUnitCell

# sleeve mesh III of the garment study: 20 x 26 Q2 shell cells with 3 x 3 Gauss points
SLEEVE_CELLS = 20 * 26
GAUSS_POINTS = 9


def measure(option: str, refinement: str, steps: int, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """One run: set-up time, per-step times, augmentations, Newton iterations, contact time."""
    t0 = time.perf_counter()
    cell = unit_cell(PlainWeave.balanced(), option, refinement, comm)
    model = ContactUnitCell(cell, THESIS_TRANSVERSELY_ISOTROPIC, contact=True)
    setup = time.perf_counter() - t0
    stopped = ""
    try:
        for n in range(1, steps + 1):
            model.solve(np.diag([1.0 + 0.02 * n, 1.0 + 0.02 * n, 1.0]), 1)
    except SolverError as exc:
        stopped = str(exc)[:120]
    st = model.steps
    wall = np.array([s.wall_s for s in st])
    solves = np.array([len(s.newton_iterations) for s in st])
    return dict(option=option, refinement=refinement, ndofs=model.ndofs, setup_s=setup, steps=len(st),
                step_s=float(np.median(wall)) if len(st) else np.nan,
                augmentation_s=float(np.median(wall / solves)) if len(st) else np.nan,
                augmentations=float(np.mean([s.augmentations for s in st])) if len(st) else np.nan,
                newton_per_step=float(np.mean([sum(s.newton_iterations) for s in st])) if len(st) else np.nan,
                contact_share=float(sum(s.contact_s for s in st) / max(wall.sum(), 1e-30)),
                peak_rss_MB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, stopped=stopped)


def fe2_paragraph(step_s: float, newton_shell: int = 5, load_steps: int = 20) -> str:
    """Cost of the concurrent FE2 route: one unit-cell load increment per shell quadrature point per
    shell Newton iteration per load step (the tangent would need extra solves; not counted)."""
    points = SLEEVE_CELLS * GAUSS_POINTS
    total = points * newton_shell * load_steps * step_s
    return (f"FE2 costing: the sleeve mesh III has {SLEEVE_CELLS} Q2 cells x {GAUSS_POINTS} Gauss points = {points} "
            f"material points. A concurrent FE2 solve consults a unit cell at each of them in every shell Newton "
            f"iteration; with the measured {step_s:.2f} s per unit-cell load increment (quarter cell, coarse, with "
            f"contact, one core), {newton_shell} shell Newton iterations per step and {load_steps} load steps, that "
            f"is {points} x {newton_shell} x {load_steps} x {step_s:.2f} s = {total:.3g} s = {total / 3600:.3g} "
            f"core-hours per sleeve simulation, before the consistent macroscopic tangent (which needs the unit "
            f"cell's sensitivity, [Man2006, sec. 4.3.6]: 3 more linear solves per point) and with the coarsest "
            f"cell, whose stress differs from the fine one. The fitted membrane law (fabricfem/fitted_law.py) "
            f"costs one closed-form evaluation per point (no solve) after a one-off grid of a few dozen "
            f"unit-cell load paths, so it is the practical path; FE2 would need ~{total / 3600 / 1000:.2g}k cores "
            f"for an hour per run.")


def unit_cell_perf(out: str = "results/unit_cell_perf", quick: bool = False, repeats: int | None = None,
                   comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Run the benchmark grid and write CSV + PNG; returns the median rows."""
    cases = [("quarter", "coarse")] if quick else [("quarter", "coarse"), ("full", "coarse"), ("quarter", "fine"),
                                                   ("full", "fine")]
    rows = []
    for option, refinement in cases:
        # medians of 3 runs of 3 increments on the coarse cells; the fine cells (18k and 70k dofs, minutes
        # per increment on this shared 2-core machine) get one run of 2 (quarter) or 1 (full) increments
        coarse = refinement == "coarse"
        steps = 2 if quick else 3 if coarse else 2 if option == "quarter" else 1
        n_runs = (1 if quick or not coarse else 3) if repeats is None else int(repeats)
        runs = [measure(option, refinement, steps, comm) for _ in range(n_runs)]
        row = dict(runs[-1])
        for k in ("setup_s", "step_s", "augmentation_s", "contact_share"):
            row[k] = float(np.median([r[k] for r in runs]))
        row["repeats"] = n_runs
        # time per increment as a ratio against the baseline (the first case, the coarse quarter cell) of this run
        row["step_over_baseline"] = row["step_s"] / (rows[0]["step_s"] if rows else row["step_s"])
        rows.append(row)
        if comm.rank == 0:
            print(f"{option:>7} {refinement:>6}: {row['ndofs']} dofs, {row['step_s']:.2f} s/increment, "
                  f"{row['augmentation_s']:.2f} s/augmentation, x{row['step_over_baseline']:.1f} the coarse quarter cell, "
                  f"contact share {100 * row['contact_share']:.0f}%, "
                  f"peak RSS {row['peak_rss_MB']:.0f} MB" + (f" STOPPED {row['stopped']}" if row["stopped"] else ""),
                  flush=True)
    if comm.rank == 0:
        os.makedirs(out, exist_ok=True)
        fio.write_csv(os.path.join(out, "unit_cell_perf.csv"), list(rows[0]), rows, comm)
        import matplotlib  # optional heavy package, loaded only when a plot is drawn
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
        fig, ax = plt.subplots(figsize=(6, 4))
        labels = [f"{r['option']}\n{r['refinement']}\n{r['ndofs']} dofs" for r in rows]
        x = np.arange(len(rows))
        ax.bar(x - 0.2, [r["step_s"] for r in rows], 0.4, label="per load increment")
        ax.bar(x + 0.2, [r["augmentation_s"] for r in rows], 0.4, label="per augmentation")
        ax.set_xticks(x, labels, fontsize=7)
        ax.set_ylabel("wall time [s] (median)")
        ax.set_yscale("log")
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "unit_cell_perf.png"), dpi=120)
        plt.close(fig)
        text = fe2_paragraph(rows[0]["step_s"])
        print(text)
        with open(os.path.join(out, "fe2_costing.txt"), "w") as f:
            f.write(text + "\n")
    return rows
