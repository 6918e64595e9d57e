"""Outputs of a wear run, what a garment engineer reads: posed body surfaces, torque plots, pressure renders
on the garment and on the skin, joint moments in OpenSim's storage format (.sto).

Pressure on the skin (`skin_pressure`): the garment's nodal contact pressures [Pa] carried onto the vertices of
the triangulated body surface (`body_surface`) by an inverse-distance-weighted mean of the nodes in contact
within a radius (about 1.5 element sizes), 0 where none is near. `render_skin_pressure` draws it in kPa with
a fixed colour range, so that frames share one scale (1 kPa = 7.50 mmHg, the unit of compression classes).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from fabricfem import io as fio
from fabricfem.render import Layer, render_layers, save_with_colour_bar

PA_PER_MMHG = 133.322387415      # Pa
MMHG_PER_KPA = 1000.0 / PA_PER_MMHG
GREY, DIM_GREY = (0.5, 0.5, 0.5), (0.41, 0.41, 0.41)     # RGB of the garment's fill and edges in the renders


TORQUE_ERROR_FROM = 10.0    # deg: a sleeve's torque curve is compared from here to the final angle


def torque_rms_error(angles: np.ndarray, torques: np.ndarray, ref_angles: np.ndarray, ref_torques: np.ndarray,
                     start: float = TORQUE_ERROR_FROM) -> float:
    """RMS of T - T_ref over the reference records at >= `start` deg (T interpolated linearly in the angle),
    divided by the mean |T_ref| over them."""
    mask = ref_angles >= start - 1e-9
    if not mask.any():
        raise ValueError(f"no reference record at or beyond {start} deg")
    diff = np.interp(ref_angles[mask], angles, torques) - ref_torques[mask]
    return float(np.sqrt(np.mean(diff ** 2)) / np.mean(np.abs(ref_torques[mask])))


def body_surface(ellipsoids, samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated surfaces of posed ellipsoids: (points (n, 3) [m], triangles (m, 3))."""
    n_theta, n_phi = samples, 2 * samples
    points = [e.surface_points(n_theta, n_phi).reshape(-1, 3) for e in ellipsoids]
    if not points:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(points), _surface_triangles(n_theta, n_phi, len(points)).copy()


@functools.lru_cache(maxsize=16)
def _surface_triangles(n_theta: int, n_phi: int, count: int) -> np.ndarray:
    """The triangles of `count` (theta, phi) grids of n_theta x n_phi points, one after the other."""
    i, j = np.meshgrid(np.arange(n_theta - 1), np.arange(n_phi), indexing="ij")
    a = i * n_phi + j
    b = i * n_phi + (j + 1) % n_phi
    c, d = a + n_phi, b + n_phi
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
    return np.concatenate([tri + k * n_theta * n_phi for k in range(count)])


def plot_wear_history(path, history, axis_label: str = "time [s]", title: str = ""):
    """PNG (rank 0) of a wear run's resisting torques [N m] per monitor against the body time [s] of every
    record (sewing, donning and settling included), each phase named at its start, the motion's records shaded
    (the records whose peaks and means the summary reports, fabricfem.wear.contract.WearHistory.summary) with the
    summary's peaks marked, and the records' axis value (e.g. the elbow angle [deg], `axis_label`) on a second
    axis where the run has one. Returns the matplotlib Figure (closed; None on the other ranks)."""
    if MPI.COMM_WORLD.rank != 0:
        return None
    import matplotlib  # optional heavy package: only when a plot is written
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(8, 5))
    steps, times = history.steps, history.times
    for name in history.monitors:
        ax.plot(times, history.torque(name), marker="o", ms=3, label=name)
    ax.set(xlabel="body time [s]", ylabel="resisting torque [N m]", title=title)
    ax.grid(True, alpha=0.3)
    starts = [k for k, s in enumerate(steps) if k == 0 or s.phase != steps[k - 1].phase]
    for k in starts:   # a record closes its interval: a phase starts one record interval before its first record
        start = times[k - 1] if k else 0.0
        ax.axvline(start, color="gray", lw=0.8, ls=":")
        ax.text(start, 0.98, f" {steps[k].phase}", transform=ax.get_xaxis_transform(), va="top", fontsize=8)
    motion = [k for k, s in enumerate(steps) if s.phase == "motion"]
    if motion:
        ax.axvspan(times[motion[0] - 1] if motion[0] else 0.0, times[motion[-1]], color="tab:orange", alpha=0.1,
                   label="motion: the records of the summary's peaks")
    if motion and history.monitors:
        summary = history.summary()
        peaks = [summary[f"torque_{name}"] for name in history.monitors]
        ax.plot([p["peak_time_s"] for p in peaks], [p["peak_Nm"] for p in peaks], "k*", ms=10, ls="none",
                label="peak (summary)")
    handles = ax.get_legend_handles_labels()[0]
    axis_values = [s.axis_value for s in steps]
    if steps and all(v is not None for v in axis_values):
        twin = ax.twinx()
        handles += twin.plot(times, axis_values, color="gray", lw=1, ls="--", alpha=0.7,
                             label=f"{axis_label.split(' [')[0]} (right axis)")
        twin.set_ylabel(axis_label)
    if handles:
        ax.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return fig


def plot_torque(path, curves: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "",
                xlabel: str = "elbow flexion angle [deg]"):
    """Resisting torque [N m] against the record coordinate (`xlabel`) for named curves (PNG, rank 0)."""
    if MPI.COMM_WORLD.rank != 0:
        return
    import matplotlib  # optional heavy package: only when a plot is written
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, (angle, torque) in curves.items():
        ax.plot(angle, torque, marker="o", ms=3, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("resisting torque [N m]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if curves:
        ax.legend()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_pressure(path, run, title: str, angle: float, clim: tuple[float, float] | None = None):
    """Deformed garment of a WearRun coloured by contact pressure [Pa] with the posed body (pyvista, off-screen);
    `title` is printed as given, the quantity and unit are on the colour bar; `clim` [Pa] fixes the colour range
    (the same for every frame of a run), default 0 to this frame's peak."""
    mesh = run.model.mesh
    surface = fio.gather_surface(mesh, run.model.displacement())
    values = fio.gather_field(mesh, run.pressure_field())
    if run.comm.rank == 0:
        fio.render_field(path, surface, values, title, bodies=[body_surface(run.posed_bodies(angle))],
                         clim=clim, scalar_bar_title="contact pressure [Pa]")


# ---------------------------------------------------------------------------------------- pressure on the skin
def gather_contact(positions: np.ndarray, pressures: np.ndarray, comm: MPI.Comm = MPI.COMM_WORLD
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The contact nodes of all ranks on rank 0: (positions (N, 3) [m], pressures (N,) [Pa]) concatenated in
    rank order; None on the other ranks. Each rank passes its owned nodes (e.g. ExplicitBodyContact.position
    and its pressures), so that no node is counted twice."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    pressures = np.asarray(pressures, dtype=float).reshape(-1)
    if len(positions) != len(pressures):
        raise ValueError(f"pressures: expected {len(positions)} values (one per position), got {len(pressures)}")
    gathered = comm.gather((positions, pressures), root=0)
    if comm.rank != 0:
        return None
    return np.concatenate([g[0] for g in gathered]), np.concatenate([g[1] for g in gathered])


def idw_at(points: np.ndarray, node_positions: np.ndarray, node_values: np.ndarray, radius: float) -> np.ndarray:
    """(n,) inverse-distance-weighted mean of the `node_values` of the nodes within `radius` [m] of each of
    the `points` (n, 3) [m], weights 1 / (d + radius / 1000); 0 where no node is within the radius."""
    out = np.zeros(len(points))
    if len(points) == 0 or len(node_positions) == 0:
        return out
    pairs = cKDTree(points).sparse_distance_matrix(cKDTree(node_positions), radius, output_type="ndarray")
    if len(pairs) == 0:
        return out
    w = 1.0 / (pairs["v"] + 1e-3 * radius)
    weight = np.bincount(pairs["i"], w, minlength=len(points))
    total = np.bincount(pairs["i"], w * node_values[pairs["j"]], minlength=len(points))
    near = weight > 0.0
    out[near] = total[near] / weight[near]
    return out


def skin_pressure(ellipsoids, samples: int, node_positions: np.ndarray, node_pressure: np.ndarray,
                  radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact pressure on the skin: the surface of the posed `ellipsoids` (`body_surface(ellipsoids, samples)`,
    points (n, 3) [m] and triangles (m, 3)) with, at each vertex, the inverse-distance-weighted mean pressure
    [Pa] of the garment nodes in contact (pressure > 0) within `radius` [m] of it (`idw_at`), 0 where there is
    none. `node_positions` (N, 3) [m] and `node_pressure` (N,) [Pa] are all nodes of the garment (rank 0:
    `gather_contact`); positions where the nodes touch the skin (contact positions) give the sharpest map.
    Choose `radius` about 1.5 element sizes: smaller leaves holes between the nodes, larger smears the peaks.
    Returns (points, triangles, values (n,) [Pa])."""
    if not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius must be a positive length [m], got {radius!r}")
    positions = np.asarray(node_positions, dtype=float)
    pressure = np.asarray(node_pressure, dtype=float).reshape(-1)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"node_positions must have shape (N, 3), got {positions.shape}")
    if len(pressure) != len(positions):
        raise ValueError(f"node_pressure: expected {len(positions)} values (one per node), got {len(pressure)}")
    points, triangles = body_surface(ellipsoids, samples)
    touching = np.isfinite(pressure) & (pressure > 0.0)
    return points, triangles, idw_at(points, positions[touching], pressure[touching], float(radius))


def render_skin_pressure(path: str | Path, points: np.ndarray, triangles: np.ndarray, values_kPa: np.ndarray,
                         title: str, clim: tuple[float, float],
                         garment_surface: tuple[np.ndarray, np.ndarray] | None = None, camera: str = "iso",
                         zoom: float = 1.0) -> None:
    """PNG (off-screen, rank 0's data) of the body surface (points (n, 3) [m], triangles (m, 3)) coloured by
    the contact pressure `values_kPa` (n,) [kPa] over the fixed colour range `clim` = (low, high) [kPa] (pass
    the same to every frame of a run), with a colour bar "contact pressure [kPa]" and a second scale in mmHg
    above it (fabricfem.render.save_with_colour_bar), the garment (points, cells) as a translucent grey surface
    with its edges if given, `title` once, seen along `camera` (one of fabricfem.render.CAMERAS) zoomed by `zoom`
    (fabricfem.render.render_layers)."""
    values = np.asarray(values_kPa, dtype=float).reshape(-1)
    if len(values) != len(points):
        raise ValueError(f"values_kPa: expected {len(points)} values (one per point), got {len(values)}")
    low, high = fio.colour_range(values, clim)
    layers = [Layer(points, triangles, values, (low, high), smooth=True)]
    if garment_surface is not None:
        # where the garment presses, its flat cells lie on or just under the finer skin and are hidden by it:
        # the grey fill and edges show the garment where it stands off the skin
        layers += [Layer(*garment_surface, colour=GREY, opacity=0.15),
                   Layer(*garment_surface, colour=DIM_GREY, opacity=0.5, wireframe=True)]
    image = render_layers(layers, camera, zoom)
    save_with_colour_bar(path, image, title, (low, high), "contact pressure [kPa]",
                         secondary=(f"[mmHg]  (1 kPa = {MMHG_PER_KPA:.2f} mmHg)", MMHG_PER_KPA))


# ---------------------------------------------------------------------------------------- OpenSim storage
# joint -> (OpenSim coordinate of its flexion, the flexion axis in the body's frame): the names of OpenSim's full-body
# models (e.g. Rajagopal 2015); the arm of fabricfem.body.arm (flexion about +z) taken as a right arm; the lower
# body of fabricfem.body.lower_body (x forward, y left, z up): the knees flex about +y (the shank swings backwards),
# the ankles dorsiflex about -y (the toes rise)
OPENSIM_COORDINATES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "elbow": ("elbow_flex_r", (0.0, 0.0, 1.0)),
    "knee_r": ("knee_angle_r", (0.0, 1.0, 0.0)), "knee_l": ("knee_angle_l", (0.0, 1.0, 0.0)),
    "ankle_r": ("ankle_angle_r", (0.0, -1.0, 0.0)), "ankle_l": ("ankle_angle_l", (0.0, -1.0, 0.0))}
STO_NOTE = ("<monitor>_moment: resisting torque of the garment about the monitor's axis [N m], positive when the "
            "garment opposes a right-handed rotation about the axis (flexion)\n"
            "<coordinate>_moment (OpenSim coordinate names, e.g. knee_angle_r_moment): the garment's moment on the "
            "body about the joint's flexion axis [N m], positive in flexion (minus the resisting torque); flip it "
            "for a model whose coordinate is negative in flexion (the knee of gait2392)\n"
            "time: body time [s] (sewing, donning and settling included); motion_time: the motion's own time [s] "
            "(a motion file's time; before its first frame in the phases before the motion)")


def opensim_coordinates(monitors) -> dict[str, tuple[str, float]]:
    """{monitor name: (OpenSim coordinate, sign)} of the torque monitors (fabricfem.wear.garment.TorqueSpec: name,
    joint, axis) whose axis is their joint's flexion axis (OPENSIM_COORDINATES; sign +1) or its opposite (-1); the
    first monitor of a coordinate takes it, the others and those about other axes or joints get none."""
    out: dict[str, tuple[str, float]] = {}
    for spec in monitors:
        if spec.joint not in OPENSIM_COORDINATES:
            continue
        coordinate, flexion = OPENSIM_COORDINATES[spec.joint]
        axis = np.asarray(spec.axis, dtype=float)
        cosine = float(np.dot(axis, flexion) / np.linalg.norm(axis))
        if abs(abs(cosine) - 1.0) < 1e-9 and coordinate not in (c for c, _ in out.values()):
            out[spec.name] = (coordinate, math.copysign(1.0, cosine))
    return out


def wear_sto_columns(steps, monitors, motion_times: Sequence[float]) -> dict[str, list[float]]:
    """The data columns of a wear run's torque.sto (STO_NOTE): motion_time [s] (`motion_times`, one per record),
    <monitor>_moment per monitor [N m] and <coordinate>_moment per monitor with an OpenSim coordinate
    (`opensim_coordinates`; left out when a monitor's column already has the name)."""
    columns = {"motion_time": [float(t) for t in motion_times]}
    columns.update({f"{spec.name}_moment": [s.torques[spec.name] for s in steps] for spec in monitors})
    for name, (coordinate, sign) in opensim_coordinates(monitors).items():
        columns.setdefault(f"{coordinate}_moment", [-sign * s.torques[name] for s in steps])
    return columns


def _sto_note_lines(header_note: str) -> list[str]:
    """The comment lines of a .sto header (ValueError naming header_note if a line could be read as a header
    key: OpenSim reads "key=value" lines before endheader as metadata)."""
    lines = [line.rstrip() for line in header_note.splitlines()]
    for line in lines:
        if "=" in line or line.strip().lower() == "endheader":
            raise ValueError(f"header_note: a comment line may not contain '=' nor be 'endheader' (OpenSim would "
                             f"read it as a header key), got {line!r}")
    return lines


def write_sto(path: str | Path, times: Sequence[float], columns: Mapping[str, Sequence[float]],
              comm: MPI.Comm = MPI.COMM_WORLD, header_note: str = "") -> None:
    """Write joint moments in OpenSim's storage format (.sto, rank 0 writes; all ranks pass the same data):

        <file stem>                  the table's name
        version=1
        nRows=<len(times)>
        nColumns=<1 + len(columns)>  (time included)
        inDegrees=no
        <the lines of header_note>   the sign convention and units, e.g. "Units are S.I. units (second, N m)"
        endheader
        time<TAB><name><TAB>...      then one row per time, tab-separated

    `times` [s] (non-decreasing, finite), `columns` {name: values (len(times),)} [N m], named
    "<joint>_moment" (no whitespace; "time" is taken). Errors name the offending parameter."""
    t = np.asarray(times, dtype=float).reshape(-1)
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0.0):
        raise ValueError("times must be finite and non-decreasing [s]")
    table = [t]
    for name, values in columns.items():
        if not name or any(c.isspace() for c in name) or name == "time":
            raise ValueError(f"columns: a column name must be non-empty, without whitespace and not 'time', "
                             f"got {name!r}")
        v = np.asarray(values, dtype=float).reshape(-1)
        if len(v) != len(t):
            raise ValueError(f"columns[{name!r}]: expected {len(t)} values (one per time), got {len(v)}")
        table.append(v)
    notes = _sto_note_lines(header_note)
    if comm.rank != 0:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = [path.stem, "version=1", f"nRows={len(t)}", f"nColumns={len(table)}", "inDegrees=no", *notes,
              "endheader", "\t".join(["time", *columns])]
    rows = ["\t".join(f"{x:.10g}" for x in row) for row in np.column_stack(table)]
    path.write_text("\n".join(header + rows) + "\n")
