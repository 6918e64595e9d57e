"""Outputs: XDMF time series (ParaView), CSV tables and off-screen PNG renders (pyvista).

Everything here is parallel-correct: XDMF is written collectively, renders gather the
owned cells to rank 0.
"""
from __future__ import annotations

import csv
import datetime
import json
import os
import resource
import time
from pathlib import Path
from typing import Sequence

import numpy as np
from dolfinx import fem, io
from mpi4py import MPI


class SurfaceSeries:
    """Displacement (and optional scalar fields) of a shell over time in one XDMF file.

    dolfinx 0.5 writes functions of the mesh's own (P1) degree, so fields are interpolated to P1.
    """

    def __init__(self, path: str | Path, mesh):
        self.path = Path(path)
        if mesh.comm.rank == 0:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        mesh.comm.barrier()
        self.mesh = mesh
        self.V1 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=3)
        self.u1 = fem.Function(self.V1, name="displacement")
        self.file = io.XDMFFile(mesh.comm, str(self.path), "w")
        self.file.write_mesh(mesh)

    def write(self, displacement: fem.Function, time: float):
        self.u1.interpolate(displacement)
        self.file.write_function(self.u1, time)

    def close(self):
        self.file.close()


def write_csv(path: str | Path, header: Sequence[str], rows: Sequence[Sequence[float]], comm=MPI.COMM_WORLD):
    """CSV table written by rank 0."""
    if comm.rank != 0:
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)


def gather_surface(mesh, displacement: fem.Function | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Deformed owned cells of all ranks on rank 0: (points (n, 3), cells (m, k) into points)."""
    V1 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=3)
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
    V1 = fem.FunctionSpace(mesh, ("Lagrange", 1))
    f1 = fem.Function(V1)
    f1.interpolate(field)
    n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
    dofs = V1.dofmap.list.array.reshape(-1, V1.dofmap.dof_layout.num_dofs)[:n_cells]
    if dofs.shape[1] == 4:
        dofs = dofs[:, [0, 1, 3, 2]]
    gathered = mesh.comm.gather(f1.x.array[dofs].reshape(-1), root=0)
    return np.concatenate(gathered) if mesh.comm.rank == 0 else None


def render_field(path: str | Path, surface: tuple[np.ndarray, np.ndarray], values: np.ndarray, title: str,
                 bodies: Sequence[tuple[np.ndarray, np.ndarray]] = (), camera: str = "xy", zoom: float = 1.0):
    """Render a gathered surface coloured by per-point `values` (viridis, from 0), with translucent body
    surfaces (points, cells) behind it, to a PNG off-screen (call on rank 0 with gathered data)."""
    os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
    import pyvista as pv  # optional heavy package, loaded only when a render is made
    points, cells = surface
    cloth = pv.PolyData(points, np.hstack([np.full((len(cells), 1), cells.shape[1]), cells]).ravel())
    cloth.point_data["field"] = values
    plotter = pv.Plotter(off_screen=True, window_size=(1200, 800))
    for bp, bc in bodies:
        plotter.add_mesh(pv.PolyData(bp, np.hstack([np.full((len(bc), 1), bc.shape[1]), bc]).ravel()),
                         color="wheat", opacity=0.35)
    # no scalar bar: its tick layout crashes VTK 9.x off-screen here (segfault in vtkScalarBarActor); the
    # colour range goes into the title instead
    top = max(float(np.max(values)), 1e-12)
    plotter.add_mesh(cloth, scalars="field", cmap="viridis", show_edges=True, show_scalar_bar=False,
                     clim=(0.0, top))
    plotter.add_text(f"{title}\ncolour: 0 (dark) to {top:.3g} (yellow)", font_size=11)
    {"xz": plotter.view_xz, "xy": plotter.view_xy, "yz": plotter.view_yz, "iso": plotter.view_isometric}[camera]()
    plotter.camera.zoom(zoom)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()


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


def plot_time_series(path: str | Path, time: Sequence[float], panels: dict[str, dict[str, Sequence[float]]],
                     title: str = "", comm=MPI.COMM_WORLD):
    """PNG of curves over time (rank 0): one panel per key of `panels` ({panel label: {curve: values}})."""
    if comm.rank != 0:
        return
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


class OutputFolder:
    """The output folder of one run: at the start the files that the previous run listed in its summary.json are
    removed (no stale output can pass for this run's) and summary.json says "running"; `finish` records the run's
    status ("completed", "stopped early: ..." or "failed: ..."), the scene's SHA-256, the start and end times and
    the files the run wrote (modified since its start), merged into the summary the runner may have written."""

    SUMMARY = "summary.json"

    def __init__(self, path: str | Path, scene_sha256: str, comm=MPI.COMM_WORLD):
        self.path, self.comm, self.scene_sha256 = Path(path), comm, scene_sha256
        self.started = time.time()
        error = None
        if comm.rank == 0:
            try:
                self.path.mkdir(parents=True, exist_ok=True)
                for name in self._read().get("outputs", []):
                    stale = self.path / name
                    if "/" not in name and stale.is_file():
                        stale.unlink()
                self._write({"status": "running", "scene_sha256": scene_sha256, "started": _iso(self.started)})
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

    def finish(self, status: str, summary: dict | None = None) -> None:
        """Record the run's status (and `summary` entries) in summary.json (rank 0)."""
        if self.comm.rank == 0:
            outputs = sorted(p.name for p in self.path.iterdir()
                             if p.is_file() and p.name != self.SUMMARY and p.stat().st_mtime >= self.started - 1.0)
            data = {**self._read(), **(summary or {}), "status": status, "scene_sha256": self.scene_sha256,
                    "started": _iso(self.started), "finished": _iso(time.time()), "outputs": outputs}
            self._write(data)
        self.comm.barrier()


def _iso(t: float) -> str:
    return datetime.datetime.fromtimestamp(t, datetime.timezone.utc).isoformat(timespec="seconds")


class Progress:
    """Elapsed time and the estimated time left of a run at a done fraction in [0, 1]. The estimate extrapolates
    the rate measured since the first update, so that the one-off form compilation and set-up before it (about
    13 s for a new form) do not inflate it."""

    def __init__(self):
        self.start = time.perf_counter()
        self.first: tuple[float, float] | None = None    # (time, done) of the first update

    def __call__(self, done: float) -> str:
        now = time.perf_counter()
        if self.first is None:
            self.first = (now, done)
        t1, d1 = self.first
        left = ("time left unknown" if done <= d1 else
                f"about {(now - t1) / (done - d1) * (1.0 - done):6.1f} s left")
        return f"[{done:5.1%}, {now - self.start:6.1f} s, {left}]"
