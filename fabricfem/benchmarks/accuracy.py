"""`fabricfem bench accuracy`: the table of the verify case accuracy-choice (fabricfem.verify.accuracy) as a CSV and
a PNG: for each scene and target (10%, 3%, 1%) the level the accuracy plan chooses, its estimated and true relative
errors, its work (dofs x steps) and wall time [s], and the cheapest level that meets the target by brute force;
then the same choice on the sleeve study's stored torque at 57 degrees, meshes I-III against mesh IV
(fabricfem.benchmarks.sleeve_accuracy). Writes <out>/accuracy/accuracy.csv, accuracy.png (true and estimated error
of the chosen level per target) and sleeve_57deg.csv."""
from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from fabricfem import io
from fabricfem.benchmarks.sleeve_accuracy import sleeve_choices, verdict
from fabricfem.verify.accuracy import TARGETS, choices


def accuracy_bench(out: str | Path = "results/bench") -> list[dict]:
    """Run the accuracy-choice scenes into <out>/accuracy/runs, write accuracy.csv and accuracy.png, then the
    sleeve's rows into sleeve_57deg.csv (rank 0; every rank runs the same serial levels). Returns the scene rows
    and the sleeve rows."""
    out = Path(out) / "accuracy"
    sleeve = sleeve_choices(TARGETS)   # first: a missing study file is refused before the runs
    rows = choices(out / "runs", MPI.COMM_SELF)
    if MPI.COMM_WORLD.rank != 0:
        return rows + sleeve
    header = list(rows[0])
    io.write_csv(out / "accuracy.csv", header, [[r[k] for k in header] for r in rows], MPI.COMM_SELF)
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene and r["true_error"] is not None]
        targets = [r["target"] for r in mine]
        ax.loglog(targets, [r["true_error"] for r in mine], "o-", label=f"{scene}: true error")
        ax.loglog(targets, [r["estimated_error"] for r in mine], "x--", label=f"{scene}: estimated")
    ax.loglog([0.01, 0.1], [0.01, 0.1], "k:", label="error = target")
    ax.set_xlabel("target (relative)")
    ax.set_ylabel("error of the delivered quantity (relative)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "accuracy.png", dpi=100)
    plt.close(fig)
    for r in rows:
        print(f"{r['scene']:<24} target {r['target']:>5.0%}: level {r['chosen_level']} ({r['chosen_cells']} "
              f"{r['chosen_model']}), estimated {r['estimated_error']:.2e}, true {r['true_error']:.2e}, work "
              f"{r['chosen_work']:.0f} ({r['chosen_wall_s']:.2f} s); brute force level {r['brute_level']} "
              f"({r['brute_wall_s']:.2f} s)", flush=True)
    header = list(sleeve[0])
    io.write_csv(out / "sleeve_57deg.csv", header, [[r[k] for k in header] for r in sleeve], MPI.COMM_SELF)
    for r in sleeve:
        print(verdict(r), flush=True)
    print(f"sleeve meshes I, II, III, IV: torque [N m] mu 0.1: {sleeve[0]['torques_Nm']}, mu 0.5: "
          f"{sleeve[-1]['torques_Nm']}; stored walls [s] {sleeve[0]['walls_s']} / {sleeve[-1]['walls_s']}", flush=True)
    print(f"wrote {out}/accuracy.csv, accuracy.png, sleeve_57deg.csv", flush=True)
    return rows + sleeve
