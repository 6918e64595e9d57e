"""`fabricfem bench commits`: the same wear scene timed at two commits of this repository, alternating.

    fabricfem bench commits --old a83e33f [--new HEAD] --scene scenes/pants_walk.toml --set motion.strides=1
                            [--repeats 3] [--ranks 2] [--out results/bench]

Each commit is checked out once as a detached git worktree under `<tmp>/fabricfem-commits/<sha>`; a run builds the scene's
explicit garment run there (fabricfem.scenes.run.build_wear_run, as `fabricfem run` does, without writing
outputs) in a fresh process (`mpirun -n ranks` when ranks > 1) and times `run.run()` (the build and the JIT
compilation excluded). The runs alternate old, new, old, new, ... so that the machine's load spreads over both;
the speed-up is the ratio of the median walls. The torque histories of the two commits are compared record by
record (largest difference over the records divided by the largest |torque| of the old commit's run): code
changes that keep the answers give round-off.

`--set key=value` (repeatable) replaces a dotted scene key (values parsed as TOML, as `fabricfem sweep --vary`),
e.g. a shorter motion for a timing window. Writes commits.csv (one row per run) and commits.json (medians, ratio,
torque difference) under `out`. SI units; times in seconds.
"""
from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.launch import child_environment
from fabricfem.scenes.sweep import parse_value, set_key

# run in the checked-out commit: build, time run.run(), print one JSON line (rank 0)
TIMER = r"""
import dataclasses, json, sys, time, tomllib
from pathlib import Path
from mpi4py import MPI
from fabricfem.scenes.run import build_wear_run
from fabricfem.scenes.schema import validate
path, data = Path(sys.argv[1]), json.loads(sys.argv[2])
scene = dataclasses.replace(validate(data, str(path)), path=path)
run = build_wear_run(scene, MPI.COMM_WORLD)[0]
MPI.COMM_WORLD.Barrier()
t0 = time.perf_counter()
history = run.run()
wall = MPI.COMM_WORLD.allreduce(time.perf_counter() - t0, op=MPI.MAX)
if MPI.COMM_WORLD.rank == 0:
    print("TIMING " + json.dumps({"wall": wall, "steps": int(run.integrator.step_count),
                                  "torques": [list(s.torques.values()) for s in history.steps]}), flush=True)
"""


def _git(*args: str, cwd: Path) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def checkout(repo: Path, commit: str, folder: Path) -> tuple[str, Path]:
    """(full sha, worktree path) of `commit`, checked out under `folder` once."""
    try:
        sha = _git("rev-parse", "--verify", f"{commit}^{{commit}}", cwd=repo)
    except subprocess.CalledProcessError:
        raise ValueError(f"old / new: {commit!r} is not a commit of {repo}") from None
    tree = folder / sha[:12]
    if not (tree / "fabricfem").is_dir():
        folder.mkdir(parents=True, exist_ok=True)
        _git("worktree", "add", "--detach", "--force", str(tree), sha, cwd=repo)
    return sha, tree


def time_once(tree: Path, scene: Path, data: dict, ranks: int) -> dict:
    """One timed run of the scene at the commit checked out in `tree`."""
    env = child_environment({"PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"})
    cmd = [sys.executable, "-c", TIMER, str(scene.resolve()), json.dumps(data)]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), *cmd]
    done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith("TIMING ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"the run at {tree} failed (exit {done.returncode}): {done.stderr[-2000:]}")
    return json.loads(lines[-1][len("TIMING "):])


def compare_commits(scene: str | Path, old: str, new: str = "HEAD", settings: tuple[str, ...] = (),
                    repeats: int = 3, ranks: int = 1, out: str | Path = "results/bench", say=print) -> dict:
    """Time `scene` (with the `settings` key=value replacements) at the commits `old` and `new` (module
    docstring); returns and writes the medians, the speed-up and the torque difference."""
    scene = Path(scene)
    if not scene.is_file():
        raise ValueError(f"scene: {str(scene)!r} is not a file")
    if isinstance(repeats, bool) or not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    if isinstance(ranks, bool) or not (isinstance(ranks, int) and ranks >= 1):
        raise ValueError(f"ranks must be a positive integer, got {ranks!r}")
    data = tomllib.loads(scene.read_text())
    for item in settings:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"set: expected key=value, got {item!r}")
        set_key(data, key.strip(), parse_value(value))
    repo = Path(__file__).resolve().parents[2]
    out = Path(out)
    folder = Path(tempfile.gettempdir()) / "fabricfem-commits"
    trees = {label: checkout(repo, commit, folder) for label, commit in (("old", old), ("new", new))}
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    rows = []
    for k in range(repeats):
        for label, (sha, tree) in trees.items():
            r = time_once(tree, scene, data, ranks)
            runs[label].append(r)
            rows.append([label, sha[:12], k + 1, ranks, r["wall"], r["steps"], 1e3 * r["wall"] / r["steps"]])
            say(f"  {label} {sha[:12]} run {k + 1}/{repeats}: {r['wall']:.1f} s, {r['steps']} steps, "
                f"{1e3 * r['wall'] / r['steps']:.2f} ms/step")
    old_t, new_t = (np.array(runs[label][-1]["torques"]) for label in ("old", "new"))
    n = min(len(old_t), len(new_t))
    scale = float(np.max(np.abs(old_t))) if old_t.size else 0.0
    difference = float(np.max(np.abs(old_t[:n] - new_t[:n])) / scale) if scale > 0 else 0.0
    medians = {label: statistics.median(r["wall"] for r in runs[label]) for label in runs}
    result = {"scene": str(scene), "settings": list(settings), "ranks": ranks, "repeats": repeats,
              "old": trees["old"][0], "new": trees["new"][0], "old_wall_s": medians["old"],
              "new_wall_s": medians["new"], "speedup": medians["old"] / medians["new"],
              "old_steps": runs["old"][-1]["steps"], "new_steps": runs["new"][-1]["steps"],
              "records": n, "torque_difference": difference}
    out.mkdir(parents=True, exist_ok=True)
    fio.write_csv(out / "commits.csv", ["commit", "sha", "run", "ranks", "wall_s", "steps", "ms_per_step"], rows,
                  MPI.COMM_SELF)
    (out / "commits.json").write_text(json.dumps(result, indent=1))
    say(f"{scene.name} {' '.join(settings)} on {ranks} rank(s): old {medians['old']:.1f} s, new {medians['new']:.1f} s "
        f"(medians of {repeats}), speed-up {result['speedup']:.2f}; torque histories differ by {difference:.2e} of "
        f"the largest |torque| over {n} records; wrote {out / 'commits.csv'}, commits.json")
    return result
