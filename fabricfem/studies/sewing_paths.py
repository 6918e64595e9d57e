"""Which stitches of a placed pattern must be sewn through another panel: `python -m fabricfem.studies.sewing_paths
SCENE`.

The sewing draws each pair of stitched nodes together along the straight line between them (fabricfem.contact.seams:
both move to the pair's centre). If that line crosses a third panel, no contact can close the seam without passing
cloth through cloth: with self-contact the seam stays open or closes through the panel, without it the cloth
crosses itself (docs/findings/2026-11-28-stitched-zones.md). This study meshes the scene's pattern garment as the run
does (fabricfem.scenes.wear.garment_mesh, serially), splits each placed quadrilateral cell into two triangles on its
corners (the placed panels are flat, so the corners span the cell) and counts, per seam, the stitched pairs whose
line meets a triangle of a panel other than the two it joins (libigl's `ray_mesh_intersect`, the library of the
intersection count's degenerate cases; hit parameters t in (1e-9, 1 - 1e-9) of the line from a to b, its ends left
out). It also prints the range of each side's reference positions. Metres.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import igl
import numpy as np
from mpi4py import MPI

from fabricfem.scenes.build import load
from fabricfem.scenes.wear import garment_mesh

END_MARGIN = 1e-9     # fraction of a stitch's line left out at each end (its own panels' edges lie there)


def panel_triangles(fabric) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) [m], triangles (2C, 3), panel tag per triangle (2C,)) of a serial FabricMesh of quadrilateral
    cells: each cell split on its corners (dolfinx's quadrilateral corner order 0, 1, 3, 2 round the cell)."""
    mesh = fabric.mesh
    corners = mesh.geometry.dofmap.array.reshape(mesh.topology.index_map(2).size_local, -1)[:, :4]
    tags = np.zeros(len(corners), dtype=np.int64)
    tags[fabric.cell_tags.indices] = fabric.cell_tags.values
    triangles = np.concatenate([corners[:, [0, 1, 3]], corners[:, [0, 3, 2]]])
    return mesh.geometry.x, triangles, np.concatenate([tags, tags])


def crossing_stitches(points_a: np.ndarray, points_b: np.ndarray, own_tags: tuple[int, int], points: np.ndarray,
                      triangles: np.ndarray, triangle_tags: np.ndarray) -> np.ndarray:
    """(n,) bool: the stitched pairs (points_a[i], points_b[i]) [m] whose straight line meets a triangle of a panel
    whose tag is not in `own_tags` (module docstring)."""
    faces = np.ascontiguousarray(triangles[~np.isin(triangle_tags, own_tags)], dtype=np.int64)
    vertices = np.ascontiguousarray(points, dtype=float)
    crossed = np.zeros(len(points_a), dtype=bool)
    if not len(faces):
        return crossed
    for i, (start, end) in enumerate(zip(points_a, points_b)):      # a study at setup, a few hundred lines
        hits = igl.ray_mesh_intersect(np.ascontiguousarray(start, dtype=float),
                                      np.ascontiguousarray(end - start, dtype=float), vertices, faces) or []
        crossed[i] = any(END_MARGIN < hit[1] < 1.0 - END_MARGIN for hit in hits)
    return crossed


def sewing_report(scene_path: Path) -> list[dict]:
    """Per seam of the scene's pattern garment: its name, stitched pairs, the pairs whose line crosses another panel,
    and the (min, max) of y and x of each side's reference positions [m]."""
    scene = load(scene_path)
    fabric, seams, _, garment = garment_mesh(scene.parsed, scene.path, MPI.COMM_SELF)
    if garment is None:
        raise ValueError(f"{scene_path}: [garment] is not a pattern (no seams to sew)")
    points, triangles, tags = panel_triangles(fabric)
    rows = []
    for seam in seams:
        crossed = crossing_stitches(seam.points_a, seam.points_b, (seam.tag_a, seam.tag_b), points, triangles, tags)
        rows.append({"seam": seam.name, "pairs": len(crossed), "through_another_panel": int(crossed.sum()),
                     **{f"{side}_{axis}": (float(p[:, k].min()), float(p[:, k].max()))
                        for side, p in (("a", seam.points_a), ("b", seam.points_b)) for axis, k in (("y", 1), ("x", 0))}})
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", type=Path, help="a wear scene with a pattern garment")
    args = parser.parse_args(argv)
    try:
        rows = sewing_report(args.scene)
    except ValueError as exc:        # SceneError is one: a bad or missing scene
        parser.error(f"scene: {exc}")
    for row in rows:
        ranges = "  ".join(f"{k} [{v[0]:+.3f}, {v[1]:+.3f}]" for k, v in row.items() if isinstance(v, tuple))
        print(f"{row['seam']:20s} pairs {row['pairs']:3d}  through another panel {row['through_another_panel']:3d}  "
              f"{ranges}")


if __name__ == "__main__":
    main()
