"""The error of a scene that cannot be run, the close-match hint of its messages, and the check of a vector value
the section validators share."""
from __future__ import annotations

import difflib
import math

import numpy as np


class SceneError(ValueError):
    """A scene file that cannot be run; the message names the offending key."""


def suggest(name: str, options) -> str:
    """" (did you mean 'x'?)" for the closest of `options` to `name`, or ""."""
    close = difflib.get_close_matches(name, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def finite_vector(where: str, value, n: int = 3) -> np.ndarray:
    """`value` as an (n,) float array: a TOML list of n finite numbers (not booleans), else SceneError naming
    `where`."""
    if not (isinstance(value, list) and len(value) == n and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise SceneError(f"{where}: expected {n} finite numbers, got {value!r}")
    return np.array(value, dtype=float)
