"""Which stitches of a placed pattern must be sewn through another panel: `python -m fabricfem.studies.sewing_paths
SCENE`.

The sewing draws each pair of stitched nodes together along the straight line between them; this study meshes the
scene's pattern garment as the run does (fabricfem.scenes.wear.garment_mesh, serially) and counts, per seam, the
stitched pairs whose line crosses a panel other than the two it joins (fabricfem.contact.sewing_lines, the test a
run with self-contact makes at setup). It also prints the range of each side's reference positions. Metres.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from mpi4py import MPI

from fabricfem.contact.sewing_lines import sewn_through
from fabricfem.scenes.build import load
from fabricfem.scenes.wear import garment_mesh


def sewing_report(scene_path: Path) -> list[dict]:
    """Per seam of the scene's pattern garment: its name, stitched pairs, the pairs whose line crosses another panel,
    and the (min, max) of y and x of each side's reference positions [m]."""
    scene = load(scene_path)
    fabric, seams, _, garment = garment_mesh(scene.parsed, scene.path, MPI.COMM_SELF)
    if garment is None:
        raise ValueError(f"{scene_path}: [garment] is not a pattern (no seams to sew)")
    rows = []
    for seam, crossed in zip(seams, sewn_through(fabric, seams, MPI.COMM_SELF)):
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
