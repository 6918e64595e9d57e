"""Sewing patterns shipped with fabricfem (GarmentCode JSON, fabricfem.meshes.pattern): `pattern_path(name)`.

pants_straight_sides.json: a four-panel pair of trousers from Garment-Pattern-Generator (MIT licence), see
README.md in this folder for its source and schema [Korosteleva2021].
"""
from __future__ import annotations

from pathlib import Path

FOLDER = Path(__file__).parent


def pattern_path(name: str) -> Path:
    """The shipped pattern file `name` (with or without .json); ValueError naming the available ones."""
    path = FOLDER / (name if name.endswith(".json") else f"{name}.json")
    if not path.is_file():
        available = sorted(p.stem for p in FOLDER.glob("*.json"))
        raise ValueError(f"pattern: no shipped pattern {name!r}; available: {available}")
    return path
