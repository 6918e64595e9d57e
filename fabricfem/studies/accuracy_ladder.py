"""An accuracy target on a windowed statistic of a wear scene, by the mesh ladder: `fabricfem plan/run SCENE
--accuracy 5% --quantity torque_elbow_window_mean_Nm`.

A windowed mean of a wear run (fabricfem.wear.statistics: a monitor's trapezoid mean over the first [output]
window of the motion) is stable against single slip events where single records are not, but on the meshes the
Richardson pilots of fabricfem.scenes.accuracy use (coarser than the scene's) it is not asymptotic either. So a
target on a windowed statistic uses the convergence ladder of fabricfem.studies.convergence instead: the scene's
garment mesh (level 0) and `[accuracy] finer_levels` levels refined by `[accuracy] ratio` (default
LADDER_RATIO) per level, each running the whole scene (a resumable batch into `<out>/accuracy/ladder/level_k/`,
read back when complete for the same scene). For each level below the finest:

    difference d_k = |q_k - q_finest| / |q_finest|     (q: the windowed statistic of the level's summary.json)

and the coarsest level with d_k <= target is chosen, run into the scene's output folder (with its renders) and
its own difference to the finest level measured again from its summary.json (`accuracy_measured_difference`; the
same number as d_k for a deterministic run on the same number of ranks). The finest level is the reference, not
a candidate: its own error is unknown (a difference to the finest is not an extrapolation; where the ladder has
three or more levels the Richardson estimate of convergence.ladder_rows is printed beside it, or why the ladder is
not asymptotic). No level below the finest within the target: refused naming accuracy.target, with the measured
differences. `[accuracy] window` (cutting the pilots' body time) does not apply: the statistic is over the motion.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

from mpi4py import MPI

from fabricfem import io
from fabricfem.scenes.accuracy import summary_value, target_of
from fabricfem.scenes.batch import read_summary
from fabricfem.scenes.build import scene_name, validate
from fabricfem.scenes.run import SceneOutcome, output_dir, run_scene
from fabricfem.scenes.schema import Scene, SceneError, accuracy_quantities, accuracy_summary_key
from fabricfem.scenes.sections import AccuracySection, section
from fabricfem.studies.convergence import COLUMNS, ladder_rows, mesh_label, run_ladder

WINDOWED_SUFFIX = "_window_mean_Nm"   # accuracy quantities that are windowed statistics
LADDER_RATIO = 1.5                    # default refinement ratio of the ladder (the convergence study's)
HEADER = ("level", "mesh", "ndofs", "value", "difference_to_finest", "wall_s", "chosen")


def quantity_name(scene: Scene, quantity: str | None) -> str | None:
    """The accuracy quantity name of `quantity`, also when given as its summary.json key (e.g.
    "torque_elbow.window_mean_Nm" -> "torque_elbow_window_mean_Nm"); other names unchanged."""
    if quantity is None:
        return None
    names = {key: name for name, key in accuracy_quantities(scene.data).items()}
    return names.get(quantity, quantity)


def uses_ladder(scene: Scene, quantity: str | None) -> bool:
    """Whether an accuracy target on `quantity` (else the scene's [accuracy] quantity) is planned on the ladder: a
    wear scene's windowed statistic."""
    if scene.kind != "wear":
        return False
    name = quantity_name(scene, quantity) or section(AccuracySection, scene.get("accuracy")).quantity
    return isinstance(name, str) and name.endswith(WINDOWED_SUFFIX)


@dataclass
class LadderPlan:
    """The ladder of a windowed statistic: per level (coarse to fine) its scene data, folder, value and difference
    to the finest; the chosen level (None: no level below the finest meets the target) and the convergence rows of
    the quantity's monitor (Richardson estimate or why not)."""

    quantity: str
    target: float
    datas: list[dict]
    folders: list[Path]
    values: list[float]
    differences: list[float]
    ndofs: list[int | None]
    walls: list[float | None]
    chosen: int | None
    note: str = ""
    rows: list[dict] = field(default_factory=list)

    def table(self) -> str:
        """The printed plan: one line per level, the choice and the ladder's note."""
        lines = [f"accuracy plan (mesh ladder): {self.quantity} to {self.target:.3g} relative to the finest level "
                 f"{mesh_label(self.datas[-1])}"]
        for k, (data, value, diff) in enumerate(zip(self.datas, self.values, self.differences)):
            mark = "  <- chosen" if k == self.chosen else ("  (reference)" if k == len(self.datas) - 1 else "")
            lines.append(f"  level {k}  {mesh_label(data):>10s}  {value: .6g}  difference {diff:.2e}{mark}")
        lines.append(f"  {self.note}")
        return "\n".join(lines)

    def plan_rows(self) -> list[list]:
        """Rows of accuracy_plan.csv (HEADER)."""
        return [[k, mesh_label(d), n, v, diff, w, k == self.chosen] for k, (d, v, diff, n, w) in
                enumerate(zip(self.datas, self.values, self.differences, self.ndofs, self.walls))]

    def require(self) -> int:
        """The chosen level; SceneError naming accuracy.target when none meets it."""
        if self.chosen is None:
            measured = ", ".join(f"{mesh_label(d)} {x:.2e}" for d, x in zip(self.datas[:-1], self.differences))
            raise SceneError(f"accuracy.target: no ladder level below the finest ({mesh_label(self.datas[-1])}) is "
                             f"within {self.target:.3g} of it for {self.quantity} (measured: {measured}); give a "
                             f"looser target or more levels (accuracy.finer_levels)")
        return self.chosen


def ladder_plan(scene: Scene, target: float | None = None, quantity: str | None = None,
                comm: MPI.Comm = MPI.COMM_WORLD, say=None) -> LadderPlan:
    """Run (or read back) the ladder and choose the level (module docstring). SceneError naming the key: a
    quantity that is not a windowed statistic of this scene, a missing or bad target, [accuracy] window given."""
    say = say or ((lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None))
    quantity, target = target_of(scene, target, quantity_name(scene, quantity))
    key = accuracy_summary_key(scene.data, quantity)
    if not quantity.endswith(WINDOWED_SUFFIX):
        raise SceneError(f"accuracy.quantity: the mesh ladder plans a windowed statistic (*{WINDOWED_SUFFIX}), "
                         f"got {quantity!r}")
    spec = section(AccuracySection, scene.get("accuracy"))
    if spec.window is not None:
        raise SceneError("accuracy.window: a windowed statistic is compared over the whole motion on the mesh "
                         "ladder; drop --window / [accuracy] window")
    ratio = spec.ratio or LADDER_RATIO
    if spec.finer_levels < 1:
        raise SceneError(f"accuracy.finer_levels: the mesh ladder needs at least one level finer than the scene's "
                         f"mesh, got {spec.finer_levels}")
    root = output_dir(scene) / "accuracy" / "ladder"
    datas, folders = run_ladder(scene, root, spec.finer_levels + 1, ratio, comm=comm, what="accuracy ladder")
    summaries = [read_summary(f) for f in folders]
    values = [summary_value(s, key) for s in summaries]
    if any(v is None or not math.isfinite(v) for v in values) or values[-1] == 0.0:
        raise SceneError(f"accuracy.quantity: {quantity} is missing, not finite or zero on the ladder "
                         f"({dict(zip(map(mesh_label, datas), values))}); check [output] windows")
    differences = [abs(v - values[-1]) / abs(values[-1]) for v in values]
    meeting = [k for k in range(len(values) - 1) if differences[k] <= target]
    monitor = key.split(".")[0][len("torque_"):]
    rows = [r for r in ladder_rows(datas, folders, ratio) if r["monitor"] == monitor] if comm.rank == 0 else []
    note = _richardson_note(rows[-1]) if rows else ""
    result = LadderPlan(quantity, target, datas, folders, values, differences,
                        [s.get("ndofs") for s in summaries], [s.get("wall_s") for s in summaries],
                        meeting[0] if meeting else None, comm.bcast(note, root=0), comm.bcast(rows, root=0))
    say(result.table())
    if comm.rank == 0:
        io.write_csv(root / "convergence.csv", COLUMNS, [[r[c] for c in COLUMNS] for r in rows], MPI.COMM_SELF)
    return result


def _richardson_note(finest: dict) -> str:
    """What Richardson says of the ladder (convergence.ladder_rows' finest row): the extrapolated value and order,
    or why not."""
    if finest["observed_order"] is None and finest["extrapolated_Nm"] is None:
        return f"Richardson: {finest['note']}"
    if finest["note"] != "asymptotic" or finest["extrapolated_Nm"] is None:
        return (f"Richardson: not asymptotic ({finest['note']}); the differences are measured, not estimated "
                f"errors")
    gci = "" if finest["gci"] is None else f" (estimated error of the finest {finest['gci']:.2e})"
    return (f"Richardson: asymptotic, order {finest['observed_order']:.3g}, extrapolated "
            f"{finest['extrapolated_Nm']:.6g}{gci}")


def run_ladder_accurate(scene: Scene, target: float | None = None, quantity: str | None = None,
                        comm: MPI.Comm = MPI.COMM_WORLD) -> tuple[LadderPlan, SceneOutcome]:
    """`fabricfem run SCENE --accuracy X --quantity <windowed statistic>`: the ladder's plan, then the chosen level
    run into the scene's output folder (its [output], renders included); summary.json gains the accuracy_* entries
    (the measured difference to the finest level among them) and accuracy_plan.csv is written beside it."""
    result = ladder_plan(scene, target, quantity, comm)
    k = result.require()
    out = output_dir(scene)
    data = copy.deepcopy(result.datas[k])
    data["output"] = {**scene.get("output", {}), "dir": str(out)}
    data.setdefault("scene", {})["name"] = scene_name(scene)
    outcome = run_scene(validate(data, source=f"accuracy ladder level {k}", path=scene.path), comm)
    key = accuracy_summary_key(scene.data, result.quantity)
    value = comm.bcast(summary_value(read_summary(out), key) if comm.rank == 0 else None, root=0)
    finest = result.values[-1]
    measured = abs(value - finest) / abs(finest) if value is not None else math.nan
    io.update_json(out / "summary.json", {
        "accuracy_quantity": result.quantity, "accuracy_target": result.target, "accuracy_method": "mesh ladder",
        "accuracy_level": k, "accuracy_mesh": mesh_label(data), "accuracy_reference_mesh": mesh_label(result.datas[-1]),
        "accuracy_reference_value": finest, "accuracy_ladder_difference": result.differences[k],
        "accuracy_measured_difference": measured, "accuracy_note": result.note}, comm)
    io.write_csv(out / "accuracy_plan.csv", list(HEADER), result.plan_rows(), comm)
    if comm.rank == 0:
        print(f"accuracy: {result.quantity} = {value:.6g} on {mesh_label(data)}, measured difference {measured:.2e} "
              f"to the finest ladder level {mesh_label(result.datas[-1])} ({finest:.6g}); target {result.target:.3g};"
              f" wrote {out}/accuracy_plan.csv", flush=True)
    return result, outcome
