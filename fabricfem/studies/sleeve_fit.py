"""`fabricfem study sleeve-fit`: how the sleeve-trends "fit" and "thickness" checks depend on the arm.

Hypothesis tested: on the ANSUR II arm (fabricfem.body.arm, upper-arm radius 0.0557 m) the
R = 0.06 m sleeve has 4.3 mm clearance, hangs, sags and wrinkles (bending-dominated, weight-driven torque),
whereas the thesis's sleeve (sec. 5.3.3-5.3.4: looser sleeve "significantly less" torque, double thickness
"roughly double" torque, "membrane rather than bending behavior ... is dominant") was snug.

Arms: both girths of the default arm times a scale s (lengths unchanged), s chosen by the clearance it
gives at the thickest upper-arm section of the R = 0.06 m sleeve, not by the outcome (`FIT_SCALES`):

    s = 1       ANSUR II medians, clearance 0.06 - 0.350 / (2 pi) = 4.3 mm
    s = 1.04    clearance about 2 mm (2.1 mm)
    s = 1.0771  = 0.06 x 2 pi / 0.350 rounded to 4 digits: clearance 1.0e-6 m ("snug"; exactly zero is
                refused by check_fit, the arm must start inside the sleeve)

For each arm three flexions (mu = 0.5, explicit route with gravity, default settle and 45 deg/s, to
57 degrees): R = 0.06 m t = 1 mm, R = 0.07 m t = 1 mm, R = 0.06 m t = 2 mm (`FIT_CASES`).

Bending share (`energy_split`): the Naghdi strain energy of forms/shell.py split into its membrane, bending
and transverse-shear parts with the same PSRI weights as the model's energy (their sum is the model's
energy). Scaling identity: a membrane-only sleeve under its own weight has weight, inertia, damping and
membrane stiffness all proportional to t, so doubling t doubles the torque exactly; bending (D ~ t^3) is
what makes the ratio differ from 2, and its energy share at rest and at 57 degrees measures the hypothesis.

Elbow taper (task B2, `long_axis_factors`): the default arm's ellipsoids have long semi-axis r1 = L / 2, so
their tips meet at the elbow centre and the arm has no girth there (fabricfem.body.arm). The same three cases
are run for arms with r1 = f L, f in `ELBOW_FACTORS` = (0.6, 0.7) (girth radius at the elbow
r sqrt(1 - 1 / (2 f)^2) = 30.8 mm and 39.0 mm on the ANSUR arm, `ArmDimensions.elbow_radius`), at girth
scale 1: `fabricfem study sleeve-fit --scales 1 --long-axis-factors 0.5,0.6,0.7` (docs prefix
fit_sensitivity_elbow). Checkpoint keys of f = 0.5 configurations are those of the runs made before the
factor existed (`_key` leaves the default factor out), so those runs are read back, not rerun.

Outputs under `out` (rank 0): curves.csv (torque vs angle per arm and case), runs.csv (per run: torque
at rest and at 57 deg, strain-energy parts at rest and 57 deg, bending share, cost), summary.csv (per arm:
clearance, max tau(R=0.07)/tau(R=0.06) over 20-57 deg, tau(t=2)/tau(t=1) at 57 deg, torques at rest),
fit_sensitivity.png; runs/<hash>.json checkpoints (a rerun resumes). The flexions run as the sweep's batch
(fabricfem.scenes.batch: under `mpirun -n N`, N at a time).
"""
from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.arm import DEFAULT_ARM, ArmDimensions
from fabricfem.forms import shell as sf
from fabricfem.materials import positive_number
from fabricfem.scenes.batch import Job, check, run_batch
from fabricfem.studies.sleeve import CURVE_HEADER, curve_history, curve_rows, relative_cost
from fabricfem.wear.config import SleeveConfig, check_fit
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.run import build_run

FIT_SCALES = (1.0, 1.04, 1.0771)
DEFAULT_LONG_AXIS_FACTOR = 0.5      # r1 = L / 2: the arm of fabricfem.body.arm (no girth at the elbow)
ELBOW_FACTORS = (0.6, 0.7)          # r1 = f L of the elbow-taper runs (task B2)
FIT_CASES = {"R=0.06 t=1mm": dict(radius=0.06, thickness=1e-3),
             "R=0.07 t=1mm": dict(radius=0.07, thickness=1e-3),
             "R=0.06 t=2mm": dict(radius=0.06, thickness=2e-3)}
BASE_CASE, LOOSE_CASE, THICK_CASE = FIT_CASES
MESHES = {"I": (10, 13), "II": (15, 20), "III": (20, 26), "IV": (30, 39)}
FRICTION = 0.5
FIT_FROM = 20.0            # deg: the thesis's "above 20 degrees" (sec. 5.3.3), as in sleeve-trends
ENERGY_PARTS = ("membrane", "bending", "shear")


def scaled_arm(scale: float, arm: ArmDimensions = DEFAULT_ARM) -> ArmDimensions:
    """`arm` with both girths times `scale` (> 0), lengths unchanged."""
    scale = positive_number("scale", scale)
    return replace(arm, upper_arm_girth=arm.upper_arm_girth * scale, forearm_girth=arm.forearm_girth * scale)


def fit_configs(scales=FIT_SCALES, mesh: str = "II", final_angle: float = 57.0,
                long_axis_factor: float = DEFAULT_LONG_AXIS_FACTOR, **overrides) -> dict[float, dict[str, SleeveConfig]]:
    """scale -> {case label: SleeveConfig} (explicit route, gravity, mu = 0.5, mesh `mesh`) for the default arm
    with long semi-axes r1 = long_axis_factor x L (ArmDimensions, ValueError naming it outside [0.5, 1]) and
    girths times scale; `overrides` go to every configuration (e.g. output_angle_step for a short test run)."""
    arm = replace(DEFAULT_ARM, long_axis_factor=long_axis_factor)
    if mesh not in MESHES:
        raise ValueError(f"mesh: unknown mesh {mesh!r}, expected one of {sorted(MESHES)}")
    n_around, n_along = MESHES[mesh]
    base = SleeveConfig.of(n_around=n_around, n_along=n_along, friction=FRICTION, solver="explicit",
                        final_angle=final_angle, **overrides)
    return {float(s): {label: base.with_(arm=scaled_arm(s, arm), **case) for label, case in FIT_CASES.items()}
            for s in scales}


# ------------------------------------------------------------------------------------- strain energy split
def energy_split_forms(model, degrees: tuple[int, int] = (4, 2)) -> dict:
    """Compiled rank-0 forms of the membrane, bending and transverse-shear energies [J] of a Naghdi
    ShellModel with a linear bending law, PSRI-weighted exactly as forms.shell.naghdi_energy ([Eischen2000]
    eqs. 3-5): bending on the full quadrature, membrane and shear split alpha / (1 - alpha),
    alpha = min(1, t_eq^2 / h^2) (forms.shell.psri_weight)."""
    if model.model != "naghdi" or model.fabric.bending_law is not None or model.fabric.membrane_law is not None:
        raise ValueError("model: the energy split needs a Naghdi shell with linear membrane and bending laws")
    F0 = ufl.grad(model.phi0)
    F = F0 + ufl.grad(model.u)
    d = sf.director(model.theta, model.a3, model.a1, model.a2)
    e1, e2 = sf.material_frame(F0, model.t1, model.t2)
    eps_m = sf.voigt(sf.membrane_strain(F, F0), e1, e2)                       # [Eischen2000, eq. 3]
    kappa = sf.voigt(sf.bending_strain(F, F0, d, model.n0), e1, e2)            # [Eischen2000, eq. 5]
    g = sf.shear_strain(F, F0, d, model.n0)                                    # [Eischen2000, eq. 4]
    gamma = ufl.as_vector([ufl.dot(g, e1), ufl.dot(g, e2)])
    psi_m = sf.quadratic_energy(eps_m, model.A)
    psi_b = sf.bending_energy(kappa, model.D)
    psi_s = 0.5 * model.shear_stiffness * ufl.dot(gamma, gamma)
    dx_full, dx_reduced = sf.psri_measures(model.mesh, *degrees)
    alpha = sf.psri_weight(model.psri_thickness, model.cell_size)
    return {"membrane": fem.form(alpha * psi_m * dx_full + (1.0 - alpha) * psi_m * dx_reduced),
            "bending": fem.form(psi_b * dx_full),
            "shear": fem.form(alpha * psi_s * dx_full + (1.0 - alpha) * psi_s * dx_reduced)}


def energy_split(model, forms: dict, state=None) -> dict[str, float]:
    """Membrane, bending, shear energies [J] (all ranks) of `state` (a PETSc vector of the model's layout;
    None: the model's current state), and bending_share = bending / (membrane + bending + shear)."""
    if state is not None:
        model.set_state(state)
    out = {name: float(model.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)) for name, form in forms.items()}
    total = sum(out[name] for name in ENERGY_PARTS)
    out["bending_share"] = out["bending"] / total if total > 0.0 else math.nan
    return out


# ------------------------------------------------------------------------------------------------ one run
def run_case(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_SELF, split_angles: tuple[float, ...] | None = None,
             on_step=None) -> tuple[WearHistory, dict[float, dict[str, float]]]:
    """One explicit flexion; returns its history and the strain-energy split at the records of
    `split_angles` [deg] (default: rest and the final angle) plus the process's CPU time in history.timings."""
    if config.route.solver != "explicit":
        raise ValueError(f"config.route.solver: the fit study runs the explicit route, got {config.route.solver!r}")
    angles = (0.0, config.motion.final_angle) if split_angles is None else tuple(float(a) for a in split_angles)
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    problem = build_run(config, comm)
    forms = energy_split_forms(problem.model, config.tube.quadrature)
    splits: dict[float, dict[str, float]] = {}

    def record(step: WearStep):
        for a in angles:
            if step.axis_value is not None and abs(step.axis_value - a) < 1e-9 and step.phase != "sew":
                saved = problem.model.w.x.array.copy()      # leave the integrator's view of the model as it was
                splits[a] = energy_split(problem.model, forms, problem.integrator.d)
                problem.model.w.x.array[:] = saved
        if on_step:
            on_step(step)

    history = problem.run(on_step=record, stop_on_failure=False)
    problem.destroy()
    history.wall = time.perf_counter() - t0
    history.timings["run_cpu_s"] = time.process_time() - cpu0
    return history, splits


# ------------------------------------------------------------------------------------------------ summary
def fit_ratios(base: tuple[np.ndarray, np.ndarray], loose: tuple[np.ndarray, np.ndarray],
               start: float = FIT_FROM) -> tuple[np.ndarray, np.ndarray]:
    """(angles a, tau_loose(a) / tau_base(a)) at the base curve's angles start < a <= (largest angle both
    reached), loose interpolated linearly, as in the sleeve-trends check."""
    end = min(base[0][-1], loose[0][-1])
    angles = base[0][(base[0] > start) & (base[0] <= end + 1e-9)]
    return angles, np.interp(angles, *loose) / np.interp(angles, *base)


def fit_ratio(base: tuple[np.ndarray, np.ndarray], loose: tuple[np.ndarray, np.ndarray],
              start: float = FIT_FROM) -> float:
    """max of `fit_ratios` (the sleeve-trends quantity); NaN if no angle lies above `start`."""
    angles, ratios = fit_ratios(base, loose, start)
    return float(np.max(ratios)) if len(angles) else math.nan


def thickness_ratio(thin: tuple[np.ndarray, np.ndarray], thick: tuple[np.ndarray, np.ndarray],
                    angle: float) -> float:
    """tau_thick(angle) / tau_thin(angle) (linear interpolation); NaN if either curve stopped before `angle`."""
    if min(thin[0][-1], thick[0][-1]) < angle - 1e-9:
        return math.nan
    return float(np.interp(angle, *thick) / np.interp(angle, *thin))


def summary_row(scale: float, arm: ArmDimensions, curves: dict[str, tuple[np.ndarray, np.ndarray]],
                final_angle: float = 57.0) -> dict:
    """One row of the summary table for the arm of girth scale `scale` (curves keyed by FIT_CASES labels)."""
    row = {"scale": scale, "long_axis_factor": arm.long_axis_factor, "upper_arm_girth_m": arm.upper_arm_girth,
           "forearm_girth_m": arm.forearm_girth, "elbow_radius_m": arm.elbow_radius,
           "clearance_m": check_fit(FIT_CASES[BASE_CASE]["radius"], arm),
           "forearm_clearance_m": FIT_CASES[BASE_CASE]["radius"] - arm.forearm_radius,
           "max_ratio_R007_R006_20_57": fit_ratio(curves[BASE_CASE], curves[LOOSE_CASE]),
           "angle_of_max_ratio_deg": math.nan, "mean_ratio_R007_R006_20_57": math.nan,
           "ratio_t2_t1_at_57": thickness_ratio(curves[BASE_CASE], curves[THICK_CASE], final_angle)}
    angles, ratios = fit_ratios(curves[BASE_CASE], curves[LOOSE_CASE])
    if len(angles):      # the maximum's angle and the mean ratio over the records: is the maximum one event?
        row["angle_of_max_ratio_deg"] = float(angles[np.argmax(ratios)])
        row["mean_ratio_R007_R006_20_57"] = float(np.mean(ratios))
    for label, (angles, torques) in curves.items():
        row[f"torque_rest_Nm[{label}]"] = float(torques[0]) if angles[0] == 0.0 else math.nan
    return row


# ------------------------------------------------------------------------------------------------ study
SKIN = "engine, blended skin w = 0.05"   # the checkpoint tag (fabricfem.body.blended.BLEND_WIDTH)


def _key(config: SleeveConfig) -> str:
    """The configuration as a string, tagged with the engine and the body's skin (SKIN: runs of the union of
    ellipsoids are rerun on the blended skin, not read back); the arm's long_axis_factor is left out at its default
    0.5 so that runs checkpointed before the factor existed keep their items."""
    items = config.key_items()
    if items["arm"].get("long_axis_factor") == DEFAULT_LONG_AXIS_FACTOR:
        del items["arm"]["long_axis_factor"]
    return repr((SKIN, sorted(items.items())))


def _checkpoint(out: Path, config: SleeveConfig) -> Path:
    return out / "runs" / f"{hashlib.sha1(_key(config).encode()).hexdigest()[:16]}.json"


def _save(out: Path, config: SleeveConfig, history: WearHistory, splits: dict) -> None:
    fio.write_text_whole(_checkpoint(out, config), json.dumps({
        "config": _key(config), "rows": curve_rows(history), "splits": {str(a): s for a, s in splits.items()},
        "wall_s": history.wall, "cpu_s": history.timings.get("run_cpu_s", math.nan), "failure": history.failure,
        "ndofs": history.ndofs}))


def _load(out: Path, config: SleeveConfig) -> tuple[WearHistory, dict, float] | None:
    path = _checkpoint(out, config)
    if not path.exists():
        return None
    data = json.loads(path.read_text())
    if data["config"] != _key(config):
        return None
    history = curve_history(config.name, [dict(zip(CURVE_HEADER, row)) for row in data["rows"]])
    history.ndofs, history.wall, history.failure = data["ndofs"], data["wall_s"], data["failure"]
    return history, {float(a): s for a, s in data["splits"].items()}, data["cpu_s"]


RUN_COLUMNS = ("scale", "long_axis_factor", "case", "radius_m", "thickness_m", "ndofs", "reached_deg", "torque_rest_Nm", "torque_57_Nm",
               "bending_share_rest", "bending_share_57", "membrane_J_rest", "bending_J_rest", "shear_J_rest",
               "membrane_J_57", "bending_J_57", "shear_J_57", "wall_s", "cpu_s", "failure")


def run_fit_study(out: str | Path = "results/sleeve_fit", mesh: str = "II", scales=FIT_SCALES,
                  final_angle: float = 57.0, docs: str | Path | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
                  long_axis_factors=(DEFAULT_LONG_AXIS_FACTOR,), prefix: str = "fit_sensitivity",
                  ranks_per_variant: int = 1, **overrides) -> list[dict]:
    """Run the 3 x len(scales) x len(long_axis_factors) flexions as one batch (fabricfem.scenes.batch.run_batch:
    groups of `ranks_per_variant` ranks, each flexion checkpointed to runs/<hash>.json and read back by a rerun),
    write curves.csv, runs.csv, summary.csv, fit_sensitivity.png under `out` (and, if `docs` is
    given, docs/<prefix>.csv = summary, .runs.csv, .curves.csv, .png); returns the summary rows (one per arm:
    factor-major, then scale)."""
    out = Path(out)
    arms = [(f, configs) for f in long_axis_factors
            for configs in [fit_configs(scales, mesh, final_angle, long_axis_factor=f, **overrides)]]
    runs = [(f, s, label, cfg) for f, configs in arms for s, cases in configs.items() for label, cfg in cases.items()]

    def flex(cfg: SleeveConfig, sub: MPI.Comm) -> str:
        history, splits = run_case(cfg, sub)
        if sub.rank == 0:
            _save(out, cfg, history, splits)
        return f"torque at rest {float(history.motion_curve()[1][0]):.4e} N m" + (
            f"; STOPPED: {history.failure}" if history.failure else "")

    jobs = [Job(f"run {k + 1}/{len(runs)}: arm scale {scale:g}, r1 = {factor:g} L (clearance "
                f"{check_fit(cfg.tube.radius, cfg.arm) * 1e3:.3f} mm, elbow radius "
                f"{cfg.arm.elbow_radius * 1e3:.1f} mm), {label}", relative_cost(cfg), lambda sub, cfg=cfg: flex(cfg, sub),
                lambda cfg=cfg: _load(out, cfg) is not None) for k, (factor, scale, label, cfg) in enumerate(runs)]
    check(run_batch(jobs, comm, ranks_per_variant, "sleeve-fit study"), "sleeve-fit study", f"{out}/runs")
    rows, run_rows, curve_rows = [], [], []
    if comm.rank == 0:
        for factor, scale, cases in ((f, s, c) for f, configs in arms for s, c in configs.items()):
            curves = {}
            for label, cfg in cases.items():
                history, splits, cpu = _load(out, cfg)
                curves[label] = history.motion_curve()
                rest, end = splits.get(0.0, {}), splits.get(float(final_angle), {})
                run_rows.append({"scale": scale, "long_axis_factor": factor, "case": label, "radius_m": cfg.tube.radius, "thickness_m": cfg.material.thickness,
                                 "ndofs": history.ndofs, "reached_deg": float(history.steps[-1].coordinate),
                                 "torque_rest_Nm": float(history.motion_curve()[1][0]),
                                 "torque_57_Nm": history.torque_at(final_angle) if not history.failure else math.nan,
                                 "bending_share_rest": rest.get("bending_share", math.nan),
                                 "bending_share_57": end.get("bending_share", math.nan),
                                 **{f"{p}_J_rest": rest.get(p, math.nan) for p in ENERGY_PARTS},
                                 **{f"{p}_J_57": end.get(p, math.nan) for p in ENERGY_PARTS},
                                 "wall_s": history.wall, "cpu_s": cpu, "failure": history.failure})
                print(f"  arm scale {scale:g}, r1 = {factor:g} L, {label}: torque at rest "
                      f"{run_rows[-1]['torque_rest_Nm']:.4e} N m, at {final_angle:g} deg "
                      f"{run_rows[-1]['torque_57_Nm']:.4e} N m; bending share {run_rows[-1]['bending_share_rest']:.3f} "
                      f"(rest), {run_rows[-1]['bending_share_57']:.3f} ({final_angle:g} deg); cpu {cpu:.0f} s"
                      + (f"; STOPPED: {history.failure}" if history.failure else ""), flush=True)
                curve_rows += [[scale, factor, label, a, t] for a, t in zip(*curves[label])]
            rows.append(summary_row(scale, next(iter(cases.values())).arm, curves, final_angle))
        _write(out, rows, run_rows, curve_rows, mesh)
        if docs is not None:
            _write(Path(docs), rows, run_rows, curve_rows, mesh, prefix=prefix)
        print(summary_markdown(rows, run_rows), flush=True)
    return comm.bcast(rows, root=0)


def _write(out: Path, rows, run_rows, curve_rows, mesh: str, prefix: str | None = None) -> None:
    """The summary, runs and curves CSVs and the figure under `out` (named after `prefix` when given)."""
    name = (lambda s: f"{prefix}.{s}" if s != "summary" else prefix) if prefix else (lambda s: s)
    fio.write_csv(out / f"{name('summary')}.csv", list(rows[0]), [list(r.values()) for r in rows], MPI.COMM_SELF)
    fio.write_csv(out / f"{name('runs')}.csv", RUN_COLUMNS, [[r[c] for c in RUN_COLUMNS] for r in run_rows],
                  MPI.COMM_SELF)
    fio.write_csv(out / f"{name('curves')}.csv", ("scale", "long_axis_factor", "case", "angle_deg", "torque_Nm"),
                  curve_rows, MPI.COMM_SELF)
    plot_fit(out / (f"{prefix}.png" if prefix else "fit_sensitivity.png"), curve_rows, rows, mesh)


def plot_fit(path: Path, curve_rows, rows, mesh: str) -> None:
    """One panel per arm (summary row): resisting torque [N m] vs elbow angle [deg] of the three cases."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, axes = plt.subplots(1, len(rows), figsize=(4.2 * len(rows), 3.8), sharey=True, squeeze=False)
    for ax, row in zip(axes[0], rows):
        for label in FIT_CASES:
            pts = np.array([[a, t] for s, f, c, a, t in curve_rows
                            if s == row["scale"] and f == row["long_axis_factor"] and c == label])
            if len(pts):
                ax.plot(pts[:, 0], pts[:, 1], marker="o", ms=2, label=label)
        taper = (f", r1 = {row['long_axis_factor']:g} L, elbow r {row['elbow_radius_m'] * 1e3:.0f} mm"
                 if row["long_axis_factor"] != DEFAULT_LONG_AXIS_FACTOR else "")
        ax.set_title(f"girths x {row['scale']:g}{taper}: clearance {row['clearance_m'] * 1e3:.2g} mm\n"
                     f"max T(R.07)/T(R.06) {row['max_ratio_R007_R006_20_57']:.2f}, "
                     f"T(2mm)/T(1mm) {row['ratio_t2_t1_at_57']:.2f}", fontsize=9)
        ax.set_xlabel("elbow flexion angle [deg]")
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("resisting torque [N m]")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"sleeve fit sensitivity (mesh {mesh}, mu = {FRICTION}, explicit, gravity)", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def summary_markdown(rows: list[dict], run_rows: list[dict]) -> str:
    """The summary table and the per-run bending shares as Markdown."""
    lines = ["| girth scale | r1 / L | elbow radius [mm] | clearance [mm] | max T(R=0.07)/T(R=0.06), 20-57 deg "
             "(at [deg]; mean) | T(t=2)/T(t=1) at 57 deg | " + " | ".join(f"T rest {c} [N m]" for c in FIT_CASES)
             + " |", "|---|---|---|---|---|---|" + "---|" * len(FIT_CASES)]
    for r in rows:
        lines.append(f"| {r['scale']:g} | {r['long_axis_factor']:g} | {r['elbow_radius_m'] * 1e3:.1f} | "
                     f"{r['clearance_m'] * 1e3:.3g} | {r['max_ratio_R007_R006_20_57']:.3f} "
                     f"({r['angle_of_max_ratio_deg']:g}; {r['mean_ratio_R007_R006_20_57']:.3f}) | "
                     f"{r['ratio_t2_t1_at_57']:.3f} | "
                     + " | ".join(f"{r[f'torque_rest_Nm[{c}]']:.4e}" for c in FIT_CASES) + " |")
    lines += ["", "| girth scale | r1 / L | case | torque rest [N m] | torque 57 [N m] | bending share rest | "
              "bending share 57 | cpu [s] |", "|---|---|---|---|---|---|---|---|"]
    for r in run_rows:
        lines.append(f"| {r['scale']:g} | {r['long_axis_factor']:g} | {r['case']} | {r['torque_rest_Nm']:.4e} | "
                     f"{r['torque_57_Nm']:.4e} | {r['bending_share_rest']:.3f} | {r['bending_share_57']:.3f} | "
                     f"{r['cpu_s']:.0f} |")
    return "\n".join(lines)
