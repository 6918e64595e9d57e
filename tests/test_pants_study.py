"""The pants study's outputs (fabricfem.studies.pants) from synthetic variant histories, and its crossing window."""
import copy
import csv
import dataclasses
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.body.crossing import obstacle_walk
from fabricfem.scenes.run import build_wear_run
from fabricfem.scenes.schema import validate
from fabricfem.studies.pants import SCENE, crossing_window, write_study

ROOT = Path(__file__).resolve().parents[1]


def test_write_study_reports_the_thesis_ratios(tmp_path):
    """Two variants whose moment magnitudes are 1 and 2 x sin^2 over the walk (and 0 during the donning): the
    study's summary gives the peak and mean ratios 2 (exact), the share of walking records with 2 mm larger 1 (all
    but the zeros), and writes the CSV (a column per variant) and the .sto and PNG."""
    t = np.linspace(0.0, 2.0, 101)
    phases = ["don" if x < 0.5 else "motion" for x in t]
    base = np.sin(3 * t) ** 2 + 0.1
    base[t < 0.5] = 0.0
    curves = {"1mm_mu0.1": (t, -base, 30 + 0 * t, phases, base),
              "2mm_mu0.1": (t, -2 * base, 30 + 0 * t, phases, 2 * base)}
    summary = write_study(tmp_path, curves, quick=True, crossing=(1.0, 1.5))
    walk = summary["ratio_2mm_to_1mm"]["walk"]
    assert walk["peak"] == 2.0 and abs(walk["mean"] - 2.0) < 1e-14 and walk["share_of_records_2mm_larger"] == 1.0
    assert summary["ratio_2mm_to_1mm"]["crossing"]["peak"] == 2.0
    rows = list(csv.reader(open(tmp_path / "knee_torque.csv")))
    assert rows[0][:4] == ["time_s", "knee_flexion_deg", "1mm_mu0.1_knee_moment_magnitude_Nm",
                           "2mm_mu0.1_knee_moment_magnitude_Nm"] and len(rows) == 102
    for name in ("knee_torque.sto", "knee_torque.png", "summary.json"):
        assert (tmp_path / name).is_file()
    assert json.loads((tmp_path / "summary.json").read_text())["quick"] is True


def test_crossing_window_of_the_pants_scene():
    """The crossing stride's body-time window is the walk's own window shifted by the donning phases and the blend
    from the standing pose (1.0 s + 0.3 s in scenes/pants_walk.toml)."""
    data = tomllib.loads(Path(SCENE).read_text())
    t0, t1 = crossing_window(data)
    own = obstacle_walk(strides=4).crossing_window
    shift = t0 - own[0]
    assert abs((t1 - t0) - (own[1] - own[0])) < 0.05          # the body's hip spacing changes the stride little
    assert abs(shift - 1.3) < 0.05


@pytest.mark.mpi
def test_pants_knee_torque_same_on_one_and_two_ranks():
    """The pants scene (scenes/pants_walk.toml at h = 0.15 m) on COMM_WORLD (2 ranks under mpirun) and COMM_SELF: the
    ranks differ in the summation order only. Compared per record: the three knee torques, the contact force on the
    body and the strain energy, each relative to its largest serial value. Through the sewing, the pull and the
    start of the growth (33 records, 0.66 s) they agree within 1e-6 (measured 4.3e-7). From there the legs press on
    the trousers (the knee moment rises to 8e-3 N m) and the round-off grows: a serial run with the fabric's density
    changed by 1e-13 (relative) differs by 3e-4 at record 34. Over all 35 records (0.7 s) the 2-rank run must
    therefore stay closer to the serial one than that perturbed serial run does (measured about 0.03 of its
    difference): a parallel error, even a small one, would not. (On the upright panels before 2026-11-28 the legs
    touched the cloth from record 10 on.)"""
    data = tomllib.loads(Path(SCENE).read_text())
    data["garment"]["h"] = 0.15

    def history(comm, density_change: float = 0.0) -> np.ndarray:
        changed = copy.deepcopy(data)
        changed["fabric"]["density"] *= 1.0 + density_change
        scene = dataclasses.replace(validate(changed, "pants"), path=Path(SCENE))
        run = build_wear_run(scene, comm)[0]
        records: list = []
        h = run.run(on_step=records.append, should_stop=lambda: "window" if len(records) >= 35 else "")
        run.destroy()
        return np.array([[s.torques[n] for n in ("knee_r", "knee_r_x", "knee_r_z")] + [s.contact_force, s.strain_energy]
                         for s in h.steps])

    parallel, serial = history(MPI.COMM_WORLD), history(MPI.COMM_SELF)
    perturbed = history(MPI.COMM_SELF, 1e-13)
    assert len(serial) == 35 and np.max(np.abs(serial[:, 0])) > 1e-3     # the legs press on the pants
    scale = np.abs(serial).max(axis=0)
    assert np.all(scale > 0.0)
    first = slice(0, 33)
    assert np.max(np.abs(parallel[first] - serial[first]) / scale) <= 1e-6
    assert np.linalg.norm((parallel - serial) / scale) < np.linalg.norm((perturbed - serial) / scale)
