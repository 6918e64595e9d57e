"""`fabricfem study convergence SCENE`: a wear scene on a ladder of garment meshes, with error bars.

The scene's garment is refined by `ratio` per level (a tube's cells around and along x ratio^k, rounded; a
pattern's element size h / ratio^k), k = 0 (the scene's own mesh) to levels - 1, and each level runs the whole
scene as one job of a resumable batch (fabricfem.scenes.batch: a level whose folder holds a completed run of the
same scene is read back, not rerun). For every torque monitor the study reports, per level:

    curve difference   RMS over the finest level's motion records of T_k - T_finest (T_k interpolated linearly on
                       the run's axis), divided by the mean |T_finest| there      (fabricfem.wear.outputs.torque_rms_error)
    windowed mean      the monitor's mean over the first [output] window (fabricfem.wear.statistics) and its
                       relative difference to the finest level's

    p95 |T|            the 95th percentile of |T| over the motion records (the statistics' percentile peak), the
                       robust size of a moment whose windowed mean is near zero (the pants' knee), and its
                       relative difference to the finest level's

and, from the three finest levels, the observed order and the Richardson-extrapolated windowed mean with the
grid convergence index of each level [Celik2008, eqs. 3-5; Roache1994] (fabricfem.scenes.richardson, plausible
orders of a dynamic scene: the explicit step follows the mesh), or the reason the ladder is not asymptotic; the
same extrapolation of p95 |T| and its note. Writes
<out>/convergence.csv (a row per level and monitor) and <out>/convergence.png (every level's curves of the first
monitor). `quick` (the tests): two levels, ratio 1.5, a tube's level 0 coarsened to about QUICK_CELLS cells (the
shipped sleeve's 44 x 57 to the thesis's mesh I, 10 x 13), and a short motion (an elbow flexion to 6 degrees in
records of 3, 0.1 s of rest; another motion cut 0.1 s after its start by [route] end_time).
"""
from __future__ import annotations

import copy
import csv
import math
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.scenes import wear
from fabricfem.scenes.batch import Job, check, completed, read_summary, run_batch
from fabricfem.scenes.build import build_fabric, scene_name, scene_sha256, validate
from fabricfem.scenes.richardson import ORDERS, Estimate, richardson
from fabricfem.scenes.run import run_scene
from fabricfem.scenes.schema import Scene
from fabricfem.wear.outputs import plot_torque, torque_rms_error

QUICK_CELLS = 130          # cells of a tube's level 0 in the quick study, at most
COLUMNS = ("level", "mesh", "ndofs", "monitor", "curve_rms_difference", "window_mean_Nm",
           "window_mean_difference", "extrapolated_Nm", "gci", "observed_order", "note", "p95_abs_Nm",
           "p95_abs_difference", "p95_extrapolated_Nm", "p95_note", "wall_s", "status")


def level_data(scene: Scene, k: int, ratio: float, out: Path, quick: bool) -> dict:
    """The scene data of level k (module docstring) writing into out/level_k, without renders."""
    data = copy.deepcopy(scene.data)
    g = data["garment"]
    scale = ratio ** k
    if quick and g.get("builder", "pattern") == "tube":
        coarse = min(1.0, math.sqrt(QUICK_CELLS / (g["n_around"] * g["n_along"])))
        g.update(n_around=max(3, round(g["n_around"] * coarse)), n_along=max(1, round(g["n_along"] * coarse)))
    if g.get("builder", "pattern") == "tube":
        g.update(n_around=max(3, round(g["n_around"] * scale)), n_along=max(1, round(g["n_along"] * scale)))
    else:
        g["h"] = scene.parsed.garment.h / scale
    if quick:
        _shorten(data, scene)
    data.pop("accuracy", None)
    data["output"] = {**data.get("output", {}), "dir": str(out / f"level_{k}"), "render": False}
    return data


def _shorten(data: dict, scene: Scene) -> None:
    """The quick study's short motion (module docstring)."""
    if data["motion"]["type"] == "elbow_flexion":
        data["motion"].update(final_angle=min(6.0, data["motion"].get("final_angle", 57.0)), output_angle_step=3.0,
                              settle_time=0.1)
        return
    parsed = scene.parsed
    plan = wear.plan(parsed, wear.wear_fabric(parsed, build_fabric), scene.path)
    data.setdefault("route", {})["end_time"] = plan.timeline.start_of("motion") + 0.1


def mesh_label(data: dict) -> str:
    g = data["garment"]
    return f"{g['n_around']}x{g['n_along']}" if g.get("builder", "pattern") == "tube" else f"h = {g['h']:.4g} m"


def _curve(folder: Path, monitor: str) -> tuple[np.ndarray, np.ndarray]:
    """(axis, torque) of the motion records of a level's torque.csv."""
    rows = [r for r in csv.DictReader(open(folder / "torque.csv")) if r["phase"] == "motion"]
    return np.array([float(r["axis"]) for r in rows]), np.array([float(r[f"{monitor}_torque_Nm"]) for r in rows])


def _relative(value: float | None, finest: float | None) -> float:
    """|value - finest| / |finest|, NaN where either is missing or the finest is 0."""
    return abs(value - finest) / abs(finest) if value is not None and finest else math.nan


def _extrapolate(values: list[float | None], ratio: float) -> Estimate | None:
    """Richardson's estimate from the three finest of `values` (coarse to fine), None with fewer or a gap."""
    if len(values) < 3 or any(v is None for v in values[-3:]):
        return None
    sizes = tuple(ratio ** -k for k in range(len(values) - 3, len(values)))
    return richardson(values[-3:], sizes, ORDERS["dynamic"])


def _note(estimate: Estimate | None, values: list[float | None]) -> str:
    """The ladder's note: why there is no extrapolation, or "asymptotic"."""
    if estimate is None:
        return ("fewer than three levels: no extrapolation" if len(values) < 3 else
                "a level without this statistic: no extrapolation")
    return estimate.note or "asymptotic"


def ladder_rows(levels: list[dict], folders: list[Path], ratio: float) -> list[dict]:
    """The rows of convergence.csv (module docstring) from the levels' outputs, coarse to fine."""
    summaries = [read_summary(f) for f in folders]
    monitors = [key[7:] for key in summaries[-1] if key.startswith("torque_")]
    rows = []
    for monitor in monitors:
        fine_x, fine_y = _curve(folders[-1], monitor)
        means = [s.get(f"torque_{monitor}", {}).get("window_mean_Nm") for s in summaries]
        peaks = [s.get("statistics", {}).get(f"torque_{monitor}", {}).get("p95_abs_Nm") for s in summaries]
        estimate, peak_estimate = _extrapolate(means, ratio), _extrapolate(peaks, ratio)
        errors = estimate.errors if estimate is not None else []
        for k, (data, summary, folder) in enumerate(zip(levels, summaries, folders)):
            x, y = _curve(folder, monitor)
            index = k - (len(levels) - 3)
            rows.append({"level": k, "mesh": mesh_label(data), "ndofs": summary.get("ndofs"), "monitor": monitor,
                         "curve_rms_difference": torque_rms_error(x, y, fine_x, fine_y,
                                                                  start=float(fine_x[0]) if len(fine_x) else 0.0),
                         "window_mean_Nm": means[k], "window_mean_difference": _relative(means[k], means[-1]),
                         "extrapolated_Nm": None if estimate is None else estimate.extrapolated,
                         "gci": errors[index] if 0 <= index < len(errors) else None,
                         "observed_order": None if estimate is None else estimate.order, "note": _note(estimate, means),
                         "p95_abs_Nm": peaks[k], "p95_abs_difference": _relative(peaks[k], peaks[-1]),
                         "p95_extrapolated_Nm": None if peak_estimate is None else peak_estimate.extrapolated,
                         "p95_note": _note(peak_estimate, peaks),
                         "wall_s": summary.get("wall_s"), "status": summary.get("status")})
    return rows


def run_ladder(scene: Scene, out: Path, levels: int, ratio: float, quick: bool = False,
               comm: MPI.Comm = MPI.COMM_WORLD, ranks_per_variant: int = 1,
               what: str = "convergence study") -> tuple[list[dict], list[Path]]:
    """Run (or read back) the levels 0 .. levels - 1 of the ladder (module docstring) into out/level_k as one
    resumable batch; returns (the levels' scene data, their folders), coarse to fine. BatchError naming a level
    that failed."""
    datas = [level_data(scene, k, ratio, out, quick) for k in range(levels)]
    scenes = [validate(d, source=f"level {k}", path=scene.path) for k, d in enumerate(datas)]
    folders = [out / f"level_{k}" for k in range(levels)]
    jobs = [Job(f"level {k} ({mesh_label(d)})", float(ratio ** (3 * k)),
                lambda sub, s=s: run_scene(s, sub).status,
                lambda s=s, f=f: completed(f, scene_sha256(s))) for k, (d, s, f) in enumerate(zip(datas, scenes, folders))]
    check(run_batch(jobs, comm, ranks_per_variant, what), what, str(out))
    return datas, folders


def run_convergence(scene: Scene, out: str | Path, levels: int = 3, ratio: float = 1.5, quick: bool = False,
                    comm: MPI.Comm = MPI.COMM_WORLD, ranks_per_variant: int = 1) -> list[dict]:
    """Run the ladder (module docstring) and write convergence.csv and .png under `out`; returns the rows."""
    if scene.kind != "wear":
        raise ValueError(f"scene: the convergence study refines a wear scene's garment, got a {scene.kind} scene")
    if not (isinstance(levels, int) and levels >= 2):
        raise ValueError(f"levels must be an integer >= 2, got {levels!r}")
    if not (math.isfinite(ratio) and 1.0 < ratio <= 4.0):
        raise ValueError(f"ratio must lie in (1, 4], got {ratio!r}")
    out = Path(out)
    levels = 2 if quick else levels
    datas, folders = run_ladder(scene, out, levels, ratio, quick, comm, ranks_per_variant)
    rows = ladder_rows(datas, folders, ratio) if comm.rank == 0 else None
    rows = comm.bcast(rows, root=0)
    if comm.rank == 0:
        fio.write_csv(out / "convergence.csv", COLUMNS, [[row[c] for c in COLUMNS] for row in rows], MPI.COMM_SELF)
        first = rows[0]["monitor"] if rows else None
        if first is not None:
            plot_torque(out / "convergence.png", {f"level {k} ({mesh_label(d)})": _curve(f, first)
                                                  for k, (d, f) in enumerate(zip(datas, folders))},
                        f"{scene_name(scene)}: {first} on the mesh ladder", xlabel="record coordinate")
    return rows
