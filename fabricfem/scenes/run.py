"""`fabricfem run SCENE`: a scene run by its kind (RUNNERS: static, dynamic, wear) into its output folder.

Wear scenes (a garment on a moving wearer) are built by fabricfem.scenes.build into a WearRun
(fabricfem.wear.contract) and run here by fabricfem.wear.run.run_wear; static and dynamic scenes by
fabricfem.scenes.static and fabricfem.scenes.dynamic.
Every run ends with its status in summary.json ("completed" or "stopped early: <why>").
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from mpi4py import MPI

from fabricfem import io
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.scenes.batch import completed, read_summary
from fabricfem.scenes.build import (  # noqa: F401 (public here)
    build_fabric,
    build_model,
    build_wear_run,
    output_dir,
    scene_limb,
    scene_name,
    scene_sha256,
    sleeve_config,
    tube_spec,
)
from fabricfem.scenes.dynamic import CHECKPOINT_EVERY, DynamicCheckpoint, DynamicRun, run_dynamic_scene  # noqa: F401
from fabricfem.scenes.schema import Scene, SceneError
from fabricfem.scenes.static import run_static_scene
from fabricfem.wear.checkpoint import Checkpoint
from fabricfem.wear.compression import compression_report
from fabricfem.wear.contract import WearHistory
from fabricfem.wear.garment import GarmentRun
from fabricfem.wear.run import run_wear
from fabricfem.wear.verdict import EXIT_WARNINGS


@dataclass
class SceneOutcome:
    """What `fabricfem run` did: the runner's result, its status ("completed", "completed with warnings: <failed
    checks>" or "stopped early: <why>") and the output folder; `exit_code` is 0 only for a completed run whose
    plausibility checks passed."""

    result: object
    status: str
    out: Path

    @property
    def exit_code(self) -> int:
        """0 completed, EXIT_WARNINGS (3) completed with failed plausibility checks, 1 stopped early."""
        if self.status == "completed":
            return 0
        return EXIT_WARNINGS if self.status.startswith("completed with warnings") else 1


def run_scene(scene: Scene, comm=MPI.COMM_WORLD, out: Path | None = None, resume: bool = False) -> SceneOutcome:
    """Run a scene by its kind (RUNNERS: static load stepping, dynamic, wear) into its output folder (`out`,
    default [output] dir; io.OutputFolder: the previous run's outputs are removed first, summary.json records the
    status). A wear scene on the explicit engine and a dynamic scene write checkpoints (every CHECKPOINT_EVERY
    records, [dynamics] checkpoint_every) and, with `resume`, continue from the folder's checkpoint
    (fabricfem.wear.checkpoint, `run_dynamic_scene`); `resume` of a folder whose summary.json holds a completed run
    of this scene says so and returns its recorded status (result None), rewriting nothing."""
    if out is not None:
        scene = with_output_dir(scene, out)
    out = output_dir(scene)
    sha_with_output = scene_sha256(scene)
    if resume and (done := _completed_status(out, sha_with_output, comm)):
        if comm.rank == 0:
            print(f"{scene_name(scene)}: the run in {out} is complete ({done}); nothing to resume", flush=True)
        return SceneOutcome(None, done, out)
    sha = scene_sha256(Scene({k: v for k, v in scene.data.items() if k != "output"}, None, scene.kind))
    folder = io.OutputFolder(out, sha_with_output, comm, keep=resume)
    try:
        result = RUNNERS[scene.kind](scene, out, comm, resume, sha)
    except Exception as exc:
        folder.finish(f"failed: {' '.join(str(exc).split())}")
        raise
    failure = result.failure if isinstance(result, (WearHistory, DynamicRun)) else ""
    warnings = result.warnings if isinstance(result, (WearHistory, DynamicRun)) else []
    status = (f"stopped early: {failure}" if failure else
              f"completed with warnings: {', '.join(warnings)}" if warnings else "completed")
    folder.finish(status, result.summary() if isinstance(result, WearHistory) else None)
    return SceneOutcome(result, status, out)


def with_output_dir(scene: Scene, out: Path) -> Scene:
    """The scene with [output] dir = `out` (`fabricfem run --out DIR`, also with --accuracy: its pilots go under
    DIR/accuracy/)."""
    return Scene({**scene.data, "output": {**scene.data.get("output", {}), "dir": str(out)}}, scene.path, scene.kind)


def _completed_status(out: Path, sha256: str, comm) -> str:
    """The status recorded in `out`/summary.json when it holds a completed run of the scene `sha256` ("completed",
    also with warnings), else "" (rank 0 reads, every rank gets it)."""
    status = ""
    if comm.rank == 0 and completed(out, sha256):
        status = str(read_summary(out)["status"])
    return comm.bcast(status, root=0)


def run_wear_scene(scene: Scene, out: Path, comm=MPI.COMM_WORLD, resume: bool = False, sha: str = ""):
    """`fabricfem run` of a wear scene: its WearRun (`build_wear_run`) with progress, the recorder's outputs and
    the summary (fabricfem.wear.run.run_wear); the explicit engine checkpoints and resumes."""
    started = time.perf_counter()
    run, headline, render_at, _ = build_wear_run(scene, comm)
    parsed, report = scene.parsed, None
    if parsed.is_tube_on_limb:
        limb = scene_limb(parsed)
        report = lambda run, history: _compression_report(run, limb, out, scene_name(scene), parsed.output.render)  # noqa: E731
    checkpoint = None
    if isinstance(run, GarmentRun):
        checkpoint = Checkpoint(out, comm, sha or scene_sha256(scene), CHECKPOINT_EVERY)
        if resume and not checkpoint.exists():
            raise SceneError(f"resume: no checkpoint in {out}/checkpoint (run the scene without --resume first)")
    return run_wear(run, out, headline, render_at, scene.parsed.output.render, scene.parsed.output.body_samples,
                    checkpoint, resume, report, parsed.checks, parsed.failure_strain,
                    parsed.output.windows, started)


def _compression_report(run: GarmentRun, limb: Ellipsoid, out: Path, name: str, render: bool) -> dict:
    """The compression report of the final state (fabricfem.wear.compression.compression_report) and its line."""
    report = compression_report(run, limb, out, name, render)
    if report is not None:
        print(f"{name}: pressure on the skin: peak {report['peak_pressure_kPa']:.3f} kPa = "
              f"{report['peak_pressure_mmHg']:.1f} mmHg, mean {report['mean_pressure_kPa']:.3f} kPa = "
              f"{report['mean_pressure_mmHg']:.1f} mmHg; ring nearest the limb's centre: p = T kappa, hoop tension "
              f"T = {report['hoop_tension_N_per_m']:.1f} N/m, largest deviation "
              f"{100 * report['laplace_deviation']:.2f}% of its peak", flush=True)
    return {"compression": report} if report is not None else {}


def _run_static(scene: Scene, out: Path, comm, resume: bool, sha: str):
    """A static scene (no checkpoint: with `resume` it says so and solves from the start)."""
    if resume and comm.rank == 0:
        print(f"{scene_name(scene)}: a static scene has no checkpoint; --resume solves it from the start", flush=True)
    return run_static_scene(scene, comm)


def _run_dynamic(scene: Scene, out: Path, comm, resume: bool, sha: str):
    return run_dynamic_scene(scene, comm, resume, sha)


# scene kind -> runner(scene, out, comm, resume, sha)
RUNNERS = {"static": _run_static, "dynamic": _run_dynamic, "wear": run_wear_scene}
