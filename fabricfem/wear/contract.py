"""The wearer contract: what every route of a garment on a moving wearer gives its callers, and the records it
returns.

Every route (explicit central differences, the garment engine `fabricfem.wear.garment.GarmentRun`; implicit
backward Euler and quasi-static Newton per pose for the arm in a sleeve) is a `WearRun` built from a garment, a
body, the contact and the torque monitors, and returns a `WearHistory` of `WearStep` records; callers (the scene
runner, the recorder, studies) use only these and never branch on the route's name nor sniff attributes. The torque
comes from the contact's torque monitors (fabricfem.contact.torque.TorqueMonitor: one path), the pressure from the
contact's one pressure field (fabricfem.contact.nodal.pressure_function: force per unit deformed cloth area [Pa]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fabricfem.body.pose import Body
from fabricfem.shell import ShellModel
from fabricfem.wear.engine import kinetic_ratio

PA_PER_MMHG = 133.322387415      # Pa per mmHg


@dataclass
class WearStep:
    """One record of a wear run (SI units). Explicit routes: means over the record interval; quasi-static and
    implicit routes: the converged state at the record."""

    phase: str                        # sew | pull | don | belt | settle | motion
    time: float                       # s, body clock
    torques: dict[str, float]         # N m, resisting torque per monitor
    peak_pressure: float              # Pa, on the body per unit deformed cloth area
    peak_segment: str                 # the segment under the peak ("" without contact)
    peak_position: tuple[float, float, float]   # m
    mean_pressure: float              # Pa, over the nodes in contact (area-weighted)
    max_penetration: float            # m
    contact_force: float              # N, |sum of contact forces on the cloth|
    seam_gap: float                   # m, largest distance of stitched nodes
    seam_forces: dict[str, float]     # N/m, mean seam line force per seam
    max_strain: float                 # largest warp/weft Green strain of a vertex (its patch's average)
    time_steps: int                   # time steps since the previous record (0: a Newton route)
    kinetic_energy: float             # J
    strain_energy: float              # J
    wall: float                       # s since the start
    axis_value: float | None = None   # the record on the run's axis (a joint angle [deg]), None: the time
    newton_iterations: int = 0        # Newton iterations since the previous record (Newton routes)
    drag_ratio: float = 0.0           # fictitious drag / contact force left in a relaxed state (quasi-static)
    intersecting_pairs: int | None = None   # pairs of the cloth's triangles that cross (None: not counted)
    layers: dict[str, float] = field(default_factory=dict)   # per garment of several (fabricfem.wear.layers): N, Pa
    sensor_pressure: float = math.nan  # Pa, the largest mean over a sensor's disc (fabricfem.wear.sensor; nan: none)
    max_local_strain: float = math.nan  # largest warp/weft Green strain at a quadrature point (nan: not measured)
    relative_kinetic_energy: float = math.nan   # J, relative to the body's motion (fabricfem.wear.relative_motion)

    @property
    def coordinate(self) -> float:
        """The record's coordinate on the run's axis (time [s] or a joint angle [deg])."""
        return self.axis_value if self.axis_value is not None else self.time

    @property
    def output_time(self) -> float:
        """The record's time coordinate in the output files (the body time [s], increasing)."""
        return self.time

    def work(self) -> str:
        """The solver work of this record: time steps and KE/SE, or Newton iterations."""
        if self.time_steps or not self.newton_iterations:
            ratio = self.kinetic_energy / self.strain_energy if self.strain_energy else 0.0
            return f"steps {self.time_steps:5d}  KE/SE {ratio:.1e}"
        return f"Newton {self.newton_iterations:3d}"

    def line(self) -> str:
        """The record's progress line: phase, time (and axis), torques, peak pressure, seam gap, work."""
        axis = f" ({self.axis_value:6.2f})" if self.axis_value is not None else ""
        torques = "".join(f"  {n} {v:+.4e} N m" for n, v in self.torques.items())
        return (f"{self.phase:6s} t {self.time:7.4f} s{axis}{torques}  peak p {self.peak_pressure / 1e3:7.3f} kPa"
                f"  seam gap {self.seam_gap:.1e} m  penetration {self.max_penetration:.1e} m  {self.work()}")


def largest_local_strain(steps: list[WearStep]) -> float | None:
    """The largest quadrature-point strain [-] of the records that measured it (None: none did)."""
    local = [s.max_local_strain for s in steps if not math.isnan(s.max_local_strain)]
    return max(local) if local else None


@dataclass
class WearHistory:
    """The records (WearStep) of a wear run, with its dofs, wall time [s], timings, the smallest garment-body gap
    at the start [m] and why it stopped early ("" when it reached its end)."""

    name: str
    steps: list[WearStep] = field(default_factory=list, kw_only=True)
    ndofs: int = field(default=0, kw_only=True)
    wall: float = field(default=0.0, kw_only=True)
    timings: dict = field(default_factory=dict, kw_only=True)
    initial_gap: float = field(default=math.nan, kw_only=True)
    failure: str = field(default="", kw_only=True)
    report: dict = field(default_factory=dict, kw_only=True)     # a scene's report of its final state (rank 0)
    verdict: dict = field(default_factory=dict, kw_only=True)    # the plausibility checks (fabricfem.wear.verdict)
    statistics: dict = field(default_factory=dict, kw_only=True)  # windowed means, percentile peaks (wear.statistics)
    wall_split: dict = field(default_factory=dict, kw_only=True)  # the process's wall time by phase (wear.run)
    self_contact: bool = field(default=False, kw_only=True)     # the cloth's contact with itself was on
    sensor_diameter: float | None = field(default=None, kw_only=True)   # m, of the records' sensor_pressure

    @property
    def completed(self) -> bool:
        return not self.failure

    @property
    def warnings(self) -> list[str]:
        """The names of the failed plausibility checks ([] when none failed or none ran)."""
        return list(self.verdict.get("failed", []))

    @property
    def times(self) -> np.ndarray:
        return np.array([s.time for s in self.steps])

    @property
    def coordinates(self) -> np.ndarray:
        """The records' coordinates on the run's axis (a joint angle [deg] or the time [s])."""
        return np.array([s.coordinate for s in self.steps])

    def torque(self, name: str) -> np.ndarray:
        """Resisting torque [N m] of monitor `name` at every record."""
        return np.array([s.torques[name] for s in self.steps])

    def motion_curve(self, name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(coordinate, resisting torque [N m]) of monitor `name` (default: the first monitor) over the motion: the
        last record before the motion (its start state) and every record of the motion."""
        name = name or self.monitors[0]
        first = next((k for k, s in enumerate(self.steps) if s.phase == "motion"), len(self.steps))
        steps = self.steps[max(first - 1, 0):]
        return np.array([s.coordinate for s in steps]), np.array([s.torques[name] for s in steps])

    def torque_at(self, coordinate: float, name: str | None = None) -> float:
        """Resisting torque [N m] of monitor `name` (default: the first) at `coordinate` on the motion (linear
        interpolation)."""
        x, y = self.motion_curve(name)
        return float(np.interp(coordinate, x, y))

    @property
    def monitors(self) -> list[str]:
        return list(self.steps[0].torques) if self.steps else []

    @property
    def seams(self) -> list[str]:
        return list(self.steps[0].seam_forces) if self.steps else []

    @property
    def layer_columns(self) -> list[str]:
        """The per-garment columns of several garments (fabricfem.wear.layers), [] for one garment."""
        return list(getattr(self.steps[0], "layers", {})) if self.steps else []

    @property
    def header(self) -> tuple[str, ...]:
        return ("time_s", "phase", "axis", *(f"{n}_torque_Nm" for n in self.monitors), "peak_pressure_Pa",
                "peak_pressure_mmHg", "peak_segment", "peak_x_m", "peak_y_m", "peak_z_m", "mean_pressure_Pa",
                "max_penetration_m", "contact_force_N", "seam_gap_m", *(f"seam_{n}_N_per_m" for n in self.seams),
                "max_strain", "time_steps", "kinetic_energy_J", "strain_energy_J", "wall_s", "newton_iterations",
                "drag_ratio", "intersecting_pairs", "sensor_pressure_Pa", "max_local_strain", "kinetic_energy_rel_J",
                *self.layer_columns)

    def rows(self) -> list[list]:
        return [[s.time, s.phase, s.coordinate, *s.torques.values(), s.peak_pressure, s.peak_pressure / PA_PER_MMHG,
                 s.peak_segment, *s.peak_position, s.mean_pressure, s.max_penetration, s.contact_force, s.seam_gap,
                 *s.seam_forces.values(), s.max_strain, s.time_steps, s.kinetic_energy, s.strain_energy, s.wall,
                 s.newton_iterations, s.drag_ratio, "" if s.intersecting_pairs is None else s.intersecting_pairs,
                 s.sensor_pressure, s.max_local_strain, s.relative_kinetic_energy,
                 *(s.layers[c] for c in self.layer_columns)]
                for s in self.steps]

    def torque_curves(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Resisting torque [N m] per monitor against the record coordinate, over the motion (`motion_curve`)."""
        return {name: self.motion_curve(name) for name in self.monitors}

    def work(self) -> str:
        steps = sum(s.time_steps for s in self.steps)
        if not steps:
            return f"{sum(s.newton_iterations for s in self.steps)} Newton iterations"
        ratio = kinetic_ratio(np.array([s.kinetic_energy for s in self.steps if s.phase == "motion"]),
                              np.array([s.strain_energy for s in self.steps if s.phase == "motion"]))
        return f"{steps} explicit steps, largest KE/SE in the motion {ratio:.2e}"

    def summary(self) -> dict:
        """Over the motion phase: peak and final per torque monitor (with their time and axis value), pressure
        peak and mean (Pa, kPa, mmHg) with the segment and position of the peak; after the sewing: the largest
        vertex strain and (explicit routes) quadrature-point strain, penetration and seam gap; the dofs, wall time
        [s], explicit step dt_s [s] and the number of steps (fabricfem.scenes.accuracy reads them); `wall_split`:
        the process's wall time by phase (fabricfem.wear.run.wall_split) when the run was made by `fabricfem run`."""
        out: dict = {"records": len(self.steps), "completed": self.completed, "ndofs": self.ndofs,
                     "wall_s": self.wall, "dt_s": self.timings.get("dt"),
                     "time_steps": int(sum(s.time_steps for s in self.steps))}
        if not self.steps:
            return out
        motion = [s for s in self.steps if s.phase == "motion"] or self.steps
        for name in self.monitors:
            out[f"torque_{name}"] = _torque_entry(motion, name)
        out["pressure"] = _pressure_entry(motion, getattr(self, "sensor_diameter", None))
        # strain and penetration once the seams are sewn (sewing draws the panels across the body)
        sewn = [s for s in self.steps if s.phase != "sew"] or self.steps
        out["max_strain"] = max(s.max_strain for s in sewn)
        local = largest_local_strain(sewn)
        if local is not None:
            out["max_local_strain"] = local
        out["max_penetration_m"] = max(s.max_penetration for s in sewn)
        out["max_seam_gap_after_sewing_m"] = max(s.seam_gap for s in sewn)
        counted = [s.intersecting_pairs for s in self.steps if s.intersecting_pairs is not None]
        if counted:     # the independent check of the cloth's state (fabricfem.contact.intersections)
            out["max_intersecting_pairs"] = max(counted)
            out["self_contact"] = bool(getattr(self, "self_contact", False))
        if self.layer_columns:     # several garments: each column's peak over the motion and its final value
            out["layers"] = {c: _peak_entry(motion, c) for c in self.layer_columns}
        out.update(self.report)
        if self.verdict:
            out["verdict"] = self.verdict
        if getattr(self, "wall_split", None):     # (a history pickled before the split has none)
            out["wall_split"] = self.wall_split
        if self.statistics:
            out["statistics"] = self.statistics
            for name in self.monitors:   # the first window's mean, a plain key for plans and sweeps
                out[f"torque_{name}"]["window_mean_Nm"] = self.statistics[f"torque_{name}"]["mean_Nm"][0] \
                    if self.statistics["windows"] else None
        return out


def _torque_entry(motion: list[WearStep], name: str) -> dict:
    """Peak (largest |tau|) and final resisting torque [N m] of monitor `name` over `motion`, with time and axis."""
    tau = np.array([s.torques[name] for s in motion])
    k = int(np.argmax(np.abs(tau)))
    entry = {"peak_Nm": float(tau[k]), "peak_time_s": motion[k].time,
             "final_Nm": float(tau[-1]), "final_time_s": motion[-1].time}
    if motion[k].axis_value is not None:
        entry.update(peak_at=motion[k].axis_value, final_at=motion[-1].axis_value)
    return entry


def _peak_entry(motion: list[WearStep], column: str) -> dict:
    """The largest value of a per-garment column over `motion` with its time, and the final value (N or Pa)."""
    values = np.array([s.layers[column] for s in motion])
    k = int(np.argmax(values))
    return {"peak": float(values[k]), "peak_time_s": motion[k].time, "final": float(values[-1])}


def _pressure_entry(motion: list[WearStep], sensor_diameter: float | None) -> dict:
    """Peak pressure over `motion` with its time, segment and position, the mean over the contact and the largest
    sensor pressure (fabricfem.wear.sensor; None when not measured) [Pa]."""
    peak = motion[int(np.argmax([s.peak_pressure for s in motion]))]
    contact = [s.mean_pressure for s in motion if s.mean_pressure > 0.0]
    mean = float(np.mean(contact)) if contact else 0.0
    sensor = [s.sensor_pressure for s in motion if math.isfinite(s.sensor_pressure)]
    sensor_peak = max(sensor) if sensor else None
    return {"peak_Pa": peak.peak_pressure, "peak_kPa": peak.peak_pressure / 1e3,
            "peak_mmHg": peak.peak_pressure / PA_PER_MMHG, "peak_time_s": peak.time,
            "peak_segment": peak.peak_segment, "peak_position_m": list(peak.peak_position),
            "mean_Pa": mean, "mean_kPa": mean / 1e3, "mean_mmHg": mean / PA_PER_MMHG,
            "sensor_peak_Pa": sensor_peak, "sensor_peak_kPa": None if sensor_peak is None else sensor_peak / 1e3,
            "sensor_diameter_m": sensor_diameter}


class WearRun(Protocol):
    """A garment on a moving wearer, ready to run (SI units; angles in degrees).

    Attributes: `name` (the run's name), `model` (the garment's ShellModel), `body` (the posed wearer),
    `torques` (the torque monitors, fabricfem.wear.garment.TorqueSpec: name, joint, axis, segments),
    `axis_label` (the records' coordinate: "time [s]" or e.g. "elbow angle [deg]")."""

    name: str
    model: ShellModel
    body: Body
    torques: tuple

    @property
    def comm(self) -> MPI.Comm: ...

    @property
    def axis_label(self) -> str: ...

    def describe(self) -> str:
        """One line naming the route and its step (for the run's log)."""

    def run(self, on_step: Callable[[WearStep], None] | None = None, stop_on_failure: bool = True,
            **options) -> WearHistory:
        """Run the motion; `on_step(step)` after every record; returns the history (its `failure` says why a run
        with stop_on_failure=False stopped early). The explicit engine also takes checkpoint options."""

    def pressure_field(self) -> fem.Function:
        """The contact pressure on the body [Pa] per unit deformed cloth area at the last record."""

    def posed_bodies(self, coordinate: float) -> list:
        """The body's ellipsoid segments at a record coordinate (a joint angle [deg] or a time [s])."""

    def body_time(self, step: WearStep) -> float:
        """The body time [s] of record `step`."""

    def motion_time(self, t: float) -> float:
        """The motion's own time [s] (a motion file's) at body time t [s]."""

    def fraction(self, step: WearStep) -> float:
        """The done fraction in [0, 1] of the run at record `step` (progress and time left)."""

    def destroy(self) -> None:
        """Free the PETSc objects of the route."""
