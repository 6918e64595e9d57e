"""Variants as one MPI batch: the machinery of `fabricfem sweep` (fabricfem.scenes.sweep) and of the studies
(fabricfem.studies: sleeve, unit cell, pants).

A batch is a list of `Job`s: a name, an estimated cost (relative; None when unknown), `run(comm)` that computes the
variant on a communicator and writes its result where `done()` finds it, and `done()` that says whether a
completed result of exactly this variant is already there. `run_batch` splits the ranks into groups of
`ranks_per_job` (MPI.Comm.Split), gives the jobs longest first to the least loaded group (`schedule`; the same on
every rank), and in each group runs its jobs in that order, skipping those already done (read back by the caller,
not rerun: a killed batch resumes). A job that raises is recorded as "failed: ..." and the others go on. The
results are read back by the caller from what the jobs wrote (`read_summary`, `completed` for a run's
summary.json; a study's own files), so a finished job and a read-back one give the same table; `write_table` writes
one CSV of rows (the sweep's sweep.csv).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from mpi4py import MPI

from fabricfem import io


@dataclass
class Job:
    """One variant of a batch: `run(comm)` computes it on `comm` (collective over it) and writes its result;
    it may return a status line (printed). `done()` is True when a completed result is already written."""

    name: str
    cost: float | None
    run: Callable[[MPI.Comm], str | None]
    done: Callable[[], bool]


def longest_first(costs: list[float | None]) -> list[int]:
    """Indices by decreasing cost; unknown costs (None) after the known ones, in the order given."""
    return sorted(range(len(costs)), key=lambda i: (costs[i] is None, -(costs[i] or 0.0), i))


def schedule(costs: list[float | None], groups: int) -> list[int]:
    """Group of each variant: longest first (unknown costs: the order given, after the known ones), each to the
    least loaded group; the same on every rank."""
    load = [0.0] * groups
    owner = [0] * len(costs)
    for i in longest_first(costs):
        g = min(range(groups), key=lambda k: (load[k], k))
        owner[i] = g
        load[g] += costs[i] if costs[i] is not None else 1.0
    return owner


def groups_of(comm: MPI.Comm, ranks_per_job: int) -> int:
    """The number of groups of `ranks_per_job` ranks; ValueError naming --ranks-per-variant when it does not divide
    the number of ranks."""
    if ranks_per_job < 1 or comm.size % ranks_per_job:
        raise ValueError(f"--ranks-per-variant: {ranks_per_job} must be a positive divisor of the "
                         f"{comm.size} rank(s)")
    return comm.size // ranks_per_job


def run_batch(jobs: list[Job], comm: MPI.Comm = MPI.COMM_WORLD, ranks_per_job: int = 1,
              title: str = "batch") -> dict[str, str]:
    """Run the jobs not yet done (module docstring); returns {name: "failed: ..."} of the jobs that raised, the same
    on every rank (after a barrier: every job's result is written when it returns)."""
    groups = groups_of(comm, ranks_per_job)
    group = comm.rank // ranks_per_job
    costs = [job.cost for job in jobs]
    owner = schedule(costs, groups)
    mine = [i for i in longest_first(costs) if owner[i] == group]
    sub = comm.Split(color=group, key=comm.rank)
    leader = sub.rank == 0
    say = (lambda m: print(m, flush=True)) if leader else (lambda m: None)
    clock = io.Progress()
    failures = {}
    try:
        for n, i in enumerate(mine):
            job = jobs[i]
            if sub.bcast(job.done() if leader else None, root=0):   # the leader's view, for the whole group
                say(f"[{title} group {group}] {job.name}: completed before, read back (not rerun)")
                continue
            say(f"[{title} group {group}] {job.name}: started {clock(n / len(mine))}")
            t0 = time.perf_counter()
            try:
                status = job.run(sub) or "done"
            except Exception as exc:  # noqa: BLE001 (any failure of one variant: recorded, the others go on)
                status = failures[job.name] = f"failed: {' '.join(str(exc).split())}"
            say(f"[{title} group {group}] {job.name}: {status} in {time.perf_counter() - t0:.1f} s "
                f"{clock((n + 1) / len(mine))}")
    finally:
        sub.Free()
    return {name: status for part in comm.allgather(failures if leader else {}) for name, status in part.items()}


class BatchError(RuntimeError):
    """Variants of a batch that raised, named after the others have run (`fabricfem` exits 1 with the message)."""


def check(failures: dict[str, str], what: str, where: str) -> None:
    """BatchError naming the failed jobs of `what` (e.g. "sleeve study") unless there are none; `where` says where
    the finished ones are kept (a rerun resumes)."""
    if failures:
        raise BatchError(f"{what}: {len(failures)} variant(s) failed (the finished ones are kept in {where}; a rerun "
                         f"resumes): " + "; ".join(f"{name}: {why}" for name, why in failures.items()))


def read_summary(folder: Path) -> dict:
    """The summary.json of a run's folder ({} when missing or unreadable)."""
    try:
        data = json.loads((Path(folder) / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def completed(folder: Path, sha256: str) -> bool:
    """True when the folder holds a completed run (summary.json: status "completed", with or without warnings, and
    scene hash) of the scene `sha256`."""
    summary = read_summary(folder)
    return str(summary.get("status", "")).startswith("completed") and summary.get("scene_sha256") == sha256


def cell(value) -> str:
    """CSV text of a table cell: repr of floats (round trip), '' for missing."""
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


def write_table(path: Path, rows: list[dict]) -> None:
    """One CSV of the rows (rank 0's business): the union of their keys as the header, in order of appearance."""
    header = list(dict.fromkeys(k for row in rows for k in row))
    io.write_csv(Path(path), header, [[cell(row.get(k)) for k in header] for row in rows], MPI.COMM_SELF)
