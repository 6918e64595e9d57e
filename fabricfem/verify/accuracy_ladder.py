"""Verification of the accuracy target on a windowed statistic (fabricfem.studies.accuracy_ladder): does the level
the mesh ladder chooses meet the target against the finest ladder level when it is run again?

The shipped sleeve (scenes/sleeve.toml: cotton tube, the whole flexion to 57 degrees, mu = 0.1, Lagrange contact)
on the thesis's mesh I (10 x 13, not the scene's converged 44 x 57: a ladder from it costs an hour) and the ladder
10x13, 15x20, 22x29 (ratio 1.5, [accuracy] finer_levels = 2); quantity: the elbow torque's
mean over 20-57 degrees (torque_elbow_window_mean_Nm); targets TARGETS. Checks: the chosen level is the coarsest
whose ladder difference meets the target; the delivered run (the chosen level run again into its own folder, with
the scene's outputs) differs from the finest ladder level by at most the target (measured from its summary.json),
and reproduces its ladder level's statistic (same arithmetic: within REPRODUCE). The reference is the finest
ladder level, not a converged value: docs/studies/sleeve.md ("Error bars") gives the ladder's distance to finer
meshes. Measured on the blended skin (one rank, other jobs running, 98 s for the ladder): 0.047181, 0.042344,
0.035530 N m, differences 32.8 % and 19.2 %, not asymptotic: 5 % refused, 25 % chooses 15x20. (On the
ellipsoid skin before it: 0.043458, 0.037368, 0.036839 N m, 15x20 chosen for 5 %, 1.44 %.)

`accuracy-converged` (CONVERGED_NAME): the same on the scene's own converged mesh, 44 x 57, with the ladder 44x57,
60x78 (ratio 60/44, [accuracy] finer_levels = 1), target 5 %: the issue's `fabricfem run scenes/sleeve.toml
--accuracy 5% --quantity torque_elbow_window_mean_Nm` with a ladder a verification can afford (about 6 min on 2
ranks, 12 serial). Its ladder and delivered run are kept in CONVERGED_OUT, and a rerun reads back the levels that
hold a completed run of the same scene (hash-checked, fabricfem.scenes.batch), so only the first `fabricfem
verify` pays for them.
"""
from __future__ import annotations

import copy
import tempfile
import tomllib
from pathlib import Path

from mpi4py import MPI

from fabricfem.scenes.build import validate
from fabricfem.scenes.run import with_output_dir
from fabricfem.scenes.schema import SceneError
from fabricfem.studies.accuracy_ladder import ladder_plan, run_ladder_accurate
from fabricfem.verify import Timer, case, result

NAME = "accuracy-ladder"
SCENE = Path(__file__).resolve().parents[2] / "scenes" / "sleeve.toml"
QUANTITY = "torque_elbow_window_mean_Nm"
TARGETS = (0.05, 0.25)
CONVERGED_NAME = "accuracy-converged"
CONVERGED_OUT = Path("results") / "verify" / CONVERGED_NAME    # kept: a rerun reads the ladder back
CONVERGED_TARGET = 0.05
REPRODUCE = 1e-9      # relative: the delivered run against its ladder level (the same run on the same ranks)


@case(NAME, in_tests=False)   # 2 min; tests/test_accuracy_ladder.py covers its parts on a 6 x 8 sleeve
def accuracy_ladder() -> list:
    """Accuracy target on a windowed statistic: the sleeve's 20-57 degree mean elbow torque at 5 % and 25 % on the
    mesh ladder 10x13, 15x20, 22x29; the chosen level is the coarsest meeting it and its rerun meets it (a refusal
    passes only when no coarser level meets it)."""
    data = _sleeve({"n_around": 10, "n_along": 13}, {"finer_levels": 2, "ratio": 1.5})
    out = []
    with Timer() as timer, tempfile.TemporaryDirectory(prefix="accuracy_ladder_") as tmp:
        scene = with_output_dir(validate(data, source=str(SCENE), path=SCENE), Path(tmp) / "run")
        for target in TARGETS:    # the ladder runs once, the second target reads it back
            out += _rows(scene, target, timer)
    return out


@case(CONVERGED_NAME, in_tests=False)   # 6 min on 2 ranks the first time; the parts as accuracy-ladder's
def accuracy_converged() -> list:
    """The shipped sleeve on its own mesh at 5 %: ladder 44x57, 60x78; the chosen level meets the target against
    60x78 when run again (module docstring)."""
    data = _sleeve({}, {"finer_levels": 1, "ratio": 60.0 / 44.0})
    with Timer() as timer:
        scene = with_output_dir(validate(data, source=str(SCENE), path=SCENE), CONVERGED_OUT)
        return _rows(scene, CONVERGED_TARGET, timer, CONVERGED_NAME)


def _sleeve(mesh: dict, accuracy: dict) -> dict:
    """scenes/sleeve.toml's data with the tube's `mesh` keys, [accuracy] `accuracy`, renders off."""
    data = copy.deepcopy(tomllib.loads(SCENE.read_text()))
    data["garment"].update(mesh)
    data["accuracy"] = accuracy
    data["output"] = {**data.get("output", {}), "render": False}
    return data


def _rows(scene, target: float, timer: Timer, name: str = NAME) -> list:
    """The rows of one target (module docstring), as case `name`."""
    label = f"sleeve {QUANTITY} at target {target:.0%}"
    try:
        plan, outcome = run_ladder_accurate(scene, target, QUANTITY, MPI.COMM_WORLD)
    except SceneError:
        plan = ladder_plan(scene, target, QUANTITY, MPI.COMM_WORLD, say=lambda m: None)
        best = min(plan.differences[:-1])
        return [result(name, f"{label}: refused; smallest difference of a coarser level to the finest {best:.3g}",
                       0.0 if best > target else 1.0, 0.0, 0.0, 0, timer.elapsed)]
    delivered = outcome.result.statistics["torque_elbow"]["mean_Nm"][0]
    k, finest = plan.chosen, plan.values[-1]
    brute = next(i for i, d in enumerate(plan.differences[:-1]) if d <= target)
    ndofs = plan.ndofs[k] or 0
    return [
        result(name, f"{label}: chosen ladder level (coarsest meeting it: {brute})", k, brute, 0.0, ndofs,
               timer.elapsed, scale=1.0),
        result(name, f"{label}: rerun of level {k} against the finest ladder level ({finest:.6g} N m), relative",
               abs(delivered - finest) / abs(finest), 0.0, target, ndofs, timer.elapsed, scale=1.0),
        result(name, f"{label}: rerun of level {k} against its ladder run ({plan.values[k]:.6g} N m)", delivered,
               plan.values[k], REPRODUCE, ndofs, timer.elapsed),
    ]
