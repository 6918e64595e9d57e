"""`fabricfem study sleeve`: the arm-sleeve parameter study of [Man2006, sec. 5.3] (Figs. 37, 39, 42, 44-46).

Each variant is one flexion (fabricfem.wear.sleeve, explicit dynamics by default) giving a resisting-torque-vs-angle curve;
each figure gets <out>/<figure>.csv (variant, angle_deg, torque_Nm, ...) and <out>/<figure>.png. Variants
that stop before the final angle (blow-up or Newton failure, see fabricfem.wear.sleeve) keep their partial curve and the
reason is written to <out>/failures.csv. The distinct variants run as one batch (fabricfem.scenes.batch, the
machinery of `fabricfem sweep`): groups of `ranks_per_variant` ranks (default 1), longest first (`relative_cost`)
to the least loaded group; the same command runs under `mpirun -n N`. `quick` runs mesh I only, to 6 degrees
(records at 3 and 6; test suite): its numbers are a reduced study, not the thesis's. `fine` / `meshes` choose
the mesh of the parameter figures (default III, as the thesis's "well-refined" sleeve) and of the mesh series
(default I-IV); a coarser choice is a reduced-resolution study and README.txt says so.

Fabrics II and III (E = 350 MPa and 7.2 GPa) run with dynamic similarity (`SleeveConfig.dynamic_similarity`:
flexion speed and mass damping times c_k / c_I, c = sqrt(E / rho)), so they cost the steps of fabric I and
carry fabric I's relative inertia and damping; fabric I of that figure runs with the flag too (factor 1).

Checkpoints: every finished variant is written to <out>/variants/<hash of its configuration>.csv and a
rerun of the study reads it instead of flexing again (an interrupted or partly rerun study resumes); the
figures are written from these files. `mesh_frictions` and `only` select the mesh series and figures.
Progress: each group's first rank prints one line when each of its variants starts and ends.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.materials import positive_number
from fabricfem.scenes.batch import Job, check, run_batch
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.outputs import plot_torque, torque_rms_error
from fabricfem.wear.run import build_run, run_sleeve
from fabricfem.wear.sleeve_implicit import run_implicit

MESHES = {"I": (10, 13), "II": (15, 20), "III": (20, 26), "IV": (30, 39)}
FABRICS = {"I": dict(E=1.2e6, G=1.2e6 / 200, density=436.0),       # [Man2006, sec. 5.3.5], G = E / 200
           "II": dict(E=350e6, G=350e6 / 200, density=436.0),
           "III": dict(E=7.2e9, G=7.2e9 / 200, density=700.0)}
FIGURE_TITLES = {"mesh_mu0.1": "mesh convergence, mu = 0.1 (Fig. 37)",
                 "mesh_mu0.5": "mesh convergence, mu = 0.5 (Fig. 39)",
                 "friction": "friction 0.1 vs 0.5 (Fig. 42)", "fit": "fit R = 0.06 vs 0.07 m, mu = 0.5 (Fig. 44)",
                 "thickness": "thickness 1 vs 2 mm, mu = 0.5 (Fig. 45)", "fabrics": "fabrics I-III, mu = 0.1 (Fig. 46)"}


# the columns of a variant's curve (the motion's records and the start state before them)
CURVE_HEADER = ("angle_deg", "torque_Nm", "torque_both_segments_Nm", "newton_iterations", "max_penetration_m",
                "contact_force_N", "wall_s", "drag_ratio", "time_steps", "kinetic_energy_J", "strain_energy_J")


def curve_rows(h: WearHistory) -> list[list]:
    """CURVE_HEADER rows of a sleeve history: the start state (the last record before the motion, with the time steps
    and Newton iterations of every record before the motion) and the motion."""
    first = max(next((k for k, s in enumerate(h.steps) if s.phase == "motion"), len(h.steps)) - 1, 0)
    before = h.steps[:first + 1]
    rows = [[s.coordinate, s.torques["elbow"], s.torques["elbow_both_segments"], s.newton_iterations,
             s.max_penetration, s.contact_force, s.wall, s.drag_ratio, s.time_steps, s.kinetic_energy,
             s.strain_energy] for s in h.steps[first:]]
    if rows:
        rows[0][3] = sum(s.newton_iterations for s in before)
        rows[0][8] = sum(s.time_steps for s in before)
    return rows


def curve_history(name: str, rows: list[dict]) -> WearHistory:
    """A WearHistory of the records of CURVE_HEADER rows (the start record's phase "settle", then "motion")."""
    h = WearHistory(name)
    for k, r in enumerate(rows):
        h.steps.append(WearStep(
            phase="motion" if k else "settle", time=math.nan,
            torques={"elbow": float(r["torque_Nm"]), "elbow_both_segments": float(r["torque_both_segments_Nm"])},
            peak_pressure=0.0, peak_segment="", peak_position=(math.nan,) * 3, mean_pressure=0.0,
            max_penetration=float(r["max_penetration_m"]), contact_force=float(r["contact_force_N"]), seam_gap=0.0,
            seam_forces={}, max_strain=0.0, time_steps=int(float(r["time_steps"])),
            kinetic_energy=float(r["kinetic_energy_J"]), strain_energy=float(r["strain_energy_J"]),
            wall=float(r["wall_s"]), axis_value=float(r["angle_deg"]),
            newton_iterations=int(float(r["newton_iterations"])), drag_ratio=float(r["drag_ratio"])))
    return h


def variants(quick: bool = False, fine: str = "III", meshes: tuple[str, ...] = ("I", "II", "III", "IV"),
             fabrics: tuple[str, ...] = ("I", "II", "III"), mesh_frictions: tuple[float, ...] = (0.1, 0.5),
             only: tuple[str, ...] | None = None) -> dict[str, dict[str, SleeveConfig]]:
    """figure -> {label: config}. Identical configurations appear in several figures (run once).
    `mesh_frictions` selects the mesh series run (mu = 0.1 and / or 0.5; a figure left out is not written);
    `only` restricts the study to the named figures (FIGURE_TITLES keys; None: all).

    `fabrics` selects the fabric sets of the fabrics figure: the explicit step scales with
    h / sqrt(E / rho), so fabrics II and III would need 17 and 60 times the steps of fabric I at the same
    flexion speed; they run with dynamic similarity (module docstring) at fabric I's cost."""
    for name in (fine, *meshes):
        if name not in MESHES:
            raise ValueError(f"fine / meshes: unknown mesh {name!r}, expected one of {sorted(MESHES)}")
    for name in fabrics:
        if name not in FABRICS:
            raise ValueError(f"fabrics: unknown fabric set {name!r}, expected one of {sorted(FABRICS)}")
    for name in only or ():
        if name not in FIGURE_TITLES:
            raise ValueError(f"only: unknown figure {name!r}, expected some of {sorted(FIGURE_TITLES)}")
    for mu in mesh_frictions:
        if mu not in (0.1, 0.5):
            raise ValueError(f"mesh_frictions: the mesh series exist for mu = 0.1 and 0.5, got {mu!r}")
    base = SleeveConfig()
    meshes = {"I": MESHES["I"]} if quick else {k: MESHES[k] for k in meshes}
    fine = MESHES["I"] if quick else MESHES[fine]
    if quick:
        base = base.with_(final_angle=6.0, angle_steps=2, output_angle_step=3.0)
    at = lambda mesh, **kw: base.with_(n_around=mesh[0], n_along=mesh[1], **kw)  # noqa: E731
    figures = {
        "mesh_mu0.1": {f"mesh {k} ({m[0]}x{m[1]})": at(m, friction=0.1) for k, m in meshes.items()},
        "mesh_mu0.5": {f"mesh {k} ({m[0]}x{m[1]})": at(m, friction=0.5) for k, m in meshes.items()},
        "friction": {"mu = 0.1": at(fine, friction=0.1), "mu = 0.5": at(fine, friction=0.5)},
        "fit": {"R = 0.06 m": at(fine, friction=0.5), "R = 0.07 m": at(fine, friction=0.5, radius=0.07)},
        "thickness": {"t = 1 mm": at(fine, friction=0.5), "t = 2 mm": at(fine, friction=0.5, thickness=2e-3)},
        "fabrics": {f"fabric {k}": at(fine, friction=0.1, dynamic_similarity=True, **FABRICS[k]) for k in fabrics},
    }
    for mu in (0.1, 0.5):
        if mu not in mesh_frictions:
            del figures[f"mesh_mu{mu}"]
    if only is not None:
        figures = {name: fig for name, fig in figures.items() if name in only}
    return figures


def relative_cost(config: SleeveConfig) -> float:
    """Estimated cost of a flexion relative to others: nodes x steps ~ (n_around n_along) x (1 / h) (the
    explicit step scales with the element size h; dynamic similarity keeps the steps of fabric I)."""
    return (config.tube.n_around * config.tube.n_along) ** 1.5


def run_study(out: str | Path = "results/sleeve_study", quick: bool = False,
              comm: MPI.Comm = MPI.COMM_WORLD, fine: str = "III",
              meshes: tuple[str, ...] = ("I", "II", "III", "IV"),
              fabrics: tuple[str, ...] = ("I", "II", "III"), mesh_frictions: tuple[float, ...] = (0.1, 0.5),
              only: tuple[str, ...] | None = None, ranks_per_variant: int = 1) -> dict[str, dict[str, WearHistory]]:
    """Run every distinct variant once as one batch (fabricfem.scenes.batch.run_batch: groups of
    `ranks_per_variant` ranks, longest first by `relative_cost` to the least loaded group; a variant saved in
    <out>/variants is read back, not rerun), then write CSV + PNG per figure from the saved variants. A variant
    that raises is reported after the others have run and saved (batch.BatchError naming it)."""
    out = Path(out)
    figures = variants(quick, fine, meshes, fabrics, mesh_frictions, only)
    unique: list[SleeveConfig] = []
    for fig in figures.values():
        for cfg in fig.values():
            if cfg not in unique:
                unique.append(cfg)
    say = (lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None)
    say(f"sleeve study{' (quick, reduced)' if quick else ''}: {len(unique)} variants on {comm.size} rank(s)")
    t0 = time.perf_counter()

    def flex(cfg: SleeveConfig, sub: MPI.Comm) -> str:
        h = run_sleeve(cfg, sub, stop_on_failure=False)
        if sub.rank == 0:
            _save_variant(out, cfg, h)
        return (f"reached {h.steps[-1].coordinate:.1f} deg, torque {h.steps[-1].torques['elbow']:.4e} N m"
                + (f" STOPPED: {h.failure}" if h.failure else ""))

    jobs = [Job(f"variant {i + 1}/{len(unique)} ({_describe(cfg)})", relative_cost(cfg),
                lambda sub, cfg=cfg: flex(cfg, sub), lambda cfg=cfg: _load_variant(out, cfg) is not None)
            for i, cfg in enumerate(unique)]
    check(run_batch(jobs, comm, ranks_per_variant, "sleeve study"), "sleeve study", f"{out}/variants")
    histories = {i: _load_variant(out, cfg) for i, cfg in enumerate(unique)}
    results = {name: {label: histories[unique.index(cfg)] for label, cfg in fig.items()}
               for name, fig in figures.items()}
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        failures = []
        for name, curves in results.items():
            fio.write_csv(out / f"{name}.csv", ("variant", *CURVE_HEADER),
                          [[label, *row] for label, h in curves.items() for row in curve_rows(h)])
            failures += [[name, label, h.failure] for label, h in curves.items() if h.failure]
            plot_torque(out / f"{name}.png", {label: h.motion_curve("elbow") for label, h in curves.items()},
                        FIGURE_TITLES[name] + (" [quick]" if quick else ""))
        fio.write_csv(out / "failures.csv", ("figure", "variant", "reason"), failures)
        similar = [label for label, cfg in figures.get("fabrics", {}).items() if cfg.similarity_factor != 1.0]
        (out / "README.txt").write_text(
            ("QUICK (reduced) study: mesh I only, 6 degrees\n" if quick else
             "full study\n" if ((fine, tuple(meshes), tuple(fabrics)) == ("III", tuple(MESHES), tuple(FABRICS))
                                 and tuple(mesh_frictions) == (0.1, 0.5)) else
             f"REDUCED study: parameter figures on mesh {fine}, mesh series {', '.join(meshes)} "
             f"(mu = {', '.join(str(m) for m in mesh_frictions)}), fabrics {', '.join(fabrics)}\n")
            + f"wall time {time.perf_counter() - t0:.0f} s on {comm.size} rank(s)\n"
            + f"flexion {base_description(next(iter(next(iter(figures.values())).values())))}\n"
            + f"figures: {', '.join(figures)}\n"
            + ("dynamic similarity (flexion speed and mass damping x c / c_fabric I): " + "; ".join(
                f"{label} at {figures['fabrics'][label].flexion_speed:.4g} deg/s" for label in similar) + "\n"
               if similar else ""))
    say(f"wrote {out}/<figure>.csv and .png for {sorted(results)} ({time.perf_counter() - t0:.0f} s)")
    return results


FIGURES = ("mesh_mu0.1", "mesh_mu0.5", "friction", "fit", "thickness", "fabrics")   # the study's figure CSVs


def read_figure(path: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """variant -> (angles [deg], resisting torque [N m]) of a figure CSV written by `run_study`."""
    curves: dict[str, list[tuple[float, float]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            curves.setdefault(row["variant"], []).append((float(row["angle_deg"]), float(row["torque_Nm"])))
    return {v: (np.array([a for a, _ in c]), np.array([t for _, t in c])) for v, c in curves.items()}


def read_figures(directory: str | Path) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """figure -> `read_figure` of the study's figure CSVs (FIGURES) present in `directory`."""
    directory = Path(directory)
    return {name: read_figure(directory / f"{name}.csv") for name in FIGURES if (directory / f"{name}.csv").exists()}


def compare_figures(out: str | Path, stored: str | Path) -> list[list]:
    """The torque curves of the figure CSVs under `out` against those under `stored` (e.g. docs/figures/sleeve, run
    with other settings or code): per figure and variant present in both, the RMS over 10 deg to the end of the
    difference relative to the stored mean |T| (fabricfem.wear.outputs.torque_rms_error) and both final torques
    [N m]. Writes comparison.csv under `out` (rank 0) and returns its rows."""
    out, stored = Path(out), Path(stored)
    if not stored.is_dir():
        raise ValueError(f"compare-with: {str(stored)!r} is not a folder of study figures")
    new_figures, old_figures = read_figures(out), read_figures(stored)
    rows = []
    for name in (f for f in FIGURES if f in new_figures and f in old_figures):
        new, old = new_figures[name], old_figures[name]
        for label in (v for v in old if v in new):
            (a, t), (a0, t0) = new[label], old[label]
            rows.append([name, label, torque_rms_error(a, t, a0, t0), float(t0[-1]), float(t[-1])])
    fio.write_csv(out / "comparison.csv", ("figure", "variant", "torque_rms_error", "stored_final_Nm", "final_Nm"),
                  rows)
    return rows


def _variant_path(out: Path, cfg: SleeveConfig) -> Path:
    """Checkpoint of one finished variant: <out>/variants/<sha1 of the configuration>.csv."""
    key = hashlib.sha1(repr(("engine", sorted(cfg.key_items().items()))).encode()).hexdigest()[:16]
    return Path(out) / "variants" / f"{key}.csv"


def _save_variant(out: Path, cfg: SleeveConfig, h: WearHistory):
    """Write a finished variant (its configuration on the first line, then its curve rows) so that an
    interrupted study resumes without rerunning it (`_load_variant`)."""
    fio.write_csv(_variant_path(out, cfg), CURVE_HEADER, curve_rows(h), MPI.COMM_SELF,
                  comment=f"{repr(sorted(cfg.flat().items()))} | wall {h.wall:.1f} | failure {h.failure}")


def _load_variant(out: Path, cfg: SleeveConfig) -> WearHistory | None:
    """The history saved by `_save_variant` for exactly this configuration, or None."""
    path = _variant_path(out, cfg)
    if not path.exists():
        return None
    with open(path) as f:
        first = f.readline()
        if not first.startswith(f"# {repr(sorted(cfg.flat().items()))} |"):
            return None
        rows = list(csv.DictReader(f))
    h = curve_history(cfg.name, rows)
    h.wall = float(first.split("| wall ")[1].split(" |")[0])
    h.failure = first.split("| failure ")[1].strip()
    return h


def base_description(cfg: SleeveConfig) -> str:
    """One line: the flexion settings common to the study's variants."""
    return (f"at {cfg.motion.angular_velocity:g} deg/s, mass damping {cfg.route.mass_damping:g} 1/s, rotary-inertia scale "
            f"{cfg.route.rotary_inertia_scale:g}, gravity {'on (-y, ' + format(cfg.motion.settle_time, 'g') + ' s rest before the flexion)' if cfg.route.gravity else 'off'}, "
            f"{cfg.contact.method} contact, records every {cfg.motion.output_angle_step:g} deg")


def _describe(cfg: SleeveConfig) -> str:
    return (f"{cfg.tube.n_around}x{cfg.tube.n_along} mu={cfg.contact.friction} R={cfg.tube.radius} t={cfg.material.thickness} E={cfg.material.E:.3g}"
            + (f" (similarity: {cfg.flexion_speed:.4g} deg/s)" if cfg.route.dynamic_similarity and
               cfg.similarity_factor != 1.0 else ""))


# ------------------------------------------------------------------------------------------------------------
# The three contact methods on the sleeve (acceptance table)
# ------------------------------------------------------------------------------------------------------------
METHODS = {"lagrange": "explicit, forward-increment Lagrange multipliers ([Man2006, Box 5])",
           "penalty": "explicit, penalty (k_N = 10 E t / h^2)",
           "augmented": "implicit backward Euler + Newton, augmented Lagrangian (Uzawa)"}
METHOD_COLUMNS = ("method", "route", "mesh", "ndofs", "ranks", "gravity", "reached_deg", "torque_57_Nm",
                  "max_penetration_m", "bounce_rms_Nm", "bounce_relative", "work", "wall_s", "cpu_s", "note")
# relative cost for the batch's schedule: measured walls 666, 728 and >= 1287 s (budget-limited) on mesh III
# (docs/figures/sleeve/sleeve_methods_gravity.csv)
METHOD_COST = {"lagrange": 1.0, "penalty": 1.0, "augmented": 2.0}
# implicit route: 4 backward-Euler steps per degree (dt = 5.6 ms at 45 deg/s), so that the 1-degree moving average of
# the bounce (`torque_bounce`) spans 4 steps as it spans the explicit steps of a record
IMPLICIT_STEPS_PER_DEGREE = 4
BOUNCE_FROM = 10.0   # deg: the bounce is measured from here to the end (contact is established by then)


def torque_bounce(angles: np.ndarray, torque: np.ndarray, window: int, from_angle: float = BOUNCE_FROM
                  ) -> tuple[float, float]:
    """Oscillation of the per-step contact torque of an explicit flexion: RMS over the steps with angle >=
    `from_angle` [deg] of tau_n - <tau>_n, where <tau>_n is the centred moving average over `window` steps
    (one record interval, 1 degree), in N m and relative to the RMS of <tau> there. Steps within half a window
    of either end are left out (their average is one-sided)."""
    angles, torque = np.asarray(angles, dtype=float), np.asarray(torque, dtype=float)
    if window < 1 or len(torque) < window + 2:
        return math.nan, math.nan
    smooth = np.convolve(torque, np.ones(window) / window, mode="same")
    keep = np.zeros(len(torque), dtype=bool)
    keep[window // 2: len(torque) - window // 2] = True
    keep &= angles >= from_angle
    if not keep.any():
        return math.nan, math.nan
    rms = float(np.sqrt(np.mean((torque - smooth)[keep] ** 2)))
    scale = float(np.sqrt(np.mean(smooth[keep] ** 2)))
    return rms, rms / scale if scale > 0 else math.nan


def _run_method(method: str, base: SleeveConfig, comm: MPI.Comm, al_budget: float) -> dict:
    row = {"method": method, "route": METHODS[method], "ranks": comm.size}
    # CPU time of this process besides wall time: on the shared, oversubscribed machine the wall time includes
    # other people's load, the CPU time is the work of this method alone
    cpu_start = time.process_time()
    if method in ("lagrange", "penalty"):
        problem = build_run(base.with_(solver="explicit", method=method), comm)
        problem.contact.monitor_penetration = True
        problem.contact.start_trace()
        h = problem.run(stop_on_failure=False)
        trace = problem.contact.trace_array()
        angles = np.array([problem.axis_at(t) for t in trace[:, 0]])
        rms, rel = torque_bounce(angles, -trace[:, 1], problem.steps_per_record)
        row.update(max_penetration_m=problem.contact.max_penetration_all(), bounce_rms_Nm=rms, bounce_relative=rel,
                   work=f"{sum(s.time_steps for s in h.steps)} steps of {problem.dt:.3g} s",
                   note=f"penetration every step; {h.failure}" if h.failure else "penetration monitored every step")
    else:
        steps_per_degree = IMPLICIT_STEPS_PER_DEGREE
        cfg = base.with_(solver="implicit", method="augmented",
                         angle_steps=int(round(steps_per_degree * base.motion.final_angle)))
        problem = build_run(cfg, comm)
        h = run_implicit(problem, stop_on_failure=False, max_wall_time=al_budget)   # with a wall-time budget
        trace = problem.trace_array()
        rms, rel = torque_bounce(trace[:, 1], trace[:, 2], steps_per_degree)
        n_steps = int(np.count_nonzero(trace[:, 0] > 0.0))
        row.update(max_penetration_m=float(np.max(trace[:, 3], initial=0.0)), bounce_rms_Nm=rms, bounce_relative=rel,
                   work=(f"{n_steps} steps of {problem.dt:.3g} s (settle {problem.settle_steps}), "
                         f"{sum(s.newton_iterations for s in h.steps)} Newton iterations"),
                   note=("penetration after every step (Uzawa to " f"{cfg.contact.augmentation_tolerance:g} m)"
                         + (f"; STOPPED: {h.failure}" if h.failure else "")))
    problem.destroy()
    reached = float(h.steps[-1].coordinate)
    row.update(mesh=f"{base.tube.n_around}x{base.tube.n_along}", ndofs=h.ndofs, reached_deg=reached,
               gravity="on" if problem.config.route.gravity else "off",
               torque_57_Nm=h.torque_at(base.motion.final_angle, "elbow") if reached >= base.motion.final_angle - 1e-9 else math.nan,
               wall_s=h.wall, cpu_s=time.process_time() - cpu_start)
    return row


def run_methods(out: str | Path = "results/sleeve_methods.csv", mesh: str = "III", friction: float = 0.1,
                methods: tuple[str, ...] = ("lagrange", "penalty", "augmented"), final_angle: float = 57.0,
                comm: MPI.Comm = MPI.COMM_WORLD, al_budget: float = 1800.0,
                ranks_per_variant: int = 1) -> list[dict]:
    """The three contact methods on the sleeve (mesh `mesh`, mu = `friction`, to `final_angle` degrees):
    maximum penetration, torque at the final angle, bounce of the per-step torque (`torque_bounce`), wall time.
    The methods run as one batch (fabricfem.scenes.batch, as the study's variants: groups of `ranks_per_variant`
    ranks, the implicit route first); each finished row is saved to <out without .csv>/<method>.json and read
    back by a rerun of the same settings (a killed run resumes). All three run with
    gravity and the settle phase (SleeveConfig defaults). The augmented-Lagrangian row is the implicit route
    (fabricfem.wear.sleeve_implicit: backward Euler with the same lumped mass, mass damping and gravity as the
    explicit rows, IMPLICIT_STEPS_PER_DEGREE steps per degree); it stops where a step fails below the minimum
    step or after `al_budget` seconds, and the row says at which angle (a measured fact, not an error).
    Each row has the wall and the CPU time (time.process_time) of its process. Writes `out` (CSV, rank 0)
    and returns the rows."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"methods: unknown {unknown or 'none given'}, expected some of {sorted(METHODS)}")
    al_budget = positive_number("al_budget", al_budget)
    if mesh not in MESHES:
        raise ValueError(f"mesh: unknown mesh {mesh!r}, expected one of {sorted(MESHES)}")
    n_around, n_along = MESHES[mesh]
    base = SleeveConfig.of(n_around=n_around, n_along=n_along, friction=friction, final_angle=final_angle)
    out = Path(out)
    folder = out.with_suffix("")                     # <out without .csv>/<method>.json: the finished methods
    key = lambda method: repr((method, al_budget, sorted(base.key_items().items())))  # noqa: E731

    def saved(method: str) -> dict | None:
        try:
            data = json.loads((folder / f"{method}.json").read_text())
        except (OSError, ValueError):
            return None
        return data["row"] if data.get("config") == key(method) else None

    def run(method: str, sub: MPI.Comm) -> str:
        row = _run_method(method, base, sub, al_budget)
        if sub.rank == 0:
            row = {k: v.item() if isinstance(v, np.generic) else v for k, v in row.items()}
            fio.write_text_whole(folder / f"{method}.json", json.dumps({"config": key(method), "row": row}))
        return f"{row}"

    jobs = [Job(f"{method} on mesh {mesh}", METHOD_COST[method], lambda sub, m=method: run(m, sub),
                lambda m=method: saved(m) is not None) for method in methods]
    check(run_batch(jobs, comm, ranks_per_variant, "sleeve methods"), "sleeve methods", str(folder))
    rows = [saved(method) for method in methods]
    if comm.rank == 0:
        fio.write_csv(out, METHOD_COLUMNS, rows, MPI.COMM_SELF)
        print(methods_markdown(rows), flush=True)
    return rows


def read_methods(path: str | Path = "results/sleeve_methods.csv") -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def methods_markdown(rows: list[dict] | None = None, path: str | Path = "results/sleeve_methods.csv") -> str:
    """The methods table as Markdown (rows from `run_methods`, or read from `path`)."""
    rows = read_methods(path) if rows is None else rows

    def num(v, fmt):
        try:
            x = float(v)
        except (TypeError, ValueError):
            return str(v)
        return "n/a" if math.isnan(x) else format(x, fmt)

    lines = ["| method | reached [deg] | torque at 57 deg [N m] | max penetration [m] | bounce RMS [N m] (relative) "
             "| wall [s] | CPU [s] | work | note |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['route']} | {num(r['reached_deg'], '.1f')} | {num(r['torque_57_Nm'], '.4e')} | "
                     f"{num(r['max_penetration_m'], '.2e')} | {num(r['bounce_rms_Nm'], '.2e')} "
                     f"({num(r['bounce_relative'], '.2f')}) | {num(r['wall_s'], '.0f')} | "
                     f"{num(r.get('cpu_s', math.nan), '.0f')} | {r['work']} | {r['note']} |")
    mesh = rows[0]["mesh"] if rows else "?"
    gravity = sorted({str(r.get("gravity", "?")) for r in rows})
    gravity_text = ("gravity on (g = 9.81 m/s^2 along -y, 0.4 s of rest on the arm before the flexion at 45 deg/s)"
                    if gravity == ["on"] else f"gravity {'/'.join(gravity)}")
    lines.append(f"\nSleeve mesh {mesh}, mu = 0.1, {gravity_text}, mass damping 10 1/s, one MPI rank per method "
                 f"(OMP_NUM_THREADS=1). Wall time measured on a shared, oversubscribed 2-core machine (it includes "
                 f"other processes' load); CPU time is that of the method's own process (time.process_time). "
                 f"Bounce: RMS of the per-step elbow torque minus its centred 1-degree moving average, "
                 f"{BOUNCE_FROM:g}-57 deg (fabricfem.studies.sleeve.torque_bounce).")
    return "\n".join(lines)
