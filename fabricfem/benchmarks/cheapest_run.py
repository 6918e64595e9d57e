"""The measurement and the conclusion shared by the speed-versus-accuracy benchmarks
(fabricfem.benchmarks.speed_accuracy, the corner-pinned cloth; fabricfem.benchmarks.speed_accuracy_tablecloth):
the median wall time of repeated runs, the baseline run the wall times are divided by, the progress printer and
the cheapest measured run per method meeting a target relative error. Times in s.
"""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence, TypeVar

from mpi4py import MPI

__all__ = ["TARGETS", "Conclusion", "MeasuredRun", "cheapest_meeting", "printer", "set_baseline", "timed"]

TARGETS = (0.01, 0.10)  # target relative errors of the conclusions [-]
T = TypeVar("T")


class MeasuredRun(Protocol):
    """A benchmark row: method, resolution, dofs, median wall time [s], its ratio to the baseline run and its error [-]
    (None until compared with the reference)."""

    method: str
    resolution: str
    ndofs: int
    wall_s: float
    wall_vs_baseline: float | None
    error: float | None


@dataclass
class Conclusion:
    """Cheapest measured run meeting a target relative error; ratio = next best method's wall / this wall."""

    target: float
    method: str | None
    resolution: str | None
    wall_s: float | None
    runner_up: str | None
    ratio: float | None  # inf when no other method meets the target

    def sentence(self) -> str:
        """The conclusion in words: the winner, its run and wall time, and how much cheaper than the runner-up."""
        if self.method is None:
            return f"target {self.target:.0%}: no measured run of any method reaches it"
        if self.runner_up is None:
            return (f"target {self.target:.0%}: {self.method} ({self.resolution}, {self.wall_s:.3g} s) is the only "
                    f"method with a measured run that reaches it")
        return (f"target {self.target:.0%}: cheapest is {self.method} ({self.resolution}, {self.wall_s:.3g} s), "
                f"{self.ratio:.3g} x cheaper than the next best, {self.runner_up} (cheapest measured run meeting "
                f"the target; no interpolation)")


def timed(run: Callable[[], T], repeats: int, comm) -> tuple[float, T]:
    """Median wall time [s] (max over ranks) of `repeats` calls of run(); the last call's result."""
    times, value = [], None
    for _ in range(repeats):
        comm.barrier()
        start = time.perf_counter()
        value = run()
        times.append(comm.allreduce(time.perf_counter() - start, op=MPI.MAX))
    return float(statistics.median(times)), value


def cheapest_meeting(rows: Sequence[MeasuredRun], target: float) -> Conclusion:
    """Cheapest measured run per method with error <= target; the winner and its ratio to the next best."""
    if not (math.isfinite(target) and target > 0):
        raise ValueError(f"target must be a positive relative error, got {target!r}")
    best: dict[str, MeasuredRun] = {}
    for r in rows:
        if r.error is not None and r.error <= target and (r.method not in best or r.wall_s < best[r.method].wall_s):
            best[r.method] = r
    ranked = sorted(best.values(), key=lambda r: r.wall_s)
    if not ranked:
        return Conclusion(target, None, None, None, None, None)
    win = ranked[0]
    if len(ranked) == 1:
        return Conclusion(target, win.method, win.resolution, win.wall_s, None, math.inf)
    return Conclusion(target, win.method, win.resolution, win.wall_s, ranked[1].method, ranked[1].wall_s / win.wall_s)


def set_baseline(rows: Sequence[MeasuredRun], method: str) -> MeasuredRun:
    """The baseline run: the coarsest (fewest dofs) run of `method`, or without one the cheapest run; sets every
    row's wall_vs_baseline = wall_s / the baseline's wall_s."""
    own = [r for r in rows if r.method == method]
    baseline = min(own, key=lambda r: r.ndofs) if own else min(rows, key=lambda r: r.wall_s)
    for r in rows:
        r.wall_vs_baseline = r.wall_s / baseline.wall_s
    return baseline


def printer(verbose: bool, comm) -> Callable[..., None]:
    """print(*args, flush=True) on rank 0 when verbose, else a no-op."""
    return (lambda *a: print(*a, flush=True)) if (verbose and comm.rank == 0) else (lambda *a: None)
