"""Unit and axis conventions of motion files, mapped to the body's: metres, Z up.

Units: a file's lengths times `unit_scale(units)` are metres; `units` is a name ("m", "cm", "mm",
"in"/"inch") or a positive number of metres per file unit (e.g. 0.0254 / 0.45 for the CMU BVH files).

Axes: the body frame is x forward, y left, z up (ground z = 0). A file whose up axis is y (the BVH
and many C3D labs' convention: x left, y up, z forward) is mapped by the fixed rotation

    p_body = R_y p_file,   R_y = [[0, 0, 1],
                                  [1, 0, 0],
                                  [0, 1, 0]]        (x_body = z_file, y_body = x_file, z_body = y_file)

a cyclic permutation (det R_y = +1, a proper rotation: handedness is kept). up = "z" is the identity.
"""
from __future__ import annotations

import math

import numpy as np

LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254}
UP_ROTATIONS = {"z": np.eye(3), "y": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])}


def unit_scale(units: str | float) -> float:
    """Metres per file unit for a unit name (LENGTH_UNITS) or a positive number [m / unit]."""
    if isinstance(units, str):
        key = units.strip().lower()
        if key not in LENGTH_UNITS:
            raise ValueError(f"units must be one of {sorted(LENGTH_UNITS)} or a number of metres per unit (a "
                             f"number, not a string), got {units!r}")
        return LENGTH_UNITS[key]
    if isinstance(units, (int, float)) and math.isfinite(units) and units > 0.0:
        return float(units)
    raise ValueError(f"units must be a unit name {sorted(LENGTH_UNITS)} or a positive number [m/unit], "
                     f"got {units!r}")


def up_rotation(up: str) -> np.ndarray:
    """The rotation R with p_body = R p_file for a file whose up axis is `up` ("z" or "y")."""
    if up not in UP_ROTATIONS:
        raise ValueError(f"up must be one of {sorted(UP_ROTATIONS)}, got {up!r}")
    return UP_ROTATIONS[up]


def to_body(points: np.ndarray, scale: float, up: str) -> np.ndarray:
    """File points (..., 3) in file units -> body frame [m]: scale R_up p."""
    return scale * (np.asarray(points, dtype=float) @ up_rotation(up).T)


def to_file(points: np.ndarray, scale: float, up: str) -> np.ndarray:
    """Body points (..., 3) [m] -> file units and axes: R_up^T p / scale (the inverse of `to_body`)."""
    return (np.asarray(points, dtype=float) @ up_rotation(up)) / scale


def check_times(times: np.ndarray, source: str) -> np.ndarray:
    """The frame times [s] as a float array; ValueError naming the first frame whose time does not
    increase (or is not finite)."""
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"{source}: need at least 2 frames, got {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise ValueError(f"{source}: time of frame {int(bad[0])} is not finite ({t[bad[0]]})")
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if len(bad):
        k = int(bad[0]) + 1
        raise ValueError(f"{source}: times do not increase at frame {k} (t[{k - 1}] = {t[k - 1]} s, "
                         f"t[{k}] = {t[k]} s)")
    return t


def fill_or_refuse_gaps(times: np.ndarray, labels, data: np.ndarray, source: str, fill_gaps: bool) -> np.ndarray:
    """Markers (T, K, 3) with gaps (non-finite samples) refused or, with fill_gaps, linearly
    interpolated in time from the marker's valid frames.

    Raises:
        ValueError naming the marker and the first frame of a gap (without fill_gaps), or a marker
        whose gap touches the first or last frame (nothing to interpolate from).
    """
    valid = np.all(np.isfinite(data), axis=2)             # (T, K)
    if valid.all():
        return data
    k = int(np.flatnonzero(~valid.all(axis=0))[0])
    frame = int(np.flatnonzero(~valid[:, k])[0])
    if not fill_gaps:
        raise ValueError(f"{source}: marker {labels[k]!r} is missing (NaN or gap) at frame {frame} "
                         f"(t = {times[frame]} s); pass fill_gaps=True to interpolate gaps")
    out = data.copy()
    for j in np.flatnonzero(~valid.all(axis=0)):          # loop over gappy markers, vectorised over frames
        ok = valid[:, j]
        if not (ok[0] and ok[-1]):
            edge = 0 if not ok[0] else len(ok) - 1
            raise ValueError(f"{source}: marker {labels[j]!r} is missing at frame {edge}, an end of the "
                             f"recording: fill_gaps cannot interpolate there")
        for c in range(3):
            out[~ok, j, c] = np.interp(times[~ok], times[ok], data[ok, j, c])
    return out
