"""An accuracy target chooses the mesh and the model: `fabricfem plan SCENE --accuracy 2%`, `fabricfem run SCENE
--accuracy 2%`.

Levels: level k is the scene with every cell count of its [mesh] (nx, ny or n_around, n_along) times 2^k, rounded
(at least one cell, three around a tube), so that any mesh has levels: a count not divisible by 4 gives
non-uniform ratios (nx = 10: 2, 5, 10 cells at the pilots), and Richardson uses the levels' relative cell sizes
sqrt(prod n_0 / prod n_k) (2^-k where the counts divide). For a dynamic scene with a numeric dt, dt is scaled by
that size (dt = "auto" follows the mesh by itself; output_every / size keeps the record times). The pilots
k = -2, -1, 0 are solved (each into `<out>/accuracy/level<k>/`, read back when that folder holds a completed run,
with or without warnings of its plausibility checks, of the same level scene); the quantity q (a monitored
output, `AccuracySection`) of the three gives the observed order, the extrapolated value q* and the estimated
relative error of every level (fabricfem.scenes.richardson: a pilot's |q_k - q*| / |q*|, a finer level's
e_0 2^(-p k); plausible orders ORDERS by scene kind). When the sequence is not asymptotic only pilots can be
chosen, with the conservative estimates of fabricfem.scenes.richardson, and a target that no pilot meets is
refused.

Model levels ([accuracy] membrane = true, the default): a shell scene whose loads, supports and monitors a
membrane can carry (no edge moments, no rotation monitors; rotation supports are dropped) is also solved with the
membrane model at the pilot levels (`<out>/accuracy/membrane<k>/`; a level that does not solve, as a membrane
without tension does not, ends the membrane's pilots). The membrane's estimated error is its difference to the
shell's best value: |q_m,k - q*| / |q*| (asymptotic shell), else |q_m,k - q_0| / |q_0| + e_0 (the shell's
conservative estimate of its finest pilot). So the membrane is chosen for pure tension, where it agrees with
the shell, and not where bending matters.

Particles ([accuracy] particles = true, the default: a particle pilot costs 0.1-1 s): a static plate scene that
the particle model can represent (fabricfem.scenes.particle_level: gravity, body forces, edge tractions, point loads,
displacement supports; no edge moments, pressure, fixed rotations, tubes or dynamics) is also solved as a particle
grid on the mesh nodes of each pilot (`<out>/accuracy/particles<k>/`). Its estimated error is measured like the
membrane's; the particle model's error floor is that of its finest pilot, and the particle levels are offered only
when the floor is at most the target (then the cheapest particle pilot meeting the target). The model's reason
for not being considered, or its floor above the target, is in the plan's notes.

Wear scenes ([scene] kind = "wear"; `WearLevels`): the levels are the garment's mesh, a tube's cell counts
(n_around, n_along) x ratio^k rounded (the compression route: n_around a multiple of 4) or a pattern's element size
h / ratio^k, with the ratio of [accuracy] ratio (default 2, or less so that the coarsest pilot keeps 6 cells
around a tube, 8 on the compression route); Richardson uses the levels' cell sizes (a tube's 1 / sqrt(n_around
n_along), a pattern's 1 / sqrt(dofs) as meshed: every edge has at least two segments, so a coarse h meshes finer
than h), so rounded counts give non-uniform ratios. The explicit step follows each mesh by itself
(its critical step), so the levels are mesh levels only, and an observed order above 2 is not asymptotic (the
dynamic range); the compression route is quasi-static (the static range). [accuracy] window [s]: the pilots run
only the first `window` seconds of body time (route.end_time; donning, settling and motion as scheduled, cut
there), so their quantity, and with it the estimate, is the window's (e.g. the peak torque over the first 0.3 s,
not over the whole flexion); the chosen level then runs the whole scene, and its quantity's error is estimated
by the window's (this holds where the error is set by the mesh, not by what happens after the window). The
membrane is not a model level of a wear scene (the engine runs the shell).

Cost: the measured wall times [s] of the pilots; a finer level's predicted wall time is
wall_0 (dofs_k steps_k / dofs_0 steps_0)^a with a from the two finest pilots, clamped to [1, 2] (work per step
is linear in the dofs up to the direct solver's fill). The level of least work (dofs x steps) whose estimated
error is at most the target is chosen (shell levels up to `finer_levels` above the scene's mesh, membrane
pilots); none: refused (`Plan.require`).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

from mpi4py import MPI
from petsc4py import PETSc

from fabricfem import io
from fabricfem.dynamics.newmark import DynamicsError
from fabricfem.scenes import particle_level, wear
from fabricfem.scenes.batch import read_summary
from fabricfem.scenes.build import build_fabric, critical_time_step_estimate, estimated_dofs, validate
from fabricfem.scenes.richardson import ORDERS, richardson
from fabricfem.scenes.run import SceneOutcome, output_dir, run_scene, scene_name, scene_sha256
from fabricfem.scenes.schema import (
    ACCURACY_KINDS,
    Scene,
    SceneError,
    accuracy_quantities,
    accuracy_summary_key,
    check_target,
)
from fabricfem.scenes.sections import AccuracySection, DynamicsSection, ModelSection, section
from fabricfem.scenes.wear_sections import GarmentSection
from fabricfem.solvers.newton import SolverError

PILOTS = (-2, -1, 0)             # levels solved to estimate the error
MESH_COUNTS = {"plate": ("nx", "ny"), "tube": ("n_around", "n_along")}
LEAST_CELLS = {"plate": (1, 1), "tube": (3, 1)}   # the fewest cells per count of a level's mesh
LEAST_AROUND = 6   # cells around a tube at the coarsest wear pilot (default ratio)


@dataclass
class Level:
    """One level of a scene: k (cell counts x 2^k; wear: x ratio^k), its scene, dofs, time step [s] (dynamic,
    wear), the number of steps, its cell size (relative: 2^-k; wear: module docstring), the quantity and wall time
    [s] when solved, the estimated relative error and the measured or predicted wall time [s]."""

    k: int
    scene: Scene
    dofs: int
    step: float | None
    steps: int
    size: float = 1.0
    value: float | None = None
    wall_s: float | None = None
    error: float | None = None
    cost_s: float | None = None
    kind: str | None = None           # "particles": a particle level (the scene's data, solved by particle_level)

    @property
    def work(self) -> float:
        """dofs x time steps (1 step for a static solve)."""
        return float(self.dofs * self.steps)

    @property
    def model(self) -> str:
        """naghdi (the shell), membrane or particles."""
        return self.kind or section(ModelSection, self.scene.get("model")).kind


@dataclass
class Plan:
    """The accuracy plan of a scene: the levels (pilots solved; shell, membrane, particles), the observed order p,
    the extrapolated value, whether the pilots are in the asymptotic range (and why not), what became of the
    membrane and particle alternatives (`model_note`) and the chosen level (None: target not met)."""

    quantity: str
    target: float
    levels: list[Level]
    order: float | None
    extrapolated: float | None
    asymptotic: bool
    note: str
    model_note: str = ""
    chosen: Level | None = None
    window: float | None = None       # s of body time the pilots ran (wear), None: the whole scene
    full_time: float | None = None    # s of body time of the whole scene (wear)
    header: tuple = field(default=("level", "model", "cells", "dofs", "step_s", "value", "estimated_error",
                                   "wall_s", "solved"))

    def rows(self) -> list[list]:
        """One row per level (the columns of `header`)."""
        return [[lv.k, lv.model, cells_of(lv.scene), lv.dofs, lv.step, lv.value, lv.error, lv.cost_s,
                 lv.value is not None] for lv in self.levels]

    def table(self) -> str:
        """The plan as printed: one line per level, the estimate and the choice."""
        estimate = (f"observed order p = {self.order:.2f}, extrapolated {self.extrapolated:.6g}" if self.asymptotic
                    else f"NOT ASYMPTOTIC ({self.note}): only the solved levels, conservative estimates")
        lines = [f"accuracy plan: {self.quantity} to {self.target:.3g} relative; {estimate}",
                 (f"  {'level':>5} {'model':>9} {'cells':>9} {'dofs':>8} {'step [s]':>10} {'value':>13} "
                  f"{'est. error':>10} {'wall [s]':>10}")]
        for lv in self.levels:
            mark = " <- chosen" if lv is self.chosen else ""
            cost = "" if lv.cost_s is None else f"{lv.cost_s:.3g}" + ("" if lv.value is not None else " (pred.)")
            lines.append(f"  {lv.k:>+5d} {lv.model:>9} {cells_of(lv.scene):>9} {lv.dofs:>8d} {_fmt(lv.step, '.4g'):>10} "
                         f"{_fmt(lv.value, '.6g'):>13} {_fmt(lv.error, '.2e'):>10} {cost:>10}{mark}")
        if self.window is not None:
            lines.append(f"  window: the pilots ran the first {self.window:g} s of {self.full_time:.4g} s of body time; "
                         f"the estimate is of the window's {self.quantity}; the whole scene costs about "
                         f"{self.full_time / self.window:.3g} x the wall times above")
        return "\n".join(lines + ([f"  {self.model_note}"] if self.model_note else []))

    def require(self) -> Level:
        """The chosen level; SceneError with the best estimate when no level meets the target."""
        if self.chosen is None:
            best = min((lv for lv in self.levels if lv.error is not None), key=lambda lv: lv.error)
            raise SceneError(f"accuracy.target: no level reaches {self.target:.3g} ({self.quantity}: best estimate "
                             f"{best.error:.3g} at level {best.k:+d}"
                             + (f"; not asymptotic: {self.note}" if not self.asymptotic else "")
                             + "); refine the scene's mesh, raise accuracy.finer_levels or the target")
        return self.chosen

    def summary(self) -> dict:
        """The entries added to the delivered run's summary.json."""
        c = self.chosen
        return {"accuracy_quantity": self.quantity, "accuracy_target": self.target, "accuracy_level": c.k,
                "accuracy_model": c.model, "accuracy_estimated_error": c.error, "accuracy_order": self.order,
                "accuracy_extrapolated": self.extrapolated, "accuracy_asymptotic": self.asymptotic,
                "accuracy_note": self.note, "accuracy_predicted_wall_s": c.cost_s * self.full_factor,
                "accuracy_window_s": self.window}

    @property
    def full_factor(self) -> float:
        """Body time of the whole scene over the pilots' window (1 without a window)."""
        return 1.0 if self.window is None else self.full_time / self.window


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def cells_of(scene: Scene) -> str:
    """The level's mesh: "nx x ny" cells (plate), "n_around x n_along" (tube, wear tube) or "h=..." (pattern)."""
    if scene.kind == "wear":
        g = scene["garment"]
        return (f"{g['n_around']}x{g['n_along']}" if g.get("builder", "pattern") == "tube"
                else f"h={g.get('h', GarmentSection.h):.3g}")
    mesh = scene["mesh"]
    return "x".join(str(mesh[key]) for key in MESH_COUNTS[mesh["type"]])


def _mesh_label(scene: Scene) -> str:
    """"6x8 cells" or, for a pattern garment, "h = 0.05 m"."""
    cells = cells_of(scene)
    return f"h = {cells[2:]} m" if cells.startswith("h=") else f"{cells} cells"


def summary_value(summary: dict, key: str):
    """The entry `key` of a run's summary.json (a dotted key names a nested entry, e.g. "torque_elbow.peak_Nm");
    None when absent."""
    value = summary
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def parse_target(text: str) -> float:
    """A relative target from `2%` or `0.02`; ValueError naming --accuracy."""
    try:
        value = float(text.strip().rstrip("%")) / (100.0 if text.strip().endswith("%") else 1.0)
    except ValueError:
        raise ValueError(f"--accuracy: a relative error target like 2% or 0.02, got {text!r}") from None
    return check_target("--accuracy", value)


def with_window(scene: Scene, window: float | None) -> Scene:
    """The scene with [accuracy] window = `window` [s] (None: unchanged), validated again (SceneError naming
    accuracy.window: not positive, longer than the scene, or not a scene on the explicit engine)."""
    if window is None:
        return scene
    data = copy.deepcopy(scene.data)
    data.setdefault("accuracy", {})["window"] = float(window)
    return validate(data, source="--window", path=scene.path)


def target_of(scene: Scene, target: float | None = None, quantity: str | None = None) -> tuple[str, float]:
    """(quantity, target) from the arguments, else the scene's [accuracy]; SceneError naming what is missing (a
    missing quantity: with the quantities the scene accepts, accuracy_quantities)."""
    spec = section(AccuracySection, scene.get("accuracy"))
    quantity = quantity if quantity is not None else spec.quantity
    target = target if target is not None else spec.target
    if scene.kind not in ACCURACY_KINDS:
        raise SceneError(f"--accuracy: an accuracy target is for {', '.join(ACCURACY_KINDS)} scenes, not "
                         f"{scene.kind!r} ones")
    if scene.kind == "wear" and wear.route_of(scene.data) != "explicit":
        raise SceneError("route.solver: an accuracy target runs a wear scene on the explicit engine (route.solver = "
                         "\"explicit\"), not the sleeve's quasistatic or implicit route")
    if quantity is None:
        accepted = ", ".join(accuracy_quantities(scene.data)) or "none"
        raise SceneError(f"accuracy.quantity: name the monitored quantity (--quantity NAME or [accuracy] quantity); "
                         f"this scene accepts: {accepted}")
    if target is None:
        raise SceneError("accuracy.target: give a relative error target (--accuracy 2% or [accuracy] target)")
    accuracy_summary_key(scene.data, quantity)
    return quantity, check_target("accuracy.target", target)


def membrane_variant(data: dict) -> tuple[dict | None, str]:
    """(the scene data with the membrane model, "") or (None, why the scene needs the shell): a membrane carries
    no edge moments and has no rotations to monitor; rotation supports are dropped (a membrane has none)."""
    if "garment" in data:
        return None, "membrane: not considered (the wear engine runs the shell)"
    if section(ModelSection, data.get("model")).kind != "naghdi":
        return None, ""
    if any(load["type"] == "edge_moment" for load in data.get("load", [])):
        return None, "membrane: not considered (the edge moments need the shell's rotations)"
    if any(m.get("field") == "theta" for m in data.get("dynamics", {}).get("monitors", [])):
        return None, "membrane: not considered (a rotation monitor needs the shell)"
    data = copy.deepcopy(data)
    data["model"] = {"kind": "membrane"}
    for support in data.get("support", []):
        support.pop("theta", None)
    return data, ""


def wear_ratio(data: dict) -> float:
    """The refinement ratio of a wear scene's levels: [accuracy] ratio, else 2 for a pattern, else the largest
    ratio <= 2 that keeps LEAST_AROUND cells around the tube at the coarsest pilot; SceneError naming
    garment.n_around when the tube is too coarse for coarser pilots."""
    ratio = section(AccuracySection, data.get("accuracy")).ratio
    g = data["garment"]
    if ratio is not None or g.get("builder", "pattern") != "tube":
        return float(ratio or 2.0)
    least = LEAST_AROUND
    ratio = min(2.0, (g["n_around"] / least) ** (1.0 / -min(PILOTS)))
    if ratio < 1.1:
        raise SceneError(f"garment.n_around: {g['n_around']} cells around leave no room for two coarser pilot "
                         f"levels (at least {least} around at the coarsest, ratio >= 1.1); refine the scene's "
                         f"tube or give accuracy.ratio")
    return ratio


def wear_level(scene: Scene, k: int, out: Path, window: bool) -> Level:
    """Level k of a wear scene (module docstring), its pilots cut at [accuracy] window when `window`; validated
    (the pattern and motion files found beside the scene file)."""
    data = copy.deepcopy(scene.data)
    spec = section(AccuracySection, data.pop("accuracy", None))
    ratio, g = wear_ratio(scene.data), data["garment"]
    scale = ratio ** k
    if g.get("builder", "pattern") == "tube":
        around = max(3, round(g["n_around"] * scale))
        g.update(n_around=around, n_along=max(1, round(g["n_along"] * scale)))
        size = 1.0 / math.sqrt(g["n_around"] * g["n_along"])
        dofs = estimated_dofs({"type": "tube", "n_around": g["n_around"], "n_along": g["n_along"]})
    else:
        g["h"] = size = section(GarmentSection, scene["garment"]).h / scale
        dofs = 0                                          # known once meshed (the pilots' summaries)
    if window and spec.window is not None:
        data.setdefault("route", {})["end_time"] = spec.window
    data.setdefault("output", {}).update(dir=str(out), render=False)
    level = validate(data, source=f"accuracy level {k:+d}", path=scene.path)
    return Level(k, level, dofs, None, 1, size)


def level_scene(scene: Scene, k: int, out: Path, data: dict | None = None, window: bool = True) -> Level:
    """Level k of `scene` (or of its variant `data`, e.g. the membrane's; module docstring) writing into `out`,
    validated: every cell count x 2^k rounded (at least LEAST_CELLS), its relative cell size
    sqrt(prod counts_0 / prod counts_k) (2^-k where the counts divide), a numeric dt times that size. A wear
    scene's level (`wear_level`) runs the pilots' window when `window`, the whole scene otherwise."""
    if scene.kind == "wear":
        return wear_level(scene, k, out, window)
    data = copy.deepcopy(scene.data if data is None else data)
    data.pop("accuracy", None)
    mesh = data["mesh"]
    counts = [mesh[key] for key in MESH_COUNTS[mesh["type"]]]
    for key, least in zip(MESH_COUNTS[mesh["type"]], LEAST_CELLS[mesh["type"]]):
        mesh[key] = max(least, round(mesh[key] * 2.0 ** k))
    size = math.sqrt(math.prod(counts) / math.prod(mesh[key] for key in MESH_COUNTS[mesh["type"]]))
    steps, step = 1, None
    if "dynamics" in data:
        dyn = data["dynamics"]
        if dyn["dt"] != "auto":
            dyn["dt"] = dyn["dt"] * size
        if dyn.get("output_every") is not None:
            dyn["output_every"] = max(1, round(dyn["output_every"] / size))
        d = section(DynamicsSection, dyn)
        step = d.dt if d.dt != "auto" else (d.dt_fraction * (critical_time_step_estimate(data) or math.nan))
        steps = max(1, math.ceil(d.end_time / step * (1.0 - 1e-12))) if math.isfinite(step) else 1
    data.setdefault("output", {}).update(dir=str(out), render=False)
    level = validate(data, source=f"accuracy level {k:+d}", path=scene.path)
    return Level(k, level, estimated_dofs(data["mesh"], section(ModelSection, data.get("model")).kind), step, steps,
                 size)


def solve(level: Level, key: str, comm=MPI.COMM_WORLD) -> bool:
    """Solve a level (or read back its completed run of the same scene) and store its quantity and wall time;
    True when it was solved now."""
    folder = Path(level.scene["output"]["dir"])
    summary = comm.bcast(read_summary(folder) if comm.rank == 0 else None, root=0)
    solved = not (_completed(summary.get("status")) and summary.get("scene_sha256") == scene_sha256(level.scene))
    if solved:
        outcome = run_scene(level.scene, comm)
        if not _completed(outcome.status):
            raise SceneError(f"accuracy level {level.k:+d} ({level.model}): the run {outcome.status}")
        summary = comm.bcast(read_summary(folder) if comm.rank == 0 else None, root=0)
    value = summary_value(summary, key)
    if value is None:
        raise SceneError(f"accuracy level {level.k:+d}: the run's summary.json has no {key!r} (the window ends "
                         f"before anything of it was recorded?)")
    level.value, level.wall_s = float(value), float(summary["wall_s"])
    level.cost_s = level.wall_s
    if level.scene.kind == "wear" and summary.get("ndofs"):   # the engine's own count, step and steps
        level.dofs, level.step, level.steps = int(summary["ndofs"]), summary["dt_s"], int(summary["time_steps"])
    return solved


def _completed(status) -> bool:
    """Whether a run's status is "completed", with or without warnings of its plausibility checks (the quantity
    is there; the warnings are in the level's summary.json)."""
    return isinstance(status, str) and status.startswith("completed")


def _membrane_pilots(scene: Scene, key: str, root: Path, comm, say) -> tuple[list[Level], str]:
    """The membrane's solved pilot levels and a note (why none or fewer were solved)."""
    data, note = membrane_variant(scene.data)
    if data is None or not section(AccuracySection, scene.get("accuracy")).membrane:
        return [], note
    solved = []
    for k in PILOTS:
        level = level_scene(scene, k, root / f"membrane{k:+d}", data)
        try:
            fresh = solve(level, key, comm)
        except (SolverError, DynamicsError, SceneError, PETSc.Error) as exc:   # a membrane without tension: singular
            why = f"PETSc error {exc.ierr} in the solve" if isinstance(exc, PETSc.Error) else " ".join(str(exc).split())
            return solved, f"membrane: level {k:+d} did not solve ({why}); not a candidate from there on"
        say(f"accuracy: membrane level {k:+d} ({_mesh_label(level.scene)}, {level.dofs} dofs) "
            f"{'solved' if fresh else 'read back'}: {level.value:.6g}")
        solved.append(level)
    return solved, ""


def _particle_pilots(scene: Scene, key: str, root: Path, comm, say) -> tuple[list[Level], str]:
    """The particle model's solved pilot levels and a note (why none or fewer were solved)."""
    data, note = particle_level.particle_variant(scene.data)
    if not section(AccuracySection, scene.get("accuracy")).particles:
        return [], ""
    if data is None:
        return [], note
    solved = []
    for k in PILOTS:
        level = level_scene(scene, k, root / f"particles{k:+d}", data)
        level.kind, level.dofs = "particles", particle_level.particle_dofs(level.scene.data)
        try:
            summary = particle_level.solve_particles(level.scene.data, level.scene["output"]["dir"], comm)
        except SceneError as exc:
            return solved, f"particles: level {k:+d} did not solve ({' '.join(str(exc).split())}); not a candidate"
        level.value, level.wall_s = float(summary_value(summary, key)), float(summary["wall_s"])
        level.cost_s = level.wall_s
        say(f"accuracy: particles level {k:+d} ({_mesh_label(level.scene)}, {level.dofs} dofs) "
            f"{'solved' if summary['solved_now'] else 'read back'}: {level.value:.6g}")
        solved.append(level)
    return solved, ""


def plan(scene: Scene, target: float | None = None, quantity: str | None = None, comm=MPI.COMM_WORLD,
         say=None) -> Plan:
    """Solve the pilots (shell, then the membrane and the particles where the scene permits them), estimate the error of every level
    and choose the one of least work that meets the target (module docstring; `Plan.chosen` is None when no level
    does, `Plan.require` refuses)."""
    say = say or ((lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None))
    quantity, target = target_of(scene, target, quantity)
    key = accuracy_summary_key(scene.data, quantity)
    finer = section(AccuracySection, scene.get("accuracy")).finer_levels
    root = output_dir(scene) / "accuracy"
    levels = [level_scene(scene, k, root / f"level{k:+d}") for k in (*PILOTS, *range(1, finer + 1))]
    window, full_time = _window(scene)
    clock = io.Progress("accuracy pilots")
    pilots = levels[:len(PILOTS)]
    if len({lv.size for lv in pilots}) < len(pilots):
        where, mend = (("accuracy.ratio", "a larger ratio or a finer scene mesh") if scene.kind == "wear" else
                       ("mesh", "a finer scene mesh"))
        raise SceneError(f"{where}: the pilot levels {[cells_of(lv.scene) for lv in pilots]} coincide after "
                         f"rounding; give {mend}")
    for i, lv in enumerate(pilots):
        solved = solve(lv, key, comm)
        say(f"accuracy: level {lv.k:+d} ({_mesh_label(lv.scene)}, {lv.dofs} dofs) "
            f"{'solved' if solved else 'read back'}: {lv.value:.6g} {clock((i + 1) / len(pilots))}")
    if scene.kind == "wear" and scene["garment"].get("builder", "pattern") != "tube":
        _meshed_sizes(scene, levels)
    estimate = richardson([lv.value for lv in pilots], [lv.size for lv in pilots], orders=_orders(scene))
    for lv, error in zip(pilots, estimate.errors):
        lv.error = error
    finest = pilots[-1]
    for lv in levels[len(PILOTS):]:
        lv.error = estimate.finer(finest.size / lv.size)
        if scene.kind == "wear":   # the dofs go with the cells, the explicit step with the cell size
            lv.dofs = round(finest.dofs * (finest.size / lv.size) ** 2)
            lv.step = None if finest.step is None else finest.step * lv.size / finest.size
            lv.steps = finest.steps if finest.step is None else math.ceil(finest.steps * finest.size / lv.size)
    a = _cost_exponent(pilots[-2], pilots[-1])
    for lv in levels[len(PILOTS):]:
        lv.cost_s = pilots[-1].wall_s * (lv.work / pilots[-1].work) ** a
    membrane, model_note = _membrane_pilots(scene, key, root, comm, say)
    best, best_error = (estimate.extrapolated, 0.0) if estimate.asymptotic else (pilots[-1].value, pilots[-1].error)
    particles, particle_note = _particle_pilots(scene, key, root, comm, say)
    for lv in membrane + particles:   # model + discretisation error: the difference to the shell's best value
        lv.error = abs(lv.value - best) / (abs(best) or 1.0) + best_error
    offered = particles
    if particles and len(particles) < len(PILOTS):   # the finest pilot did not solve: no floor, not offered
        offered = []
    elif particles and particles[-1].error > target:   # the particle model's error floor: its finest pilot's
        offered = []
        particle_note = (f"particles: error floor {particles[-1].error:.2e} (finest pilot "
                         f"{_mesh_label(particles[-1].scene)}) above the target {target:.3g}; not offered")
    elif particles:
        particle_note = (f"particles: error floor {particles[-1].error:.2e} (finest pilot "
                         f"{_mesh_label(particles[-1].scene)}) within the target {target:.3g}; offered")
    model_note = "; ".join(n for n in (model_note, particle_note) if n)
    result = Plan(quantity, target, levels + membrane + particles, estimate.order, estimate.extrapolated,
                  estimate.asymptotic, estimate.note, model_note, window=window, full_time=full_time)
    meeting = [lv for lv in result.levels if lv.error is not None and lv.error <= target
               and (lv.model != "particles" or any(lv is o for o in offered))]
    result.chosen = min(meeting, key=lambda lv: lv.work) if meeting else None
    say(result.table())
    c = result.chosen
    if c is not None:
        say(f"accuracy: chose level {c.k:+d} {c.model} ({_mesh_label(c.scene)}, {c.dofs} dofs): estimated error "
            f"{c.error:.2e} <= {target:.3g}, {'measured' if c.value is not None else 'predicted'} wall "
            f"{c.cost_s:.3g} s" + ("" if window is None else
                                   f" on the window, about {c.cost_s * result.full_factor:.3g} s for the whole scene")
            + ("" if estimate.asymptotic else
                                   f" (NOT ASYMPTOTIC: {estimate.note}; conservative choice)"))
    return result


def _meshed_sizes(scene: Scene, levels: list[Level]) -> None:
    """A pattern garment's cell sizes from its meshed dofs (1 / sqrt(dofs), relative): every edge gets at least
    two segments, so a coarse level's cells are smaller than its h; the finer levels h / ratio^k of the finest
    pilot's. SceneError naming accuracy.ratio when two pilots meshed alike."""
    pilots, ratio = levels[:len(PILOTS)], wear_ratio(scene.data)
    if len({lv.dofs for lv in pilots}) < len(pilots):
        raise SceneError(f"accuracy.ratio: the pilots h = {[lv.scene['garment']['h'] for lv in pilots]} m meshed with "
                         f"equal dofs {[lv.dofs for lv in pilots]}; give a larger ratio or a smaller garment.h")
    for lv in pilots:
        lv.size = lv.dofs ** -0.5
    for lv in levels[len(PILOTS):]:
        lv.size = pilots[-1].size / ratio ** lv.k


def _orders(scene: Scene) -> tuple[float, float]:
    """Plausible observed orders (fabricfem.scenes.richardson.ORDERS): a wear scene on the explicit engine as a
    dynamic one (its step follows the mesh)."""
    return ORDERS["dynamic" if scene.kind == "wear" else scene.kind]


def _window(scene: Scene) -> tuple[float | None, float | None]:
    """(the pilots' window [s], the whole scene's body time [s]) of a wear scene with [accuracy] window, else
    (None, None)."""
    window = section(AccuracySection, scene.get("accuracy")).window
    if scene.kind != "wear" or window is None:
        return None, None
    parsed = scene.parsed
    return window, wear.scene_body_time(wear.plan(parsed, wear.wear_fabric(parsed, build_fabric), scene.path))


def _cost_exponent(coarse: Level, fine: Level) -> float:
    """a of wall ~ work^a from two solved levels, clamped to [1, 2] (set-up time dominates tiny levels)."""
    if fine.work <= coarse.work or not (coarse.wall_s and fine.wall_s):
        return 1.0
    return min(2.0, max(1.0, math.log(fine.wall_s / coarse.wall_s) / math.log(fine.work / coarse.work)))


def run_accurate(scene: Scene, target: float | None = None, quantity: str | None = None, comm=MPI.COMM_WORLD):
    """`fabricfem run SCENE --accuracy X`: plan, then run the chosen level into the scene's output folder (with
    its renders) and add the plan's estimate to its summary.json; writes accuracy_plan.csv beside it. Returns
    (plan, SceneOutcome)."""
    chosen = plan(scene, target, quantity, comm)
    level = chosen.require()
    if level.model == "particles":
        return chosen, _deliver_particles(scene, chosen, level, comm)
    if scene.kind == "wear":   # the whole scene, not the pilots' window
        level = level_scene(scene, level.k, output_dir(scene), window=False)
    data = copy.deepcopy(level.scene.data)
    data["output"] = {**scene.get("output", {}), "dir": str(output_dir(scene))}
    data.setdefault("scene", {})["name"] = scene_name(scene)
    delivered = validate(data, source=f"accuracy level {chosen.chosen.k:+d}", path=scene.path)
    outcome = run_scene(delivered, comm)
    _write_plan(scene, chosen, comm)
    return chosen, outcome


def _deliver_particles(scene: Scene, chosen: Plan, level: Level, comm) -> SceneOutcome:
    """The chosen particle level solved into the scene's output folder (summary.json with the plan's entries)."""
    out = output_dir(scene)
    if comm.rank == 0:   # a previous delivery of another level is not read back
        (out / "summary.json").unlink(missing_ok=True)
    comm.barrier()
    summary = particle_level.solve_particles(level.scene.data, out, comm)
    io.update_json(out / "summary.json", {"scene": scene_name(scene), "ranks": comm.size}, comm)
    if comm.rank == 0:
        print(f"particles ({_mesh_label(level.scene)}, {level.dofs} dofs): {summary['newton_iterations']} Newton "
              f"iterations, {summary['wall_s']:.3g} s; probe displacement {summary['probe_displacement_m']} m",
              flush=True)
    _write_plan(scene, chosen, comm)
    return SceneOutcome(summary, "completed", out)


def _write_plan(scene: Scene, chosen: Plan, comm) -> None:
    """The plan's entries into the delivered run's summary.json, accuracy_plan.csv beside it, and the result."""
    out = output_dir(scene)
    io.update_json(out / "summary.json", chosen.summary(), comm)
    io.write_csv(out / "accuracy_plan.csv", list(chosen.header), chosen.rows(), comm)
    if comm.rank == 0:
        key = accuracy_summary_key(scene.data, chosen.quantity)
        value = summary_value(read_summary(out), key)
        print(f"accuracy: {chosen.quantity} = {value} at level {chosen.chosen.k:+d} ({chosen.chosen.model}), "
              f"estimated relative error {chosen.chosen.error:.2e} (target {chosen.target:.3g}); "
              f"wrote {out}/accuracy_plan.csv", flush=True)
