"""The corner-pinned cloth WITH BENDING: its converged reference and the cheapest run per target error.

Cloth: the corner-pinned cloth of fabricfem.benchmarks.speed_accuracy ([Peng2022, sec. 4.1]: side 1 m, k/rho =
1000 (m/s)^2, rho = 0.117 kg/m^2, h = 0.001177 m, air drag 0.351 kg/(m^2 s), gravity -z, pinned at (0, 0, 0) and
(0, 1, 0), from rest) as the Naghdi shell with the seed's square-root bending law (B0 = 3.3e-3 N m, kappa0 = 30
1/m; fabricfem.verify.strain_limit.corner_pinned_cloth(model="naghdi"), n x n Q2, full quadrature), no strain limit.
Quantity: the displacement u_c of the free corner (1, 1, 0) at T_END = 0.6 s; error |u_c - u_ref| / |u_ref|.

Route ("explicit"): central differences with lumped mass, rotary inertia scale ROTARY_SCALE = 100 (part of the
model here: the reference uses it too), the compiled loop (fabricfem.dynamics.compiled_loop), dt = STEP_FRACTION x
the element estimate of the critical step (fabricfem.dynamics.critical_time_step) and the safe-step check every
STEP_CHECK_EVERY steps (docs/findings/2026-11-27-safe-step.md); when the check shortens the step the run is
continued to T_END in equal steps no longer than the shortened one (as the dynamic scenes do).

Reference (`reference`, stored in REFERENCE_CSV so that the comparison is rerun without it): the explicit route on
n x n meshes with n doubling; `richardson` takes the three finest: observed order p = log2(|u_m - u_c| / |u_f - u_m|)
and u_ref = u_f + (u_f - u_m) / (2^p - 1); its uncertainty is the larger of the GCI's 1.25 |u_ref - u_f| / |u_ref|
(three meshes, safety 1.25) and, with a fourth mesh, the change of the estimate from the coarser triple's. A row at
half the step on a mesh shows the step error.

Ladder (`ladder`): routes "explicit" (above), "explicit-fixed" (the same first step without the step check; the
energy check still stops a blow-up) and "implicit" (trapezoidal Newmark, consistent mass with the physical rotary
inertia, dt of IMPLICIT_DTS) on small meshes; the solve loop (integrator set-up + run from rest to T_END, step checks
and continuation included; the critical-step estimate excluded, as speed_accuracy and explicit_floor time it) as the
median of `repeats` runs after one untimed run, error against the stored reference. Newton's bending figures (warp 1.19,
CPU, one thread; measured elsewhere, quoted) are NEWTON_S. Writes bending_floor.csv under `out`. SI units.

    python -m fabricfem.benchmarks.bending_floor [--repeats 7] [--cells 1 2 3 4 6 8] [--routes explicit ...]
        [--implicit-max-n 4] [--implicit-dt 0.02 0.1 0.15] [--out results/bench]
    python -m fabricfem.benchmarks.bending_floor --reference 4 8 16 32 --half-step 16   # then --reference 64:
        # recompute REFERENCE_CSV's rows (merged into it; --reference-out for another file)
"""
from __future__ import annotations

import argparse
import csv
import math
import statistics
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from fabricfem import io
from fabricfem.benchmarks.explicit_floor import against_newton, cheapest_per_target
from fabricfem.benchmarks.speed_accuracy import AIR_DRAG, K_OVER_RHO, NEWTON_OPTIONS, free_corner
from fabricfem.dynamics import CentralDifference, NewmarkIntegrator, critical_time_step
from fabricfem.dynamics.newmark import DynamicsError
from fabricfem.verify.strain_limit import corner_pinned_cloth

ROTARY_SCALE = 100.0      # rotary inertia scale of the explicit shell [-]
STEP_FRACTION = 0.9       # dt = STEP_FRACTION x the critical-step estimate
STEP_CHECK_EVERY = 20     # steps between the safe-step estimates
T_END = 0.6               # s
NEWTON_S = {0.10: 2.1e-3, 0.03: 5.3e-3, 0.01: 19.5}     # s, Newton's bending solve loop per target error
TARGETS = (0.10, 0.03, 0.01)
ROUTES = ("explicit", "explicit-fixed", "implicit")
IMPLICIT_DTS = (0.02, 0.1, 0.15)   # s, the implicit route's steps (0.02: speed_accuracy's coarsest implicit level)
GCI_SAFETY = 1.25         # factor of safety of the three-mesh grid convergence index [-]
REFERENCE_CSV = Path(__file__).resolve().parents[2] / "docs" / "figures" / "bending_floor_reference.csv"
REFERENCE_COLUMNS = ("n", "step_fraction", "steps", "reductions", "dt_final", "cpu_s", "u_x", "u_y", "u_z")
COLUMNS = ("route", "n", "steps", "reductions", "dt_start", "dt_final", "solve_s", "us_per_step", "in_c_us_per_step",
           "error", "u_x", "u_y", "u_z")


def shell_cloth(n: int):
    """The corner-pinned cloth with bending, n x n Q2 (module docstring)."""
    return corner_pinned_cloth(K_OVER_RHO, n, model="naghdi")


def swing(model, dt: float, check: int | None = STEP_CHECK_EVERY, compiled: bool | str = True) -> dict:
    """Run the explicit route from rest to T_END with first step dt [s] (<= the critical-step estimate); returns the
    corner displacement u [m] (nan after a blow-up, whose reason is in "stopped"), steps, step reductions, final
    step [s], the solve loop [s] (set-up + run), the loop's route and the time of its C calls [s] (in_c_s)."""
    model.w.x.array[:] = 0.0
    start = time.perf_counter()
    integ = CentralDifference(model, dt, air_drag=AIR_DRAG, rotary_inertia_scale=ROTARY_SCALE, compiled=compiled,
                              step_check_every=check)
    n_steps = int(math.ceil(T_END / dt - 1e-9))
    integ.set_time_step(T_END / n_steps)
    history = integ.run(n_steps, output_every=n_steps, stop_on_blowup=True)
    while not history.stopped and integ.t < T_END * (1.0 - 1e-12):   # a check shortened the step: finish in equal steps
        rest = int(math.ceil((T_END - integ.t) / integ.dt * (1.0 - 1e-12)))
        integ.set_time_step((T_END - integ.t) / rest)
        history = integ.run(integ.run_step + rest, output_every=rest, history=history, stop_on_blowup=True)
    wall = time.perf_counter() - start
    u = np.full(3, np.nan) if history.stopped else free_corner(model)
    out = {"u": u, "steps": integ.step_count, "reductions": integ.step_reductions, "dt_final": integ.dt,
           "solve_s": wall, "route": integ.route, "in_c_s": integ.timings.get("compiled_steps", math.nan),
           "stopped": history.stopped}
    integ.destroy()
    if not (history.stopped or np.all(np.isfinite(u))):
        raise RuntimeError(f"non-finite corner displacement {u!r}")
    return out


def first_step(model, fraction: float = STEP_FRACTION) -> float:
    """fraction x the element estimate of the critical step with rotary scale ROTARY_SCALE [s]."""
    return fraction * critical_time_step(model, rotary_inertia_scale=ROTARY_SCALE)


# ------------------------------------------------------------------------------------------- reference
def reference(cells: Sequence[int], half_step_on: int | None = None, say=print) -> list[dict]:
    """Reference rows (REFERENCE_COLUMNS) of the explicit route on each n x n mesh of `cells` (one run each, CPU time
    of the run), and one at half the step on `half_step_on` (step-error check)."""
    rows = []
    runs = [(n, STEP_FRACTION) for n in cells] + ([(half_step_on, STEP_FRACTION / 2)] if half_step_on else [])
    for n, fraction in runs:
        model = shell_cloth(n)
        dt = first_step(model, fraction)
        cpu = time.process_time()
        r = swing(model, dt)
        cpu = time.process_time() - cpu
        rows.append({"n": n, "step_fraction": fraction, "steps": r["steps"], "reductions": r["reductions"],
                     "dt_final": r["dt_final"], "cpu_s": cpu, "u_x": r["u"][0], "u_y": r["u"][1], "u_z": r["u"][2]})
        say(f"n = {n:2d} at {fraction:.2f} x dt_crit: {r['steps']} steps, {r['reductions']} reductions, "
            f"corner {np.array2string(r['u'], precision=7)} m, {cpu:.1f} s CPU", flush=True)
    return rows


def read_reference(path: Path = REFERENCE_CSV) -> list[dict]:
    """The stored reference rows (REFERENCE_COLUMNS): n, steps and reductions as int, the rest as float."""
    with open(path, newline="") as handle:
        lines = [line for line in handle if not line.startswith("#")]
    whole = ("n", "steps", "reductions")
    return [{c: int(float(row[c])) if c in whole else float(row[c]) for c in REFERENCE_COLUMNS}
            for row in csv.DictReader(lines)]


def _extrapolate(u_c: np.ndarray, u_m: np.ndarray, u_f: np.ndarray) -> tuple[float, np.ndarray]:
    """(observed order p, Richardson estimate [m]) of three solutions on meshes n, 2n, 4n."""
    p = math.log2(np.linalg.norm(u_m - u_c) / np.linalg.norm(u_f - u_m))
    return p, u_f + (u_f - u_m) / (2.0 ** p - 1.0)


def richardson(rows: Sequence[dict]) -> dict:
    """From the rows at STEP_FRACTION on the three finest meshes (n doubling): observed order p, the Richardson
    estimate u_ref [m] and its relative uncertainty, the larger of the GCI's GCI_SAFETY |u_ref - u_f| / |u_ref| and,
    with a fourth mesh, the change of the estimate from the three coarser meshes' (|u_ref - u_ref'| / |u_ref|);
    also the finest mesh's difference to the next coarser one (relative) and the coarser triple's order."""
    full = sorted((r for r in rows if r["step_fraction"] == STEP_FRACTION), key=lambda r: r["n"])[-4:]
    if len(full) < 3 or any(b["n"] != 2 * a["n"] for a, b in zip(full, full[1:])):
        raise ValueError("richardson needs three meshes with n doubling")
    u = [np.array([r["u_x"], r["u_y"], r["u_z"]]) for r in full]
    p, u_ref = _extrapolate(*u[-3:])
    scale = float(np.linalg.norm(u_ref))
    gci = GCI_SAFETY * float(np.linalg.norm(u_ref - u[-1])) / scale
    out = {"order": p, "u": u_ref, "gci": gci, "uncertainty": gci,
           "finest_difference": float(np.linalg.norm(u[-1] - u[-2])) / scale,
           "meshes": tuple(int(r["n"]) for r in full[-3:]), "order_coarser": math.nan, "change": math.nan}
    if len(full) == 4:
        out["order_coarser"], u_prev = _extrapolate(*u[:3])
        out["change"] = float(np.linalg.norm(u_ref - u_prev)) / scale
        out["uncertainty"] = max(gci, out["change"])
    return out


def store_reference(cells: Sequence[int], half_step_on: int | None, path: Path, say=print) -> dict:
    """Compute the reference rows (`reference`), merge them into the rows stored at `path` (a new row replaces a
    stored one of the same mesh and step fraction), write them sorted and, with three doubling meshes, the
    Richardson estimate. Returns {"rows", "reference" (None with fewer than three meshes)}."""
    rows = reference(cells, half_step_on, say)
    new = {(r["n"], r["step_fraction"]) for r in rows}
    if path.exists():
        rows += [r for r in read_reference(path) if (int(r["n"]), r["step_fraction"]) not in new]
    rows.sort(key=lambda r: (-r["step_fraction"], r["n"]))
    io.write_csv(path, REFERENCE_COLUMNS, [[r[c] for c in REFERENCE_COLUMNS] for r in rows])
    try:
        ref = richardson(rows)
    except ValueError as exc:
        say(f"no Richardson estimate: {exc}")
        return {"rows": rows, "reference": None}
    say(f"order {ref['order']:.3f} on {ref['meshes']}, u_ref {np.array2string(ref['u'], precision=7)} m, "
        f"uncertainty {ref['uncertainty']:.2e}, finest difference {ref['finest_difference']:.2e}")
    return {"rows": rows, "reference": ref}


def error(u: np.ndarray, u_ref: np.ndarray) -> float:
    """|u - u_ref| / |u_ref| [-]."""
    return float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))


# ---------------------------------------------------------------------------------------------- ladder
def implicit_swing(model, n_steps: int) -> dict:
    """Trapezoidal Newmark (consistent mass, physical rotary inertia; as speed_accuracy.run_implicit) from rest to
    T_END in n_steps steps: the corner displacement u [m] (nan when Newton fails, the reason in "stopped"), steps
    and the solve loop [s] (set-up + run)."""
    model.w.x.array[:] = 0.0
    start = time.perf_counter()
    integ = NewmarkIntegrator(model, T_END / n_steps, beta=0.25, gamma=0.5, air_drag=AIR_DRAG,
                              newton_options=NEWTON_OPTIONS)
    stopped = ""
    try:
        integ.run(n_steps, output_every=n_steps)
    except DynamicsError as exc:
        stopped = str(exc)
    wall = time.perf_counter() - start
    integ.destroy()
    return {"u": np.full(3, np.nan) if stopped else free_corner(model), "steps": n_steps, "reductions": 0,
            "dt_final": T_END / n_steps, "solve_s": wall, "route": "implicit", "in_c_s": math.nan, "stopped": stopped}


def _route_runs(route: str, n: int, repeats: int, implicit_dt: float = IMPLICIT_DTS[0]) -> tuple[float, list[dict]]:
    """(first step [s], `repeats` runs after one untimed run) of `route` on the n x n cloth (implicit: the largest
    step <= implicit_dt [s] dividing T_END)."""
    model = shell_cloth(n)
    if route == "implicit":
        n_steps = int(math.ceil(T_END / implicit_dt - 1e-9))
        dt = T_END / n_steps
        run = lambda: implicit_swing(model, n_steps)  # noqa: E731
    else:
        dt = first_step(model)
        check = STEP_CHECK_EVERY if route == "explicit" else None
        run = lambda: swing(model, dt, check)  # noqa: E731
    run()                                             # build or load the compiled loop / forms once
    runs = [run() for _ in range(repeats)]
    if route != "implicit" and runs[-1]["route"] != "compiled":
        raise RuntimeError(f"n = {n}: the run took the {runs[-1]['route']!r} loop, not the compiled one")
    return dt, runs


def ladder(cells: Sequence[int], repeats: int, u_ref: np.ndarray, routes: Sequence[str] = ROUTES,
           implicit_max_n: int = 4, implicit_dts: Sequence[float] = IMPLICIT_DTS, say=print) -> list[dict]:
    """Rows (COLUMNS) of each route of ROUTES on each n x n mesh of `cells`: median solve loop of `repeats` runs.
    "explicit": the safe step (check every STEP_CHECK_EVERY steps); "explicit-fixed": the same first step, no
    check (a blow-up is still stopped by the energy check); "implicit": Newmark at each step of `implicit_dts`, on
    the meshes with n <= implicit_max_n only."""
    rows = []
    for n in cells:
        plan = [(r, None) for r in routes if r != "implicit"]
        if "implicit" in routes and n <= implicit_max_n:
            plan += [("implicit", dt) for dt in implicit_dts]
        for route, implicit_dt in plan:
            dt, runs = _route_runs(route, n, repeats, implicit_dt or IMPLICIT_DTS[0])
            wall = statistics.median(r["solve_s"] for r in runs)
            last = runs[-1]
            row = {"route": route, "n": n, "steps": last["steps"], "reductions": last["reductions"],
                   "dt_start": dt, "dt_final": last["dt_final"], "solve_s": wall,
                   "us_per_step": 1e6 * wall / last["steps"],
                   "in_c_us_per_step": 1e6 * statistics.median(r["in_c_s"] for r in runs) / last["steps"],
                   "error": math.inf if last.get("stopped") else error(last["u"], u_ref),
                   "u_x": last["u"][0], "u_y": last["u"][1], "u_z": last["u"][2]}
            rows.append(row)
            say(f"n = {n:2d} {route:>14}: dt {dt:.3g} s, {row['steps']:5d} steps ({row['reductions']} reductions), "
                f"solve loop "
                f"{1e3 * wall:8.2f} ms ({row['us_per_step']:.1f} us/step, in C {row['in_c_us_per_step']:.1f}; "
                f"{min(r['solve_s'] for r in runs) * 1e3:.2f}-{max(r['solve_s'] for r in runs) * 1e3:.2f} ms), "
                f"error {row['error']:.3e}" + (f"; stopped: {last['stopped'][:90]}" if last.get("stopped") else ""),
                flush=True)
    return rows


def qualifies(row: dict, rows: Sequence[dict], target: float) -> bool:
    """The row meets `target` and, for the implicit route, so does the same mesh's run at its smallest measured step:
    a large step whose time error happens to cancel the mesh's error does not count."""
    if not row["error"] <= target:
        return False
    if row["route"] != "implicit":
        return True
    same = [r for r in rows if r["route"] == "implicit" and r["n"] == row["n"]]
    return min(same, key=lambda r: r["dt_start"])["error"] <= target


def conclusions(rows: Sequence[dict], uncertainty: float = 0.0, say=print) -> list[tuple[float, dict | None]]:
    """The cheapest measured run qualifying for each target error (`qualifies`, against the reference estimate),
    next to Newton's bending solve loop; `uncertainty` (the reference's, relative) is added to the error to say
    whether the target is met for certain."""
    out = cheapest_per_target(rows, lambda r, target: qualifies(r, rows, target), TARGETS)
    for target, best in out:
        if best is None:
            say(f"target {target:.0%}: no measured run meets it")
            continue
        sure = "met" if best["error"] + uncertainty <= target else "not certain"
        say(f"target {target:.0%}: {best['route']} n = {best['n']} ({best['steps']} steps) "
            f"{1e3 * best['solve_s']:.2f} ms, error {best['error']:.2e} (+ reference {uncertainty:.1e}: {sure}) "
            f"against Newton's {NEWTON_S[target]:.3g} s: " + against_newton(best, NEWTON_S[target]))
    return out


def main(argv: Sequence[str] | None = None) -> dict:
    """The command line (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--cells", type=int, nargs="+", default=[1, 2, 3, 4, 6, 8])
    parser.add_argument("--routes", nargs="+", default=list(ROUTES), choices=ROUTES)
    parser.add_argument("--implicit-max-n", type=int, default=4, help="the implicit route on n <= this only")
    parser.add_argument("--implicit-dt", type=float, nargs="+", default=list(IMPLICIT_DTS), help="implicit steps [s]")
    parser.add_argument("--out", default="results/bench")
    parser.add_argument("--reference", type=int, nargs="+", default=None,
                        help="compute the reference rows on these meshes and merge them into --reference-out")
    parser.add_argument("--half-step", type=int, default=None, help="also a run at half the step on this mesh")
    parser.add_argument("--reference-out", default=str(REFERENCE_CSV))
    args = parser.parse_args(argv)
    if args.reference is not None:
        return store_reference(args.reference, args.half_step, Path(args.reference_out))
    ref = richardson(read_reference(Path(args.reference_out)))
    print(f"reference: {np.array2string(ref['u'], precision=7)} m (order {ref['order']:.2f} on {ref['meshes']}, "
          f"uncertainty {ref['uncertainty']:.2e})")
    rows = ladder(args.cells, args.repeats, ref["u"], args.routes, args.implicit_max_n, args.implicit_dt)
    found = conclusions(rows, ref["uncertainty"])
    io.write_csv(Path(args.out) / "bending_floor.csv", COLUMNS, [[r[c] for c in COLUMNS] for r in rows])
    return {"rows": rows, "conclusions": found, "reference": ref}


if __name__ == "__main__":
    main()
