"""Outputs of a wear run: posed body surfaces, torque plots, pressure renders."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio


def body_surface(ellipsoids, samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated surfaces of posed ellipsoids: (points (n, 3) [m], triangles (m, 3))."""
    points, cells, offset = [], [], 0
    n_theta, n_phi = samples, 2 * samples
    for e in ellipsoids:
        pts = e.surface_points(n_theta, n_phi)
        i, j = np.meshgrid(np.arange(n_theta - 1), np.arange(n_phi), indexing="ij")
        a = i * n_phi + j
        b = i * n_phi + (j + 1) % n_phi
        c, d = a + n_phi, b + n_phi
        tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
        points.append(pts.reshape(-1, 3))
        cells.append(tri + offset)
        offset += len(points[-1])
    return np.concatenate(points), np.concatenate(cells)


def plot_torque(path, curves: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "",
                xlabel: str = "elbow flexion angle [deg]"):
    """Resisting torque [N m] against the record coordinate (`xlabel`) for named curves (PNG, rank 0)."""
    if MPI.COMM_WORLD.rank != 0:
        return
    import matplotlib  # optional heavy package: only when a plot is written
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, (angle, torque) in curves.items():
        ax.plot(angle, torque, marker="o", ms=3, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("resisting torque [N m]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_pressure(path, run, title: str, angle: float):
    """Deformed garment of a WearRun coloured by contact pressure [Pa] with the posed body (pyvista, off-screen)."""
    mesh = run.model.mesh
    surface = fio.gather_surface(mesh, run.model.displacement())
    values = fio.gather_field(mesh, run.pressure_field())
    if run.comm.rank == 0:
        fio.render_field(path, surface, values, f"{title}, contact pressure [Pa]",
                         bodies=[body_surface(run.posed_bodies(angle))])
