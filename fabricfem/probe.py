"""Parallel-correct point probes: values of a Function at a mesh node, identical on every rank."""
from __future__ import annotations

from typing import Sequence

import numpy as np
from dolfinx import fem
from mpi4py import MPI


def owned_node(V: fem.FunctionSpace, point: Sequence[float], candidates: np.ndarray | None = None) -> int | None:
    """Local block index of the node of V at `point` on the owning rank, None on the others.

    `candidates` (local block indices) restricts the search, e.g. to the nodes of one side of a slit.
    Raises ValueError when no node lies within 1e-8 (relative to the domain size) of `point`, or when
    several distinct nodes do (coincident nodes: pass the side's candidates).
    """
    comm = V.mesh.comm
    X = V.tabulate_dof_coordinates()
    n_owned = V.dofmap.index_map.size_local
    dist = np.linalg.norm(X[:n_owned] - np.asarray(point, dtype=float), axis=1)
    if candidates is not None:
        allowed = np.zeros(n_owned, dtype=bool)
        allowed[candidates[candidates < n_owned]] = True
        dist[~allowed] = np.inf
    local_best = dist.min() if n_owned else np.inf
    best = comm.allreduce(local_best, op=MPI.MIN)
    scale = comm.allreduce(max(1.0, float(np.abs(X).max(initial=0.0))), op=MPI.MAX)
    if best > 1e-8 * scale:
        raise ValueError(f"point {tuple(point)} is not a mesh node (nearest node {best:.3e} m away)")
    if comm.allreduce(int(np.count_nonzero(dist <= 1e-8 * scale)), op=MPI.SUM) > 1:
        raise ValueError(f"side: {tuple(point)} holds coincident nodes (a slit or seam); name the edge tag "
                         "of the side to read")
    owner = comm.allreduce(comm.rank if local_best == best else comm.size, op=MPI.MIN)
    return int(np.argmin(dist)) if comm.rank == owner else None


def node_value(f: fem.Function, point: Sequence[float]) -> np.ndarray:
    """Value (all components) of a Lagrange Function at the mesh node `point`, on all ranks."""
    V = f.function_space
    bs = V.dofmap.index_map_bs
    node = owned_node(V, point)
    out = np.zeros(bs)
    if node is not None:
        out[:] = f.x.array[node * bs:(node + 1) * bs]
    return V.mesh.comm.allreduce(out, op=MPI.SUM)
