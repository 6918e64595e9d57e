"""Checkpoints of a garment run (fabricfem.wear.checkpoint) and of a dynamic scene (fabricfem.scenes.run
DynamicCheckpoint): a run killed after a checkpoint and resumed gives the records of an uninterrupted run; Ctrl-C
stops at a record with valid outputs; another scene's checkpoint, another rank count, a missing checkpoint and an
integrator whose state cannot be saved are refused."""
import csv
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from mpi4py import MPI
from toml_text import dumps

from fabricfem import io as fio
from fabricfem import scenes as scene_module
from fabricfem.contact.seams import SeamSpec
from fabricfem.launch import child_environment
from fabricfem.materials import Fabric
from fabricfem.meshes.pattern import Panel, Pattern, Stitch
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.scenes.run import DynamicCheckpoint, run_scene
from fabricfem.scenes.schema import SceneError
from fabricfem.wear.checkpoint import Checkpoint
from fabricfem.wear.garment import ExplicitSettings, Timeline, TorqueSpec, build_garment_run
from fabricfem.wear.run import interrupt_flag

# a child fabricfem or mpirun must not inherit this process's MPI job (fabricfem.launch)
CHILD_ENV = child_environment()
COTTON = Fabric(E1=1.2e6, E2=1.2e6, G12=1e5, nu12=0.0, thickness=1e-3, density=436.0)


class Killed(Exception):
    """Stands for a SIGKILL: the run ends where it is, nothing is cleaned up."""


def _run(comm):
    """Two 0.1 m squares sewn in 0.05 s and falling onto a sphere under gravity with friction (contact, seams,
    stick points: the state a checkpoint must carry), 10 records."""
    from fabricfem.body.pose import Body, Segment

    class Still:
        names = ("p", "d", "m")
        time_range = (0.0, 0.0)

        def positions(self, t):
            return {"p": np.array([0.12, 0.05, -0.194]), "d": np.array([0.13, 0.05, -0.194]),
                    "m": np.array([0.125, 1.0, -0.194])}

    square = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    pattern = Pattern({"l": Panel("l", square), "r": Panel("r", square, translation=(0.15, 0.0, 0.0))},
                      [Stitch(("l", 1), ("r", 3))])
    garment = mesh_pattern(pattern, 0.05, comm=comm)
    seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
             for s in garment.stitches]
    ball = Body([Segment("ball", "p", "d", "m", (0.19, 0.19, 0.19)), Segment("cap", "d", "p", "m", (0.01, 0.01,
                                                                                                    0.01))], Still())
    return build_garment_run("ckpt", garment.fabric, COTTON, ball, seams=seams, friction=0.3,
                             torques=[TorqueSpec("t", "p", (0.0, 1.0, 0.0), ("ball",))],
                             timeline=Timeline(record_time=0.01, sewing_time=0.05, settle_time=0.05, motion_time=0.0),
                             settings=ExplicitSettings(gravity=(0.0, 0.0, -9.81)), measure_strain=False)


def _rows(history) -> np.ndarray:
    return np.array([[s.time, s.torques["t"], s.peak_pressure, s.contact_force, s.seam_gap, s.kinetic_energy]
                     for s in history.steps])


def _folder(comm) -> Path:
    return Path(comm.bcast(tempfile.mkdtemp() if comm.rank == 0 else None, root=0))


def _kill_and_resume(comm):
    whole = _rows(_run(comm).run())
    folder = _folder(comm)
    run = _run(comm)
    checkpoint = Checkpoint(folder, comm, "scene-hash", every=3)

    def kill_at_seven(step):
        if len(seen) == 6:
            raise Killed
        seen.append(step)
    seen = []
    with pytest.raises(Killed):
        run.run(on_step=kill_at_seven, checkpoint=checkpoint)
    resumed = _run(comm).run(checkpoint=Checkpoint(folder, comm, "scene-hash", every=3), resume=True)
    assert whole[-1, 3] > 0.0                                        # the squares touch the ball
    np.testing.assert_allclose(_rows(resumed), whole, rtol=1e-12, atol=1e-300)
    with pytest.raises(ValueError, match="another scene"):
        _run(comm).run(checkpoint=Checkpoint(folder, comm, "other-hash"), resume=True)


def test_killed_run_resumes_to_the_uninterrupted_history():
    """Killed after its 7th record (checkpoints every 3: the last one after record 6), rebuilt and resumed: every
    record (time, torque, peak pressure, contact force, seam gap, kinetic energy) equals the uninterrupted run's
    within 1e-12 relative (measured: identical; the resumed steps repeat the same arithmetic); a checkpoint of
    another scene's hash is refused."""
    _kill_and_resume(MPI.COMM_SELF)


@pytest.mark.mpi
def test_killed_run_resumes_on_two_ranks():
    """The same on 2 ranks (each rank keeps its own part of the state)."""
    _kill_and_resume(MPI.COMM_WORLD)


def test_interrupt_stops_at_a_record():
    """should_stop answering an interrupt after the 4th record ends the run there with the reason in `failure`;
    Ctrl-C or a kill (SIGTERM) inside interrupt_flag sets the flag instead of ending the process."""
    calls = []
    history = _run(MPI.COMM_SELF).run(should_stop=lambda: (calls.append(1), "interrupted (SIGINT)" if len(calls) == 4
                                                           else "")[1])
    assert len(history.steps) == 4 and history.failure.startswith("interrupted (SIGINT)")
    with interrupt_flag(MPI.COMM_SELF) as interrupted:
        assert interrupted() == ""
        os.kill(os.getpid(), signal.SIGINT)
        assert interrupted() == "interrupted (SIGINT)"
    with interrupt_flag(MPI.COMM_SELF) as interrupted:         # a kill (SIGTERM) stops the run the same way
        os.kill(os.getpid(), signal.SIGTERM)
        assert interrupted() == "interrupted (SIGTERM)"
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL   # and the handlers are given back


SQUARES = """stitches = [["l", 1, "r", 3]]
[panels.l]
vertices = [[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]]
[panels.r]
vertices = [[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]]
translation = [0.15, 0.0, 0.0]
"""
SCENE = """[scene]
name = "squares"
kind = "wear"
[garment]
pattern = "squares.toml"
h = 0.05
sewing_time = 0.05
[fabric]
E1 = 1.2e6
E2 = 1.2e6
G12 = 1e5
nu12 = 0.0
thickness = 1e-3
density = 436.0
[body]
type = "limb"
center = [0.125, 0.05, -0.2]
radii = [0.3, 0.195, 0.195]
[motion]
type = "still"
duration = 0.4
record_time = 0.01
[contact]
friction = 0.3
[checks]
max_kinetic_ratio = 1e4     # two squares dropped onto a ball (KE / SE 964): a falling cloth, not a worn garment
[output]
render = false
"""


def test_sigint_then_resume_from_the_command_line(tmp_path):
    """`fabricfem run` of a small wear scene interrupted by SIGINT: it exits 1 saying so, torque.csv holds the
    records up to the interrupt and cloth.xdmf opens (meshio) with as many steps; `fabricfem run --resume` then
    completes the run, and its torque.csv equals an uninterrupted run's to 1e-12."""
    (tmp_path / "squares.toml").write_text(SQUARES)
    (tmp_path / "scene.toml").write_text(SCENE)
    command = [sys.executable, "-m", "fabricfem.cli", "run", str(tmp_path / "scene.toml")]
    whole = tmp_path / "whole"
    assert subprocess.run(command + ["--out", str(whole)], capture_output=True, env=CHILD_ENV).returncode == 0
    part = tmp_path / "part"
    process = subprocess.Popen(command + ["--out", str(part)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=CHILD_ENV)
    for line in process.stdout:          # wait for a few records, then Ctrl-C
        if line.strip().startswith("motion"):
            process.send_signal(signal.SIGINT)
            break
    out, err = process.communicate(timeout=300)
    assert process.returncode == 1 and "interrupted (SIGINT)" in err, err
    rows = list(csv.reader(open(part / "torque.csv")))[1:]
    assert 0 < len(rows) < 45
    with meshio.xdmf.TimeSeriesReader(part / "cloth.xdmf") as reader:
        reader.read_points_cells()
        assert reader.num_steps == len(rows)
    resumed = subprocess.run(command + ["--out", str(part), "--resume"], capture_output=True, text=True,
                             env=CHILD_ENV)
    assert resumed.returncode == 0, (resumed.returncode, resumed.stdout[-3000:], resumed.stderr)
    def table(folder):
        rows = list(csv.DictReader(open(folder / "torque.csv")))
        keys = [k for k in rows[0] if k not in ("phase", "peak_segment", "wall_s")]
        return np.array([[float(r[k]) for k in keys] for r in rows])
    np.testing.assert_allclose(table(part), table(whole), rtol=1e-12, atol=1e-300)
    # the resumed run's summary lists every file of the run, those written before the interrupt too
    listed = {folder: set(json.loads((folder / "summary.json").read_text())["outputs"]) for folder in (part, whole)}
    assert listed[part] >= listed[whole] - {"checkpoint"}, listed[whole] - listed[part]


# ------------------------------------------------------------------------------------------- dynamic scenes
ROOT = Path(__file__).resolve().parents[1]


def _corner_pinned(folder: Path, n: int = 6, end_time: float = 0.6) -> Path:
    """scenes/corner_pinned.toml on an n x n mesh to `end_time` [s] (strain limit on: its projection's log is
    part of the state), a record every 2 steps, a checkpoint every 5 records; returns the scene file."""
    data = tomllib.loads((ROOT / "scenes" / "corner_pinned.toml").read_text())
    data["mesh"].update(nx=n, ny=n)
    data["dynamics"].update(end_time=end_time, output_every=2, checkpoint_every=5)
    data["output"] = {"dir": str(folder / "out"), "render": False}
    path = folder / "corner.toml"
    path.write_text(dumps(data))
    return path


def _table(folder: Path) -> np.ndarray:
    rows = list(csv.DictReader(open(folder / "corner-pinned.csv")))
    return np.array([[float(v) for v in r.values()] for r in rows])


def _relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    assert a.shape == b.shape, (a.shape, b.shape)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def _xdmf_steps(folder: Path) -> list[float]:
    """The times of corner-pinned.xdmf (meshio) after checking that h5py opens its HDF5 file."""
    with h5py.File(folder / "corner-pinned.h5", "r") as f:
        assert "Function" in f
    with meshio.xdmf.TimeSeriesReader(folder / "corner-pinned.xdmf") as reader:
        reader.read_points_cells()
        return [reader.read_data(k)[0] for k in range(reader.num_steps)]


def _kill_and_resume_scene(tmp_path: Path, launcher: list[str]) -> float:
    """Run the small corner-pinned scene whole, then again killed by SIGKILL (the whole process group: mpirun and
    its ranks) once half its steps are done and a checkpoint exists, then with --resume; returns the largest
    relative difference of the resumed CSV from the whole one."""
    scene = _corner_pinned(tmp_path)
    command = launcher + [sys.executable, "-m", "fabricfem.cli", "run", str(scene)] + \
        (["--all-ranks"] if launcher else []) + ["--out"]     # a small scene would run on rank 0 alone
    whole, part = tmp_path / "whole", tmp_path / "part"
    done = subprocess.run(command + [str(whole)], capture_output=True, text=True, env=CHILD_ENV)
    assert done.returncode == 0, done.stderr
    process = subprocess.Popen(command + [str(part)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               env=CHILD_ENV, start_new_session=True)
    killed = ""
    for line in process.stdout:      # progress lines "step k/n t = ... [50.1%, ...]" every tenth of the run
        if "%" in line and float(line.split("[")[1].split("%")[0]) >= 50.0 and \
                (part / "checkpoint" / "rank0.pkl").exists():
            os.killpg(process.pid, signal.SIGKILL)
            killed = line
            break
    process.wait(timeout=120)
    assert killed and process.returncode == -signal.SIGKILL, "the run ended before it was killed"
    assert (part / "checkpoint" / "rank0.pkl").exists()
    resumed = subprocess.run(command + [str(part), "--resume"], capture_output=True, text=True, env=CHILD_ENV)
    assert resumed.returncode == 0, resumed.stderr
    assert "resumed at t = " in resumed.stdout
    table = _table(part)
    assert np.allclose(_xdmf_steps(part), table[:, 0], rtol=1e-12, atol=0.0)
    return _relative_difference(table, _table(whole))


def test_killed_dynamic_scene_resumes_to_the_uninterrupted_history(tmp_path):
    """`fabricfem run` of a small corner-pinned cloth (explicit, strain limit, air drag; 6 x 6 Q2 membrane, 123
    steps, 63 records, a checkpoint every 5) killed by SIGKILL half-way (after record 31, last checkpoint at 30),
    then `--resume`: every CSV column (time, energies, monitors, strains, Newton iterations) equals the
    uninterrupted run's within 1e-12 relative (measured: identical, max relative difference 0), and the XDMF
    opens (h5py, meshio) with a step per CSV row at its times."""
    assert _kill_and_resume_scene(tmp_path, []) <= 1e-12


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="needs mpirun")
def test_killed_dynamic_scene_resumes_on_two_ranks(tmp_path):
    """The same with `mpirun -n 2` for the three runs (each rank restores its own part of the state; measured:
    identical)."""
    assert _kill_and_resume_scene(tmp_path, ["mpirun", "-n", "2"]) <= 1e-12


def test_sigint_stops_a_dynamic_scene_with_valid_outputs(tmp_path):
    """Ctrl-C (SIGINT) half-way: exit code 1 saying "interrupted (SIGINT)", the CSV ends at the last record
    (fewer rows than the whole run's, the same values), the XDMF opens with h5py and meshio with one step per CSV
    row ending at its last time, summary.json says "stopped early"; `--resume` completes the whole history."""
    scene = _corner_pinned(tmp_path)
    command = [sys.executable, "-m", "fabricfem.cli", "run", str(scene), "--out"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert subprocess.run(command + [str(whole)], capture_output=True, env=CHILD_ENV).returncode == 0
    process = subprocess.Popen(command + [str(part)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=CHILD_ENV)
    for line in process.stdout:
        if "%" in line and float(line.split("[")[1].split("%")[0]) >= 30.0:
            process.send_signal(signal.SIGINT)
            break
    out, err = process.communicate(timeout=120)
    assert process.returncode == 1 and "interrupted (SIGINT)" in err, err
    table, full = _table(part), _table(whole)
    assert 0 < len(table) < len(full)
    assert _relative_difference(table, full[:len(table)]) <= 1e-12
    assert _xdmf_steps(part) == pytest.approx(list(table[:, 0]), rel=1e-12)
    assert "stopped early: interrupted (SIGINT)" in (part / "summary.json").read_text()
    resumed = subprocess.run(command + [str(part), "--resume"], capture_output=True, text=True, env=CHILD_ENV)
    assert resumed.returncode == 0, resumed.stderr
    assert _relative_difference(_table(part), full) <= 1e-12
    assert _xdmf_steps(part) == pytest.approx(list(full[:, 0]), rel=1e-12)


class _Killed(Exception):
    """Stands for a kill inside the run (after a checkpoint): nothing is cleaned up."""


def _killed_after(monkeypatch, records: int):
    """Make DynamicCheckpoint.after_record raise _Killed after the record `records` (and its checkpoint)."""
    original = DynamicCheckpoint.after_record

    def after_record(self, history):
        original(self, history)
        if len(history.time) - 1 == records:
            raise _Killed
    monkeypatch.setattr(DynamicCheckpoint, "after_record", after_record)


def test_newmark_scene_resumes_and_bad_resumes_are_refused(tmp_path, monkeypatch):
    """scenes/cantilever_vibration.toml (implicit Newmark, consistent mass, Rayleigh damping b > 0: the frozen
    damping state is part of the checkpoint) to 16 steps, stopped inside the run after record 12 (checkpoint
    at 10), resumed: the history equals the uninterrupted one within 1e-12 (measured: identical). Refused with a
    message naming it: --resume without a checkpoint, of a changed scene (hash), of another rank count (the
    killed run's checkpoint file as written by 2 ranks), and of the generalized-alpha integrator (PETSc TS)."""
    data = tomllib.loads((ROOT / "scenes" / "cantilever_vibration.toml").read_text())
    data["dynamics"].update(end_time=16 * data["dynamics"]["dt"], checkpoint_every=5, rayleigh=[0.0, 1e-3])
    comm = MPI.COMM_SELF

    def scene(out, **dynamics):
        changed = {**data, "dynamics": {**data["dynamics"], **dynamics}, "output": {"dir": str(out), "render": False}}
        return scene_module.Scene(changed, None, "dynamic")

    whole = run_scene(scene(tmp_path / "whole"), comm).result.history
    with pytest.raises(SceneError, match="no checkpoint in"):
        run_scene(scene(tmp_path / "part"), comm, resume=True)
    _killed_after(monkeypatch, 12)
    with pytest.raises(_Killed):
        run_scene(scene(tmp_path / "part"), comm)
    monkeypatch.undo()
    with pytest.raises(SceneError, match="another scene"):
        run_scene(scene(tmp_path / "part", air_drag=0.01), comm, resume=True)
    files = fio.Checkpoint(tmp_path / "part", comm, "")       # the checkpoint file of the killed run, as 2 ranks'
    saved = files.path.read_bytes()
    files.path.write_bytes(pickle.dumps({**pickle.loads(saved), "ranks": 2}))
    with pytest.raises(SceneError, match=r"written by 2 rank\(s\)"):
        run_scene(scene(tmp_path / "part"), comm, resume=True)
    files.path.write_bytes(saved)
    resumed = run_scene(scene(tmp_path / "part"), comm, resume=True).result.history
    assert len(resumed.time) == len(whole.time) == 17
    assert _relative_difference(np.array(resumed.columns()[1]), np.array(whole.columns()[1])) <= 1e-12
    assert resumed.newton_iterations == whole.newton_iterations
    again = run_scene(scene(tmp_path / "part"), comm, resume=True)     # complete: nothing to resume, nothing run
    assert again.result is None and again.status.startswith("completed")
    with pytest.raises(SceneError, match="GeneralizedAlphaIntegrator integrator cannot resume"):
        run_scene(scene(tmp_path / "part", integrator="generalized-alpha"), comm, resume=True)


@pytest.mark.mpi
def test_a_kill_between_the_ranks_renames_resumes_from_the_common_record(tmp_path_factory):
    """io.Checkpoint: after two checkpoints, rank 0 alone gets a third (a kill after its rename, before the
    others'): every rank reads the second, the newest all ranks hold; one rank alone reads its newest."""
    comm = MPI.COMM_WORLD
    folder = comm.bcast(str(tmp_path_factory.mktemp("ckpt")) if comm.rank == 0 else None, root=0)
    files = fio.Checkpoint(folder, comm, "sha", every=1)
    for record in (1, 2):
        files.write({"record": record})
    if comm.rank == 0:                 # rank 0 one generation ahead, as a kill between the renames leaves it
        os.replace(files.path, files.previous)
        with open(files.path, "wb") as f:
            pickle.dump({"record": 3, "sha": "sha", "ranks": comm.size, "generation": 3}, f)
    comm.barrier()
    state = fio.Checkpoint(folder, comm, "sha", every=1).read()
    assert state["record"] == (2 if comm.size > 1 else 3)
