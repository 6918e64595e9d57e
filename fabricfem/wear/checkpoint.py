"""Checkpoints of a garment run (fabricfem.wear.garment.GarmentRun): kill it, resume it, get the same history.

Every `every` records each rank writes `<folder>/checkpoint/rank<r>.pkl`: the `state()` of every stateful part of the
run, the part it owns (the integrator's: d, v, a, t, the step counts, work and dissipation,
fabricfem.dynamics.newmark.TimeIntegrator.state; the body contact's: its stick points; each handle's: a grip's
anchors; the cloth self-contact's: its Verlet list and impact-zone counts, fabricfem.contact.self_contact), the
adaptive step (GarmentRun.step_state: the last record's largest strain and the steps per record in use, which
set dt), the run's records so far (the same on every rank), the recorder's state (rank 0: the body frames and the
kept skin frames; beside them copies of the XDMF files as they were, xdmf_<records>_cloth.xdmf/.h5 and
xdmf_<records>_cloth_pressure.xdmf/.h5, put back on resume and appended to) and the scene's SHA-256. A file is
written to a temporary name and renamed, so a kill leaves the previous checkpoint whole. `load` gives each part its state back (`restore`) in a run built from the same scene on
the same number of ranks; a checkpoint of another scene (another hash), another rank count or an older layout is
refused with a message naming it. The central-difference step from a restored state is the step from the saved one
(the same arithmetic on the same numbers), so a resumed run gives the records of an uninterrupted run exactly. The
files, their atomic writes and the checks are those of fabricfem.io.Checkpoint (shared with the dynamic scenes,
fabricfem.scenes.run).
"""
from __future__ import annotations

import time

from fabricfem import io

PARTS = ("integrator", "contact", "handles", "steps", "self_contact")   # the run's parts besides its records


class Checkpoint(io.Checkpoint):
    """The checkpoint files of one garment run under `folder` (module docstring); `every` [records] between
    writes."""

    def save(self, run, history, records: int, recorder=None) -> None:
        """Write the state after `records` record intervals (all ranks); the recorder's copies of its XDMF files
        (xdmf_<records>_*) replace those of the previous checkpoint once the state is written. `seconds` [s]
        sums the wall time of the saves."""
        tic = time.perf_counter()
        tag = f"xdmf_{records}"
        self.write({"records": records, "history": history, "integrator": run.integrator.state(),
                    "contact": run.contact.state(), "handles": [handle.state() for handle in run.handles],
                    "steps": run.step_state(),
                    "self_contact": cloth.state() if (cloth := getattr(run, "self_contact", None)) else None,
                    "recorder": recorder.state(self.folder, tag) if recorder is not None else None})
        if self.comm.rank == 0:
            for old in self.folder.glob("xdmf_*"):
                if not old.name.startswith(f"{tag}_"):
                    old.unlink()
        self.seconds = getattr(self, "seconds", 0.0) + time.perf_counter() - tic

    def load(self, run, recorder=None):
        """Restore the saved state into `run` (and `recorder`); returns (history, records done)."""
        state = self.read()
        missing = [part for part in PARTS if part not in state]
        if missing:
            raise ValueError(f"resume: the checkpoint in {self.folder} has an older layout (no {', '.join(missing)}); "
                             f"run the scene without --resume")
        if len(state["handles"]) != len(run.handles):
            raise ValueError(f"resume: the checkpoint in {self.folder} holds {len(state['handles'])} handle(s), this "
                             f"run has {len(run.handles)}")
        run.integrator.restore(state["integrator"])
        run.contact.restore(state["contact"])
        run.restore_steps(state["steps"])
        cloth = getattr(run, "self_contact", None)
        if (cloth is None) != (state["self_contact"] is None):
            raise ValueError(f"resume: the checkpoint in {self.folder} was written "
                             f"{'with' if cloth is None else 'without'} cloth self-contact, this run has "
                             f"{'none' if cloth is None else 'it'}")
        if cloth is not None:
            cloth.restore(state["self_contact"])
        for handle, saved in zip(run.handles, state["handles"]):
            handle.restore(saved)
        if recorder is not None and state["recorder"] is not None:
            if "series" not in state["recorder"]:
                raise ValueError(f"resume: the checkpoint in {self.folder} has an older layout (no copies of the XDMF "
                                 f"files); run the scene without --resume")
            recorder.restore(state["recorder"], self.folder)
        return state["history"], state["records"]

