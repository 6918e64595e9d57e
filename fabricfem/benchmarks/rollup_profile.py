"""Benchmarks (on demand): where the time of a nonlinear shell solve goes.

`fabricfem bench rollup-profile` rolls the strip up to a full circle on several meshes under
cProfile and splits the wall time into form compilation, assembly (the residual and Jacobian
callbacks), the linear solver and SNES internals (time inside SNESSolve outside the callbacks)
and Python (the rest). Each figure is the median of `repeats` runs (the first run also JIT-compiles
the forms; compilation is reported from that run). Writes CSV and PNG under `out`.
"""
from __future__ import annotations

import cProfile
import pstats
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io
from fabricfem.verify import Timer
from fabricfem.verify.cantilevers import rollup


def _cumulative(stats: pstats.Stats, predicate) -> float:
    return sum(v[3] for k, v in stats.stats.items() if predicate(k))


def profile_rollup(nx: int) -> dict[str, float]:
    profiler = cProfile.Profile()
    with Timer() as timer:
        profiler.enable()
        model, _, _, history = rollup(nx=nx)
        profiler.disable()
    stats = pstats.Stats(profiler)
    name = lambda k: k[2]  # noqa: E731
    assembly = _cumulative(stats, lambda k: k[0].endswith("shell.py") and name(k) in ("residual", "jacobian"))
    snes = _cumulative(stats, lambda k: "solve" in name(k) and "SNES" in name(k))
    compile_s = _cumulative(stats, lambda k: k[0].endswith("shell.py") and name(k) == "compile")
    iterations = sum(h.iterations for h in history)
    linear = max(snes - assembly, 0.0)
    total = timer.elapsed
    return {"nx": nx, "ndofs": model.ndofs, "steps": len(history), "newton_iterations": iterations,
            "wall_s": total, "compile_s": compile_s, "assembly_s": assembly, "linear_solver_s": linear,
            "python_s": max(total - compile_s - assembly - linear, 0.0)}


def rollup_profile(out: str = "results/bench", meshes=(20, 40, 80, 160), repeats: int = 3) -> list[dict]:
    out = Path(out)
    rows = []
    for nx in meshes:
        runs = [profile_rollup(nx) for _ in range(repeats)]
        row = {k: float(np.median([r[k] for r in runs])) for k in runs[0]}
        row["compile_s"] = runs[0]["compile_s"]
        rows.append(row)
        if MPI.COMM_WORLD.rank == 0:
            share = {k: row[k] / row["wall_s"] for k in ("assembly_s", "linear_solver_s", "python_s")}
            print(f"nx = {nx:4d}: {int(row['ndofs'])} dofs, {int(row['newton_iterations'])} Newton iterations, "
                  f"median wall {row['wall_s']:.2f} s: assembly {share['assembly_s']:.0%}, "
                  f"linear solver + SNES {share['linear_solver_s']:.0%}, Python {share['python_s']:.0%} "
                  f"(first-run compile {runs[0]['compile_s']:.1f} s)", flush=True)
    keys = list(rows[0])
    io.write_csv(out / "rollup_profile.csv", keys, [[r[k] for k in keys] for r in rows])
    if MPI.COMM_WORLD.rank == 0:
        import matplotlib  # optional heavy package, loaded only when a plot is drawn
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
        fig, ax = plt.subplots(figsize=(7, 4))
        labels = [f"{int(r['ndofs'])}" for r in rows]
        bottom = np.zeros(len(rows))
        for key, label in (("assembly_s", "assembly"), ("linear_solver_s", "linear solver + SNES"),
                           ("python_s", "Python")):
            values = np.array([r[key] for r in rows])
            ax.bar(labels, values, bottom=bottom, label=label)
            bottom += values
        ax.set_xlabel("dofs (roll-up strip, 20 load steps to a full circle)")
        ax.set_ylabel("median wall time [s]")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "rollup_profile.png", dpi=120)
    return rows
