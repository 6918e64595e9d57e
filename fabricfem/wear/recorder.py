"""The recorder of a wear run: what `fabricfem run` writes while a garment moves on its wearer.

Under the output folder: cloth.xdmf (garment displacement [m]) and cloth_pressure.xdmf (contact pressure on the
body [Pa] per unit deformed cloth area) per record, for ParaView and meshio (the XDMF time is the body time [s],
or the angle [deg] of a quasi-static sleeve; a resumed run appends to the files of its checkpoint, so that each
holds every record once), body_NNNN.vtp + body.pvd
(the posed body surfaces per record), torque.csv (the history's header), torque.png (the torques against the body
time with the phases and the summary's records marked, fabricfem.wear.outputs.plot_wear_history), torque.sto (OpenSim
storage of the torques against the body time, with the motion's own time and OpenSim coordinate names,
fabricfem.wear.outputs.STO_NOTE), renders of the pressure on the skin at the requested
coordinates and at the record of the largest pressure of the motion (pressure_peak.png). It reads the
run only through the wearer contract (fabricfem.wear.contract.WearRun).

The time loop pays only for copies: the XDMF records are kept in memory and written in bulk and the body frames
written by a writer thread (fabricfem.wear.writer; every FLUSH_EVERY records, at a checkpoint and at `close`);
the pressure on the skin of the peak record is computed when the frame is final (the next render, a checkpoint,
`close`), not at every new peak. `seconds` [s] is the wall time spent in `record`.
"""
from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
from dolfinx import fem

from fabricfem import io as fio
from fabricfem.wear.outputs import (
    STO_NOTE,
    body_surface,
    plot_wear_history,
    render_skin_pressure,
    skin_pressure,
    wear_sto_columns,
    write_sto,
)
from fabricfem.wear.skin_records import SkinPressureRecords
from fabricfem.wear.writer import BackgroundWriter, BodyFrames, FieldSeries

COLOUR_PERCENTILE = 99.0   # the renders' colour range ends at this percentile of the pressures in contact


def colour_top(frames: list[np.ndarray]) -> tuple[float, float]:
    """(the COLOUR_PERCENTILE-th percentile of the positive skin pressures over `frames`, their largest) [Pa]: one
    outlier record does not darken every frame; the true maximum is stated beside the colour bar."""
    values = np.concatenate([np.asarray(f, dtype=float).ravel() for f in frames]) if frames else np.zeros(0)
    positive = values[values > 0.0]
    if not len(positive):
        return 0.0, 0.0
    return float(np.percentile(positive, COLOUR_PERCENTILE)), float(positive.max())


class WearRecorder:
    """Writes the records of one WearRun into `out` (all ranks construct it and call `record` and `close`);
    `render_at`: record coordinates of the pressure renders."""

    def __init__(self, run, out: Path, render_at: list[float], render: bool = True, body_samples: int = 24):
        self.run, self.out = run, Path(out)
        self.render, self.samples = render, body_samples
        self.pending = sorted(render_at)
        comm = run.comm
        if comm.rank == 0:
            self.out.mkdir(parents=True, exist_ok=True)
        comm.barrier()
        model = run.model
        self.u_out = fem.Function(model.V2, name="displacement")
        self.p_out = fem.Function(fem.FunctionSpace(model.mesh, ("Lagrange", 2)), name="contact_pressure")
        # one field per file (meshio's XDMF reader keeps one function per time step): file stem -> its function;
        # a resumed run puts back the files' copies of its checkpoint and appends to them (`restore`)
        self.fields = {"cloth": self.u_out, "cloth_pressure": self.p_out}
        self.writer = BackgroundWriter() if comm.rank == 0 else None
        self.files = {name: self._open(name, "w") for name in self.fields}
        self.bodies = BodyFrames()       # the body frames' files, written on the writer thread
        self.peak_frame: tuple | None = None   # (step, displacement, pressure) of a new peak, kept when final
        self.seconds = 0.0               # s, wall time in `record`
        self.frames: list[tuple[float, str]] = []
        self.renders: list[str] = []     # names of the pressure renders written
        self.skin_frames: list = []      # (name, title, (points, triangles, values [Pa]), garment surface), rank 0
        self.peak = 0.0                  # Pa, the largest peak pressure of the motion's records so far
        self.label = run.axis_label
        self.skin_records = SkinPressureRecords.of(run, self.out)   # a mesh skin's pressure per record
        self.unit = "deg" if "[deg]" in self.label else "s"

    def record(self, step) -> None:
        """Keep the record of `step` for the files (its coordinate is the time coordinate of the files)."""
        tic = time.perf_counter()
        run, x, stamp = self.run, step.coordinate, step.output_time
        displacement, pressure = run.model.displacement(), run.pressure_field()
        self.u_out.interpolate(displacement)
        self.p_out.interpolate(pressure)
        for series in self.files.values():
            series.add(stamp)
        if run.comm.rank == 0:
            name = f"body_{len(self.frames):04d}.vtp"   # frame k of record k, also after a resume
            (points, triangles), path = body_surface(run.posed_bodies(x), self.samples), self.out / name
            self.writer.submit(lambda: self.bodies.write(path, points, triangles))
            self.frames.append((stamp, name))
        while self.render and self.pending and x >= self.pending[0] - 1e-9:
            at = self.pending.pop(0)
            self._keep_peak_frame()
            self._keep_skin_frame(step, f"pressure_{at:05.2f}{self.unit}.png")
        peak = step.peak_pressure
        if self.render and step.phase == "motion" and peak > self.peak:
            # the peak pressure map: the skin at the record of the largest pressure of the motion so far (the
            # state kept here, its skin pressure computed once no later record replaces it)
            self.peak = peak
            self.peak_frame = (step, self._copy(displacement, self.peak_frame, 1),
                               self._copy(pressure, self.peak_frame, 2))
        if self.skin_records is not None:
            self.skin_records.record()
        self.seconds += time.perf_counter() - tic

    @staticmethod
    def _copy(function: fem.Function, previous: tuple | None, k: int) -> fem.Function:
        """A copy of `function` (into previous[k], the copy of an earlier peak, when there is one)."""
        copy = previous[k] if previous is not None else fem.Function(function.function_space)
        copy.x.array[:] = function.x.array
        return copy

    def _keep_peak_frame(self) -> None:
        """The skin frame of the kept peak record (pressure_peak.png), replacing the earlier one (all ranks)."""
        if self.peak_frame is None:
            return
        step, displacement, pressure = self.peak_frame
        self.peak_frame = None
        self.skin_frames = [f for f in self.skin_frames if f[0] != "pressure_peak.png"]
        self._keep_skin_frame(step, "pressure_peak.png", displacement, pressure)

    def _open(self, name: str, mode: str) -> FieldSeries:
        """The XDMF series <out>/<name>.xdmf ("w": new, with the mesh; "a": appended to), written in bulk."""
        return FieldSeries(self.out / f"{name}.xdmf", self.fields[name], mode, self.writer)

    def _flush(self) -> None:
        """Every kept record on disk (all ranks): the XDMF series flushed and the writer thread waited for."""
        for series in self.files.values():
            series.flush()
        if self.writer is not None:
            self.writer.wait()

    def state(self, folder: Path, tag: str) -> dict:
        """What a checkpoint keeps of the recorder (all ranks call it): the body frames, the skin frames kept for
        the renders, and copies of the XDMF files as they are now, <folder>/<tag>_<file stem>.xdmf/.h5 (the kept
        records written first; the files are closed between the bulk writes)."""
        self._keep_peak_frame()
        self._flush()
        for name in self.fields:
            fio.copy_xdmf(self.out / f"{name}.xdmf", folder, f"{tag}_{name}", self.run.comm)
        return {"frames": list(self.frames), "skin_frames": [tuple(f) for f in self.skin_frames],
                "pending": list(self.pending),
                "peak": self.peak, "series": tag}

    def restore(self, state: dict, folder: Path) -> None:
        """Continue from a checkpoint's `state` in `folder`: its copies of the XDMF files put back in place (the
        records up to the checkpoint; those after it are written again, once) and appended to from here on."""
        self.frames, self.skin_frames, self.pending = state["frames"], state["skin_frames"], state["pending"]
        self.peak, self.peak_frame = state["peak"], None
        self._flush()
        for name in self.fields:
            fio.SurfaceSeries.restore(self.out / f"{name}.xdmf", folder, f"{state['series']}_{name}", self.run.comm)
            self.files[name] = self._open(name, "a")

    def _keep_skin_frame(self, step, name: str, displacement: fem.Function | None = None,
                         pressure: fem.Function | None = None) -> None:
        """The pressure on the body's skin at record `step` (rank 0 keeps it; rendered at `close` with one colour
        range across the frames): the garment's nodal pressure [Pa] spread onto the skin within two node
        spacings (wear.outputs.skin_pressure); `displacement` [m] and `pressure` [Pa]: the garment's at that
        record (default: now). The skin pressure is computed on the writer thread (the frame's entry is whole
        after `_flush`)."""
        run = self.run
        displacement = run.model.displacement() if displacement is None else displacement
        surface = fio.gather_surface(run.model.mesh, displacement)
        values = fio.gather_field(run.model.mesh, run.pressure_field() if pressure is None else pressure)
        if run.comm.rank != 0:
            return
        points, cells = surface
        bodies, samples = run.posed_bodies(step.coordinate), 2 * self.samples
        what = self.label.split(" [")[0]
        title = f"{run.name}: {what} {step.coordinate:.2f} {self.unit}, pressure on the skin"
        entry = [name, title, None, (points, cells)]
        self.skin_frames.append(entry)

        def spread() -> None:
            spacing = float(np.median(np.linalg.norm(points[cells[:, 0]] - points[cells[:, 1]], axis=1)))
            entry[2] = skin_pressure(bodies, samples, points, values, 2.0 * max(spacing, 1e-6))
        self.writer.submit(spread)

    def close(self, history) -> None:
        """Write the kept records (XDMF files, body frames) and torque.csv, body.pvd, torque.sto, torque.png and
        the renders; end the writer thread."""
        if self.skin_records is not None:
            self.skin_records.close()
        self._keep_peak_frame()
        self._flush()
        if self.writer is not None:
            self.writer.close()
        comm = self.run.comm
        fio.write_csv(self.out / "torque.csv", history.header, history.rows(), comm)
        if comm.rank == 0:
            with open(self.out / "body.pvd", "w") as f:
                f.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n<Collection>\n')
                f.writelines(f'  <DataSet timestep="{x}" file="{name}"/>\n' for x, name in self.frames)
                f.write("</Collection>\n</VTKFile>\n")
        times = [self.run.body_time(s) for s in history.steps]
        write_sto(self.out / "torque.sto", times,
                  wear_sto_columns(history.steps, self.run.torques, [self.run.motion_time(t) for t in times]),
                  comm, STO_NOTE)
        self._render_skin_frames(comm)
        plot_wear_history(self.out / "torque.png", history, self.label, f"{history.name}: resisting torque")
        comm.barrier()                         # every rank's renders are on disk when the run returns

    def _render_skin_frames(self, comm) -> None:
        """The skin pressure renders (rank 0's frames, one colour range for all), shared among the ranks: the k-th
        distinct frame on rank (k + 1) % size, so that rank 0, which also plots the torque, takes fewer; a frame
        equal to an earlier one (the peak at a requested coordinate) is a copy of its file, made by the same rank."""
        frames = comm.bcast(self.skin_frames if comm.rank == 0 else None, root=0) if comm.size > 1 \
            else self.skin_frames
        if not frames:
            return
        top, true_max = colour_top([skin[2] for _, _, skin, _ in frames])
        note = (f" (colours to the {COLOUR_PERCENTILE:g}th percentile {top / 1e3:.3g} kPa; "
                f"largest {true_max / 1e3:.3g} kPa)")
        first = _first_equal(frames)
        distinct = sorted(set(first))
        for i, (name, title, (points, triangles, values), garment) in enumerate(frames):
            if (distinct.index(first[i]) + 1) % comm.size == comm.rank:
                if first[i] == i:
                    render_skin_pressure(self.out / name, points, triangles, values / 1e3, title + note,
                                         (0.0, max(top / 1e3, 1e-9)), garment)
                else:
                    shutil.copyfile(self.out / frames[first[i]][0], self.out / name)
            if comm.rank == 0:
                self.renders.append(name)


def _first_equal(frames: list) -> list[int]:
    """For each skin frame (name, title, (points, triangles, values), (garment points, cells)), the index of the
    first frame with the same title and arrays (itself when none before it is equal)."""
    def same(a, b) -> bool:
        arrays = (*a[2], *a[3]), (*b[2], *b[3])
        return a[1] == b[1] and all(np.array_equal(x, y) for x, y in zip(*arrays))
    return [next(j for j in range(i + 1) if same(frames[j], frames[i])) for i in range(len(frames))]
