"""Robust statistics of a wear run (fabricfem.wear.statistics): windowed means against closed forms, percentile
peaks beside the raw maxima, in summary.json and statistics.csv; the same on 1 and 2 ranks."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from shipped_scenes import scene_data

from fabricfem import scenes as scene_module
from fabricfem.scenes.run import run_scene
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.statistics import default_windows, motion_statistics, window_mean

ROOT = Path(__file__).resolve().parents[1]


def test_window_mean_of_a_linear_and_a_quadratic_curve():
    """Trapezoid mean: exact for y = 2 + 3 x on [1, 4] (2 + 3 x 2.5 = 9.5); y = x^2 on [0, 1] with 101 records: 1/3 + 1/(6 n^2)."""
    x = np.linspace(0.0, 5.0, 11)
    assert window_mean(x, 2.0 + 3.0 * x, (1.0, 4.0)) == pytest.approx(9.5, rel=1e-14)
    x = np.linspace(0.0, 1.0, 101)
    assert window_mean(x, x ** 2, (0.0, 1.0)) == pytest.approx(1.0 / 3.0 + 1.0 / (6 * 100 ** 2), rel=1e-12)
    assert np.isnan(window_mean(x, x, (2.0, 3.0)))          # no records in the window


def _history(values) -> WearHistory:
    steps = [WearStep(phase="motion", time=0.1 * k, torques={"elbow": v}, peak_pressure=1e3 * abs(v),
                      peak_segment="", peak_position=(0.0, 0.0, 0.0), mean_pressure=0.0, max_penetration=0.0,
                      contact_force=1.0, seam_gap=0.0, seam_forces={}, max_strain=0.0, time_steps=1,
                      kinetic_energy=0.0, strain_energy=1.0, wall=0.0, axis_value=float(k))
             for k, v in enumerate(values)]
    return WearHistory("test", steps=steps)


def test_percentile_peak_beside_the_raw_maximum():
    """One spike of 10 among 40 records of 1: the 95th percentile stays at 1, the largest is 10."""
    h = _history([1.0] * 40 + [10.0])
    stats = motion_statistics(h, default_windows(h, angle_axis=True))
    assert stats["windows"] == [[20.0, 40.0]]
    entry = stats["torque_elbow"]
    assert entry["p95_abs_Nm"] == pytest.approx(1.0) and entry["max_abs_Nm"] == 10.0
    assert entry["mean_Nm"][0] == pytest.approx((19.5 * 1.0 + 0.5 * 10.0) / 20.0)


def _short_sleeve(out: Path) -> dict:
    data = scene_data("sleeve.toml")
    data["motion"].update(final_angle=4.0, output_angle_step=1.0, settle_time=0.1)
    data["output"] = {"dir": str(out), "render": False, "windows": [[1.0, 4.0], [2.0, 3.0]]}
    return data


def test_a_wear_run_reports_its_windowed_means(tmp_path):
    run_scene(scene_module.validate(_short_sleeve(tmp_path)), MPI.COMM_SELF)
    summary = json.loads((tmp_path / "summary.json").read_text())
    stats = summary["statistics"]
    assert stats["windows"] == [[1.0, 4.0], [2.0, 3.0]]
    rows = list(csv.DictReader(open(tmp_path / "torque.csv")))
    motion = [(float(r["axis"]), float(r["elbow_torque_Nm"])) for r in rows if r["phase"] == "motion"]
    x, y = np.array(motion).T
    assert stats["torque_elbow"]["mean_Nm"][0] == pytest.approx(window_mean(x, y, (1.0, 4.0)), rel=1e-12)
    assert summary["torque_elbow"]["window_mean_Nm"] == stats["torque_elbow"]["mean_Nm"][0]
    table = list(csv.reader(open(tmp_path / "statistics.csv")))
    assert table[0][:4] == ["quantity", "window_start", "window_end", "window_mean"] and len(table) == 1 + 3 * 2


@pytest.mark.mpi
def test_statistics_on_two_ranks_equal_serial(tmp_path):
    """The same short sleeve on COMM_WORLD (2 ranks under mpirun) and on one rank: windowed means within 1e-6."""
    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(str(tmp_path), root=0))
    parallel = run_scene(scene_module.validate(_short_sleeve(folder / "world")), comm).result
    serial = None
    if comm.rank == 0:
        serial = run_scene(scene_module.validate(_short_sleeve(folder / "self")), MPI.COMM_SELF).result
    serial = comm.bcast(None if serial is None else serial.statistics, root=0)
    for key in ("torque_elbow", "torque_elbow_both_segments"):
        np.testing.assert_allclose(parallel.statistics[key]["mean_Nm"], serial[key]["mean_Nm"], rtol=1e-6,
                                   atol=1e-12)
    # statistics.csv and summary.json as written: every row's windowed mean, percentile peak and largest value
    tables = [list(csv.reader(open(folder / run / "statistics.csv"))) for run in ("world", "self")]
    assert tables[0][0] == tables[1][0] and [r[:3] for r in tables[0]] == [r[:3] for r in tables[1]]
    assert len(tables[0]) == 1 + 3 * 2                     # two monitors and the peak pressure, two windows
    values = [np.array([[float(x) for x in r[3:]] for r in t[1:]]) for t in tables]
    np.testing.assert_allclose(values[0], values[1], rtol=1e-6, atol=1e-12)
    summaries = [json.loads((folder / run / "summary.json").read_text()) for run in ("world", "self")]
    for key in ("torque_elbow", "torque_elbow_both_segments"):
        assert summaries[0][key]["window_mean_Nm"] == pytest.approx(summaries[1][key]["window_mean_Nm"], rel=1e-6)
