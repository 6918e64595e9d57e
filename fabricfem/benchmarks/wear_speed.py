"""The wearer engine's speed against its accuracy: `fabricfem bench wear`.

For each sleeve mesh (I-IV of [Man2006, sec. 5.3]: 10x13 ... 30x39 Q2) the explicit flexion of the default sleeve
(settle 0.4 s under gravity, then 45 deg/s to 57 deg, mu = 0.1) runs with

* `reference`: the former settings (FFCx kernels compiled with dolfinx's default flags
  `-O2`, the element formula's critical step, the reference geometry recomputed at every evaluation of the
  internal force, no mass scaling): the baseline of every ratio, measured in the same run;
* `kernels`: the shell kernels compiled with fabricfem.forms.jit.KERNEL_FLAGS;
* `eigenvalue step`: `kernels` with the critical step from the largest eigenvalue of the assembled system instead of
  the element formula (fabricfem.dynamics.stability.max_frequency), dt = 0.8 of it;
* `quadrature geometry`: `eigenvalue step` with the reference geometry evaluated once at the quadrature points and
  the coefficients packed once (fabricfem.shell_reference);
* `safety 0.9`: `quadrature geometry` with dt = 0.9 of the eigenvalue's critical step (the sleeve route's
  default, fabricfem.dynamics.stability.STEP_SAFETY);
* `hand kernel`: `safety 0.9` with the internal force by the hand-written C kernel (fabricfem.forms.naghdi_kernel)
  instead of FFCx's;
* `compiled contact`: `hand kernel` with the explicit contact step by the compiled loops (fabricfem.contact.compiled)
  instead of numpy: the default now;
* `mass xS`: the default plus mass scaling S (fabricfem.dynamics.explicit: every lumped mass x S, the weight and
  the damping of the physical mass, critical step x sqrt(S)).

and the pants scene (`pants`: scenes/pants_walk.toml, donning and four strides, or a walk cut to `duration`) with
the same variants (their [route] keys). Run under `mpirun -n 2` for the 2-core figures.

Per run: wall time of the run with its set-up (mesh, forms, the eigenvalue of the critical step; the kernels are
compiled before the clock runs), explicit steps, ms per step, the breakdown of
fabricfem.wear.engine.step_breakdown (of the flexion loop), the largest kinetic / strain energy ratio of the
flexion records (the quasi-static check of explicit codes) and the accuracy of the resisting elbow torque curve
against the reference's: RMS over the records from 10 to 57 deg of (T - T_ref), divided by the mean |T_ref| over
them (the speed study's measure; its bound is 3 %); for the pants the relative difference of the mean magnitude
of the right-knee moment over the walk (`mean_moment_error`: the walk is chaotic, record by record two runs part
after a few records). Times are medians over `repeats` runs of each variant, the variants
alternating so that the machine's load spreads over all of them; speed-ups are ratios of medians against
`reference` on the same mesh and communicator.

Writes wear_speed.csv (one row per mesh and variant) and wear_speed.png (speed-up against torque error) under
`out` (rank 0). SI units; times in seconds.
"""
from __future__ import annotations

import csv
import math
import statistics
import time
import tomllib
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.contact.explicit import numpy_contact
from fabricfem.forms.jit import DOLFINX_DEFAULT_FLAGS, KERNEL_FLAGS, kernel_flags
from fabricfem.scenes.build import build_wear_run
from fabricfem.scenes.schema import Scene
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.engine import TIMING_PARTS, kinetic_ratio
from fabricfem.wear.outputs import torque_rms_error
from fabricfem.wear.run import build_run

MESHES = {"I": (10, 13), "II": (15, 20), "III": (20, 26), "IV": (30, 39)}
PANTS = "pants"          # the case of scenes/pants_walk.toml
PANTS_SCENE = Path(__file__).resolve().parents[2] / "scenes" / "pants_walk.toml"
# variant -> (compiler flags of the shell kernels, SleeveConfig changes, internal force: FORCES, contact: CONTACTS)
ESTIMATED_STEP = {"critical_step": "estimate"}
EIGENVALUE_STEP = {"critical_step": "eigenvalue", "time_step_safety": 0.8}
SAFETY_09 = {"critical_step": "eigenvalue", "time_step_safety": 0.9}
# how the shell's internal force is evaluated (ShellModel.use_internal_force): the reference geometry recomputed at
# every evaluation (FFCx), at the quadrature points with FFCx's kernel, or with the hand-written kernel (the default)
PER_EVALUATION, QUADRATURE_FFCX, HAND = "per evaluation", "quadrature, FFCx", "hand kernel"
FORCES = {PER_EVALUATION: "ffcx", QUADRATURE_FFCX: "ffcx-quadrature", HAND: "kernel"}
# how the explicit Lagrange contact step runs: numpy, or the compiled loops (the default)
NUMPY, COMPILED = "numpy", "compiled"
CONTACTS = {NUMPY: numpy_contact, COMPILED: nullcontext}
VARIANTS = {"reference": (DOLFINX_DEFAULT_FLAGS, ESTIMATED_STEP, PER_EVALUATION, NUMPY),
            "kernels": (KERNEL_FLAGS, ESTIMATED_STEP, PER_EVALUATION, NUMPY),
            "eigenvalue step": (KERNEL_FLAGS, EIGENVALUE_STEP, PER_EVALUATION, NUMPY),
            "quadrature geometry": (KERNEL_FLAGS, EIGENVALUE_STEP, QUADRATURE_FFCX, NUMPY),
            "safety 0.9": (KERNEL_FLAGS, SAFETY_09, QUADRATURE_FFCX, NUMPY),
            "hand kernel": (KERNEL_FLAGS, SAFETY_09, HAND, NUMPY),
            "compiled contact": (KERNEL_FLAGS, SAFETY_09, HAND, COMPILED),
            "mass x4": (KERNEL_FLAGS, {"mass_scale": 4.0}, HAND, COMPILED),
            "mass x16": (KERNEL_FLAGS, {"mass_scale": 16.0}, HAND, COMPILED)}
COLUMNS = ("mesh", "variant", "ranks", "runs", "steps", "ms_per_step", "wall_s", "speedup", "step_speedup",
           *(f"{p}_share" for p in TIMING_PARTS), "kinetic_ratio", "torque_rms_error", "torque_final_Nm")


@dataclass
class Measured:
    """The runs of one variant on one mesh."""

    walls: list = field(default_factory=list)        # s, per run
    steps: int = 0
    shares: list = field(default_factory=list)       # per run: part -> share of the flexion loop
    angles: np.ndarray | None = None                 # deg, records of the last run
    torques: np.ndarray | None = None                # N m
    kinetic_ratio: float = 0.0


def pants_moment(history) -> tuple[np.ndarray, np.ndarray]:
    """(body times [s], magnitude of the right-knee moment [N m]) of the motion records of a pants run (the
    scene's three knee monitors: the thesis's moment magnitude)."""
    motion = [s for s in history.steps if s.phase == "motion"]
    return np.array([s.time for s in motion]), np.array([right_knee_moment(s.torques) for s in motion])


def right_knee_moment(torques: dict[str, float]) -> float:
    """Magnitude [N m] of the right-knee moment from the monitors named knee_r* (their components)."""
    return math.sqrt(sum(v ** 2 for k, v in torques.items() if k.startswith("knee_r")))


def csv_moment(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """`pants_moment` of a finished run's torque.csv (fabricfem.wear.outputs): (times [s], magnitude of the
    right-knee moment [N m]) over the motion records, e.g. the mean of `fabricfem run scenes/pants_walk.toml`:
    `python -c "from fabricfem.benchmarks.wear_speed import csv_moment; print(csv_moment('DIR/torque.csv')[1].mean())"`."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["phase"] == "motion"]
    if not rows:
        raise ValueError(f"path: {path} has no motion records")
    keys = [k for k in rows[0] if k.endswith("_torque_Nm")]
    return (np.array([float(r["time_s"]) for r in rows]),
            np.array([right_knee_moment({k: float(r[k]) for k in keys}) for r in rows]))


def mean_moment_error(moments: np.ndarray, ref_moments: np.ndarray) -> float:
    """|mean M - mean M_ref| / mean M_ref over the walk: the pants' accuracy measure (the walk amplifies round-off
    threefold per record, docs/studies/pants.md, so two runs agree in their statistics, not record by record)."""
    return float(abs(np.mean(moments) - np.mean(ref_moments)) / np.mean(ref_moments))


def build_case(case: str, variant: str, final_angle: float, duration: float | None, comm: MPI.Comm):
    """The explicit run of a sleeve mesh (SleeveConfig, flexion to `final_angle` [deg]) or of the pants scene
    (scenes/pants_walk.toml, its walk cut to `duration` [s] if given) with the variant's flags and settings."""
    flags, changes, force, contact = VARIANTS[variant]
    with kernel_flags(flags), CONTACTS[contact]():
        if case == PANTS:
            data = tomllib.loads(PANTS_SCENE.read_text())
            data.setdefault("route", {}).update(changes)
            if duration is not None:
                data["motion"]["duration"] = float(duration)
            run = build_wear_run(Scene(data, PANTS_SCENE, "wear"), comm)[0]
        else:
            n_around, n_along = MESHES[case]
            run = build_run(SleeveConfig.of(n_around=n_around, n_along=n_along, final_angle=float(final_angle),
                                            **changes), comm)
    run.model.use_internal_force(FORCES[force])     # before the run's first evaluation of the force
    return run


def run_variant(mesh: str, variant: str, final_angle: float, comm: MPI.Comm,
                duration: float | None = None) -> tuple[float, object, object]:
    """One explicit run: (wall [s] of the run with its set-up, its history, its integrator's step count)."""
    comm.Barrier()
    t0 = time.perf_counter()
    run = build_case(mesh, variant, final_angle, duration, comm)
    history = run.run()
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    steps = run.integrator.step_count
    run.destroy()
    return wall, history, steps


def measure_mesh(mesh: str, variants: list[str], repeats: int, final_angle: float, comm: MPI.Comm,
                 say, duration: float | None = None) -> dict[str, Measured]:
    """`repeats` rounds of every variant on `mesh` (a sleeve mesh or PANTS), alternating."""
    measured = {v: Measured() for v in variants}
    for v in variants:                    # compile every variant's kernels before the clock runs
        build_case(mesh, v, final_angle, 0.02, comm).destroy()
    for k in range(repeats):
        for v in variants:
            wall, history, steps = run_variant(mesh, v, final_angle, comm, duration)
            m = measured[v]
            m.walls.append(wall)
            m.steps = steps
            m.shares.append({p: history.timings[f"{p}_share"] for p in TIMING_PARTS})
            if mesh == PANTS:
                m.angles, m.torques = pants_moment(history)
                records = [s for s in history.steps if s.phase == "motion"]
            else:
                m.angles, m.torques = history.motion_curve("elbow")
                records = [s for s in history.steps if s.phase == "motion"]
            m.kinetic_ratio = kinetic_ratio(np.array([s.kinetic_energy for s in records]),
                                            np.array([s.strain_energy for s in records]))
            say(f"  {mesh}, {v}, run {k + 1}/{repeats}: {wall:.1f} s, {steps} steps, "
                f"{1e3 * wall / steps:.2f} ms/step, torque at {m.angles[-1]:g} {'s' if mesh == PANTS else 'deg'} "
                f"{m.torques[-1]:.4e} N m")
    return measured


def rows_of(mesh: str, measured: dict[str, Measured], ranks: int) -> list[list]:
    """CSV rows of one mesh: medians, ratios against `reference`, torque errors against `reference`'s curve."""
    ref = measured["reference"]
    ref_wall = statistics.median(ref.walls)
    ref_step_ms = ref_wall / ref.steps
    rows = []
    for v, m in measured.items():
        wall = statistics.median(m.walls)
        shares = [statistics.median(s[p] for s in m.shares) for p in TIMING_PARTS]
        error = (mean_moment_error(m.torques, ref.torques) if mesh == PANTS
                 else torque_rms_error(m.angles, m.torques, ref.angles, ref.torques))
        rows.append([mesh, v, ranks, len(m.walls), m.steps, 1e3 * wall / m.steps, wall, ref_wall / wall,
                     ref_step_ms / (wall / m.steps), *shares, m.kinetic_ratio, error, float(m.torques[-1])])
    return rows


def plot(path: Path, rows: list[list]):
    """Speed-up against the torque curve's RMS error, one marker per mesh and variant, the 3 % bound."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    markers = dict(zip(VARIANTS, "osvP*D^"))
    for mesh in dict.fromkeys(r[0] for r in rows):
        for r in (r for r in rows if r[0] == mesh):
            ax.scatter(max(100.0 * r[-2], 1e-3), r[7], marker=markers.get(r[1], "x"),
                       label=f"mesh {mesh}, {r[1]}")
    ax.axvline(3.0, color="k", ls=":", lw=0.8, label="3 % bound")
    ax.set_xscale("log")
    ax.set_xlabel("torque error against the reference [%]")
    ax.set_ylabel("speed-up against the reference (wall, same run)")
    ax.set_title("explicit wear runs: speed against accuracy\n(sleeve: RMS over 10-57 deg; pants: mean knee moment)",
                 fontsize=10)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def wear_bench(out: str | Path = "results/bench", meshes: tuple[str, ...] = ("I", "III"),
               variants: tuple[str, ...] = tuple(VARIANTS), repeats: int = 3, final_angle: float = 57.0,
               quick: bool = False, comm: MPI.Comm = MPI.COMM_WORLD, duration: float | None = None) -> list[list]:
    """Run the cases (module docstring) and write wear_speed.csv / .png under `out`.
    quick: mesh I to 15 deg, reference and kernels, one run each (smoke test). duration: the pants' walk [s]
    (default: the scene's four strides)."""
    for mesh in meshes:
        if mesh not in MESHES and mesh != PANTS:
            raise ValueError(f"meshes: unknown case {mesh!r}, expected some of {sorted(MESHES) + [PANTS]}")
    if duration is not None and not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be a positive time [s], got {duration!r}")
    for v in variants:
        if v not in VARIANTS:
            raise ValueError(f"variants: unknown variant {v!r}, expected some of {list(VARIANTS)}")
    if isinstance(repeats, bool) or not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    if quick:
        meshes, variants, repeats, final_angle = ("I",), ("reference", "kernels"), 1, 15.0
    variants = ["reference", *(v for v in variants if v != "reference")]
    say = (lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None)
    rows = []
    for mesh in meshes:
        span = (f"donning and the walk{'' if duration is None else f' cut to {duration:g} s'}" if mesh == PANTS
                else f"settle and flexion to {final_angle:g} deg")
        say(f"bench wear: {mesh}, {len(variants)} variants x {repeats} run(s), {span}, on {comm.size} rank(s)")
        rows += rows_of(mesh, measure_mesh(mesh, variants, repeats, final_angle, comm, say, duration), comm.size)
    if comm.rank == 0:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        fio.write_csv(out / "wear_speed.csv", COLUMNS, rows, comm)
        plot(out / "wear_speed.png", rows)
    for r in rows:
        say(f"{r[0]} {r[1]:>15s}: {r[6]:7.1f} s, {r[4]} steps, {r[5]:.2f} ms/step, speed-up {r[7]:.2f} "
            f"(per step {r[8]:.2f}), KE/SE {r[-3]:.3g}, torque error {100 * r[-2]:.2f} %")
    say(f"wrote {Path(out) / 'wear_speed.csv'} and .png")
    return rows
