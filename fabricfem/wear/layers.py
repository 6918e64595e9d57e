"""Monitors per garment of several garments worn one over the other (fabricfem.scenes.garments).

The garments are connected parts of one mesh, each with its own cell tag (index + 1, inside out;
fabricfem.meshes.layers). `layer_labels` gives every node of the cloth surface its garment; the cloth-cloth
contact (fabricfem.contact.self_contact.SelfContact with `layer` set) then keeps, per pair of garments (a, b), the
normal contact forces f_i [N] that the pairs between them put on the nodes (`SelfContact.between[(a, b)]`).

Per record (`LayerMonitor.values`, columns of the CSV; their peaks in summary.json), for garments a < b (b outside):

    <b>_on_<a>_force_N   F = sum over a's nodes of |f_i|: the normal load of the outer garment on the inner one
    <b>_on_<a>_peak_Pa   max over a's nodes of |f_i| / A_i (A_i the node's lumped reference area [m^2], the area
                         of the contact law, fabricfem.contact.self_contact)
    <b>_on_<a>_mean_Pa   F / sum of A_i over a's nodes with f_i != 0 (the mean over the contact)
    <g>_skin_peak_Pa     the largest contact pressure of garment g on the body [Pa] (the run's pressure field,
                         per unit deformed cloth area, fabricfem.contact.nodal), and <g>_skin_mean_Pa its
                         area-weighted mean over g's nodes in contact

Layer forces are the state of the last step of the record (the contact law is a penalty: the force on a node is
its spring's, no time average); the skin pressure is the body contact's record mean. SI units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.self_contact import SelfContact


def layer_labels(surface: ClothSurface, fmesh) -> np.ndarray:
    """(N,) the garment index (cell tag - 1) of every node of the cloth `surface` (global order, every rank), from
    the cell tags of the FabricMesh `fmesh` (ValueError when the mesh has none)."""
    if fmesh.cell_tags is None:
        raise ValueError("fmesh: several garments need the cell tags of their layers (fabricfem.meshes.layers)")
    n_cells = fmesh.mesh.topology.index_map(2).size_local
    local = np.full(n_cells, -1, dtype=np.int64)
    tags = fmesh.cell_tags
    owned = tags.indices < n_cells
    local[tags.indices[owned]] = tags.values[owned] - 1
    cells = np.concatenate(surface.comm.allgather(local))         # the order of surface.cell_nodes
    labels = np.full(surface.count, -1, dtype=np.int64)
    labels[surface.cell_nodes.ravel()] = np.repeat(cells, surface.cell_nodes.shape[1])
    if (labels < 0).any():
        raise ValueError(f"fmesh: {int(np.sum(labels < 0))} nodes belong to no tagged layer")
    return labels


@dataclass
class LayerMonitor:
    """The monitors of several garments (module docstring): their `names` inside out, the (N,) garment `labels` of
    the nodes and the cloth-cloth contact whose `between` forces it reads."""

    names: tuple[str, ...]
    labels: np.ndarray
    cloth: SelfContact

    def layer_values(self) -> dict[str, float]:
        """{column: value} of the outer-on-inner loads [N] and pressures [Pa] of every pair of garments."""
        out: dict[str, float] = {}
        area = self.cloth.surface.area
        for a in range(len(self.names)):
            for b in range(a + 1, len(self.names)):
                force = self.cloth.between.get((a, b))
                on_a = self.labels == a
                magnitude = np.linalg.norm(force[on_a], axis=1) if force is not None else np.zeros(int(on_a.sum()))
                total, touched = float(magnitude.sum()), magnitude > 0.0
                key = f"{self.names[b]}_on_{self.names[a]}"
                out[f"{key}_force_N"] = total
                out[f"{key}_peak_Pa"] = float((magnitude / area[on_a]).max(initial=0.0))
                out[f"{key}_mean_Pa"] = total / float(area[on_a][touched].sum()) if touched.any() else 0.0
        return out

    def skin_values(self, pressure: np.ndarray, area: np.ndarray, owned_labels: np.ndarray, comm) -> dict[str, float]:
        """{column: value} of each garment's contact pressure on the body: `pressure` [Pa] and `area` [m^2] of this
        rank's contact nodes, `owned_labels` their garments; peak and area-weighted mean over the contact, all
        ranks."""
        out: dict[str, float] = {}
        for g, name in enumerate(self.names):
            mine = owned_labels == g
            on = mine & (pressure > 0.0)
            peak = comm.allreduce(float(pressure[mine].max(initial=0.0)), op=MPI.MAX)
            sums = comm.allreduce(np.array([float(np.sum(pressure[on] * area[on])), float(np.sum(area[on]))]),
                                  op=MPI.SUM)
            out[f"{name}_skin_peak_Pa"] = peak
            out[f"{name}_skin_mean_Pa"] = float(sums[0] / sums[1]) if sums[1] > 0.0 else 0.0
        return out

    def values(self, pressure: np.ndarray, contact) -> dict[str, float]:
        """Every column of a record: `pressure` [Pa] of the body contact's moving nodes of this rank (the order of
        `contact.area`, fabricfem.contact.explicit.ExplicitBodyContact) and the layer loads."""
        owned = self.labels[self.cloth.surface.owned][contact.moving]
        return {**self.layer_values(), **self.skin_values(pressure, contact.area, owned, contact.comm)}
