"""The scene commands: `fabricfem run`, `plan` and `sweep` (a scene file, TOML), `fabricfem scenes` (the scene-file
reference) and `fabricfem demo` (the rolled strip)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.cli.common import Subparsers, add_command, json_stdout, print_json, say
from fabricfem.demo import rollup_demo
from fabricfem.dynamics.newmark import DynamicsError
from fabricfem.scenes.accuracy import parse_target, plan, run_accurate, with_window
from fabricfem.scenes.batch import read_summary
from fabricfem.scenes.ranks import SERIAL_BELOW_DOFS, runs_alone
from fabricfem.scenes.run import run_scene, scene_name, with_output_dir
from fabricfem.scenes.sweep import parse_vary, run_sweep
from fabricfem.solvers.newton import SolverError
from fabricfem.studies.accuracy_ladder import HEADER as LADDER_HEADER
from fabricfem.studies.accuracy_ladder import ladder_plan, run_ladder_accurate, uses_ladder


def _add_scene_options(parser: argparse.ArgumentParser) -> None:
    """The scene path and the accuracy options shared by run and plan."""
    parser.add_argument("scene", help="path of the scene file (TOML)")
    parser.add_argument("--accuracy", default=None, metavar="TARGET",
                        help="relative error target (2%% or 0.02): run the cheapest mesh level that meets it")
    parser.add_argument("--quantity", default=None,
                        help="the monitored quantity of the target (default [accuracy]; without one the message lists "
                             "the scene's quantities)")
    parser.add_argument("--window", type=float, default=None, metavar="SECONDS",
                        help="wear scenes: the pilots run the first SECONDS of body time (default [accuracy] window)")


def _scene_and_target(args: argparse.Namespace) -> tuple[scene_module.Scene, float | None]:
    """The scene of run / plan (with --window applied) and the --accuracy target (None: not given)."""
    scene = with_window(scene_module.load(args.scene), args.window)
    return scene, None if args.accuracy is None else parse_target(args.accuracy)


def _run(args: argparse.Namespace) -> int:
    """run: the scene (through the accuracy plan when a target, quantity or window is given, on the command line or
    in [accuracy]); exit 1 with the reason when it stopped early. A small scene under mpirun runs on rank 0 alone
    (fabricfem.scenes.ranks) unless --all-ranks."""
    scene, target = _scene_and_target(args)
    accurate = (target is not None or args.quantity is not None or args.window is not None
                or scene.get("accuracy", {}).get("target"))
    world = MPI.COMM_WORLD
    dofs = None if accurate or args.all_ranks else runs_alone(scene, world.size)
    if dofs is None:
        return _run_on(args, scene, target, accurate, world)
    say(f"{scene_name(scene)}: about {dofs} dofs, fewer than {SERIAL_BELOW_DOFS}: rank 0 runs it alone "
        f"({world.size} ranks are slower at this size; --all-ranks uses them)")
    code = 0
    try:
        if world.rank == 0:
            code = _run_on(args, scene, target, accurate, MPI.COMM_SELF)
    finally:   # also when rank 0 raises: the others get 0 and exit, mpirun reports rank 0's code
        code = world.bcast(code, root=0)
    return code


def _run_on(args: argparse.Namespace, scene: scene_module.Scene, target: float | None, accurate, comm) -> int:
    """`_run` on the ranks of `comm` (the others, if any, wait for its exit code)."""
    out = None if args.out is None else Path(args.out)
    try:
        with json_stdout(args.json):
            if accurate:
                scene = scene if out is None else with_output_dir(scene, out)
                accurate_run = run_ladder_accurate if uses_ladder(scene, args.quantity) else run_accurate
                _, outcome = accurate_run(scene, target, args.quantity)
            else:
                outcome = run_scene(scene, comm, out=out, resume=args.resume)
    except (SolverError, DynamicsError) as exc:   # the run stopped: summary.json says "failed: ..."
        say(f"fabricfem run: stopped: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    if args.json:
        print_json(read_summary(outcome.out))
    if outcome.exit_code:
        say(f"fabricfem run: {outcome.status}", file=sys.stderr)
    return outcome.exit_code


def _plan(args: argparse.Namespace) -> int:
    """plan: the levels with their estimates and costs; exit 2 (SceneError) when no level meets the target."""
    scene, target = _scene_and_target(args)
    if uses_ladder(scene, args.quantity):   # a wear scene's windowed statistic: the mesh ladder
        with json_stdout(args.json):
            ladder = ladder_plan(scene, target, args.quantity)
        if args.json:
            print_json({"quantity": ladder.quantity, "target": ladder.target, "method": "mesh ladder",
                        "chosen": ladder.chosen, "note": ladder.note,
                        "levels": [dict(zip(LADDER_HEADER, row)) for row in ladder.plan_rows()]})
        ladder.require()
        return 0
    with json_stdout(args.json):
        levels = plan(scene, target, args.quantity)
    if args.json:
        print_json({"quantity": levels.quantity, "target": levels.target, "order": levels.order,
                    "extrapolated": levels.extrapolated, "asymptotic": levels.asymptotic,
                    "chosen": None if levels.chosen is None else levels.chosen.k,
                    "levels": [dict(zip(levels.header, row)) for row in levels.rows()]})
    levels.require()
    return 0


def _sweep(args: argparse.Namespace) -> int:
    """sweep: the variants as one batch into --out (default results/<scene name>_sweep); exit 1 unless every
    variant completed."""
    scene = scene_module.load(args.scene)
    out = Path("results") / f"{scene_name(scene)}_sweep" if args.out is None else Path(args.out)
    with json_stdout(args.json):
        rows = run_sweep(scene, [parse_vary(text) for text in args.vary], out, args.ranks_per_variant, args.plot)
    if args.json:
        print_json(rows)
    return 0 if all(row["status"] == "completed" for row in rows) else 1


def _scenes(args: argparse.Namespace) -> int:
    """scenes: the scene-file reference printed, or written to --markdown."""
    text = scene_module.schema.reference_markdown()
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    else:
        say(text)
    return 0


def _demo(args: argparse.Namespace) -> int:
    """demo: the rolled strip into --out."""
    rollup_demo(args.out)
    return 0


def add_scene_commands(sub: Subparsers) -> None:
    """run, plan, sweep, scenes and demo."""
    run = add_command(sub, "run", _run, help="run a scene file (TOML), e.g. scenes/rollup.toml")
    _add_scene_options(run)
    run.add_argument("--out", default=None, help="output folder (default: the scene's [output] dir); with --accuracy "
                     "the chosen level's outputs, its pilots under OUT/accuracy/")
    run.add_argument("--all-ranks", action="store_true",
                     help="under mpirun, run a small scene on every rank too (by default a scene below "
                          f"{SERIAL_BELOW_DOFS} estimated dofs runs on rank 0 alone, which is faster)")
    run.add_argument("--resume", action="store_true",
                     help="wear and dynamic scenes: continue from the output folder's checkpoint after a kill or "
                          "Ctrl-C")
    _add_scene_options(add_command(sub, "plan", _plan, help="the mesh levels of a scene with their estimated errors "
                                   "and costs, and the level an accuracy target chooses (no full run)"))
    sweep = add_command(sub, "sweep", _sweep, help="run the variants of a scene as one MPI batch")
    sweep.add_argument("scene", help="path of the scene file (TOML)")
    sweep.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2,...",
                       help="a dotted scene key and its values (TOML), e.g. fabric.E1=1e6,2e6; repeat for a product")
    sweep.add_argument("--out", default=None, help="output folder (default results/<scene name>_sweep)")
    sweep.add_argument("--ranks-per-variant", type=int, default=1, help="MPI ranks of each variant's group")
    sweep.add_argument("--plot", default=None, metavar="QUANTITY",
                       help="summary.json entry drawn against the first varied key in sweep.png")
    scenes = add_command(sub, "scenes", _scenes,
                         help="the scene-file reference: every section and key with type, default, unit")
    scenes.add_argument("--markdown", metavar="PATH", help="write it to PATH (docs/scenes.md) instead of printing")
    demo = add_command(sub, "demo", _demo, help="the default demo: a fabric strip rolled up by an end moment")
    demo.add_argument("--out", default="results/demo", help="output folder (XDMF, PNG, CSV; default %(default)s)")
