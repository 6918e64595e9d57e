"""The sleeve on a ladder of meshes: does the elbow torque and the peak skin pressure converge?
`python -m fabricfem.benchmarks.skin_ladder [--scene scenes/sleeve.toml] [--meshes 10x13,...] [--out DIR]`.

Each mesh level runs the scene (`fabricfem run`, renders off) with the tube's cells around x along set to the
level's, into DIR/<mesh>/ (a level whose folder holds a completed summary.json is read back, not rerun; `--ranks 2`
runs each level under `mpirun -n 2`). Per level, against the finest:

    curve difference     RMS over the finest level's motion records from 10 deg of T_k - T_finest (T_k interpolated
                         in the angle), over the mean |T_finest| (fabricfem.wear.outputs.torque_rms_error)
    window mean          the mean elbow torque over the records from 20 to 57 deg and its relative difference
    peak pressure        the largest record's peak skin pressure of the motion [Pa] (each record's pressure is the
                         time average over its interval) and the 99th percentile of the records' peaks
    sensor pressure      the largest record's sensor pressure (the mean over a disc of the scene's
                         [output] sensor_diameter, fabricfem.wear.sensor) [Pa]

Writes DIR/skin_ladder.csv and DIR/skin_ladder.png (every level's torque curve and the peak pressure against the
mesh size). SI units.
"""
from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

from fabricfem.launch import child_environment
from fabricfem.wear.outputs import torque_rms_error

MESHES = ("10x13", "15x20", "20x26", "30x39", "36x60", "40x52", "44x57", "60x78", "80x104")
WINDOW_DEG = (20.0, 57.0)
COLUMNS = ("mesh", "ndofs", "curve_rms_difference", "window_mean_Nm", "window_mean_difference",
           "peak_pressure_Pa", "p99_peak_pressure_Pa", "sensor_pressure_Pa", "max_strain", "wall_s", "status")


def level_scene(scene: Path, mesh: str, folder: Path) -> Path:
    """A copy of `scene` with the tube's mesh `mesh` ("n_aroundxn_along") and renders off, written in `folder`."""
    around, along = (int(v) for v in mesh.split("x"))
    lines = []
    for line in scene.read_text().splitlines():
        key = line.split("=")[0].strip()
        if key in ("n_around", "n_along"):
            line = f"{key} = {around if key == 'n_around' else along}"
        elif key == "render_at":
            line = "render = false"
        lines.append(line)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"scene_{mesh}.toml"
    path.write_text("\n".join(lines) + "\n")
    tomllib.loads(path.read_text())        # still a valid scene file
    return path


def run_level(scene: Path, mesh: str, out: Path, ranks: int = 1) -> Path:
    """The level's run folder, run by `fabricfem run` (on `ranks` MPI ranks) unless it holds a completed summary."""
    folder = out / mesh
    summary = folder / "summary.json"
    if summary.exists() and json.loads(summary.read_text()).get("completed"):
        return folder
    path = level_scene(scene, mesh, out)
    command = [sys.executable, "-m", "fabricfem.cli", "run", str(path), "--out", str(folder)]
    subprocess.run((["mpirun", "-n", str(ranks)] if ranks > 1 else []) + command, check=False,
                   env=child_environment())
    return folder


def read_level(folder: Path) -> dict:
    """Angles [deg], elbow torques [N m], the records' peak pressures [Pa] of the motion and the summary."""
    rows = [r for r in csv.DictReader((folder / "torque.csv").open()) if r["phase"] == "motion"]
    return {"angle": np.array([float(r["axis"]) for r in rows]),
            "torque": np.array([float(r["elbow_torque_Nm"]) for r in rows]),
            "peak": np.array([float(r["peak_pressure_Pa"]) for r in rows]),
            "sensor": np.array([float(r.get("sensor_pressure_Pa") or "nan") for r in rows]),
            "strain": np.array([float(r["max_strain"]) for r in rows]),
            "summary": json.loads((folder / "summary.json").read_text())}


def ladder_rows(levels: dict[str, dict]) -> list[dict]:
    """The rows of the CSV (module docstring), the last level the finest."""
    finest = list(levels.values())[-1]
    window = (finest["angle"] >= WINDOW_DEG[0] - 1e-9) & (finest["angle"] <= WINDOW_DEG[1] + 1e-9)
    reference_mean = float(np.mean(finest["torque"][window]))
    rows = []
    for mesh, level in levels.items():
        inside = (level["angle"] >= WINDOW_DEG[0] - 1e-9) & (level["angle"] <= WINDOW_DEG[1] + 1e-9)
        mean = float(np.mean(level["torque"][inside]))
        rows.append({"mesh": mesh, "ndofs": level["summary"].get("ndofs"),
                     "curve_rms_difference": torque_rms_error(level["angle"], level["torque"], finest["angle"],
                                                              finest["torque"]),
                     "window_mean_Nm": mean, "window_mean_difference": mean / reference_mean - 1.0,
                     "peak_pressure_Pa": float(level["peak"].max()),
                     "p99_peak_pressure_Pa": float(np.percentile(level["peak"], 99)),
                     "sensor_pressure_Pa": float(level["sensor"].max()),
                     "max_strain": float(level["strain"].max()), "wall_s": level["summary"].get("wall_s"),
                     "status": level["summary"].get("status")})
    return rows


def plot(levels: dict[str, dict], rows: list[dict], path: Path) -> None:
    """Every level's torque curve, and the peak pressure against the cells around."""
    import matplotlib  # optional heavy package: imported only to draw

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package: imported only to draw

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    for mesh, level in levels.items():
        left.plot(level["angle"], level["torque"], label=mesh)
    left.set(xlabel="elbow angle [deg]", ylabel="elbow torque [N m]", title="blended arm")
    left.legend()
    around = [int(r["mesh"].split("x")[0]) for r in rows]
    right.plot(around, [r["peak_pressure_Pa"] / 1e3 for r in rows], "o-", label="largest record")
    right.plot(around, [r["p99_peak_pressure_Pa"] / 1e3 for r in rows], "s--", label="99th percentile")
    right.plot(around, [r["sensor_pressure_Pa"] / 1e3 for r in rows], "^-", label="sensor disc, largest record")
    right.set(xlabel="cells around", ylabel="peak skin pressure [kPa]", yscale="log")
    right.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes/sleeve.toml")
    parser.add_argument("--meshes", default=",".join(MESHES), help="levels, coarse to fine, e.g. 10x13,20x26")
    parser.add_argument("--out", default="results/skin_ladder")
    parser.add_argument("--ranks", type=int, default=1, help="MPI ranks of each level's run")
    args = parser.parse_args(argv)
    out = Path(args.out)
    levels = {m: read_level(run_level(Path(args.scene), m, out, args.ranks)) for m in args.meshes.split(",")}
    rows = ladder_rows(levels)
    with (out / "skin_ladder.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    plot(levels, rows, out / "skin_ladder.png")
    for r in rows:
        print(f"{r['mesh']:>7}  curve {100 * r['curve_rms_difference']:6.2f} %  mean {r['window_mean_Nm']:.5f} N m "
              f"({100 * r['window_mean_difference']:+6.2f} %)  peak {r['peak_pressure_Pa'] / 1e3:7.2f} kPa  "
              f"p99 {r['p99_peak_pressure_Pa'] / 1e3:7.2f} kPa  sensor {r['sensor_pressure_Pa'] / 1e3:7.3f} kPa  "
              f"strain {r['max_strain']:.3f}")


if __name__ == "__main__":
    main()
