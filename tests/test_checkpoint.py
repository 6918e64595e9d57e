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
