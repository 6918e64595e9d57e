"""The fixed cost per explicit step, and the corner-pinned comparison it decides.

Cloth: the corner-pinned membrane of fabricfem.benchmarks.speed_accuracy ([Peng2022, sec. 4.1], k/rho = 1000
(m/s)^2, air drag, n x n Q2, central differences at 0.9 x the critical step to t_end = 0.6 s).

Per-step cost (`step_cost`): the same run by the Python loop (the baseline, measured in the same process) and by
the compiled loop (fabricfem.dynamics.compiled_loop); medians of `repeats` runs of
* solve loop [s]: integrator set-up + run from rest (what speed_accuracy.run_explicit times), and per step
  = solve loop / steps;
* in C [s per step]: the compiled loop's C calls alone (timings["compiled_steps"] / steps).

Accuracy ladder (`ladder`): the compiled runs at n = 2, 3, 4, ... with their error |u_c - u_ref| / |u_ref| at the
free corner against the reference of docs/figures/speed_accuracy.csv (implicit membrane 32 x 32, dt = 2.5 ms). That
file stores each row's corner displacement and error but not the reference itself: REFERENCE_U is the point whose
relative distances to the 13 rows' displacements are their errors (least squares, largest residual 3.5e-18), and the
n = 4 row is rerun to check that the model has not changed since (`model_drift`). Newton's figures (warp 1.19, CPU,
one thread, VBD on a 4 x 4 grid; measured elsewhere, quoted) are NEWTON_S. Times on a shared machine: only the
ratios within one run are meaningful. Writes explicit_floor.csv under `out`. SI units.

    python -m fabricfem.benchmarks.explicit_floor [--repeats 7] [--cells 2 3 4 6 8] [--out results/bench]
    python -m fabricfem.benchmarks.explicit_floor --single 2      # one run: time the whole command around it
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from fabricfem import io
from fabricfem.benchmarks.speed_accuracy import AIR_DRAG, EXPLICIT_SAFETY, free_corner, membrane_cloth
from fabricfem.dynamics import CentralDifference
from fabricfem.dynamics import critical_time_step as shell_critical_time_step

REFERENCE_U = np.array([-0.8036191455474277, 0.002116977797929501, -0.9939599441185456])   # m (module docstring)
STORED_N4 = np.array([-0.8060780519857036, 0.00254554635462266, -1.0008819776069648])      # m, the stored n = 4 row
NEWTON_S = {0.10: 0.8e-3, 0.03: 1.85e-3, 0.01: 0.905}    # s, Newton's membrane solve loop per target error
TARGETS = (0.10, 0.03, 0.01)
T_END = 0.6   # s
COLUMNS = ("n", "steps", "dt", "route", "solve_s", "us_per_step", "in_c_us_per_step", "vs_python", "error")


def _steps(model) -> tuple[int, float]:
    """Steps and step [s] to T_END at EXPLICIT_SAFETY x the critical step (as speed_accuracy)."""
    n_steps = int(math.ceil(T_END / (EXPLICIT_SAFETY * shell_critical_time_step(model)) - 1e-12))
    return n_steps, T_END / n_steps


def timed_runs(model, compiled: bool, repeats: int) -> tuple[float, float, np.ndarray]:
    """(median solve loop [s], median C time [s], corner displacement [m]) of `repeats` runs from rest."""
    n_steps, dt = _steps(model)
    solve, in_c = [], []
    for _ in range(repeats):
        model.w.x.array[:] = 0.0
        start = time.perf_counter()
        integ = CentralDifference(model, dt, air_drag=AIR_DRAG, compiled=compiled)
        integ.run(n_steps, output_every=n_steps)
        solve.append(time.perf_counter() - start)
        in_c.append(integ.timings.get("compiled_steps", math.nan))
        integ.destroy()
    return statistics.median(solve), statistics.median(in_c), free_corner(model)


def error(u: np.ndarray) -> float:
    """|u - REFERENCE_U| / |REFERENCE_U| [-]."""
    return float(np.linalg.norm(u - REFERENCE_U) / np.linalg.norm(REFERENCE_U))


def ladder(cells: Sequence[int], repeats: int, say=print) -> list[dict]:
    """Rows (COLUMNS) of the Python baseline and the compiled loop on every n x n mesh of `cells`."""
    rows = []
    for n in cells:
        model = membrane_cloth(n)
        n_steps, dt = _steps(model)
        timed_runs(model, True, 1)        # build once (the compiled loop, the -O3 energy form)
        base, _, u_base = timed_runs(model, False, repeats)
        solve, in_c, u = timed_runs(model, True, repeats)
        for route, wall, c, corner in (("python", base, math.nan, u_base), ("compiled", solve, in_c, u)):
            rows.append({"n": n, "steps": n_steps, "dt": dt, "route": route, "solve_s": wall,
                         "us_per_step": 1e6 * wall / n_steps, "in_c_us_per_step": 1e6 * c / n_steps,
                         "vs_python": wall / base, "error": error(corner)})
            say(f"n = {n:2d}, {n_steps:4d} steps, {route:>8}: solve loop {1e3 * wall:8.3f} ms "
                f"({1e6 * wall / n_steps:6.1f} us/step, in C {1e6 * c / n_steps:5.2f} us/step), x{wall / base:.3f} "
                f"of the Python loop, error {error(corner):.3e}")
        if not np.array_equal(u, u_base):
            say(f"  the two routes' corners differ by {np.abs(u - u_base).max():.3e} m")
    return rows


def cheapest_per_target(rows: Sequence[dict], meets, targets: Sequence[float] = TARGETS
                        ) -> list[tuple[float, dict | None]]:
    """(target, the run of least `solve_s` among the rows for which meets(row, target) holds, or None) per target."""
    out = []
    for target in targets:
        meeting = [r for r in rows if meets(r, target)]
        out.append((target, min(meeting, key=lambda r: r["solve_s"]) if meeting else None))
    return out


def against_newton(run: dict, newton_s: float) -> str:
    """Newton's solve loop `newton_s` [s] against the run's `solve_s`: "<r> x cheaper" or "<1/r> x dearer"."""
    ratio = newton_s / run["solve_s"]
    return f"{ratio:.3g} x cheaper" if ratio >= 1 else f"{1 / ratio:.3g} x dearer"


def conclusions(rows: list[dict], say=print) -> list[tuple[float, dict | None]]:
    """The cheapest compiled run meeting each target error, next to Newton's solve loop."""
    out = cheapest_per_target(rows, lambda r, target: r["route"] == "compiled" and r["error"] <= target)
    for target, best in out:
        if best is None:
            say(f"target {target:.0%}: no measured explicit run meets it")
            continue
        say(f"target {target:.0%}: n = {best['n']} ({best['steps']} steps) {1e3 * best['solve_s']:.3f} ms against "
            f"Newton's {1e3 * NEWTON_S[target]:.3g} ms: " + against_newton(best, NEWTON_S[target]))
    return out


def model_drift(say=print) -> float:
    """|u(n = 4) now - the stored n = 4 row| [m]: the reference is valid only if the model is unchanged."""
    model = membrane_cloth(4)
    _, _, u = timed_runs(model, True, 1)
    drift = float(np.abs(u - STORED_N4).max())
    say(f"n = 4 rerun against the stored row: {drift:.2e} m")
    return drift


def main(argv: Sequence[str] | None = None) -> dict:
    """The command line (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--cells", type=int, nargs="+", default=[2, 3, 4, 6, 8])
    parser.add_argument("--out", default="results/bench")
    parser.add_argument("--single", type=int, default=None,
                        help="only one compiled run on this n x n mesh (time the whole command around it)")
    args = parser.parse_args(argv)
    if args.single is not None:
        wall, _, u = timed_runs(membrane_cloth(args.single), True, 1)
        print(f"n = {args.single}: corner {np.array2string(u, precision=5)} m, error {error(u):.3e}, solve loop "
              f"{1e3 * wall:.2f} ms (first run: builds or loads the compiled loop)")
        return {"u": u, "solve_s": wall}
    drift = model_drift()
    rows = ladder(args.cells, args.repeats)
    found = conclusions(rows)
    io.write_csv(Path(args.out) / "explicit_floor.csv", COLUMNS, [[r[c] for c in COLUMNS] for r in rows])
    return {"rows": rows, "conclusions": found, "drift": drift}


if __name__ == "__main__":
    main()
