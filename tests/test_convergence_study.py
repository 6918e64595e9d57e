"""`fabricfem study convergence`: a wear scene on a mesh ladder (fabricfem.studies.convergence)."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest

from fabricfem import cli
from fabricfem.studies.convergence import ladder_rows

ROOT = Path(__file__).resolve().parents[1]


def _level(folder: Path, mean: float, scale: float, p95: float | None = None) -> None:
    """A level's outputs: summary.json with the window mean (and the statistics' p95 |T|), torque.csv with
    T = scale x sin(axis)."""
    folder.mkdir(parents=True)
    summary = {"torque_knee": {"window_mean_Nm": mean}, "ndofs": 10, "status": "completed", "wall_s": 1.0}
    if p95 is not None:
        summary["statistics"] = {"torque_knee": {"p95_abs_Nm": p95}}
    (folder / "summary.json").write_text(json.dumps(summary))
    x = np.linspace(0.0, 1.0, 21)
    with open(folder / "torque.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "phase", "axis", "knee_torque_Nm"])
        w.writerows([[t, "motion", t, scale * np.sin(t)] for t in x])


def test_a_second_order_ladder_extrapolates_to_its_limit(tmp_path):
    """Window means q_k = 1 + 0.1 h_k^2 on h_k = 1.5^-k (p95 |T| 2 - 0.3 h_k^1.5): observed order 2 and extrapolated
    values 1 (2) (exact to
    round-off: the Richardson formula is exact for a pure power law); curve differences 1 - s_k / s_fine of
    T = s_k sin(x) relative to the finest's mean |T|, by hand."""
    ratio, folders, levels = 1.5, [], []
    for k in range(3):
        h = ratio ** -k
        folders.append(tmp_path / f"level_{k}")
        _level(folders[-1], 1.0 + 0.1 * h ** 2, 1.0 + 0.1 * h ** 2, p95=2.0 - 0.3 * h ** 1.5)
        levels.append({"garment": {"builder": "tube", "n_around": 10 * (k + 1), "n_along": 13}})
    rows = ladder_rows(levels, folders, ratio)
    assert [r["level"] for r in rows] == [0, 1, 2]
    assert rows[-1]["observed_order"] == pytest.approx(2.0, rel=1e-6)
    assert rows[-1]["extrapolated_Nm"] == pytest.approx(1.0, rel=1e-12)
    assert rows[-1]["note"] == "asymptotic"
    assert rows[-1]["p95_extrapolated_Nm"] == pytest.approx(2.0, rel=1e-12) and rows[-1]["p95_note"] == "asymptotic"
    assert rows[0]["p95_abs_difference"] == pytest.approx(0.3 * (1 - ratio ** -3) / (2.0 - 0.3 * ratio ** -3),
                                                          rel=1e-12)
    x = np.linspace(0.0, 1.0, 21)
    fine = (1.0 + 0.1 / ratio ** 4) * np.sin(x)
    coarse = 1.1 * np.sin(x)
    expected = np.sqrt(np.mean((coarse - fine) ** 2)) / np.mean(np.abs(fine))
    assert rows[0]["curve_rms_difference"] == pytest.approx(expected, rel=1e-12)


def test_quick_convergence_study_of_the_shipped_sleeve(tmp_path, capsys):
    assert cli.main(["study", "convergence", str(ROOT / "scenes" / "sleeve.toml"), "--quick", "--out",
                     str(tmp_path)]) == 0
    rows = list(csv.DictReader(open(tmp_path / "convergence.csv")))
    assert {r["mesh"] for r in rows} == {"10x13", "15x20"} and {r["monitor"] for r in rows} >= {"elbow"}
    finest = [r for r in rows if r["level"] == "1"]
    assert all(float(r["curve_rms_difference"]) == 0.0 for r in finest)
    assert (tmp_path / "convergence.png").exists()
    assert "fewer than three levels" in capsys.readouterr().out
