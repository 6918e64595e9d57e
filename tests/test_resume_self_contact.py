"""`fabricfem run --resume` with cloth self-contact impulses and impact zones (scenes/sleeve_130.toml on a 10 x 13
mesh, flexed fast to 120 degrees): a run interrupted at 116 degrees, where the impact zones act and the adaptive
step (fabricfem.wear.garment.GarmentRun.adaptive_steps) has shortened dt, and resumed gives the records,
summary.json and impact-zone counts of the uninterrupted run (a non-finite velocity in the cloth-cloth correction:
tests/test_impact_zones.py)."""
from __future__ import annotations

import ast
import csv
import json
import re
import tempfile
import tomllib
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.scenes.run import run_scene
from fabricfem.wear import run as wear_run

ROOT = Path(__file__).resolve().parents[1]
INTERRUPT = 67     # the record at 116 degrees: 9 settling records, then one per 2 degrees
RUN_KEYS = ("scene_sha256", "started", "finished", "wall_s", "wall_split", "outputs")   # of the process, not the run


def _scene(out: Path):
    """scenes/sleeve_130.toml on 10 x 13, settling 0.05 s, flexed at 360 deg/s to 120 deg, a record per 2 deg."""
    data = tomllib.loads((ROOT / "scenes" / "sleeve_130.toml").read_text())
    data["garment"].update(n_around=10, n_along=13)
    data["motion"].update(final_angle=120.0, angular_velocity=360.0, settle_time=0.05, output_angle_step=2.0)
    data["output"] = {"dir": str(out), "render": False}
    return scene_module.validate(data)


def _table(folder: Path) -> tuple[list[str], np.ndarray]:
    rows = list(csv.DictReader(open(folder / "torque.csv")))
    keys = [k for k in rows[0] if k not in ("phase", "peak_segment", "wall_s")]
    return keys, np.array([[float(r[k]) for k in keys] for r in rows])


def _summary(folder: Path) -> dict:
    return {k: v for k, v in json.loads((folder / "summary.json").read_text()).items() if k not in RUN_KEYS}


def _zone_totals(text: str) -> list[dict]:
    """The impact zones' totals printed after each record (fabricfem.wear.run.run_wear)."""
    return [ast.literal_eval(m) for m in re.findall(r"impact zones: (\{[^}]*\})", text)]


@contextmanager
def _interrupt_at(record: int):
    """An interrupt (as Ctrl-C) answered after the `record`-th record of the run."""
    original, calls = wear_run.interrupt_flag, []

    @contextmanager
    def flag(comm):
        yield lambda: (calls.append(1), "interrupted (SIGINT)" if len(calls) == record else "")[1]
    wear_run.interrupt_flag = flag
    try:
        yield
    finally:
        wear_run.interrupt_flag = original


def _interrupt_and_resume(comm, folder: Path, capsys) -> None:
    whole = run_scene(_scene(folder / "whole"), comm)
    whole_zones = _zone_totals(capsys.readouterr().out)
    with _interrupt_at(INTERRUPT):
        first = run_scene(_scene(folder / "part"), comm)
    first_zones = _zone_totals(capsys.readouterr().out)
    resumed = run_scene(_scene(folder / "part"), comm, resume=True)
    resumed_zones = _zone_totals(capsys.readouterr().out)
    assert first.status.startswith("stopped early: interrupted (SIGINT) at t = ")
    assert resumed.status == whole.status
    if comm.rank != 0:
        return
    keys, a = _table(folder / "whole")
    _, b = _table(folder / "part")
    steps = a[:, keys.index("time_steps")]
    assert steps[INTERRUPT] > steps[0]             # the interval after the interrupt runs with a shortened dt
    assert 0 < whole_zones[INTERRUPT - 1]["collisions"] < whole_zones[-1]["collisions"]   # zones act on both sides
    assert a.shape == b.shape and len(a) == INTERRUPT + 2
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=0.0)
    assert _summary(folder / "part") == _summary(folder / "whole")
    assert first_zones == whole_zones[:INTERRUPT] and resumed_zones == whole_zones[INTERRUPT:]


def test_interrupted_sleeve_with_zones_resumes_to_the_uninterrupted_run(tmp_path, capsys):
    """Interrupted at record 67 (116 deg: the zones have resolved collisions and dt is shortened to 27 steps per
    record, from 24) and resumed: every torque.csv column (torques, pressures, penetration, strain, steps, energies,
    intersecting triangle pairs) equals the uninterrupted run's within 1e-12 relative (measured: identical),
    summary.json too (but for the run's times, hash and file list), and the impact zones' running totals go on
    from the checkpoint. Without the adaptive step in the checkpoint the resumed interval ran 24 steps of the
    reference dt and the run blew up (non-finite velocities) 5 records later."""
    _interrupt_and_resume(MPI.COMM_SELF, tmp_path, capsys)


@pytest.mark.mpi
def test_interrupted_sleeve_with_zones_resumes_on_two_ranks(capsys):
    """The same on the ranks of COMM_WORLD (each rank checkpoints its own part; the gathered self-contact state
    is the same on every rank)."""
    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(tempfile.mkdtemp() if comm.rank == 0 else None, root=0))
    _interrupt_and_resume(comm, folder, capsys)

