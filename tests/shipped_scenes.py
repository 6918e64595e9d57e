"""The shipped scenes as the tests run them. scenes/sleeve.toml ships on its converged mesh (44 x 57, docs/studies/
sleeve.md "Error bars"); the tests check behaviour, not that figure, and run it on the thesis's mesh I (10 x 13),
about 30x cheaper per second of motion."""
from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST_MESH = {"n_around": 10, "n_along": 13}     # cells around x along the tube


def scene_data(name: str) -> dict:
    """scenes/<name> as data; the sleeve (a tube garment of scenes/sleeve.toml) on TEST_MESH."""
    data = tomllib.loads((ROOT / "scenes" / name).read_text())
    if name == "sleeve.toml":
        data["garment"].update(TEST_MESH)
    return data
