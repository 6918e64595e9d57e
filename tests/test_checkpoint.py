"""Checkpoints of a garment run (fabricfem.wear.checkpoint): a run killed after a checkpoint and resumed gives the
records of an uninterrupted run; Ctrl-C stops at a record with valid outputs; another scene's checkpoint is
refused."""
import os
import signal
import tempfile
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.contact.seams import SeamSpec
from fabricfem.materials import Fabric
from fabricfem.meshes.pattern import Panel, Pattern, Stitch
from fabricfem.meshes.pattern_mesh import mesh_pattern
from fabricfem.wear.checkpoint import Checkpoint
from fabricfem.wear.garment import ExplicitSettings, Timeline, TorqueSpec, build_garment_run
from fabricfem.wear.run import interrupt_flag

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
    Ctrl-C inside interrupt_flag sets the flag instead of raising."""
    calls = []
    history = _run(MPI.COMM_SELF).run(should_stop=lambda: (calls.append(1), "interrupted (SIGINT)" if len(calls) == 4
                                                           else "")[1])
    assert len(history.steps) == 4 and history.failure.startswith("interrupted (SIGINT)")
    with interrupt_flag(MPI.COMM_SELF) as interrupted:
        assert interrupted() == ""
        os.kill(os.getpid(), signal.SIGINT)
        assert interrupted() == "interrupted (SIGINT)"


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
[output]
render = false
"""


def test_sigint_then_resume_from_the_command_line(tmp_path):
    """`fabricfem run` of a small wear scene interrupted by SIGINT: it exits 1 saying so, torque.csv holds the
    records up to the interrupt and cloth.xdmf opens (meshio) with as many steps; `fabricfem run --resume` then
    completes the run, and its torque.csv equals an uninterrupted run's to 1e-12."""
    import csv
    import subprocess
    import sys

    import meshio
    (tmp_path / "squares.toml").write_text(SQUARES)
    (tmp_path / "scene.toml").write_text(SCENE)
    command = [sys.executable, "-m", "fabricfem.cli", "run", str(tmp_path / "scene.toml")]
    whole = tmp_path / "whole"
    assert subprocess.run(command + ["--out", str(whole)], capture_output=True).returncode == 0
    part = tmp_path / "part"
    process = subprocess.Popen(command + ["--out", str(part)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
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
    resumed = subprocess.run(command + ["--out", str(part), "--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    def table(folder):
        rows = list(csv.DictReader(open(folder / "torque.csv")))
        keys = [k for k in rows[0] if k not in ("phase", "peak_segment", "wall_s")]
        return np.array([[float(r[k]) for k in keys] for r in rows])
    np.testing.assert_allclose(table(part), table(whole), rtol=1e-12, atol=1e-300)
