"""Checkpoints of a garment run (fabricfem.wear.garment.GarmentRun): kill it, resume it, get the same history.

Every `every` records each rank writes `<folder>/checkpoint/rank<r>.pkl`: the explicit state it owns (the
integrator's d, v, a and time and step count; the body contact's stick points; the grips' anchors), the run's
records so far (the same on every rank), the recorder's state (rank 0: the body frames and the kept skin frames)
and the scene's SHA-256. A file is written to a temporary name and renamed, so a kill leaves the previous
checkpoint whole. `load` restores a run built from the same scene on the same number of ranks; a checkpoint of
another scene (another hash) or another rank count is refused with a message naming it. The central-difference
step from a restored state is the step from the saved one (the same arithmetic on the same numbers), so a
resumed run gives the records of an uninterrupted run exactly. The files, their atomic writes and the checks
are those of fabricfem.io.Checkpoint (shared with the dynamic scenes, fabricfem.scenes.run).
"""
from __future__ import annotations

import numpy as np

from fabricfem import io


class Checkpoint(io.Checkpoint):
    """The checkpoint files of one garment run under `folder` (module docstring); `every` [records] between
    writes."""

    def save(self, run, history, records: int, recorder=None) -> None:
        """Write the state after `records` record intervals (all ranks)."""
        integ, contact = run.integrator, run.contact
        self.write({"records": records, "history": history,
                    "d": integ.d.getArray(readonly=True).copy(), "v": integ.v.getArray(readonly=True).copy(),
                    "a": integ.a.getArray(readonly=True).copy(), "t": integ.t, "step_count": integ.step_count,
                    "stick_local": contact._stick_local.copy(), "stick_segment": contact._stick_segment.copy(),
                    "anchors": [getattr(h, "_anchor", None) for h in run.handles],
                    "recorder": recorder.state() if recorder is not None else None})

    def load(self, run, recorder=None):
        """Restore the saved state into `run` (and `recorder`); returns (history, records done)."""
        state = self.read()
        integ, contact = run.integrator, run.contact
        for name in ("d", "v", "a"):
            target = getattr(integ, name).getArray()
            if target.shape != state[name].shape:
                raise ValueError(f"resume: the checkpoint's state does not fit this run's mesh ({name})")
            target[:] = state[name]
        integ.t, integ.step_count = state["t"], state["step_count"]
        contact._stick_local[:] = state["stick_local"]
        contact._stick_segment[:] = state["stick_segment"]
        for handle, anchor in zip(run.handles, state["anchors"]):
            if anchor is not None:
                handle._anchor = np.asarray(anchor)
        if recorder is not None and state["recorder"] is not None:
            recorder.restore(state["recorder"])
        return state["history"], state["records"]
