"""The pants study [Man2006, sec. 5.4, Figs. 47-49]: the resisting torque of pants about the right knee while the
wearer walks (and steps over an obstacle), for crimped cotton pants 1 mm and 2 mm thick (and mu = 0.5; and 1 mm on a coarser mesh, h = 10 cm instead of 7 cm).

`fabricfem study pants [--quick] [--out DIR]` runs the variants of scenes/pants_walk.toml as one batch on the
ranks of COMM_WORLD (fabricfem.scenes.batch, the machinery of `fabricfem sweep`: groups of `ranks_per_variant`
ranks, longest first to the least loaded group; each variant writes its own folder: the garment and body over
time, renders of the pressure on the skin at the donning and walking frames, torque.csv/.sto, summary.json), then
writes on rank 0:

    knee_torque.csv   time [s], right-knee flexion [deg], the resisting knee torque of every variant [N m]
    knee_torque.sto   OpenSim storage of the same torques (columns knee_r_moment_<variant>)
    knee_torque.png   the torques against time, the knee flexion on a second axis (Fig. 49's analogue)
    summary.json      per variant: peak and mean torque over the walk (and over the crossing stride); the thesis's
                      claim (2 mm gives the larger torque) as the measured peak and mean ratios 2 mm / 1 mm

The knee flexion is measured on the posed body: the angle between the right thigh's and shank's long axes
(e1 of fabricfem.body.pose), independent of the motion source. A finished variant (its summary.json completed
with the same scene hash) is read back, not rerun.
"""
from __future__ import annotations

import copy
import json
import math
import time
import tomllib
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.blend import BlendedStart
from fabricfem.scenes import build as scene_build
from fabricfem.scenes import wear
from fabricfem.scenes.batch import Job, check, completed, run_batch
from fabricfem.scenes.build import build_wear_run, scene_sha256
from fabricfem.scenes.contract import parse
from fabricfem.scenes.schema import Scene
from fabricfem.wear.outputs import write_sto
from fabricfem.wear.run import run_wear

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "pants_walk.toml"
# label -> (thickness [m], friction, mesh size h [m] or None: the scene's): the thesis's two thicknesses at
# mu = 0.1, the friction variant, and 1 mm at mu = 0.1 on a coarser mesh (how far the default h is from mesh
# convergence)
VARIANTS = {"1mm_mu0.1": (1e-3, 0.1, None), "2mm_mu0.1": (2e-3, 0.1, None), "1mm_mu0.5": (1e-3, 0.5, None),
            "1mm_mu0.1_h10cm": (1e-3, 0.1, 0.10)}


def variant_data(base: dict, thickness: float, friction: float, out: Path, quick: bool,
                 h: float | None = None) -> dict:
    """The scene data of one variant (its own output folder; `h`: its mesh size [m]; quick: one stride on a
    coarse mesh)."""
    data = copy.deepcopy(base)
    data["fabric"]["thickness"] = thickness
    data.setdefault("contact", {})["friction"] = friction
    if h is not None:
        data["garment"]["h"] = h
    data["output"] = {**data.get("output", {}), "dir": str(out)}
    if quick:
        data["garment"]["h"] = 0.1
        data["motion"]["strides"] = 1
        if "crossing_stride" in data["motion"]:       # an obstacle walk: the one stride crosses
            data["motion"]["crossing_stride"] = 1
        data["motion"]["duration"] = 0.2
    return data


def knee_flexion(body, times: np.ndarray) -> np.ndarray:
    """Right-knee flexion [deg] of the posed body at `times` [s]: the angle between thigh_r's and shank_r's axes."""
    out = np.empty(len(times))
    for k, t in enumerate(times):     # one pose per record (a few hundred)
        p = body.kinematics.positions(float(t))
        thigh, shank = p["knee_r"] - p["hip_r"], p["ankle_r"] - p["knee_r"]
        c = np.dot(thigh, shank) / (np.linalg.norm(thigh) * np.linalg.norm(shank))
        out[k] = math.degrees(math.acos(min(max(c, -1.0), 1.0)))
    return out


def crossing_window(data: dict) -> tuple[float, float] | None:
    """Body-time window [s] of the crossing stride of an obstacle walk (its motion delayed by the donning phases
    and the blend), None for another motion."""
    if data["motion"].get("type") != "obstacle_walk":
        return None
    parsed = parse(data, "wear")
    plan = wear.plan(parsed, wear.wear_fabric(parsed, scene_build.build_fabric))
    walk = plan.body.kinematics
    blend = 0.0
    if isinstance(walk, BlendedStart):
        walk, blend = walk.motion, walk.blend_time
    start = plan.timeline.start_of("motion") + blend - walk.time_range[0]
    return (start + walk.crossing_window[0], start + walk.crossing_window[1])


def variant_cost(data: dict) -> float:
    """Estimated relative cost of a variant for the batch's schedule: nodes x explicit steps ~ h^-2 x h^-1."""
    return float(data["garment"]["h"]) ** -3


def _run_variant(data: dict, out: Path, comm: MPI.Comm) -> str:
    """Run one variant on `comm` into `out` (io.OutputFolder: status and hash in summary.json), with the knee
    flexion of its records in knee.csv; returns its status."""
    scene = Scene(data, None, "wear")
    folder = fio.OutputFolder(out, scene_sha256(scene), comm)
    run, headline, render_at, output = build_wear_run(scene, comm)
    # donning frames (end of the sewing, the pull and the belt) and walking frames (the thirds of the motion)
    starts = {p: run.timeline.start_of(p) for p in run.timeline.PHASES}
    frames = [starts["pull"], starts["don"], starts["settle"]] + [starts["motion"] + f * (run.duration -
                                                                                        starts["motion"])
                                                                  for f in (1 / 3, 2 / 3, 1.0)]
    body = run.body
    history = run_wear(run, out, headline, sorted({round(t, 6) for t in frames if t > 0}), output.render)
    times = np.array([s.time for s in history.steps])
    fio.write_csv(out / "knee.csv", ["time_s", "knee_flexion_deg"], np.column_stack([times, knee_flexion(body, times)]),
                  comm)
    status = f"stopped early: {history.failure}" if history.failure else "completed"
    folder.finish(status, history.summary())
    return status


def _read_variant(out: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(times [s], knee torque about the flexion axis [N m], knee flexion [deg], phases, magnitude of the knee
    moment [N m]: the thesis's "instantaneous moment magnitude about the knee") of a finished variant's outputs."""
    rows = np.genfromtxt(out / "torque.csv", delimiter=",", names=True, dtype=None, encoding=None)
    knee = np.loadtxt(out / "knee.csv", delimiter=",", skiprows=1, ndmin=2)
    flexion = np.asarray(rows["knee_r_torque_Nm"], dtype=float)
    names = rows.dtype.names
    magnitude = np.sqrt(sum(np.asarray(rows[f"{c}_torque_Nm"], dtype=float) ** 2
                            for c in ("knee_r", "knee_r_x", "knee_r_z") if f"{c}_torque_Nm" in names))
    return (np.asarray(rows["time_s"], dtype=float), flexion, knee[:, 1], [str(p) for p in rows["phase"]], magnitude)


def run_pants_study(out: str | Path = "results/pants_study", quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD,
                    variants: dict[str, tuple[float, float, float | None]] | None = None,
                    scene: Path = SCENE, ranks_per_variant: int = 1) -> dict:
    """Run the variants (module docstring) as one batch (fabricfem.scenes.batch.run_batch: groups of
    `ranks_per_variant` ranks, longest first by `variant_cost`) and write the study's outputs; returns the summary
    (rank 0). A variant that raises is reported after the others have run (batch.BatchError naming it)."""
    out = Path(out)
    variants = variants or VARIANTS
    base = tomllib.loads(Path(scene).read_text())
    say = (lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None)
    t0 = time.perf_counter()
    datas = {label: variant_data(base, th, mu, out / label, quick, h) for label, (th, mu, h) in variants.items()}
    for label, data in datas.items():          # every variant validated before anything runs
        scene_build.validate(copy.deepcopy(data), f"variant {label}")
    labels = list(datas)
    say(f"pants study{' (quick)' if quick else ''}: {len(labels)} variants on {comm.size} rank(s): {labels}")
    jobs = [Job(label, variant_cost(data), lambda sub, data=data, label=label: _run_variant(data, out / label, sub),
                lambda data=data, label=label: completed(out / label, scene_sha256(Scene(data, None, "wear"))))
            for label, data in datas.items()]
    check(run_batch(jobs, comm, ranks_per_variant, "pants study"), "pants study", str(out))
    if comm.rank != 0:
        return {}
    curves = {label: _read_variant(out / label) for label in labels}
    summary = write_study(out, curves, quick, crossing_window(datas[labels[0]]))
    say(f"pants study: wrote {out}/knee_torque.csv, .sto, .png, summary.json ({time.perf_counter() - t0:.0f} s)")
    for line in summary["lines"]:
        say(line)
    return summary


def write_study(out: Path, curves: dict, quick: bool, crossing: tuple[float, float] | None = None) -> dict:
    """knee_torque.csv/.sto/.png and summary.json of the finished variants (rank 0); `crossing`: the body-time
    window [s] of the crossing stride."""
    labels = list(curves)
    n = min(len(c[0]) for c in curves.values())
    times = curves[labels[0]][0][:n]
    motion = np.array([p == "motion" for p in curves[labels[0]][3][:n]])
    flexion = {label: curves[label][1][:n] for label in labels}
    magnitude = {label: curves[label][4][:n] for label in labels}
    knee = curves[labels[0]][2][:n]
    fio.write_csv(out / "knee_torque.csv",
                  ["time_s", "knee_flexion_deg", *(f"{lab}_knee_moment_magnitude_Nm" for lab in labels),
                   *(f"{lab}_knee_flexion_torque_Nm" for lab in labels)],
                  np.column_stack([times, knee, *magnitude.values(), *flexion.values()]), MPI.COMM_SELF)
    write_sto(out / "knee_torque.sto", times, {f"knee_r_moment_{lab}": v for lab, v in flexion.items()},
              MPI.COMM_SELF, "resisting torque of the pants about the right knee's flexion axis (+y) [N m]: positive "
              "when the pants oppose knee flexion; time: body time [s] (donning, then the walk)")
    _plot(out / "knee_torque.png", times, magnitude, knee, motion, quick, crossing)
    windows = {"walk": motion}
    if crossing is not None:
        windows["crossing"] = motion & (times >= crossing[0]) & (times <= crossing[1])
    stats = {label: {w: {"peak_Nm": float(np.max(magnitude[label][mask], initial=0.0)),
                         "mean_Nm": float(np.mean(magnitude[label][mask])) if mask.any() else 0.0}
                     for w, mask in windows.items()} for label in labels}
    lines = [f"{lab}: knee moment magnitude over the walk: peak {s['walk']['peak_Nm']:.4e} N m, mean "
             f"{s['walk']['mean_Nm']:.4e} N m" for lab, s in stats.items()]
    summary = {"variants": stats, "quick": quick, "crossing_window_s": crossing}
    if "1mm_mu0.1" in stats and "2mm_mu0.1" in stats:
        one, two = magnitude["1mm_mu0.1"], magnitude["2mm_mu0.1"]
        ratios = {}
        for w, mask in windows.items():
            a, b = stats["1mm_mu0.1"][w], stats["2mm_mu0.1"][w]
            ratios[w] = {"peak": b["peak_Nm"] / a["peak_Nm"] if a["peak_Nm"] else math.nan,
                         "mean": b["mean_Nm"] / a["mean_Nm"] if a["mean_Nm"] else math.nan,
                         "share_of_records_2mm_larger": float(np.mean(two[mask] > one[mask])) if mask.any() else 0.0}
            lines.append(f"2 mm / 1 mm over the {w}: peak ratio {ratios[w]['peak']:.3f}, mean ratio "
                         f"{ratios[w]['mean']:.3f}, 2 mm larger in {100 * ratios[w]['share_of_records_2mm_larger']:.0f}"
                         f" % of the records (the thesis, Fig. 49: the thicker pants give the greater torque)")
        summary["ratio_2mm_to_1mm"] = ratios
    summary["lines"] = lines
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _plot(path: Path, times: np.ndarray, columns: dict, knee: np.ndarray, motion: np.ndarray, quick: bool,
          crossing: tuple[float, float] | None) -> None:
    """The knee moment magnitude of every variant against time over the walk, the knee flexion on a second axis,
    the crossing stride shaded (Fig. 49's analogue)."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, tau in columns.items():
        ax.plot(times[motion], tau[motion], "--" if "mu0.5" in label else "-", label=label.replace("_", ", "))
    if crossing is not None:
        ax.axvspan(*crossing, color="orange", alpha=0.12, label="crossing stride")
    ax.set(xlabel="body time [s]", ylabel="knee moment magnitude [N m]",
           title="pants: moment about the right knee while walking" + (" [quick]" if quick else ""))
    ax.grid(True, alpha=0.3)
    twin = ax.twinx()
    twin.plot(times[motion], knee[motion], color="gray", lw=1, alpha=0.6, label="knee flexion")
    twin.set_ylabel("right-knee flexion [deg]")
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
