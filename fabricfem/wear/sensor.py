"""The skin pressure a sensor of finite size reads: the largest mean contact pressure over a disc of the skin.

The nodal contact pressure (force over the node's cloth area, fabricfem.contact.nodal.pressure_function) of a
garment that touches the skin along a line (the tip of a fold, a belt, a hem) is a line load spread over one node
spacing h: its largest value grows like 1/h as the mesh is refined and has no limit. What a garment engineer
measures is the mean over a sensor's area. The sensor pressure of a record is

    p_D = max over the nodes i in contact of  sum_j p_j A_j / sum_j A_j,   j: |x_j - x_i| <= D / 2,

the area-weighted mean of the nodal pressures p_j [Pa] (with the nodes' current cloth areas A_j [m^2], the nodes
without contact counted with p_j = 0) over the cloth nodes within a ball of diameter D [m] around a node in
contact: on the skin, a disc of diameter D (its area pi D^2 / 4 once D is several node spacings; on a mesh coarser
than D, one node, and p_D is the nodal peak). It has a mesh limit also where the nodal peak has none (a line
contact); docs/studies/sleeve.md, "Peak pressure", and docs/studies/pants.md compare the two. Units: metres, pascals.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

SENSOR_DIAMETER = 0.03    # m: the default disc (`[output] sensor_diameter`)


def sensor_pressure(points: np.ndarray, pressure: np.ndarray, area: np.ndarray, diameter: float,
                    comm: MPI.Comm = MPI.COMM_SELF) -> float:
    """p_D [Pa] (module docstring) of the cloth nodes at `points` (N, 3) [m] with nodal `pressure` (N,) [Pa] and
    current `area` (N,) [m^2], each rank passing its own nodes (every rank gets the same value; 0 without
    contact)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    pressure, area = np.asarray(pressure, dtype=float), np.asarray(area, dtype=float)
    if comm.size > 1:
        gathered = comm.allgather((points, pressure, area))
        everyone = [np.concatenate([g[k] for g in gathered]) for k in range(3)]
    else:
        everyone = [points, pressure, area]
    centres = points[pressure > 0.0]
    local = 0.0
    if len(centres):
        all_points, all_pressure, all_area = everyone
        near = cKDTree(centres).sparse_distance_matrix(cKDTree(all_points), diameter / 2.0, output_type="ndarray")
        force = np.bincount(near["i"], weights=(all_pressure * all_area)[near["j"]], minlength=len(centres))
        covered = np.bincount(near["i"], weights=all_area[near["j"]], minlength=len(centres))
        local = float(np.max(force / covered))
    return float(comm.allreduce(local, op=MPI.MAX)) if comm.size > 1 else local
