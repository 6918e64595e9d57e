"""Whether a scene pays for several MPI ranks. A small scene runs slower on 2 ranks than on 1 (the ghost exchange,
the collective monitors and the rank that waits for the other's contact work cost more than half of its
arithmetic): `fabricfem run` under `mpirun -n N` runs a scene of fewer than SERIAL_BELOW_DOFS estimated degrees of
freedom on rank 0 alone, says so, and the other ranks wait for its exit code (`--all-ranks` runs it on every rank
regardless). The threshold is measured on this 2-core machine (docs/benchmarks.md, "Parallel runs").

The estimate is made before meshing: a plate or tube of P2 cells from its cell counts (fabricfem.scenes.build
`estimated_dofs`: nodes x 5 for the shell), the garments of a wear scene summed, a pattern garment from its
panels' area A and element size h: about A / (sqrt(3)/4 h^2) triangles, twice as many P2 nodes, 5 dofs each.
"""
from __future__ import annotations

import math

import numpy as np

from fabricfem.scenes.build import estimated_dofs
from fabricfem.scenes.schema import Scene
from fabricfem.scenes.wear import read_pattern
from fabricfem.scenes.wear_sections import garment_tables

SERIAL_BELOW_DOFS = 2000      # estimated dofs below which one rank is as fast as two or faster (docs/benchmarks.md)
SHELL_DOFS_PER_NODE = 5


def estimated_scene_dofs(scene: Scene) -> int | None:
    """The scene's degrees of freedom estimated before meshing (module docstring); None when unknown (a kind or
    garment without an estimate)."""
    data = scene.data
    if scene.kind in ("static", "dynamic"):
        mesh = data.get("mesh", {})
        if mesh.get("type") not in ("plate", "tube"):
            return None
        return estimated_dofs(mesh, data.get("model", {}).get("kind", "naghdi"))
    if scene.kind != "wear":
        return None
    total = 0
    for table in garment_tables(data):
        if table.get("builder", "pattern") == "tube":
            total += estimated_dofs({"type": "tube", "n_around": table["n_around"], "n_along": table["n_along"]})
        else:
            total += _pattern_dofs(scene, float(table.get("h", 0.05)))
    return total


def _pattern_dofs(scene: Scene, h: float) -> int:
    """A pattern garment's dofs from its panels' outline area [m^2] and element size h [m] (module docstring)."""
    pattern = read_pattern(scene.parsed, scene.path)
    area = sum(_polygon_area(np.asarray(panel.vertices, dtype=float)) for panel in pattern.panels.values())
    triangles = area / (math.sqrt(3.0) / 4.0 * h * h)
    return int(2 * triangles * SHELL_DOFS_PER_NODE)


def _polygon_area(vertices: np.ndarray) -> float:
    """Area [m^2] of a planar polygon (N, 2) by the shoelace formula (the outline's straight chords)."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def runs_alone(scene: Scene, ranks: int) -> int | None:
    """The estimated dofs when the scene should run on one rank of `ranks` (fewer than SERIAL_BELOW_DOFS), else
    None (one rank, or large enough, or no estimate)."""
    if ranks < 2:
        return None
    dofs = estimated_scene_dofs(scene)
    return dofs if dofs is not None and dofs < SERIAL_BELOW_DOFS else None
