"""Where a wear run's cloth crosses itself: `python -m fabricfem.studies.fold_crossings RUN_DIR SCENE [--record K]`,
and which cells the crossing triangles belong to: `python -m fabricfem.studies.fold_crossings RUN_DIR --cells K ...`.

Reads the cloth of record K (default the last) from RUN_DIR/cloth.xdmf (Q2 cells, each split into 8 triangles on
its 3 x 3 nodes as the self-contact splits them, fabricfem.contact.cloth_surface.split_cell), lists the
intersecting triangle pairs (fabricfem.contact.intersections.intersecting) and, for the two triangles of each pair,
the gap of their centroids to the body's skin, the skin's segment and normal there (the scene's body posed at that
record, the blended skin of fabricfem.contact.projection.skin_gap). It tells a fold stacked on one side of the skin
(both triangles' skin normals alike) from cloth pinched between two facing sheets of skin (opposed normals), and
prints the counts. Metres, degrees.

The triangles that touch across a seam are not counted (as in the run's own count): nodes that coincide within
STITCH_TOLERANCE at the record are taken as one point (a sewn seam's stitched nodes, whose gap after the sewing is
below 1e-3 m in the shipped garments; two unstitched nodes that close would be merged too). `--cells` sorts each
record's pairs by the Q2 cells of their two triangles: the same cell, neighbouring cells (sharing a node), or cells
apart. A pair within a cell or between neighbours is a cell folded tighter than its 8-triangle proxy shows; only
a pair apart is one part of the cloth passing through another.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import meshio
import numpy as np
from mpi4py import MPI
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

from fabricfem.contact.cloth_surface import joined_labels, split_cell
from fabricfem.contact.intersections import intersecting
from fabricfem.contact.projection import skin_gap
from fabricfem.scenes import load
from fabricfem.scenes.build import build_wear_run

STITCH_TOLERANCE = 5e-4   # m: nodes closer than this at a record count as one point (a seam's stitched nodes)
PER_CELL = 8     # triangles per Q2 cell (split_cell)
OPPOSED = -0.5   # cosine of the angle between the two skin normals below which the skin faces itself
VTK_GRID = np.array([[0, 4, 1], [7, 8, 5], [3, 6, 2]])   # the file's quad9 nodes on the 3 x 3 grid (cloth_surface.GRID)


def cloth_triangles(folder: Path, record: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(deformed points (N, 3) [m], triangles (T, 3), the record's time) of record `record` of cloth.xdmf."""
    with meshio.xdmf.TimeSeriesReader(str(folder / "cloth.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        index = record if record >= 0 else reader.num_steps + record
        time, point_data, _ = reader.read_data(index)
    triangles = cells[0].data[:, split_cell(VTK_GRID)].reshape(-1, 3)
    return points + next(iter(point_data.values()))[:, :3], triangles, float(time)


def stitched_by_position(x: np.ndarray, tolerance: float = STITCH_TOLERANCE) -> np.ndarray:
    """(N,) labels: nodes of x (N, 3) [m] joined through neighbours closer than `tolerance` share a label."""
    return joined_labels(cKDTree(x).query_pairs(tolerance, output_type="ndarray"), len(x))


def pairs_by_cell(pairs: np.ndarray, triangles: np.ndarray, labels: np.ndarray) -> dict[str, int]:
    """Counts of the intersecting triangle pairs (P, 2) whose triangles lie in the same Q2 cell (PER_CELL
    consecutive triangles), in neighbouring cells (a node label in common) or in cells apart."""
    cell = np.arange(len(triangles)) // PER_CELL
    incidence = coo_matrix((np.ones(triangles.size), (np.repeat(cell, 3), labels[triangles].ravel())),
                           shape=(cell[-1] + 1, labels.max() + 1)).tocsr()
    a, b = cell[pairs[:, 0]], cell[pairs[:, 1]]
    shared = np.asarray(incidence[a].multiply(incidence[b]).sum(axis=1)).ravel() > 0
    same = a == b
    return {"same_cell": int(same.sum()), "neighbouring_cells": int((shared & ~same).sum()),
            "cells_apart": int((~shared).sum())}


def crossing_counts(folder: Path, record: int) -> dict:
    """The intersecting pairs of record `record` of folder/cloth.xdmf without seam neighbours, and `pairs_by_cell`."""
    x, triangles, time = cloth_triangles(folder, record)
    labels = stitched_by_position(x)
    pairs = intersecting(x, triangles, same=labels)
    return {"record": record, "time_s": time, "pairs": len(pairs), **pairs_by_cell(pairs, triangles, labels)}


def crossing_report(folder: Path, scene_path: Path, record: int = -1) -> dict:
    """Counts of the intersecting pairs of the record by the skin's segments under their triangles and by the
    relative direction of the skin normals, and the gaps [m] of their centroids to the skin."""
    x, triangles, time = cloth_triangles(folder, record)
    pairs = intersecting(x, triangles, same=stitched_by_position(x))
    run, *_ = build_wear_run(load(scene_path), MPI.COMM_SELF)
    coordinate = run.axis_at(time) if run.axis is not None else time
    bodies = run.posed_bodies(coordinate)
    names, widths = _active_segments(run, coordinate)
    centroid = x[triangles].mean(axis=1)
    first = skin_gap(centroid[pairs[:, 0]], bodies, widths)
    second = skin_gap(centroid[pairs[:, 1]], bodies, widths)
    cosine = np.sum(first[1] * second[1], axis=1)
    segments = {f"{names[a]}-{names[b]}": int(np.sum((first[2] == a) & (second[2] == b)))
                for a in range(len(names)) for b in range(len(names))}
    gaps = np.concatenate([first[0], second[0]])
    return {"time_s": time, "coordinate": coordinate, "pairs": len(pairs), "segments": segments,
            "opposed_normals": int(np.sum(cosine < OPPOSED)), "same_side": int(np.sum(cosine > -OPPOSED)),
            "gap_median_m": float(np.median(gaps)) if len(gaps) else float("nan"),
            "gap_max_m": float(gaps.max()) if len(gaps) else float("nan")}


def _active_segments(run, coordinate: float) -> tuple[list[str], np.ndarray | None]:
    """The names and the blend widths [m] of the segments `run.posed_bodies(coordinate)` returns (a segment removed
    for the donning, the pants' feet, is left out of both)."""
    names, active = list(run.body.segments), run.active_segments(coordinate)
    widths = None if run.contact.widths is None else np.asarray(run.contact.widths)[np.ix_(active, active)]
    return [n for n, on in zip(names, active) if on], widths


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("scene", nargs="?", help="the run's scene file (for the skin report)")
    parser.add_argument("--record", type=int, default=-1, help="record index (default: the last)")
    parser.add_argument("--cells", type=int, nargs="+", metavar="K",
                        help="records whose pairs are sorted by cell (instead of the skin report)")
    args = parser.parse_args(argv)
    folder = Path(args.run_dir)
    if not (folder / "cloth.xdmf").is_file():
        parser.error(f"run_dir: no cloth.xdmf in {folder} (the output folder of a wear run)")
    if args.cells:
        with meshio.xdmf.TimeSeriesReader(str(folder / "cloth.xdmf")) as reader:
            count = reader.num_steps
        outside = [k for k in args.cells if not -count <= k < count]
        if outside:
            parser.error(f"--cells: records {outside} are not in {folder / 'cloth.xdmf'} ({count} records)")
        for record in args.cells:
            print(" ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                           for k, v in crossing_counts(folder, record).items()), flush=True)
        return
    if args.scene is None:
        parser.error("scene: the skin report needs the run's scene file (or give --cells)")
    for key, value in crossing_report(folder, Path(args.scene), args.record).items():
        print(f"{key:>16}  {value}")


if __name__ == "__main__":
    main()
