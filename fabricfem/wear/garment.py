"""Any garment on any moving wearer: the explicit wear engine's run of a sewn garment on a posed body.

Inputs (SI units): a garment mesh (fabricfem.meshes: a tube, or panels from a sewing pattern with their
stitches, fabricfem.meshes.pattern), a fabric (fabricfem.materials.Fabric: any law the shell knows), a body
(fabricfem.body.pose.Body: named ellipsoid segments posed from joints and markers by any kinematics source),
and a timeline of phases on one body clock:

    sew     [0, T_sew]                  stitched nodes drawn together (fabricfem.contact.seams), body still
    don     [T_sew, T_sew + T_don]      the body's transverse radii grow from `grow_from` to 1 (the garment is
                                         placed around a thinner body and the body swells into it)
    settle  [.., + T_settle]            the body at rest in its start pose, the garment settles (gravity)
    motion  [.., + T_motion]            the kinematics source runs from its start (delayed by the phases above)

Dynamics: central differences with the lumped mass, mass-proportional damping C = alpha M (of the velocity
relative to the ground, or to the body's motion with damping_frame = "body": fabricfem.contact.body_frame) and
rotary-inertia scaling (fabricfem.dynamics.explicit; the sleeve's settings [Man2006, ch. 5]), contact by
forward-increment Lagrange multipliers or penalty against the body (fabricfem.contact.explicit) and the seams as a second
forward-increment constraint. The step is dt = safety x the estimated critical step, shortened so that a
record interval holds a whole number of steps.

Records (`WearStep`, one per record interval, time-averaged over it): the resisting torque about each
monitored joint (TorqueSpec: tau = a . sum_i (x_i - J) x f_i over the chosen segments' contact forces f_i on
the body [Man2006, ch. 5 intro]; reported as -tau, positive when the garment opposes a right-handed rotation
about the axis), the contact pressure on the body per unit deformed cloth area (peak with its segment and
position, and the mean over the contact area), the largest penetration, the largest seam gap and the seam
line forces, the largest fabric Green strain (warp and weft) of a vertex (its patch's average) and at a quadrature
point, kinetic and strain energy.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI

from fabricfem.body.blend import BlendedStart, smoothstep
from fabricfem.body.blended import BLEND_WIDTH
from fabricfem.body.pose import Body
from fabricfem.body.skin import Skin
from fabricfem.contact.body_frame import DAMPING_FRAMES, BodyFrameDamping
from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.explicit import ExplicitBodyContact
from fabricfem.contact.intersections import intersecting_pairs
from fabricfem.contact.seams import SeamSpec, SeamTies
from fabricfem.contact.self_contact import SelfContact
from fabricfem.dynamics import stability
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.strain_limit import FastProjection
from fabricfem.materials import Fabric
from fabricfem.shell import ShellModel
from fabricfem.wear.contract import WearHistory, WearStep
from fabricfem.wear.engine import Phase, run_phases
from fabricfem.wear.layers import LayerMonitor
from fabricfem.wear.relative_motion import relative_kinetic_energy
from fabricfem.wear.sensor import SENSOR_DIAMETER, sensor_pressure

# the self-contact's penalty spring at most this fraction of the shell's highest frequency: the critical step
# shrinks by at most 1 / sqrt(1 + 0.5^2), 11 % (with the default k_N = 10 E t / h^2 its spring would set the step:
# 1.6x more steps on the sleeve's mesh 40x52); k_N still holds 1 kPa at 50 um of the 1 mm contact distance there
SELF_CONTACT_FREQUENCY = 0.5


@dataclass(frozen=True)
class TorqueSpec:
    """A torque monitor: the resisting torque [N m] about `joint` along `axis` of the contact forces on
    `segments` (the thesis's knee torque counts the segments below the knee)."""

    name: str
    joint: str
    axis: tuple[float, float, float]
    segments: tuple[str, ...]


@dataclass(frozen=True)
class Timeline:
    """The phases of a garment run [s] (module docstring) and the record interval."""

    record_time: float = 0.01
    sewing_time: float = 0.0
    donning_time: float = 0.0
    grow_from: float = 1.0
    settle_time: float = 0.0
    motion_time: float | None = None
    pull_time: float = 0.0
    belt_time: float = 0.0
    end_time: float | None = None        # body time [s] at which the run stops (None: after the motion)

    PHASES = ("sew", "pull", "don", "belt", "settle", "motion")

    def __post_init__(self):
        for key in ("sewing_time", "donning_time", "settle_time", "pull_time", "belt_time"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{key} must be a time >= 0 [s], got {v!r}")
        if not (isinstance(self.record_time, (int, float)) and math.isfinite(self.record_time) and self.record_time > 0):
            raise ValueError(f"record_time must be a positive time [s], got {self.record_time!r}")
        if not (0.0 < self.grow_from <= 1.0):
            raise ValueError(f"grow_from must lie in (0, 1], got {self.grow_from!r}")
        if self.grow_from < 1.0 and self.donning_time == 0.0:
            raise ValueError("donning_time: growing the body (grow_from < 1) needs a donning time > 0 [s]")
        if self.motion_time is not None and not (math.isfinite(self.motion_time) and self.motion_time >= 0.0):
            raise ValueError(f"motion_time must be a time >= 0 [s], got {self.motion_time!r}")
        if self.end_time is not None and not (math.isfinite(self.end_time) and self.end_time > 0.0):
            raise ValueError(f"end_time must be a positive time [s], got {self.end_time!r}")

    def records(self, duration: float) -> int:
        """Whole record intervals covering `duration` [s]."""
        return math.ceil(duration / self.record_time - 1e-9)

    def durations(self, motion_time: float) -> dict[str, float]:
        """Duration [s] of each phase in order (PHASES), the motion's given."""
        return {"sew": self.sewing_time, "pull": self.pull_time, "don": self.donning_time, "belt": self.belt_time,
                "settle": self.settle_time, "motion": motion_time}

    def motion_length(self, kinematics) -> float:
        """Length [s] of the motion phase: `motion_time`, else the kinematics source's time range."""
        if self.motion_time is not None:
            return self.motion_time
        return kinematics.time_range[1] - kinematics.time_range[0]

    def phase_records(self, motion_time: float) -> dict[str, int]:
        """Record intervals of each phase in order (PHASES), the motion's length [s] given; the phases are cut at
        `end_time` (a run that stops early: the accuracy pilots' window)."""
        out, left = {}, (math.inf if self.end_time is None else self.records(self.end_time))
        for name, duration in self.durations(motion_time).items():
            out[name] = min(self.records(duration), left)
            left -= out[name]
        return out

    def start_of(self, phase: str) -> float:
        """Body time [s] at which `phase` starts (whole record intervals of the phases before it)."""
        before = self.PHASES[:self.PHASES.index(phase)]
        durations = self.durations(0.0)
        return sum(self.records(durations[p]) for p in before) * self.record_time


@dataclass(frozen=True)
class ExplicitSettings:
    """Central-difference settings (the sleeve's defaults, fabricfem.wear.config.RouteSpec)."""

    mass_damping: float = 10.0                 # alpha [1/s]
    stiffness_damping: float = 0.0             # beta [s] of beta K_M(d): damps deformation only
    rotary_inertia_scale: float = 100.0        # s >= 1
    time_step_safety: float = 0.8              # dt = safety x estimated critical step
    # omega_max by fabricfem.dynamics.stability.max_frequency: the element formula, whose margin the pants' obstacle
    # crossing needs (with the eigenvalue step they blew up at t = 5.07 s; docs/findings/2026-11-26-critical-step.md)
    critical_step: str = "estimate"
    mass_scale: float = 1.0                    # S >= 1 on every lumped mass (CentralDifference), dt x sqrt(S)
    gravity: tuple[float, float, float] | None = (0.0, 0.0, -9.81)   # m/s^2, None: off
    # what the mass damping's velocity is relative to: "ground" (C v) or "body" (C (v - v_body), the rigid velocity
    # of the body's segments at each node: no drag on a garment carried along; fabricfem.contact.body_frame)
    damping_frame: str = "ground"


class DelayedKinematics:
    """A kinematics source held in its start pose until `t0` [s], run from its own start after it and held in
    its end pose after its end."""

    def __init__(self, source, t0: float):
        self.source, self.t0 = source, float(t0)
        self.names = source.names
        start, end = source.time_range
        self._start, self._end = start, end
        self.time_range = (0.0, self.t0 + end - start)

    def positions(self, t: float) -> dict[str, np.ndarray]:
        """The source's positions at its own time start + (t - t0), held at its start before t0 and at its end
        after it (the explicit contact poses the body one step ahead of the last record)."""
        return self.source.positions(min(self._start + max(float(t) - self.t0, 0.0), self._end))

    def inner_time(self, t: float) -> float:
        """The source's own time [s] at time t [s]: start + (t - t0), not held (before its start before t0)."""
        return self._start + float(t) - self.t0


@dataclass
class GarmentRun:
    """A garment on a moving wearer set up for the explicit engine (the wearer contract,
    fabricfem.wear.contract.WearRun; `build_garment_run`)."""

    name: str
    model: ShellModel
    body: Body
    contact: ExplicitBodyContact
    seams: SeamTies | None
    integrator: CentralDifference
    timeline: Timeline
    phases: list[Phase]
    dt: float
    dt_estimate: float
    steps_per_record: int
    torques: tuple[TorqueSpec, ...]
    config: object = None
    strain: FastProjection | None = None
    axis: tuple[str, Callable[[float], float]] | None = None   # (label, motion time [s] -> value), e.g. an angle
    handles: tuple = ()          # the donning handles (fabricfem.contact.handles)
    safety: float = 0.8          # dt = safety x the estimated critical step
    _last_strain: float = 0.0    # largest Green strain of the last record (adaptive_steps)
    _steps_now: int = 0          # steps per record in use
    self_contact: SelfContact | None = None   # the cloth-cloth contact hook (None: the cloth may pass through itself)
    _surface: ClothSurface | None = None      # the cloth's triangulation of the intersection count
    _stitched: np.ndarray | None = None       # its node labels, one per point of the cloth (seams' stitched nodes)
    layers: LayerMonitor | None = None        # the monitors per garment of several garments (fabricfem.wear.layers)
    sensor_diameter: float = SENSOR_DIAMETER  # m, the disc of the records' sensor pressure (fabricfem.wear.sensor)

    @property
    def axis_label(self) -> str:
        """The label of the records' coordinate: "time [s]" or the axis's (e.g. "elbow angle [deg]")."""
        return "time [s]" if self.axis is None else self.axis[0]

    @property
    def body_damping(self) -> BodyFrameDamping | None:
        """The hook of the mass damping relative to the body (damping_frame "body"), None in the ground frame."""
        return next((h for h in self.integrator.contact if isinstance(h, BodyFrameDamping)), None)

    @property
    def motion_start(self) -> float:
        """Body time [s] at which the motion phase starts."""
        return self.timeline.start_of("motion")

    @property
    def comm(self) -> MPI.Comm:
        return self.model.comm

    @property
    def duration(self) -> float:
        return sum(p.records for p in self.phases) * self.timeline.record_time

    def describe(self) -> str:
        phases = ", ".join(f"{p.name} {p.records * self.timeline.record_time:.3g} s" for p in self.phases if p.records)
        return (f"explicit central differences, dt = {self.dt:.3g} s (estimated critical step {self.dt_estimate:.3g} s), "
                f"{self.steps_per_record} steps per record of {self.timeline.record_time:g} s; phases: {phases}")

    def axis_at(self, t: float, phase: Phase | None = None) -> float | None:
        """The axis value at body time t [s] (its value at the motion's start before the motion), or None."""
        if self.axis is None:
            return None
        # rounded to 1e-9 of the axis unit: t = n dt carries round-off the record's nominal coordinate does not
        return round(self.axis[1](max(t - self.motion_start, 0.0) if phase is None or phase.name == "motion" else 0.0),
                     9)

    def motion_time(self, t: float) -> float:
        """The motion's own time [s] at body time t [s]: the time of the kinematics source the run was given (a
        motion file's time) through the delay of the phases before the motion (DelayedKinematics) and a blend
        from the standing pose (fabricfem.body.blend.BlendedStart); before the motion's first frame (negative
        from a file's start at 0) in the phases before it."""
        source, time_s = self.body.kinematics, float(t)
        while isinstance(source, (DelayedKinematics, BlendedStart)):
            time_s = source.inner_time(time_s)
            source = source.source if isinstance(source, DelayedKinematics) else source.motion
        return time_s

    def time_at(self, coordinate: float) -> float:
        """Body time [s] of a record coordinate (the inverse of the axis on the motion phase, by bisection of
        the monotonic axis; the coordinate itself when the axis is time)."""
        if self.axis is None:
            return float(coordinate)
        lo, hi = 0.0, self.phases[-1].records * self.timeline.record_time
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.axis[1](mid) < coordinate else (lo, mid)
        return self.motion_start + 0.5 * (lo + hi)

    def pressure_field(self):
        """Contact pressure on the body [Pa] per unit deformed cloth area, mean over the last record."""
        return self.contact.pressure_field()

    def active_segments(self, coordinate: float) -> np.ndarray:
        """(S,) bool over `body.segments`: the segments in the body at the record coordinate (time [s] or the axis
        value); False for one removed for the donning."""
        if self.contact.segment_active is None:
            return np.ones(len(self.body.segments), dtype=bool)
        return np.asarray(self.contact.segment_active(self.time_at(coordinate)), dtype=bool)

    def posed_bodies(self, coordinate: float) -> list:
        """The body's segments as the contact sees them at the record coordinate (time [s] or the axis value;
        grown, inactive ones left out: `active_segments`)."""
        bodies = self.contact.body_at(self.time_at(coordinate))
        return [e for e, on in zip(bodies, self.active_segments(coordinate)) if on]

    def adaptive_steps(self) -> int:
        """Steps of the next record interval, with dt set for it: the St. Venant-Kirchhoff membrane stiffens under
        stretch, its tangent modulus E (1 + 3 E_g) at the Green strain E_g (dP/dlambda of P = E lambda
        (lambda^2 - 1) / 2), so the critical step estimated on the reference state, dt_est [Man2006, eq. 2.87],
        shrinks by sqrt(1 + 3 E_g). When the step in use comes within 5 % of dt_est / sqrt(1 + 3 E_g) at the
        largest strain of the last record, the record interval is split into more, shorter steps (dt = safety x
        that estimate); a garment that relaxes returns to the initial step. Without a strain meter: the fixed
        steps."""
        base = self.steps_per_record
        if self.strain is None or self._last_strain <= 0.0:
            n = base
        else:
            limit = self.dt_estimate / math.sqrt(1.0 + 3.0 * self._last_strain)
            record_time = self.timeline.record_time
            n = base if record_time / base < 0.95 * limit else max(base, math.ceil(record_time / (self.safety * limit)))
        if n != self._steps_now:
            self._steps_now = n
            self.integrator.set_time_step(self.timeline.record_time / n)   # tells the seams and hooks too
        return n

    def step_state(self) -> dict:
        """The adaptive step for a checkpoint: the last record's largest Green strain and the steps per record in
        use (they set dt, which the integrator's own state does not hold)."""
        return {"last_strain": self._last_strain, "steps_now": self._steps_now}

    def restore_steps(self, state: dict) -> None:
        """The adaptive step of `step_state` back, with the integrator's dt = record_time / steps per record [s]."""
        self._last_strain = float(state["last_strain"])
        if state["steps_now"] != self._steps_now:
            self._steps_now = int(state["steps_now"])
            self.integrator.set_time_step(self.timeline.record_time / self._steps_now)

    def body_time(self, step: WearStep) -> float:
        """The body time [s] of record `step`."""
        return step.time

    def _note_strain(self, strain: float) -> float:
        """Keep the record's largest strain for the next interval's step (`adaptive_steps`)."""
        self._last_strain = float(strain)
        return strain

    def fraction(self, step: WearStep) -> float:
        """The done fraction of the run at record `step` (body time over the run's duration)."""
        return step.time / self.duration

    def destroy(self) -> None:
        self.integrator.destroy()
        if self.strain is not None:
            self.strain.destroy()

    def intersections(self, d: np.ndarray) -> int:
        """The number of intersecting triangle pairs of the cloth at the displacements `d` (local array of W):
        the independent check of fabricfem.contact.intersections on the whole surface, each rank counting its part
        of the pairs, summed over the ranks (all ranks call this); triangles joined by a seam's stitched nodes are
        neighbours (`ClothSurface.stitched`), not counted."""
        if self._surface is None:
            cloth = self.self_contact         # it has the same surface and seams' labels (the same SeamTies)
            self._surface = cloth.surface if cloth is not None else ClothSurface(self.model)
            self._stitched = (cloth.stitched if cloth is not None
                              else self._surface.stitched(self.seams.joined_nodes() if self.seams else None))
        x = self._surface.positions(d)
        part = (self.comm.rank, self.comm.size)
        return int(self.comm.allreduce(intersecting_pairs(x, self._surface.triangles, part, self._stitched),
                                       op=MPI.SUM))

    def _peak(self, pressure: np.ndarray) -> tuple[float, str, tuple, float]:
        """(peak [Pa], segment, position, area-weighted mean over the contact [Pa]) over all ranks."""
        c, comm = self.contact, self.comm
        local_max = float(pressure.max(initial=0.0))
        k = int(np.argmax(pressure)) if len(pressure) else -1
        candidate = (local_max, comm.rank)
        best = comm.allreduce(candidate, op=MPI.MAX)
        segment, position = "", (math.nan,) * 3
        if best[0] > 0.0:
            info = (c.names[int(c.segment[k])], tuple(float(v) for v in c.position[k])) if comm.rank == best[1] else None
            segment, position = comm.bcast(info, root=best[1])
        on = pressure > 0.0
        sums = comm.allreduce(np.array([float(np.sum(pressure[on] * c.area[on])), float(np.sum(c.area[on]))]),
                              op=MPI.SUM)
        return best[0], segment, position, (sums[0] / sums[1] if sums[1] > 0 else 0.0)

    def run(self, on_step: Callable[[WearStep], None] | None = None, stop_on_failure: bool = True,
            checkpoint=None, resume: bool = False, recorder=None,
            should_stop: Callable[[], str] | None = None) -> WearHistory:
        """Run the phases; `on_step(step)` after every record; returns the history (module docstring).

        `checkpoint` (fabricfem.wear.checkpoint.Checkpoint): written every `checkpoint.every` records (with the
        `recorder`'s state); `resume`: continue from it (the records before it are restored, not rerun);
        `should_stop()`: asked after every record, a non-empty reason ends the run there (an interrupt)."""
        integ, contact, t0 = self.integrator, self.contact, time.perf_counter()
        history = WearHistory(self.name, ndofs=self.model.ndofs)
        integ.initialize(t0=0.0)
        done = 0
        if resume and checkpoint is not None and checkpoint.exists():
            history, done = checkpoint.load(self, recorder)
            history.failure = ""          # the interrupt that ended the saved run
        else:
            history.initial_gap = contact.min_gap(integ.d.getArray(readonly=True), 0.0)
            if history.initial_gap <= 0.0 and self.timeline.grow_from == 1.0:
                raise ValueError(f"body: the body penetrates the garment at the start (min gap "
                                 f"{history.initial_gap:.3e} m); place the garment around it or grow the body "
                                 f"(donning grow_from < 1)")
        history.timings = {"dt": self.dt, "dt_estimate": self.dt_estimate}
        history.self_contact = self.self_contact is not None
        history.sensor_diameter = self.sensor_diameter

        def record(phase: Phase, k: int, steps: int) -> WearStep:
            means = contact.mean_torques()
            d = integ.d.getArray(readonly=True)
            pressure = self.pressure_field().x.array[contact.nodes.node_index[contact.moving]]
            peak, segment, position, mean = self._peak(pressure)
            sensor = sensor_pressure(contact.reference + d[contact.dofs], pressure, contact.current_areas(),
                                     self.sensor_diameter, self.comm)
            strains = self.strain.strain_summary() if self.strain is not None else {"max_warp": 0.0, "max_weft": 0.0}
            local = self.strain.point_strain_max() if self.strain is not None else math.nan
            return WearStep(
                phase=phase.name, time=integ.t, torques={s.name: -means[s.name] for s in self.torques},
                peak_pressure=peak, peak_segment=segment, peak_position=position, mean_pressure=mean,
                max_penetration=contact.max_penetration(d, integ.t),
                contact_force=float(np.linalg.norm(contact.total_force())),
                seam_gap=self.seams.max_gap(d) if self.seams else 0.0,
                seam_forces=self.seams.line_forces() if self.seams else {},
                max_strain=self._note_strain(max(strains["max_warp"], strains["max_weft"])), time_steps=steps,
                kinetic_energy=integ.kinetic_energy(), strain_energy=integ.strain_energy(),
                wall=time.perf_counter() - t0, axis_value=self.axis_at(integ.t, phase),
                intersecting_pairs=self.intersections(d),
                layers=self.layers.values(pressure, contact) if self.layers is not None else {},
                sensor_pressure=sensor, max_local_strain=local,
                relative_kinetic_energy=relative_kinetic_energy(integ, contact, integ.t))

        save = None
        if checkpoint is not None:
            def save(n: int) -> None:
                if n % checkpoint.every == 0:
                    checkpoint.save(self, history, n, recorder)
        history.timings.update(run_phases(integ, contact, self.phases, self.adaptive_steps, record, history,
                                          on_step, stop_on_failure, timed=lambda p: p.name == "motion",
                                          label=self.name, start_record=done, after_record=save,
                                          should_stop=should_stop))
        history.wall = time.perf_counter() - t0
        return history


def _follow_schedule(contact: ExplicitBodyContact, posed: Body) -> None:
    """The contact sees the body's segment schedule: segments switched off, and returning ones regrowing."""
    if posed.schedule is None:
        return
    names = list(posed.segments)
    contact.segment_active = lambda t: np.isin(names, posed.active(t))
    if posed.schedule.regrow_time > 0.0:
        contact.segment_size = lambda t: posed.schedule.sizes(names, t)


def build_garment_run(name: str, fmesh, fabric: Fabric, body: Body, *, seams: Sequence[SeamSpec] = (),
                      holds: Sequence[str] = (), clamped: Sequence[str] = (), torques: Sequence[TorqueSpec] = (), timeline: Timeline = Timeline(),
                      settings: ExplicitSettings = ExplicitSettings(), contact_method: str = "lagrange",
                      friction: float = 0.0, penalty: float | None = None,
                      psri_degrees: tuple[int, int] = (4, 2), measure_strain: bool = True,
                      config: object = None, axis: tuple[str, Callable[[float], float]] | None = None,
                      handles: Sequence[Callable[[ShellModel], object]] = (), blend_width: float = BLEND_WIDTH,
                      skin: Skin | None = None, self_contact: bool = False,
                      self_contact_distance: float | None = None, self_friction: float = 0.0,
                      self_contact_passes: int = 0, impact_zones: bool = False) -> GarmentRun:
    """Shell, seams, body contact, monitors, integrator and phases of a garment run (module docstring).

    Args:
        fmesh: the garment mesh (FabricMesh; Q2 quadrilaterals for the nodal contact); `holds` names its
            facet tags whose nodes are held in place (u = 0), `clamped` those of them whose rotations are held too.
        body: the wearer; its kinematics start after the sewing, donning and settling phases.
        seams: the stitches to sew and hold (fabricfem.contact.seams); sewn during `timeline.sewing_time`.
        torques: the torque monitors (their segments and joints are checked against the body).
        body.schedule (fabricfem.body.schedule.SegmentSchedule, on the run's clock): segments switched off while
            the garment goes on (the thesis removes the feet); they take no contact while off.
        axis: (label, motion time [s] -> value): the records' coordinate (e.g. the elbow angle [deg]); None: time.
        handles: builders model -> hook of the donning handles (fabricfem.contact.handles: EdgeGrip during the
            pull phase, Belt from the belt phase), applied after the seams and before the body contact.
        blend_width: the width [m] of the blend joining the segments (fabricfem.body.blended); skin: another skin.
        self_contact: the cloth against itself (contact.self_contact.SelfContact, the seams join the panels), with
            self_contact_distance d_c [m] (default thickness), self_friction mu, self_contact_passes, impact_zones.
    """
    if fabric.density <= 0.0:
        raise ValueError("density: the explicit engine needs a positive fabric density [kg/m^3]")
    for spec in torques:
        try:
            body.check_joint(spec.joint)
            body.check_segments(spec.segments)
        except ValueError as exc:
            raise ValueError(f"torques.{spec.name}: {exc}") from None
    model = ShellModel(fmesh, fabric, rebase=False, psri_degrees=psri_degrees)
    for tag in holds:
        model.constrain(tag, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0) if tag in clamped else None)
    if settings.gravity is not None:
        model.add_gravity(tuple(settings.gravity))
    model.compile()
    motion_time = timeline.motion_length(body.kinematics)
    posed = Body(list(body.segments.values()), DelayedKinematics(body.kinematics, timeline.start_of("motion")),
                 body.schedule)
    if skin is not None and hasattr(skin, "with_body"):     # a rigged mesh skin moves with the run's clock
        skin = skin.with_body(posed)
    contact = ExplicitBodyContact(model, posed, friction=friction, method=contact_method, penalty=penalty,
                                  blend_width=blend_width, skin=skin)
    for spec in torques:
        contact.track_torque(spec.name, spec.joint, spec.axis, spec.segments)
    if timeline.grow_from < 1.0:
        t_don0, t_don = timeline.start_of("don"), timeline.donning_time
        g0 = timeline.grow_from
        contact.transverse_scale = lambda t: g0 + (1.0 - g0) * smoothstep((t - t_don0) / t_don)
        if skin is not None and hasattr(skin, "transverse_scale"):
            skin.transverse_scale = contact.transverse_scale
    _follow_schedule(contact, posed)
    ties = SeamTies(model, seams, sewing_time=timeline.sewing_time) if seams else None
    handles = [make(model) for make in handles]
    cloth = _self_contact(model, ties, self_contact_distance, self_friction, self_contact_passes, self_contact,
                          impact_zones)
    dt_estimate = _critical_step(model, settings, contact, cloth)
    steps_per_record = math.ceil(timeline.record_time / (settings.time_step_safety * dt_estimate))
    dt = timeline.record_time / steps_per_record
    hooks = _hook_order([_frame_hook(settings, contact), ties, *handles], cloth, contact)
    t_sewn = timeline.start_of("pull")
    # the garment's weight acts once it is sewn (panels would fall while their seams close), ramped on over
    # a tenth of the sewing time
    load = 1.0 if t_sewn == 0.0 else (lambda t: smoothstep((t - t_sewn) / (0.1 * t_sewn)))
    integrator = CentralDifference(model, dt, load_factor=load, dt_crit=dt_estimate,
                                   rayleigh=(settings.mass_damping, settings.stiffness_damping),
                                   energy_bound=None, rotary_inertia_scale=settings.rotary_inertia_scale,
                                   mass_scale=settings.mass_scale, contact=hooks)
    phases = [Phase(n, records) for n, records in timeline.phase_records(motion_time).items()]
    strain = FastProjection(model, 1.0) if measure_strain else None
    return GarmentRun(name, model, posed, contact, ties, integrator, timeline, phases, dt, dt_estimate,
                      steps_per_record, tuple(torques), config, strain, axis, tuple(handles),
                      settings.time_step_safety, 0.0, steps_per_record, self_contact=cloth)


def _hook_order(before: list, cloth: SelfContact | None, contact: ExplicitBodyContact) -> list:
    """The explicit hooks in their order: damping frame, seams, handles (`before`, None where absent), then the body
    contact (a seam drawn across the body cannot pull a node into it). The cloth-cloth contact comes before the body
    contact, or after it when it applies impulses (fabricfem.contact.impulses) or impact zones
    (fabricfem.contact.impact_zones): they then see the nodes the body contact has just put on the body and hold
    those (`SelfContact.body`)."""
    hooks = [h for h in before if h is not None]
    if cloth is None:
        return hooks + [contact]
    if cloth.passes or cloth.zones:
        cloth.body = contact
        return hooks + [contact, cloth]
    return hooks + [cloth, contact]


def _frame_hook(settings: ExplicitSettings, contact: ExplicitBodyContact) -> BodyFrameDamping | None:
    """The hook that refers the mass damping to the body's motion (damping_frame "body": its model, posed body, blend
    width and active segments those of the body contact), None in the ground frame; ValueError naming
    `damping_frame` for another value."""
    if settings.damping_frame not in DAMPING_FRAMES:
        raise ValueError(f"damping_frame must be one of {DAMPING_FRAMES}, got {settings.damping_frame!r}")
    if settings.damping_frame == "ground":
        return None
    return BodyFrameDamping(contact.model, contact.body, contact.blend_width, contact.segment_active)


def _critical_step(model: ShellModel, settings: ExplicitSettings, contact: ExplicitBodyContact,
                   cloth: SelfContact | None) -> float:
    """The estimated critical step [s] of the shell with the body contact's and the self-contact's penalty
    springs; the self-contact's k_N first lowered to SELF_CONTACT_FREQUENCY of the shell's highest frequency."""
    omega_shell = stability.max_frequency(model, settings.rotary_inertia_scale, settings.critical_step)
    if cloth is not None:
        cloth.limit_frequency(SELF_CONTACT_FREQUENCY * omega_shell)
    omega = math.hypot(omega_shell, contact.penalty_frequency(), cloth.penalty_frequency() if cloth else 0.0)
    return stability.critical_time_step(model, (settings.mass_damping, settings.stiffness_damping), omega_max=omega,
                                        mass_scale=settings.mass_scale)


def _self_contact(model: ShellModel, ties: SeamTies | None, distance: float | None, friction: float,
                  passes: int = 0, on: bool = True, zones: bool = False) -> SelfContact | None:
    """The cloth-cloth contact hook of a garment (None unless `on`): contact distance `distance` [m] (default the
    thickness), Coulomb `friction`, `passes` of impulses, impact `zones`, the seams' tied node pairs joining the
    panels; a bad value refused naming its scene key."""
    if not on:
        return None
    joined = ties.joined_nodes() if ties is not None else None
    try:
        return SelfContact(model, contact_distance=distance, friction=friction, joined=joined, passes=passes,
                           zones=zones)
    except ValueError as exc:
        key = ("self_contact_distance" if "contact_distance" in str(exc) else
               "self_contact_passes" if "passes" in str(exc) else
               "impact_zones" if "impact_zones" in str(exc) else "self_friction")
        raise ValueError(f"{key}: {exc}") from None
