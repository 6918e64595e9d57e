"""After a kill and `--resume`, one XDMF file per field holds every record: cloth.xdmf and
cloth_pressure.xdmf open in meshio with a step per row of torque.csv at its times, the killed run's records
included, and no *_resumed files are left; `--resume` of a static scene says that it solves from the start
(item 6)."""
import csv
import signal
import subprocess
import sys
import tomllib
from contextlib import contextmanager
from pathlib import Path

import meshio
import numpy as np
import pytest
from mpi4py import MPI
from test_checkpoint import SCENE, SQUARES

from fabricfem import scenes as scene_module
from fabricfem.launch import child_environment
from fabricfem.scenes.run import run_scene
from fabricfem.wear import run as wear_run

ROOT = Path(__file__).resolve().parents[1]
FIELDS = ("cloth.xdmf", "cloth_pressure.xdmf")


def _scene(folder: Path) -> Path:
    """The two sewn squares on a limb (tests/test_checkpoint.py): 45 records, a checkpoint after record 25."""
    (folder / "squares.toml").write_text(SQUARES)
    path = folder / "scene.toml"
    path.write_text(SCENE)
    return path


def _check_series(out: Path) -> None:
    """Every field's XDMF file reads in meshio with one step per torque.csv row at its body time [s], and no
    *_resumed file is left."""
    times = [float(row["time_s"]) for row in csv.DictReader(open(out / "torque.csv"))]
    assert len(times) == 45
    for name in FIELDS:
        with meshio.xdmf.TimeSeriesReader(out / name) as reader:
            points, _ = reader.read_points_cells()
            steps = [reader.read_data(k) for k in range(reader.num_steps)]
        assert [t for t, _, _ in steps] == pytest.approx(times, rel=1e-12), name
        assert all(len(next(iter(data.values()))) == len(points) for _, data, _ in steps)
    assert not [p.name for p in out.iterdir() if "resumed" in p.name]


def test_killed_run_resumes_into_the_same_xdmf_files(tmp_path):
    """`fabricfem run` killed by SIGKILL after its checkpoint (record 25) and two more records, then `--resume`:
    both XDMF files hold all 45 records (the ones written again after the checkpoint once)."""
    command = [sys.executable, "-m", "fabricfem.cli", "run", str(_scene(tmp_path)), "--out", str(tmp_path / "out")]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               env=child_environment())
    records = 0
    for line in process.stdout:
        records += line.strip().startswith(("sew", "motion"))
        if records == 28:
            process.send_signal(signal.SIGKILL)
            break
    process.wait(timeout=120)
    assert process.returncode == -signal.SIGKILL, "the run ended before it was killed"
    resumed = subprocess.run(command + ["--resume"], capture_output=True, text=True, env=child_environment())
    assert resumed.returncode not in (1, 2), resumed.stderr
    assert (tmp_path / "out" / "summary.json").read_text().count('"status": "completed') == 1
    _check_series(tmp_path / "out")


def test_interrupted_run_resumes_into_the_same_xdmf_files(tmp_path, monkeypatch):
    """An interrupt (should_stop answering after the 30th record) ends the run with a checkpoint there; the
    resumed run (in the same process) appends the other 15 records to both XDMF files."""
    scene = scene_module.load(_scene(tmp_path))
    calls = []

    @contextmanager
    def interrupt_at_30(comm):
        yield lambda: (calls.append(1), "interrupted (SIGINT)" if len(calls) == 30 else "")[1]
    monkeypatch.setattr(wear_run, "interrupt_flag", interrupt_at_30)
    first = run_scene(scene, MPI.COMM_SELF, out=tmp_path / "out")
    assert first.status.startswith("stopped early: interrupted (SIGINT)")
    with meshio.xdmf.TimeSeriesReader(tmp_path / "out" / "cloth.xdmf") as reader:
        reader.read_points_cells()
        assert reader.num_steps == 30
    resumed = run_scene(scene, MPI.COMM_SELF, out=tmp_path / "out", resume=True)
    assert resumed.status.startswith("completed") and len(resumed.result.steps) == 45
    _check_series(tmp_path / "out")


def test_resume_of_a_static_scene_says_it_solves_from_the_start(tmp_path, capsys):
    """A static scene has no checkpoint: `--resume` says that it solves the scene from the start, and does."""
    data = tomllib.loads((ROOT / "scenes" / "drape.toml").read_text())
    data["mesh"].update(nx=4, ny=2)
    data["output"].update(dir=str(tmp_path), render=False)
    outcome = run_scene(scene_module.validate(data), MPI.COMM_SELF, resume=True)
    assert outcome.exit_code == 0 and (tmp_path / "history.csv").is_file()
    assert "a static scene has no checkpoint; --resume solves it from the start" in capsys.readouterr().out
    assert np.isfinite(float(list(csv.DictReader(open(tmp_path / "history.csv")))[-1]["probe_uz_m"]))
