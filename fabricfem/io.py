"""Outputs: XDMF time series (ParaView), CSV tables and off-screen PNG renders (fabricfem.render; pyvista for
render_surfaces).

Everything here is parallel-correct: XDMF is written collectively, renders gather the
owned cells to rank 0.
"""
from __future__ import annotations

import csv
import datetime
import json
import math
import os
import pickle
import resource
import shutil
import time
import weakref
from pathlib import Path
from typing import Iterable, Mapping, Sequence
from xml.etree import ElementTree

import numpy as np
from dolfinx import fem, io
from mpi4py import MPI

from fabricfem.render import Layer, render_layers, save_with_colour_bar


class SurfaceSeries:
    """Displacement (and optional scalar fields) of a shell over time in one XDMF file.

    dolfinx 0.5 writes functions of the mesh's own (P1) degree, so fields are interpolated to P1.
    append=True continues an existing file of the same mesh and rank count (a resumed run, see `snapshot`).
    """

    def __init__(self, path: str | Path, mesh, append: bool = False):
        self.path = Path(path)
        if mesh.comm.rank == 0:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        mesh.comm.barrier()
        self.mesh = mesh
        self.V1 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=3)
        self.u1 = fem.Function(self.V1, name="displacement")
        self.file = io.XDMFFile(mesh.comm, str(self.path), "a" if append else "w")
        if not append:
            self.file.write_mesh(mesh)

    def write(self, displacement: fem.Function, time: float):
        self.u1.interpolate(displacement)
        self.file.write_function(self.u1, time)

    def snapshot(self, folder: Path, tag: str) -> list[str]:
        """Close the file (the HDF5 file is complete on disk), copy the .xdmf and .h5 into `folder` as
        <tag>.xdmf and <tag>.h5 (rank 0), reopen it for appending; returns the copies' names. A run killed later
        may leave a broken HDF5 file: the copy is the series up to now (`restore`)."""
        comm = self.mesh.comm
        self.file.close()
        names = copy_xdmf(self.path, folder, tag, comm)
        self.file = io.XDMFFile(comm, str(self.path), "a")
        return names

    @staticmethod
    def restore(path: str | Path, folder: Path, tag: str, comm=MPI.COMM_WORLD) -> None:
        """Put the `snapshot` <tag>.xdmf/.h5 of `folder` back as `path` (.xdmf) and its .h5 (rank 0)."""
        path = Path(path)
        if comm.rank == 0:
            for suffix in (".xdmf", ".h5"):
                shutil.copyfile(folder / f"{tag}{suffix}", path.with_suffix(suffix))
        comm.barrier()

    def close(self):
        self.file.close()


def copy_xdmf(path: str | Path, folder: Path, tag: str, comm=MPI.COMM_WORLD) -> list[str]:
    """Copy a closed XDMF file `path` and its .h5 into `folder` as <tag>.xdmf and <tag>.h5 (rank 0, each through a
    temporary name and a rename; all ranks return when the copies exist); returns the copies' names. The copy's
    XML still names the original's .h5: put it back with SurfaceSeries.restore before reading it."""
    path = Path(path)
    names = [f"{tag}{suffix}" for suffix in (".xdmf", ".h5")]
    if comm.rank == 0:
        for suffix, name in zip((".xdmf", ".h5"), names):
            tmp = folder / f"{name}.tmp"
            shutil.copyfile(path.with_suffix(suffix), tmp)
            os.replace(tmp, folder / name)
    comm.barrier()
    return names


class Checkpoint:
    """Per-rank checkpoint files of one run under `<folder>/checkpoint/` (what a state holds is the caller's).

    `write(state)` pickles the rank's `state` dict with the scene's SHA-256, the rank count and the checkpoint's
    generation (its number in this folder) to rank<r>.pkl through a temporary name; once every rank has written,
    each moves its current file to rank<r>.prev.pkl and the new one into place. A kill between the ranks' renames
    leaves some ranks one generation ahead: `read()` takes the generation every rank holds (the newest of them, in
    rank<r>.pkl or rank<r>.prev.pkl), so the ranks restore the same record. It refuses (ValueError naming the folder)
    a checkpoint of another scene (hash) or rank count, or ranks with no common generation. `every` [records] between
    writes (positive integer)."""

    def __init__(self, folder: str | Path, comm, scene_sha256: str, every: int = 10):
        if isinstance(every, bool) or not (isinstance(every, int) and every >= 1):
            raise ValueError(f"checkpoint_every must be a positive number of records, got {every!r}")
        self.folder = Path(folder) / "checkpoint"
        self.comm, self.sha, self.every = comm, scene_sha256, every
        self.generation = 0
        if comm.rank == 0:
            self.folder.mkdir(parents=True, exist_ok=True)
        comm.barrier()

    @property
    def path(self) -> Path:
        return self.folder / f"rank{self.comm.rank}.pkl"

    @property
    def previous(self) -> Path:
        return self.folder / f"rank{self.comm.rank}.prev.pkl"

    def exists(self) -> bool:
        """Whether every rank finds a checkpoint file."""
        found = self.path.is_file() or self.previous.is_file()
        return bool(self.comm.allreduce(int(found), op=MPI.MIN))

    def write(self, state: dict) -> None:
        """Write this rank's `state` (all ranks call it; returns when every rank has written)."""
        self.generation += 1
        state = {**state, "sha": self.sha, "ranks": self.comm.size, "generation": self.generation}
        tmp = self.path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            pickle.dump(state, f)
        self.comm.barrier()               # every rank's new file is whole before any rank replaces its current one
        if self.path.is_file():
            os.replace(self.path, self.previous)
        os.replace(tmp, self.path)
        self.comm.barrier()

    def read(self) -> dict:
        """This rank's saved state of the generation every rank holds, after the checks of the class docstring."""
        states = {}
        for path in (self.path, self.previous):
            if path.is_file():
                with open(path, "rb") as f:
                    state = pickle.load(f)
                states[state.get("generation", 0)] = state
        common = set(states)
        for others in self.comm.allgather(sorted(states)):
            common &= set(others)
        if not common:
            raise ValueError(f"resume: the ranks' checkpoints in {self.folder} hold no common record; run without "
                             f"--resume")
        state = states[max(common)]
        if state["sha"] != self.sha:
            raise ValueError(f"resume: the checkpoint in {self.folder} belongs to another scene (hash "
                             f"{state['sha'][:12]}..., this scene {self.sha[:12]}...); run without --resume")
        if state["ranks"] != self.comm.size:
            raise ValueError(f"resume: the checkpoint in {self.folder} was written by {state['ranks']} rank(s), this "
                             f"run has {self.comm.size}")
        self.generation = max(common)
        return state


def xdmf_fields(path: str | Path) -> dict[str, list[float]]:
    """{function name: its times} of an XDMF file written by dolfinx (io.XDMFFile.write_function). dolfinx writes
    one temporal collection per function; meshio's xdmf.TimeSeriesReader reads only the last collection of a
    file, so read the names here (and the data of the other functions with h5py, at "/Function/<name>/<time>")."""
    root = ElementTree.parse(path).getroot()
    fields: dict[str, list[float]] = {}
    for grid in root.iter("Grid"):
        if grid.get("CollectionType") == "Temporal":
            fields[grid.get("Name")] = [float(t.get("Value")) for t in grid.iter("Time")]
    return fields


def write_csv(path: str | Path, header: Sequence[str], rows: Iterable[Sequence | Mapping], comm=MPI.COMM_WORLD,
              comment: str | None = None):
    """CSV table written by rank 0 (its folder made): an optional "# comment" line, the header line, then one line
    per row; written to a temporary file and renamed, so an interrupted write leaves the previous file whole.

    A row is a sequence of values in the header's order, or a mapping from header names to values (written in
    the header's order, a missing name as an empty field, as csv.DictWriter; a name not in the header raises
    ValueError)."""
    if comm.rank != 0:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    with open(partial, "w", newline="") as f:
        if comment is not None:
            f.write(f"# {comment}\n")
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(_in_header_order(row, header) for row in rows)
    os.replace(partial, path)


def _in_header_order(row: Sequence | Mapping, header: Sequence[str]) -> Sequence:
    """The row's values in the header's order ("" for a missing name) if it is a mapping, else the row."""
    if not isinstance(row, Mapping):
        return row
    unknown = [key for key in row if key not in header]
    if unknown:
        raise ValueError(f"write_csv: row names {unknown} are not in the header {list(header)}")
    return [row.get(key, "") for key in header]


_P1_SPACES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def p1_space(mesh, vector: bool) -> fem.FunctionSpace:
    """The P1 space of `mesh` (3-vector or scalar), made once per mesh (a new space costs a JIT cache lookup)."""
    spaces = _P1_SPACES.setdefault(mesh, {})
    if vector not in spaces:
        spaces[vector] = (fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=3) if vector
                          else fem.FunctionSpace(mesh, ("Lagrange", 1)))
    return spaces[vector]


def gather_surface(mesh, displacement: fem.Function | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Deformed owned cells of all ranks on rank 0: (points (n, 3), cells (m, k) into points)."""
    V1 = p1_space(mesh, True)
    u1 = fem.Function(V1)
    if displacement is not None:
        u1.interpolate(displacement)
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    dofs = V1.dofmap.list.array.reshape(-1, V1.dofmap.dof_layout.num_dofs)[:n_cells]
    X = V1.tabulate_dof_coordinates() + u1.x.array.reshape(-1, 3)
    if dofs.shape[1] == 4:  # dolfinx quadrilaterals are tensor-ordered; VTK wants them cyclic
        dofs = dofs[:, [0, 1, 3, 2]]
    cell_points = X[dofs]  # (m, k, 3), one copy of each vertex per cell
    gathered = mesh.comm.gather(cell_points, root=0)
    if mesh.comm.rank != 0:
        return None
    allcells = np.concatenate(gathered)
    m, k, _ = allcells.shape
    return allcells.reshape(-1, 3), np.arange(m * k).reshape(m, k)


def gather_field(mesh, field: fem.Function) -> np.ndarray | None:
    """A scalar field at the vertices of the owned cells of all ranks on rank 0 (interpolated to P1), in the
    point layout of `gather_surface` (one copy of each vertex per cell)."""
    V1 = p1_space(mesh, False)
    f1 = fem.Function(V1)
    f1.interpolate(field)
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    dofs = V1.dofmap.list.array.reshape(-1, V1.dofmap.dof_layout.num_dofs)[:n_cells]
    if dofs.shape[1] == 4:
        dofs = dofs[:, [0, 1, 3, 2]]
    gathered = mesh.comm.gather(f1.x.array[dofs].reshape(-1), root=0)
    return np.concatenate(gathered) if mesh.comm.rank == 0 else None


WHEAT = (0.96, 0.87, 0.70)      # RGB of the translucent bodies behind a rendered field


def polydata(points: np.ndarray, cells: np.ndarray):
    """pyvista PolyData of a surface: points (n, 3) [m], cells (m, k) into points (all of one kind)."""
    import pyvista as pv  # optional heavy package, loaded only when a surface file is written
    cells = np.asarray(cells, dtype=np.int64)
    return pv.PolyData(np.asarray(points, dtype=float), np.hstack([np.full((len(cells), 1), cells.shape[1]),
                                                                   cells]).ravel())


def colour_range(values: np.ndarray, clim: tuple[float, float] | None = None) -> tuple[float, float]:
    """The colour range (low, high) of a render: `clim` if given (finite, low < high; ValueError naming clim
    otherwise), else (0, max(values)) (at least (0, 1e-12), so that a zero field still renders)."""
    if clim is None:
        finite = np.asarray(values, dtype=float)
        finite = finite[np.isfinite(finite)]
        return 0.0, max(float(np.max(finite, initial=0.0)), 1e-12)
    if len(clim) != 2 or not all(np.isfinite(clim)) or not float(clim[0]) < float(clim[1]):
        raise ValueError(f"clim must be two finite numbers (low, high) with low < high, got {clim!r}")
    return float(clim[0]), float(clim[1])


def render_field(path: str | Path, surface: tuple[np.ndarray, np.ndarray], values: np.ndarray, title: str,
                 bodies: Sequence[tuple[np.ndarray, np.ndarray]] = (), camera: str = "xy", zoom: float = 1.0,
                 clim: tuple[float, float] | None = None, scalar_bar_title: str = ""):
    """Render a gathered surface coloured by per-point `values` (viridis over `clim`, default 0 to the largest
    value), with its cell edges and translucent body surfaces (points, cells) behind it, to a PNG off-screen
    (fabricfem.render; call on rank 0 with gathered data). The title is printed once, as given; the colour bar
    carries `scalar_bar_title` (the quantity and its unit, e.g. "contact pressure [Pa]"); pass the same `clim` to
    frames that share a scale; `camera` one of fabricfem.render.CAMERAS."""
    low_high = colour_range(values, clim)
    layers = [Layer(bp, bc, colour=WHEAT, opacity=0.35) for bp, bc in bodies]
    layers.append(Layer(*surface, values=np.asarray(values, dtype=float), clim=low_high, edges=True))
    image = render_layers(layers, camera, zoom)
    save_with_colour_bar(path, image, title, low_high, scalar_bar_title or "value")


def render_surfaces(path: str | Path, surfaces: list[tuple[np.ndarray, np.ndarray]], title: str = "",
                    colors: Sequence[str] | None = None, camera: str = "xz"):
    """Render gathered surfaces (points, cells) to a PNG off-screen (rank 0 only)."""
    if MPI.COMM_WORLD.rank != 0:
        return
    os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
    import pyvista as pv  # optional heavy package, loaded only when a render is made
    pv.OFF_SCREEN = True
    plotter = pv.Plotter(off_screen=True, window_size=(1200, 800))
    for i, (points, cells) in enumerate(surfaces):
        k = cells.shape[1]
        faces = np.hstack([np.full((len(cells), 1), k), cells]).ravel()
        surface = pv.PolyData(points, faces)
        color = colors[i] if colors else None
        plotter.add_mesh(surface, color=color, show_edges=False)
    if title:
        plotter.add_text(title, font_size=12)
    {"xz": plotter.view_xz, "xy": plotter.view_xy, "yz": plotter.view_yz, "iso": plotter.view_isometric}[camera]()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()


def peak_memory_mib(comm=MPI.COMM_WORLD) -> dict[str, float | list[float]]:
    """Peak resident memory of the processes: ru_maxrss (Linux: KiB) of each rank in MiB, gathered on all
    ranks: {"max_mib": max over ranks, "total_mib": sum, "per_rank_mib": [...]}. It includes what the
    process held before the run (interpreter, libraries, JIT-compiled forms)."""
    kib = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    per_rank = comm.allgather(kib / 1024.0)
    return {"max_mib": max(per_rank), "total_mib": sum(per_rank), "per_rank_mib": per_rank}


def write_json(path: str | Path, data: dict, comm=MPI.COMM_WORLD):
    """JSON file written by rank 0 (numbers and strings; paths converted to str)."""
    if comm.rank != 0:
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        json.dump(data, f, indent=1, default=str)


def write_text_whole(path: str | Path, text: str) -> None:
    """Write `text` to `path` (its folder created) through a temporary name and a rename, so that a process killed
    meanwhile leaves either the previous file or the whole new one (a study's checkpoint of a finished variant)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def update_json(path: str | Path, data: dict, comm=MPI.COMM_WORLD):
    """Merge `data` into the JSON object in `path` (created if missing or unreadable; its entries are kept
    unless `data` replaces them), written by rank 0: how a runner adds its results to a run's summary.json
    (OutputFolder.finish keeps them)."""
    if comm.rank != 0:
        return
    path = Path(path)
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        old = {}
    write_json(path, {**(old if isinstance(old, dict) else {}), **data}, MPI.COMM_SELF)


def plot_time_series(path: str | Path, time: Sequence[float], panels: dict[str, dict[str, Sequence[float]]],
                     title: str = "", comm=MPI.COMM_WORLD):
    """PNG of curves over time [s] (rank 0): one panel per key of `panels` ({panel label with its unit, e.g.
    "energy [J]": {curve: values}}); returns the matplotlib Figure (closed; None on the other ranks)."""
    if comm.rank != 0:
        return None
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    n = max(1, len(panels))
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.4 * n), sharex=True, squeeze=False)
    for ax, (label, curves) in zip(axes[:, 0], panels.items()):
        for curve, values in curves.items():
            ax.plot(time, values, label=curve)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        if len(curves) > 1:
            ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        axes[0, 0].set_title(title)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


class OutputFolder:
    """The output folder of one run: at the start the files that the previous run listed in its summary.json are
    removed (no stale output can pass for this run's) and summary.json says "running"; `finish` records the run's
    status ("completed", "stopped early: ..." or "failed: ..."), the scene's SHA-256, the start and end times and
    the files the run wrote (modified since its start; for a resumed run, `keep`, since the start of the run it
    continues), merged into the summary the runner may have written."""

    SUMMARY = "summary.json"

    def __init__(self, path: str | Path, scene_sha256: str, comm=MPI.COMM_WORLD, keep: bool = False):
        self.path, self.comm, self.scene_sha256 = Path(path), comm, scene_sha256
        self.started = time.time()
        self.since = self.started        # files modified since then are the run's (a resumed run: its first start)
        error = None
        if comm.rank == 0:
            try:
                self.path.mkdir(parents=True, exist_ok=True)
                if keep:
                    self.since = _first_start(self._read(), self.started)
                for name in ([] if keep else self._read().get("outputs", [])):   # keep: a resumed run
                    stale = self.path / name
                    if "/" not in name and stale.is_file():
                        stale.unlink()
                self._write({"status": "running", "scene_sha256": scene_sha256, "started": _iso(self.since)})
            except OSError as exc:
                error = f"output.dir: cannot write the output folder {str(self.path)!r} ({exc.strerror or exc})"
        error = comm.bcast(error, root=0)
        if error:
            raise OSError(error)

    def _read(self) -> dict:
        try:
            return json.loads((self.path / self.SUMMARY).read_text())
        except (OSError, ValueError):
            return {}

    def _write(self, data: dict) -> None:
        with open(self.path / self.SUMMARY, "w") as f:
            json.dump(data, f, indent=1, default=str)

    def add(self, **data) -> None:
        """Add entries (JSON-serialisable; paths become strings) to the run's summary.json now (rank 0 writes;
        `finish` keeps them)."""
        update_json(self.path / self.SUMMARY, data, self.comm)

    def finish(self, status: str, summary: dict | None = None) -> None:
        """Record the run's status (and `summary` entries) in summary.json (rank 0)."""
        if self.comm.rank == 0:
            outputs = sorted(p.name for p in self.path.iterdir()
                             if p.is_file() and p.name != self.SUMMARY and p.stat().st_mtime >= self.since - 1.0)
            data = {**self._read(), **(summary or {}), "status": status, "scene_sha256": self.scene_sha256,
                    "started": _iso(self.since), "finished": _iso(time.time()), "outputs": outputs}
            self._write(data)
        self.comm.barrier()


def _first_start(summary: dict, now: float) -> float:
    """The start time [s since the epoch] in an interrupted run's `summary` ("started"), else `now`."""
    try:
        return min(now, datetime.datetime.fromisoformat(summary["started"]).timestamp())
    except (KeyError, TypeError, ValueError):
        return now


def _iso(t: float) -> str:
    return datetime.datetime.fromtimestamp(t, datetime.timezone.utc).isoformat(timespec="seconds")


class Progress:
    """Elapsed time and the estimated time left of a run at a done fraction in [0, 1], optionally per phase.

    `clock(done)` returns "[40.0%, 12.3 s, about 18.5 s left]"; with a phase label (given to the constructor
    or to a call: `clock(done, "donning")`) "[donning 40.0%, ...]". The estimate extrapolates the rate
    measured since the first update of the current phase, so that the one-off form compilation and set-up
    before it (about 13 s for a new form) do not inflate it; until the fraction has grown past that first
    update (or when it is not a finite number) it reads "estimating". A new phase label restarts the
    fraction (each phase runs from 0 to 1) and the estimate; the elapsed time counts from the construction."""

    def __init__(self, phase: str = ""):
        self.start = time.perf_counter()
        self.phase = phase
        self.first: tuple[float, float] | None = None    # (time, done) of the first update of the phase

    def __call__(self, done: float, phase: str | None = None) -> str:
        now = time.perf_counter()
        if phase is not None and phase != self.phase:
            self.phase, self.first = phase, None
        finite = isinstance(done, (int, float, np.floating, np.integer)) and math.isfinite(done)
        if finite and self.first is None:
            self.first = (now, float(done))
        left = "estimating"
        if finite and self.first is not None and done > self.first[1]:
            t1, d1 = self.first
            left = f"about {(now - t1) / (done - d1) * max(1.0 - done, 0.0):6.1f} s left"
        label = f"{self.phase} " if self.phase else ""
        fraction = f"{done:5.1%}" if finite else "  ?  "
        return f"[{label}{fraction}, {now - self.start:6.1f} s, {left}]"
