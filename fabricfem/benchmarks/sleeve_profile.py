"""Where the explicit sleeve's time goes: the wall-time breakdown of the central-difference flexion.

`fabricfem bench sleeve-profile [--out results/bench] [--quick]` (run it under `mpirun -n 2` for the parallel
numbers; every rank runs the same flexion on the full communicator):

* short flexions (to `short_angle` degrees, past the first contact at about 5 degrees) on meshes I and III,
  `repeats` times each; every part of `fabricfem.wear.engine.step_breakdown` (internal-force assembly, contact
  search and corrections, pose and torque sums, output, other Python) is quoted as the MEDIAN over the
  repeats of its share of the loop's wall time, with the median ms per step in wall and in CPU time of the
  process (the machine is shared, so single timings scatter; ratios and CPU times scatter less than wall times);
* one full flexion to 57 degrees on mesh IV (`full=True`): wall time, steps, breakdown and the torque at
  57 degrees, for the README.

Under MPI the parts are rank 0's (each rank times its own assembly and its own owned contact nodes; the
tube is split along its length, so the ranks' contact loads differ; the loop wall time is common).

Writes sleeve_profile.csv (one row per case) and sleeve_profile.png (stacked shares) under `out` (rank 0).
Target: contact search and corrections below 20 % of the total. SI units; times in seconds.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.engine import TIMING_PARTS
from fabricfem.wear.run import build_run

MESHES = {"I": (10, 13), "II": (15, 20), "III": (20, 26), "IV": (30, 39)}
COLUMNS = ("case", "mesh", "ranks", "final_angle_deg", "runs", "steps", "ndofs", "ms_per_step", "cpu_ms_per_step",
           "wall_s",
           *(f"{p}_share" for p in TIMING_PARTS), "torque_Nm", "max_penetration_m")


@dataclass
class ProfileRow:
    case: str
    mesh: str
    ranks: int
    final_angle_deg: float
    runs: int
    steps: int
    ndofs: int
    ms_per_step: float      # median over the runs
    cpu_ms_per_step: float  # median CPU time of rank 0's process per step (steadier on a shared machine)
    wall_s: float           # median wall time of one flexion (build excluded)
    shares: dict            # part -> median share of the loop time
    torque_Nm: float        # resisting elbow torque at the final angle (last run)
    max_penetration_m: float

    def row(self) -> list:
        return [self.case, self.mesh, self.ranks, self.final_angle_deg, self.runs, self.steps, self.ndofs,
                self.ms_per_step, self.cpu_ms_per_step, self.wall_s, *(self.shares[p] for p in TIMING_PARTS), self.torque_Nm,
                self.max_penetration_m]


def profile_flexion(mesh: str, final_angle: float, repeats: int, comm: MPI.Comm = MPI.COMM_WORLD,
                    case: str = "short", say=print) -> ProfileRow:
    """`repeats` explicit flexions of the default sleeve (mu = 0.1) on `mesh` to `final_angle` [deg];
    medians of the per-part shares and of ms per step."""
    if mesh not in MESHES:
        raise ValueError(f"mesh: unknown mesh {mesh!r}, expected one of {sorted(MESHES)}")
    if int(repeats) < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats!r}")
    n_around, n_along = MESHES[mesh]
    config = SleeveConfig.of(n_around=n_around, n_along=n_along, final_angle=float(final_angle))
    timings, walls = [], []
    history = problem = None
    for k in range(int(repeats)):
        problem = build_run(config, comm)
        t0 = time.perf_counter()
        history = problem.run()
        walls.append(time.perf_counter() - t0)
        timings.append(history.timings)
        problem.destroy()
        say(f"  mesh {mesh} to {final_angle:g} deg, run {k + 1}/{repeats}: {walls[-1]:.1f} s, "
            f"{history.timings['ms_per_step']:.2f} ms/step, contact {history.timings['contact_share']:.1%}")
    shares = {p: statistics.median(t[f"{p}_share"] for t in timings) for p in TIMING_PARTS}
    return ProfileRow(case, mesh, comm.size, float(final_angle), int(repeats), int(timings[-1]["steps"]),
                      problem.model.ndofs, statistics.median(t["ms_per_step"] for t in timings),
                      statistics.median(t["cpu_ms_per_step"] for t in timings), statistics.median(walls), shares, history.steps[-1].torques["elbow"],
                      max(s.max_penetration for s in history.steps))


def plot_shares(path: Path, rows: list[ProfileRow]):
    """Grouped bars: the median share of every part per case, with the 20 % target of the contact (rank 0)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(8, 4))
    width = 0.8 / max(len(rows), 1)
    x = np.arange(len(TIMING_PARTS))
    for k, r in enumerate(rows):
        ax.bar(x + k * width, [100.0 * r.shares[p] for p in TIMING_PARTS], width,
               label=f"{r.case}, mesh {r.mesh}, {r.ranks} rank(s): {r.ms_per_step:.1f} ms/step")
    ax.axhline(20.0, color="k", ls=":", lw=0.8, label="20 % (contact target)")
    ax.set_xticks(x + 0.4 - width / 2, [p.replace("_", " ") for p in TIMING_PARTS])
    ax.set_ylabel("share of the flexion's wall time [%]")
    ax.set_title("explicit sleeve: time per part (medians)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def sleeve_profile(out: str | Path = "results/bench", quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD,
                   meshes: tuple[str, ...] = ("I", "III"), short_angle: float = 10.0, repeats: int = 3,
                   full: bool = True, full_mesh: str = "IV", full_angle: float = 57.0) -> list[ProfileRow]:
    """Run the profile cases (module docstring) and write sleeve_profile.csv / .png under `out`.
    quick: mesh I only, 6 degrees, 2 repeats, no full flexion (smoke test)."""
    say = (lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None)
    if quick:
        meshes, short_angle, repeats, full = ("I",), 6.0, 2, False
    rows = []
    for mesh in meshes:
        say(f"sleeve-profile: mesh {mesh}, {repeats} flexions to {short_angle:g} deg on {comm.size} rank(s)")
        rows.append(profile_flexion(mesh, short_angle, repeats, comm, case=f"to {short_angle:g} deg", say=say))
    if full:
        say(f"sleeve-profile: full flexion to {full_angle:g} deg on mesh {full_mesh} ({comm.size} rank(s))")
        rows.append(profile_flexion(full_mesh, full_angle, 1, comm, case=f"full {full_angle:g} deg", say=say))
    if comm.rank == 0:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        fio.write_csv(out / "sleeve_profile.csv", COLUMNS, [r.row() for r in rows], comm)
        plot_shares(out / "sleeve_profile.png", rows)
    for r in rows:
        shares = ", ".join(f"{p.replace('_', ' ')} {r.shares[p]:.1%}" for p in TIMING_PARTS)
        say(f"{r.case}, mesh {r.mesh} ({r.ndofs} dofs, {r.ranks} rank(s)): {r.wall_s:.1f} s, {r.steps} steps, "
            f"{r.ms_per_step:.2f} ms/step ({r.cpu_ms_per_step:.2f} ms CPU); {shares}; torque {r.torque_Nm:.4e} N m")
    say(f"wrote {out}/sleeve_profile.csv and .png")
    return rows
