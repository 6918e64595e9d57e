"""The files of a wear run's records written off the time loop, in bulk, by one writer thread.

A record costs the time loop only the copies of its arrays (and, on several ranks, one gather of the owned values
to rank 0); rank 0's `BackgroundWriter` thread writes them with plain numpy, zlib and h5py (never dolfinx, PETSc or
MPI in the thread):

- `FieldSeries`: one function's XDMF time series in the layout of dolfinx 0.5 `XDMFFile.write_function` (the same
  XML text and HDF5 datasets "/Function/<name>/<time with '.' as '_'>" of the values at the owned geometry nodes,
  in the global node order; the mesh written by dolfinx `write_mesh`). The records are kept in memory and written
  every `flush_every` records and at `flush`/`close`: the HDF5 file is opened, appended to and closed, then the
  XML is replaced (a temporary name and a rename). Between two flushes both files on disk are whole and agree,
  so a run killed in the loop leaves valid files with the records up to the last flush.
- `write_vtp`: a triangulated surface (points [m], triangles) as VTK XML PolyData, binary, zlib-compressed (what
  pyvista's `PolyData.save` writes, read back identically by VTK, pyvista and meshio) without importing VTK.
"""
from __future__ import annotations

import base64
import os
import queue
import re
import threading
import time
import zlib
from pathlib import Path
from typing import Callable
from xml.etree import ElementTree

import h5py
import numpy as np
from dolfinx import fem
from dolfinx import io as dio
from mpi4py import MPI

FLUSH_EVERY = 50          # records kept in memory between two writes of an XDMF series


class BackgroundWriter:
    """One daemon thread that runs submitted jobs (callables of plain numpy / file I/O) in order. `wait()` returns
    when every job submitted so far has run and raises the first error a job raised (RuntimeError naming it).
    `cpu` [s]: the thread's CPU time in its jobs."""

    def __init__(self):
        self.cpu = 0.0
        self._jobs: queue.Queue = queue.Queue()
        self._errors: list[BaseException] = []
        self._thread = threading.Thread(target=self._work, name="fabricfem-writer", daemon=True)
        self._thread.start()

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            tic = time.thread_time()
            try:
                if job is None:
                    return
                job()
            except BaseException as exc:   # kept, raised on the caller's thread by wait()
                self._errors.append(exc)
            finally:
                self.cpu += time.thread_time() - tic
                self._jobs.task_done()

    def submit(self, job: Callable[[], None]) -> None:
        """Run `job()` on the writer thread after the jobs submitted before it."""
        if not self._thread.is_alive():
            raise RuntimeError("the output writer is closed")
        self._jobs.put(job)

    def wait(self) -> None:
        """Block until the submitted jobs have run; raise the first error of a job."""
        self._jobs.join()
        if self._errors:
            error = self._errors.pop(0)
            self._errors.clear()
            raise RuntimeError(f"writing the outputs failed: {error}") from error

    def close(self) -> None:
        """Run the remaining jobs, end the thread, raise a job's error."""
        if self._thread.is_alive():
            self._jobs.put(None)
            self._thread.join()
        self.wait()


# ---------------------------------------------------------------------------------------- VTK PolyData
def _zlib_block(array: np.ndarray) -> str:
    """The base64 text of one VTK binary data array, zlib-compressed in one block with UInt32 headers."""
    raw = np.ascontiguousarray(array).tobytes()
    packed = zlib.compress(raw, 1)
    header = np.array([1, len(raw), len(raw), len(packed)], dtype="<u4").tobytes()
    return base64.b64encode(header).decode() + base64.b64encode(packed).decode()


def _data_array(kind: str, name: str, array: np.ndarray, components: int | None = None) -> str:
    size = f' NumberOfComponents="{components}"' if components else ""
    return (f'        <DataArray type="{kind}" Name="{name}"{size} format="binary">\n'
            f"          {_zlib_block(array)}\n        </DataArray>\n")


def polys_block(triangles: np.ndarray) -> str:
    """The <Polys> element of `triangles` (m, 3) (connectivity and offsets, Int64): the same for every frame of a
    body, so computed once (`write_vtp`'s `polys`)."""
    tri = np.asarray(triangles, dtype="<i8")
    offsets = 3 * np.arange(1, len(tri) + 1, dtype="<i8")
    return ("      <Polys>\n" + _data_array("Int64", "connectivity", tri.ravel())
            + _data_array("Int64", "offsets", offsets) + "      </Polys>\n")


def write_vtp(path: str | Path, points: np.ndarray, triangles: np.ndarray, polys: str | None = None) -> None:
    """Write the surface of `points` (n, 3) [m] and `triangles` (m, 3) to `path` (VTK XML PolyData, binary,
    zlib-compressed; `polys`: `polys_block(triangles)` when already made). Through a temporary name and a rename."""
    pts = np.asarray(points, dtype="<f8").reshape(-1, 3)
    polys = polys if polys is not None else polys_block(triangles)
    text = ('<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian" '
            'header_type="UInt32" compressor="vtkZLibDataCompressor">\n  <PolyData>\n'
            f'    <Piece NumberOfPoints="{len(pts)}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" '
            f'NumberOfPolys="{len(triangles)}">\n      <PointData>\n      </PointData>\n      <CellData>\n'
            '      </CellData>\n      <Points>\n' + _data_array("Float64", "Points", pts.ravel(), 3)
            + "      </Points>\n" + polys + "    </Piece>\n  </PolyData>\n</VTKFile>\n")
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(text)
    os.replace(partial, path)


class BodyFrames:
    """The posed body per record as VTP files (`write` on the writer thread), the <Polys> block of the
    triangulation made once while it does not change."""

    def __init__(self):
        self.polys: tuple[np.ndarray, str] | None = None

    def write(self, path: str | Path, points: np.ndarray, triangles: np.ndarray) -> None:
        """Write the surface `points` (n, 3) [m], `triangles` (m, 3) to `path` (arrays not changed after)."""
        if self.polys is None or not np.array_equal(self.polys[0], triangles):
            self.polys = (triangles, polys_block(triangles))
        write_vtp(path, points, triangles, self.polys[1])


# ---------------------------------------------------------------------------------------- XDMF time series
def time_name(t: float) -> str:
    """The time as dolfinx 0.5 writes it into the XML (17 significant digits, the shortest %g form)."""
    return f"{t:.17g}"


def geometry_order(function: fem.Function) -> np.ndarray:
    """Indices into `function.x.array` (block size bs) of the values at the owned geometry nodes, node by node:
    the point values dolfinx 0.5 writes for a function of the mesh's own Lagrange degree. Raises ValueError for
    a function whose element does not match the geometry's nodes."""
    V = function.function_space
    mesh = V.mesh
    n_cells = len(mesh.geometry.dofmap.offsets) - 1
    nodes = mesh.geometry.dofmap.array.reshape(n_cells, -1)
    dofs = V.dofmap.list.array.reshape(n_cells, -1)
    if nodes.shape != dofs.shape:
        raise ValueError(f"{function.name}: its element has {dofs.shape[1]} nodes per cell, the geometry "
                         f"{nodes.shape[1]}: write it with dolfinx.io.XDMFFile")
    n_owned = mesh.geometry.index_map().size_local
    node_dof = np.full(len(mesh.geometry.x), -1, dtype=np.int64)
    node_dof[nodes.ravel()] = dofs.ravel()
    bs = V.dofmap.index_map_bs
    return (bs * node_dof[:n_owned, None] + np.arange(bs)).ravel()


class FieldSeries:
    """The XDMF time series <path> (.xdmf + .h5) of one function (fem.Function of the mesh's own degree), written
    in bulk (module docstring); all ranks construct it and call `add`, `flush` and `close` (collective).

    mode "w": a new file with the mesh (dolfinx write_mesh); "a": append to an existing file of this series (a
    resumed run: its records are kept). `writer`: the rank-0 writer thread shared with the other outputs."""

    def __init__(self, path: str | Path, function: fem.Function, mode: str, writer: BackgroundWriter | None,
                 flush_every: int = FLUSH_EVERY):
        self.path, self.function, self.writer = Path(path), function, writer
        self.comm: MPI.Comm = function.function_space.mesh.comm
        self.flush_every = flush_every
        if mode == "w":
            with dio.XDMFFile(self.comm, str(self.path), "w") as handle:
                handle.write_mesh(function.function_space.mesh)
        self.order = geometry_order(function)
        self.width = function.function_space.dofmap.index_map_bs
        self.buffer: list[tuple[float, np.ndarray]] = []
        self.head, self.entries = self._read_xml() if self.comm.rank == 0 else ("", [])
        nodes = re.search(r'<Geometry GeometryType="[A-Z]+">\s*<DataItem Dimensions="(\d+)', self.head)
        self.nodes = nodes.group(1) if nodes else "0"

    def _read_xml(self) -> tuple[str, list[str]]:
        """(the XML text before this function's collection, the times (XML strings) already in the file)."""
        text = self.path.read_text()
        marker = re.search(rf'\n\s*<Grid Name="{re.escape(self.function.name)}" GridType="Collection"', text)
        head = text[:marker.start()] if marker else text[:text.rindex("\n  </Domain>")]
        times = []
        for grid in ElementTree.fromstring(text).iter("Grid"):
            if grid.get("CollectionType") == "Temporal" and grid.get("Name") == self.function.name:
                times = [t.get("Value") for t in grid.iter("Time")]
        return head, times

    def add(self, t: float) -> None:
        """Keep the function's values now, at time `t` (one gather on several ranks); write every flush_every."""
        values = self.function.x.array[self.order].reshape(-1, self.width)
        if self.comm.size > 1:
            parts = self.comm.gather(values, root=0)
            values = np.concatenate(parts) if self.comm.rank == 0 else values
        else:
            values = values.copy()
        if self.comm.rank == 0:
            self.buffer.append((t, values))
        if len(self.buffer) >= self.flush_every:
            self.flush()

    def flush(self) -> None:
        """Hand the kept records to the writer thread (rank 0); `wait` on the writer for them to be on disk."""
        if self.comm.rank != 0 or not self.buffer:
            return
        records, self.buffer = self.buffer, []
        self.entries += [time_name(t) for t, _ in records]
        job = _Flush(self.path, self.function.name, (self.nodes, self.width), records, self.head, list(self.entries))
        if self.writer is None:
            job()
        else:
            self.writer.submit(job)


class _Flush:
    """One bulk write of a FieldSeries (on the writer thread): the datasets into the .h5, then the whole XML."""

    def __init__(self, path: Path, name: str, shape: tuple[str, int], records: list, head: str, entries: list[str]):
        self.path, self.name, self.records = path, name, records
        self.nodes, self.width = shape
        self.head, self.entries = head, entries

    def __call__(self) -> None:
        h5 = self.path.with_suffix(".h5")
        with h5py.File(h5, "a") as f:
            for t, values in self.records:
                key = f"/Function/{self.name}/{time_name(t).replace('.', '_')}"
                if key in f:
                    del f[key]
                f.create_dataset(key, data=values)
        partial = self.path.with_name(self.path.name + ".partial")
        partial.write_text(self.xml(h5.name))
        os.replace(partial, self.path)

    def xml(self, h5_name: str) -> str:
        """The XDMF text: the mesh part, then one temporal collection of every record (dolfinx 0.5's layout)."""
        kind, n = "Scalar" if self.width == 1 else "Vector", self.nodes
        grids = "".join(
            f'      <Grid Name="{self.name}" GridType="Uniform">\n'
            '        <xi:include xpointer="xpointer(/Xdmf/Domain/Grid[@GridType=\'Uniform\'][1]/*[self::Topology '
            'or self::Geometry])" />\n'
            f'        <Time Value="{t}" />\n'
            f'        <Attribute Name="{self.name}" AttributeType="{kind}" Center="Node">\n'
            f'          <DataItem Dimensions="{n} {self.width}" Format="HDF">{h5_name}:/Function/{self.name}/'
            f'{t.replace(".", "_")}</DataItem>\n        </Attribute>\n      </Grid>\n' for t in self.entries)
        return (f'{self.head}\n    <Grid Name="{self.name}" GridType="Collection" CollectionType="Temporal">\n'
                f"{grids}    </Grid>\n  </Domain>\n</Xdmf>\n")
