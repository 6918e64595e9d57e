"""The contact pressure on a triangulated skin: cloth nodes' normal forces spread onto the skin's vertices.

A cloth node at x_i pressing the skin with the normal force f_i [N] (>= 0) loads the skin triangle of its closest
point, shared among the triangle's corners by the barycentric coordinates b_ij of the foot (the linear shape
functions: force and moment of the node's load are kept). The pressure at skin vertex j is the nodal load over the
vertex's area, p_j = sum_i b_ij f_i / A_j [Pa], with A_j one third of the areas of the triangles around j (the
lumped, barycentric area), so that sum_j p_j A_j = sum_i f_i.

`SkinPressureWriter` writes the field over time: an XDMF time series (meshio; the rest mesh once, then per time
the pressure and the displacement from the rest pose, for ParaView's Warp By Vector) and one VTP file per time of
the posed skin (pyvista). Under MPI the cloth nodes are gathered to rank 0, which alone computes and writes: pass
each node once (the owned nodes of each rank).
"""
from __future__ import annotations

from pathlib import Path

import h5py
import meshio
import numpy as np
from mpi4py import MPI

from fabricfem.body.mesh_distance import face_normals_areas
from fabricfem.io import polydata


def vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) lumped areas [m^2]: one third of the areas of the triangles around each vertex."""
    areas = face_normals_areas(vertices, faces)[1]
    return np.bincount(faces.reshape(-1), weights=np.repeat(areas / 3.0, 3), minlength=len(vertices))


def skin_pressure(skin, t: float, points: np.ndarray, normal_force: np.ndarray) -> np.ndarray:
    """(V,) pressure [Pa] on the vertices of `skin` (a `MeshSkin`) posed at time t [s] from cloth nodes at
    `points` (M, 3) [m] pressing with `normal_force` (M,) [N] (module docstring)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    force = np.asarray(normal_force, dtype=float).reshape(-1)
    if len(force) != len(points):
        raise ValueError(f"normal_force has {len(force)} values for {len(points)} points")
    vertices, faces = skin.surface(t)
    load = np.zeros(len(vertices))
    if len(points):
        _, triangle, bary, _, _ = skin.closest(points, t)
        b = np.clip(bary, 0.0, 1.0)
        b /= b.sum(axis=1, keepdims=True)
        load = np.bincount(faces[triangle].reshape(-1), weights=(b * force[:, None]).reshape(-1),
                           minlength=len(vertices))
    return load / vertex_areas(vertices, faces)


class SkinPressureWriter:
    """The skin's pressure over time as `<stem>.xdmf` (+ .h5) and `<stem>_<k>.vtp` in `folder` (module docstring).

    Args:
        folder: output folder (created). stem: file name stem. skin: the `MeshSkin`. comm: the cloth's
            communicator (rank 0 writes).
    """

    def __init__(self, folder: str | Path, stem: str, skin, comm=MPI.COMM_WORLD):
        self.folder, self.stem, self.skin, self.comm = Path(folder), stem, skin, comm
        self.count = 0
        self._series = None
        if comm.rank == 0:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._series = meshio.xdmf.TimeSeriesWriter(str(self.folder / f"{stem}.xdmf"))
            # the HDF5 file beside the XDMF file (meshio's __enter__ opens it in the working directory)
            self._series.h5_filename = str(self.folder / f"{stem}.h5")
            self._series.h5_file = h5py.File(self._series.h5_filename, "w")
            self._series.write_points_cells(skin.mesh.vertices, [("triangle", skin.mesh.faces)])

    def write(self, t: float, points: np.ndarray, normal_force: np.ndarray) -> np.ndarray | None:
        """Write the pressure at time t [s] of this rank's cloth nodes (`skin_pressure`); the field (V,) [Pa] on
        rank 0, None elsewhere."""
        gathered = self.comm.gather((np.asarray(points, dtype=float).reshape(-1, 3),
                                     np.asarray(normal_force, dtype=float).reshape(-1)), root=0)
        if self.comm.rank != 0:
            return None
        pressure = skin_pressure(self.skin, t, np.concatenate([g[0] for g in gathered]),
                                 np.concatenate([g[1] for g in gathered]))
        vertices, faces = self.skin.surface(t)
        self._series.write_data(float(t), point_data={"pressure": pressure,
                                                      "displacement": vertices - self.skin.mesh.vertices})
        surface = polydata(vertices, faces)
        surface.point_data["pressure"] = pressure
        surface.save(str(self.folder / f"{self.stem}_{self.count:05d}.vtp"))
        self.count += 1
        return pressure

    def close(self) -> None:
        """Close the XDMF series (rank 0)."""
        if self._series is not None:
            self._series.__exit__(None, None, None)
            self._series = None
