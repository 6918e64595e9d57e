"""`fabricfem bench parallel`: does a wear scene pay for 2 ranks? The same scene on 1 and on 2 ranks, alternating.

    fabricfem bench parallel --scene scenes/sleeve.toml --meshes 10x13,20x26,30x39,44x57
                             [--set motion.final_angle=20] [--repeats 3] [--out results/bench]

For each tube mesh (the garment's cells around x along; a pattern scene: `--meshes scene`, its own mesh) the
scene's explicit garment run is built and `run.run()` timed in a fresh process (fabricfem.benchmarks.commits
`time_once` on this checkout: the build and the JIT compilation excluded, the slowest rank's wall), once on 1 rank
and once under `mpirun -n 2`, alternating 1, 2, 1, 2, ... `repeats` times so that the machine's load spreads over
both. Per mesh: the medians, the speed-up (median 1-rank wall / median 2-rank wall) and the largest difference of
the two torque histories (over the largest |torque|: round-off, or the divergence of a long run's slip events).
Writes parallel.csv (a row per run), parallel.json (a row per mesh) and parallel.png (speed-up against dofs) under
`out`. Times in seconds.
"""
from __future__ import annotations

import json
import statistics
import tomllib
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.benchmarks.commits import time_once
from fabricfem.scenes.build import estimated_dofs
from fabricfem.scenes.sweep import parse_value, set_key
from fabricfem.scenes.wear_sections import garment_tables

RANKS = (1, 2)


def scene_at(data: dict, mesh: str, settings: tuple[str, ...]) -> tuple[dict, int | None]:
    """The scene data with the tube's mesh `mesh` ("AxB"; "scene": unchanged) and the key=value `settings`, and
    its estimated dofs (None for a pattern)."""
    data = json.loads(json.dumps(data))
    for item in settings:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"set: expected key=value, got {item!r}")
        set_key(data, key.strip(), parse_value(value))
    garments = garment_tables(data)
    if mesh != "scene":
        around, _, along = mesh.partition("x")
        if not (around.isdigit() and along.isdigit()) or len(garments) != 1 or garments[0].get("builder") != "tube":
            raise ValueError(f"meshes: {mesh!r} is not 'AxB' cells of a scene's one tube garment (or 'scene')")
        garments[0].update(n_around=int(around), n_along=int(along))
    tubes = all(g.get("builder") == "tube" for g in garments)
    return data, (sum(estimated_dofs({"type": "tube", "n_around": g["n_around"], "n_along": g["n_along"]})
                      for g in garments) if tubes else None)


def parallel_bench(scene: str | Path, meshes: tuple[str, ...], settings: tuple[str, ...] = (), repeats: int = 3,
                   out: str | Path = "results/bench", say=print) -> list[dict]:
    """Time `scene` on 1 and 2 ranks per mesh (module docstring); returns the per-mesh rows."""
    scene = Path(scene)
    if not scene.is_file():
        raise ValueError(f"scene: {str(scene)!r} is not a file")
    if isinstance(repeats, bool) or not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    base = tomllib.loads(scene.read_text())
    repo = Path(__file__).resolve().parents[2]
    rows, table = [], []
    for mesh in meshes:
        data, dofs = scene_at(base, mesh, settings)
        runs: dict[int, list[dict]] = {r: [] for r in RANKS}
        for k in range(repeats):
            for ranks in RANKS:
                r = time_once(repo, scene, data, ranks)
                runs[ranks].append(r)
                rows.append([mesh, dofs, ranks, k + 1, r["wall"], r["steps"], 1e3 * r["wall"] / r["steps"]])
                say(f"  {mesh} on {ranks} rank(s), run {k + 1}/{repeats}: {r['wall']:.2f} s, {r['steps']} steps")
        medians = {ranks: statistics.median(r["wall"] for r in runs[ranks]) for ranks in RANKS}
        one, two = (np.array(runs[ranks][-1]["torques"]) for ranks in RANKS)
        scale = float(np.max(np.abs(one))) if one.size else 0.0
        difference = float(np.max(np.abs(one - two)) / scale) if scale > 0 and one.shape == two.shape else 0.0
        table.append({"mesh": mesh, "dofs": dofs, "serial_s": medians[1], "two_ranks_s": medians[2],
                      "speedup": medians[1] / medians[2], "steps": runs[1][-1]["steps"],
                      "torque_difference": difference, "repeats": repeats})
        say(f"{mesh}: serial {medians[1]:.2f} s, 2 ranks {medians[2]:.2f} s (medians of {repeats}), speed-up "
            f"{medians[1] / medians[2]:.2f}; torques differ by {difference:.1e} of the largest")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fio.write_csv(out / "parallel.csv", ["mesh", "dofs", "ranks", "run", "wall_s", "steps", "ms_per_step"], rows,
                  MPI.COMM_SELF)
    (out / "parallel.json").write_text(json.dumps({"scene": str(scene), "settings": list(settings),
                                                   "meshes": table}, indent=1))
    _plot(table, out / "parallel.png", scene.name)
    say(f"wrote {out / 'parallel.csv'}, parallel.json, parallel.png")
    return table


def _plot(table: list[dict], path: Path, title: str) -> None:
    """Speed-up of 2 ranks over 1 against the dofs (the mesh labels beside the points)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(6, 4))
    x = [row["dofs"] or 0 for row in table]
    y = [row["speedup"] for row in table]
    ax.plot(x, y, "o-")
    for xi, yi, row in zip(x, y, table):
        ax.annotate(row["mesh"], (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(1.7, color="k", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_xlabel("degrees of freedom (estimated)")
    ax.set_ylabel("speed-up, 2 ranks over 1 (medians)")
    ax.set_title(f"{title}: time loop on 1 and 2 ranks")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
