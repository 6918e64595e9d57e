"""Motion-capture files -> `JointTrajectory` (name -> (T, 3) positions [m], body frame: x forward,
y left, z up), and the mapping of file markers onto a body's joints and markers.

Readers: `read_c3d` (via ezc3d), `read_trc`, `read_marker_csv`, `fabricfem.body.bvh.read_bvh`, and
`load_motion` dispatching on the suffix and applying a point mapping. Each maps the file's units
(its metadata, or an explicit `units=` that overrides it) and up axis (`up=`, see
`fabricfem.body.conventions` for the exact rotation) and refuses, naming the item, non-increasing
times (the frame index) and missing samples (marker and frame; `fill_gaps=True` interpolates them
linearly in time instead). Writers for round trips: `write_c3d`, `write_trc` (`write_bvh` in `bvh`).

Point mapping (`map_points`): body point name -> a file marker name, `Mean(names)` (e.g. the
midpoint of two markers) or `Offset(base, vector)` (a point or mean shifted by a fixed vector [m],
body frame). `segment_points` builds it from segment -> (J1, J2, M) sources; `point_source` and
`mapping_sources` read it from plain data (a scene's TOML): "M", {marker = "M"} or {mean = ["A", "B"]},
each table with an optional offset = [dx, dy, dz] [m].
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence, Union

import ezc3d
import numpy as np

from fabricfem.body.bvh import read_bvh
from fabricfem.body.conventions import check_times, fill_or_refuse_gaps, to_body, to_file, unit_scale
from fabricfem.body.motion import JointTrajectory
from fabricfem.body.pose import Segment


# ------------------------------------------------------------------------------------------------
# Mapping file markers onto body points
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mean:
    """The mean of named markers (the midpoint for two)."""

    names: tuple[str, ...]

    def __post_init__(self):
        if len(self.names) == 0 or not all(isinstance(n, str) for n in self.names):
            raise ValueError(f"Mean.names must be one or more marker names, got {self.names!r}")


@dataclass(frozen=True)
class Offset:
    """A marker (or a Mean) shifted by a fixed vector [m] in the body frame."""

    base: Union[str, Mean]
    vector: tuple[float, float, float]

    def __post_init__(self):
        v = np.asarray(self.vector, dtype=float)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"Offset.vector must be a finite (3,) vector [m], got {self.vector!r}")


PointSource = Union[str, Mean, Offset]


def _needed(source: PointSource) -> tuple[str, ...]:
    if isinstance(source, str):
        return (source,)
    if isinstance(source, Mean):
        return source.names
    if isinstance(source, Offset):
        return _needed(source.base)
    raise ValueError(f"a point source must be a marker name, Mean or Offset, got {source!r}")


def _evaluate(source: PointSource, samples: Mapping[str, np.ndarray]) -> np.ndarray:
    if isinstance(source, str):
        return samples[source]
    if isinstance(source, Mean):
        return np.mean([samples[n] for n in source.names], axis=0)
    return _evaluate(source.base, samples) + np.asarray(source.vector, dtype=float)


SOURCE_KEYS = ("marker", "mean", "offset")


def _offset_vector(value) -> tuple[float, float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise ValueError(f"offset must be [dx, dy, dz]: three finite numbers [m] (body frame), got {value!r}")
    return tuple(float(v) for v in value)


def point_source(value) -> PointSource:
    """The point source of its plain-data (TOML) form: a marker name "M" (-> "M"), a table {marker = "M"} (-> "M")
    or {mean = ["A", "B", ...]} (-> Mean), exactly one of the two, with an optional offset = [dx, dy, dz] [m, body
    frame] (-> Offset(base, offset)).

    Raises:
        ValueError (one line) for any other form, naming the key at fault.
    """
    if isinstance(value, str):
        return value
    if not isinstance(value, Mapping):
        raise ValueError(f"expected a marker name or a table {{marker = \"M\"}} or {{mean = [\"A\", \"B\"]}} "
                         f"with an optional offset = [dx, dy, dz] [m], got {value!r}")
    unknown = sorted(set(value) - set(SOURCE_KEYS))
    if unknown:
        raise ValueError(f"unknown keys {unknown}; allowed: marker or mean, and offset")
    if ("marker" in value) == ("mean" in value):
        raise ValueError(f"give exactly one of marker or mean, got the keys {sorted(value)}")
    if "marker" in value:
        base = value["marker"]
        if not isinstance(base, str) or not base:
            raise ValueError(f"marker must be a marker name, got {base!r}")
    else:
        names = value["mean"]
        if not (isinstance(names, (list, tuple)) and names and all(isinstance(n, str) and n for n in names)):
            raise ValueError(f"mean must list one or more marker names, got {names!r}")
        base = Mean(tuple(names))
    return Offset(base, _offset_vector(value["offset"])) if "offset" in value else base


def mapping_sources(mapping: Mapping[str, object]) -> dict[str, PointSource]:
    """Body point name -> point source of a plain-data mapping (`point_source` of each value).

    Raises:
        ValueError "mapping.NAME: ..." for a value that is no point source.
    """
    sources = {}
    for name, value in mapping.items():
        try:
            sources[name] = point_source(value)
        except ValueError as exc:
            raise ValueError(f"mapping.{name}: {exc}") from None
    return sources


def map_points(trajectory: JointTrajectory, mapping: Mapping[str, PointSource]) -> JointTrajectory:
    """The body points of `mapping` (body name -> source), computed from the trajectory's markers.

    Raises:
        ValueError naming every mapped marker the trajectory lacks, with the available names.
    """
    if len(mapping) == 0:
        raise ValueError("mapping must name at least one body point")
    missing = {body: [n for n in _needed(src) if n not in trajectory.names] for body, src in mapping.items()}
    missing = {body: names for body, names in missing.items() if names}
    if missing:
        listed = "; ".join(f"{names} (for {body!r})" for body, names in missing.items())
        raise ValueError(f"mapping: the motion lacks the markers {listed}; available: {list(trajectory.names)}")
    samples = trajectory.samples()
    return JointTrajectory(trajectory.times, {body: _evaluate(src, samples) for body, src in mapping.items()})


def segment_points(segments: Sequence[Segment], sources: Mapping[str, tuple[PointSource, PointSource, PointSource]]
                   ) -> dict[str, PointSource]:
    """Point mapping from segment name -> (J1 source, J2 source, M source) (the segment's proximal,
    distal joint and marker). A joint shared by two segments must get the same source.

    Raises:
        ValueError naming an unknown segment, a source triple of the wrong length, or a joint given two
        different sources.
    """
    by_name = {s.name: s for s in segments}
    unknown = [n for n in sources if n not in by_name]
    if unknown:
        raise ValueError(f"sources: unknown segments {unknown} (known: {list(by_name)})")
    mapping: dict[str, PointSource] = {}
    for name, triple in sources.items():
        if len(triple) != 3:
            raise ValueError(f"sources[{name!r}] must be (J1, J2, M) sources, got {triple!r}")
        s = by_name[name]
        for point, src in zip((s.proximal, s.distal, s.marker), triple):
            if mapping.setdefault(point, src) != src:
                raise ValueError(f"sources[{name!r}]: point {point!r} is already mapped to {mapping[point]!r}, "
                                 f"not {src!r}")
    return mapping


# ------------------------------------------------------------------------------------------------
# Readers and writers
# ------------------------------------------------------------------------------------------------
def _trajectory(times, labels: Sequence[str], data: np.ndarray, source: str, scale: float, up: str,
                fill_gaps: bool) -> JointTrajectory:
    """File markers (T, K, 3) in file units/axes -> JointTrajectory [m, body frame], refusing bad times,
    duplicate labels and gaps."""
    t = check_times(times, source)
    duplicates = sorted({n for n in labels if list(labels).count(n) > 1})
    if duplicates:
        raise ValueError(f"{source}: duplicate marker labels {duplicates}")
    data = to_body(fill_or_refuse_gaps(t, labels, data, source, fill_gaps), scale, up)
    return JointTrajectory(t, {name: data[:, k] for k, name in enumerate(labels)})


def _uniform_rate(trajectory: JointTrajectory) -> tuple[float, int]:
    """(rate [Hz], index of the first frame) for a uniformly sampled trajectory starting at a frame
    time k / rate (what C3D and TRC store)."""
    dt = np.diff(trajectory.times)
    if np.max(np.abs(dt - dt.mean())) > 1e-9 * dt.mean():
        raise ValueError("trajectory: times must be uniformly spaced to be written as C3D or TRC")
    rate = 1.0 / dt.mean()
    first = round(trajectory.times[0] * rate)
    if abs(first / rate - trajectory.times[0]) > 1e-9 / rate:
        raise ValueError(f"trajectory: the first time {trajectory.times[0]} s is not a whole frame k / rate")
    return rate, int(first)


def read_c3d(path: str | Path, units: str | float | None = None, up: str = "z", fill_gaps: bool = False
             ) -> JointTrajectory:
    """Markers of a C3D file (POINT:LABELS, POINT:RATE, POINT:UNITS), frame k at (first_frame + k) / rate
    [s] (ezc3d's 0-based first frame). Samples that are NaN or exactly (0, 0, 0) (the C3D convention
    for an invisible marker) are gaps.

    Args:
        units: overrides POINT:UNITS (a unit name or metres per unit).
        up: the file's up axis ("z" or "y").
        fill_gaps: interpolate gaps linearly in time instead of refusing them.
    """
    source = f"path: {path}"
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    labels = [str(s).strip() for s in point["LABELS"]["value"]]
    rate = float(point["RATE"]["value"][0])
    if units is None:
        if "UNITS" not in point:
            raise ValueError(f"{source}: no POINT:UNITS in the file; pass units=")
        units = str(point["UNITS"]["value"][0])
    data = np.array(c3d["data"]["points"][:3], dtype=float).transpose(2, 1, 0)   # (T, K, 3)
    data[np.all(data == 0.0, axis=2)] = math.nan
    times = (c3d["header"]["points"]["first_frame"] + np.arange(data.shape[0])) / rate
    return _trajectory(times, labels, data, source, unit_scale(units), up, fill_gaps)


def write_c3d(path: str | Path, trajectory: JointTrajectory, units: str = "mm", up: str = "z") -> None:
    """Write the trajectory as C3D markers in `units` (stored as float32: 1e-4 mm relative resolution
    ~6e-8) with the given up axis. Times must be uniform and start at a whole frame k / rate."""
    rate, first = _uniform_rate(trajectory)
    samples = trajectory.samples()
    data = to_file(np.stack([samples[n] for n in trajectory.names], axis=1), unit_scale(units), up)
    points = np.ones((4, len(trajectory.names), len(trajectory.times)))
    points[:3] = data.transpose(2, 1, 0)
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(trajectory.names)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [units]
    c3d["header"]["points"]["first_frame"] = first
    c3d["data"]["points"] = points
    c3d.write(str(path))


def read_trc(path: str | Path, units: str | float | None = None, up: str = "z", fill_gaps: bool = False
             ) -> JointTrajectory:
    """Read a TRC marker file (the tab-separated text format of Motion Analysis / OpenSim).

    Layout: line 1 "PathFileType ...", line 2 the header keys (DataRate, CameraRate, NumFrames,
    NumMarkers, Units, ...), line 3 their values, line 4 "Frame#  Time  name1 <tab><tab> name2 ...",
    line 5 the coordinate labels X1 Y1 Z1 ..., then one row per frame; empty fields are gaps.

    Args:
        units: overrides the header's Units (a unit name or metres per unit).
        up: the file's up axis ("z" or "y"; OpenSim's TRC files are usually "y").
        fill_gaps: interpolate gaps linearly in time instead of refusing them.
    """
    source = f"path: {path}"
    lines = Path(path).read_text().splitlines()
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise ValueError(f"{source} is not a TRC file (first line must start with 'PathFileType')")
    header = {k.strip(): v.strip() for k, v in zip(lines[1].split("\t"), lines[2].split("\t"))}
    if "NumMarkers" not in header or (units is None and "Units" not in header):
        raise ValueError(f"{source}: TRC header lacks NumMarkers or Units (pass units=)")
    n_markers = int(header["NumMarkers"])
    labels = [s.strip() for s in lines[3].split("\t")[2:] if s.strip()]
    if len(labels) != n_markers:
        raise ValueError(f"{source}: {len(labels)} marker labels but NumMarkers = {n_markers}")
    width = 2 + 3 * n_markers
    rows = [line.split("\t") for line in lines[5:] if line.strip()]
    table = np.array([[float(v) if v.strip() else math.nan for v in (r + [""] * width)[:width]] for r in rows])
    data = table[:, 2:].reshape(len(rows), n_markers, 3)
    return _trajectory(table[:, 1], labels, data, source, unit_scale(units if units is not None else header["Units"]),
                       up, fill_gaps)


def write_trc(path: str | Path, trajectory: JointTrajectory, units: str = "mm", up: str = "z") -> None:
    """Write the trajectory as a TRC file in `units` (10 significant digits) with the given up axis.
    Times must be uniform and start at a whole frame k / rate."""
    rate, first = _uniform_rate(trajectory)
    names = trajectory.names
    samples = trajectory.samples()
    data = to_file(np.stack([samples[n] for n in names], axis=1), unit_scale(units), up)
    n = len(trajectory.times)
    keys = ["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate", "OrigDataStartFrame",
            "OrigNumFrames"]
    values = [f"{rate:.12g}", f"{rate:.12g}", str(n), str(len(names)), units, f"{rate:.12g}", str(first + 1), str(n)]
    head = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}", "\t".join(keys), "\t".join(values),
            "Frame#\tTime\t" + "\t".join(f"{name}\t\t" for name in names),
            "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, len(names) + 1)), ""]
    table = np.column_stack([first + 1 + np.arange(n), trajectory.times, data.reshape(n, -1)])
    with open(path, "w") as fh:
        fh.write("\n".join(head) + "\n")
        np.savetxt(fh, table, fmt=["%d"] + ["%.10g"] * (table.shape[1] - 1), delimiter="\t")


def read_marker_csv(path: str | Path, units: str | float = "m", up: str = "z", fill_gaps: bool = False
                    ) -> JointTrajectory:
    """Read a CSV marker file: a header "time, NAME_x, NAME_y, NAME_z, ..." (time in s; suffixes _x/_y/_z,
    case-insensitive, also ".x" or ":x") and one row per sample, coordinates in `units`."""
    source = f"path: {path}"
    with open(path, newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    if len(rows) < 3:
        raise ValueError(f"{source}: need a header and at least 2 samples")
    header = [h.strip() for h in rows[0]]
    if header[0].lower() not in ("time", "t", "time_s", "time [s]"):
        raise ValueError(f"{source}: the first column must be 'time', got {header[0]!r}")
    columns: dict[str, dict[str, int]] = {}
    for j, h in enumerate(header[1:], start=1):
        if len(h) < 3 or h[-2] not in "_.:" or h[-1].lower() not in "xyz":
            raise ValueError(f"{source}: column {h!r} is not NAME_x / NAME_y / NAME_z")
        columns.setdefault(h[:-2], {})[h[-1].lower()] = j
    for name, cols in columns.items():
        if set(cols) != {"x", "y", "z"}:
            raise ValueError(f"{source}: marker {name!r} lacks a coordinate column")
    width = len(header)
    table = np.array([[float(c) if c.strip() else math.nan for c in (r + [""] * width)[:width]] for r in rows[1:]])
    data = np.stack([table[:, [c["x"], c["y"], c["z"]]] for c in columns.values()], axis=1)
    return _trajectory(table[:, 0], list(columns), data, source, unit_scale(units), up, fill_gaps)


def load_motion(path: str | Path, mapping: Mapping[str, PointSource] | None = None,
                units: str | float | None = None, up: str | None = None, fill_gaps: bool = False
                ) -> JointTrajectory:
    """Read a motion file by its suffix (.c3d, .trc, .bvh, .csv) and, with `mapping`, keep only the
    mapped body points (`map_points`), so that a missing marker is refused when the motion is loaded.
    `units`/`up` default to the reader's (file metadata; BVH: units required, up "y")."""
    suffix = Path(path).suffix.lower()
    readers = {".c3d": read_c3d, ".trc": read_trc, ".bvh": read_bvh, ".csv": read_marker_csv}
    if suffix not in readers:
        raise ValueError(f"path: unknown motion file type {suffix!r} (known: {sorted(readers)})")
    if suffix == ".bvh" and units is None:
        raise ValueError("units: a BVH file has no unit metadata; pass units= (a unit name or metres per unit)")
    options = {k: v for k, v in (("units", units), ("up", up)) if v is not None}
    trajectory = readers[suffix](path, fill_gaps=fill_gaps, **options)
    return map_points(trajectory, mapping) if mapping is not None else trajectory
