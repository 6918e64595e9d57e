"""Command line: `fabricfem run SCENE [--accuracy 2%] [--quantity NAME] [--window S]`, `fabricfem plan SCENE --accuracy 2%`,
`fabricfem sweep SCENE --vary key=v1,v2 [--vary ...] [--out DIR] [--ranks-per-variant K] [--plot QUANTITY]`, `fabricfem verify [CASE ...] [--json]`, `fabricfem demo`,
`fabricfem bench ...`,
`fabricfem study sleeve [--quick] [--out DIR] [--fine III] [--meshes I,II,III,IV] [--fabrics I,II,III]
[--mesh-frictions 0.1,0.5] [--only mesh_mu0.5,fit]`,
`fabricfem study sleeve-methods [--mesh III] [--methods lagrange,penalty,augmented] [--al-budget 1800]
[--out results/sleeve_methods_gravity.csv]`,
`fabricfem study unit-cell [--quick] [--out DIR] [--recompute-stopped [--coarse-only | --fine-only]]
[--budget SECONDS]`,
`fabricfem study pants [--quick] [--out results/pants_study]` ([Man2006, sec. 5.4]: 1 and 2 mm pants, mu 0.1 and 0.5)."""
from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from pathlib import Path

from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.benchmarks import stability_map
from fabricfem.benchmarks.accuracy import accuracy_bench
from fabricfem.benchmarks.commits import compare_commits
from fabricfem.benchmarks.internal_force import internal_force_bench
from fabricfem.benchmarks.rollup_profile import rollup_profile
from fabricfem.benchmarks.sleeve_profile import sleeve_profile
from fabricfem.benchmarks.speed_accuracy import speed_accuracy
from fabricfem.benchmarks.unit_cell_perf import unit_cell_perf
from fabricfem.benchmarks.wear_speed import wear_bench
from fabricfem.demo import rollup_demo
from fabricfem.dynamics.newmark import DynamicsError
from fabricfem.scenes.accuracy import parse_target, plan, run_accurate, with_window
from fabricfem.scenes.batch import BatchError, groups_of
from fabricfem.scenes.run import run_scene, scene_name
from fabricfem.scenes.sweep import parse_vary, run_sweep
from fabricfem.solvers.newton import SolverError
from fabricfem.studies import unit_cell as unit_cell_study
from fabricfem.studies.fabric_link import OUT_DIR, run_fabric_link
from fabricfem.studies.pants import run_pants_study
from fabricfem.studies.sleeve import compare_figures, run_methods, run_study, variants
from fabricfem.studies.sleeve_fit import DEFAULT_LONG_AXIS_FACTOR, FIT_SCALES, fit_configs, run_fit_study
from fabricfem.verify import load_cases, load_reproductions
from fabricfem.verify.report import report


def _print(*args, **kw):
    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kw, flush=True)


# errors a user can cause (bad scene values, files, folders): one line on stderr, exit code 2 (--debug: traceback)
USER_ERRORS = (scene_module.SceneError, ValueError, OSError, UnicodeDecodeError)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="fabricfem", description=__doc__)
    parser.add_argument("--verbose", action="store_true", help="show the form compiler's and other libraries' INFO lines")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an input error")
    sub = parser.add_subparsers(dest="command", required=True)
    p_verify = sub.add_parser("verify", help="run verification cases against independent references")
    p_verify.add_argument("cases", nargs="*", help="case names (default: all)")
    p_verify.add_argument("--json", action="store_true", help="print a JSON list of results")
    p_verify.add_argument("--list", action="store_true", help="list the cases and exit")
    p_verify.add_argument("--markdown", metavar="PATH", help="also write the table as Markdown to PATH")
    p_reproduce = sub.add_parser("reproduce", help="the source papers' figures and tables beside ours, with each "
                                                  "deviation's measured cause (a report, not a gate)")
    p_reproduce.add_argument("cases", nargs="*", help="reproduction names (default: all)")
    p_reproduce.add_argument("--json", action="store_true", help="print a JSON list of results")
    p_reproduce.add_argument("--list", action="store_true", help="list the reproductions and exit")
    p_reproduce.add_argument("--markdown", metavar="PATH", help="also write the table as Markdown to PATH")
    p_run = sub.add_parser("run", help="run a scene file (TOML), e.g. scenes/rollup.toml")
    p_run.add_argument("scene", help="path of the scene file")
    p_run.add_argument("--accuracy", default=None, metavar="TARGET",
                       help="relative error target (2%% or 0.02): run the cheapest mesh level that meets it")
    p_run.add_argument("--quantity", default=None, help="the monitored quantity of the target (default [accuracy])")
    p_run.add_argument("--window", type=float, default=None, metavar="SECONDS",
                       help="wear scenes: the pilots run the first SECONDS of body time (default [accuracy] window)")
    p_run.add_argument("--out", default=None, help="output folder (default: the scene's [output] dir)")
    p_run.add_argument("--resume", action="store_true",
                       help="wear and dynamic scenes: continue from the output folder's checkpoint after a kill "
                            "or Ctrl-C")
    p_plan = sub.add_parser("plan", help="the mesh levels of a scene with their estimated errors and costs, and "
                                         "the level an accuracy target chooses (no full run)")
    p_plan.add_argument("scene", help="path of the scene file")
    p_plan.add_argument("--accuracy", default=None, metavar="TARGET", help="relative error target (2%% or 0.02)")
    p_plan.add_argument("--quantity", default=None, help="the monitored quantity (default [accuracy] quantity)")
    p_plan.add_argument("--window", type=float, default=None, metavar="SECONDS",
                        help="wear scenes: the pilots run the first SECONDS of body time (default [accuracy] window)")
    p_sweep = sub.add_parser("sweep", help="run the variants of a scene as one MPI batch (fabricfem.scenes.sweep)")
    p_sweep.add_argument("scene", help="path of the scene file")
    p_sweep.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2,...",
                         help="a dotted scene key and its values (TOML), e.g. fabric.E1=1e6,2e6; repeat for a product")
    p_sweep.add_argument("--out", default=None, help="output folder (default results/<scene name>_sweep)")
    p_sweep.add_argument("--ranks-per-variant", type=int, default=1, help="MPI ranks of each variant's group")
    p_sweep.add_argument("--plot", default=None, metavar="QUANTITY",
                         help="summary.json entry drawn against the first varied key in sweep.png")
    p_scenes = sub.add_parser("scenes", help="the scene-file reference: every section and key with type, default, unit")
    p_scenes.add_argument("--markdown", metavar="PATH", help="write it to PATH (docs/scenes.md) instead of printing")
    p_demo = sub.add_parser("demo", help="the default demo: a fabric strip rolled up by an end moment")
    p_demo.add_argument("--out", default="results/demo", help="output folder (XDMF, PNG, CSV)")
    p_bench = sub.add_parser("bench", help="benchmarks (results/ CSV and PNG)")
    p_bench.add_argument("name", nargs="?", default="rollup-profile", choices=["rollup-profile", "stability-map", "speed-accuracy", "unit-cell",
                                          "sleeve-profile", "accuracy", "wear", "commits", "kernel"],
                         help="benchmark to run")
    p_bench.add_argument("--out", default="results/bench")
    p_bench.add_argument("--quick", action="store_true",
                         help="reduced smoke-test runs (stability-map: one k/rho, the smallest mesh, short runs; "
                              "speed-accuracy: t = 0.3 s, two levels per method, one timing)")
    p_bench.add_argument("--meshes", default="I,III",
                         help="wear, kernel: sleeve meshes (and for wear the pants scene), comma-separated "
                              "(I, II, III, IV, pants)")
    p_bench.add_argument("--duration", type=float, default=None,
                         help="wear: the pants' walk [s] (default: the scene's four strides)")
    p_bench.add_argument("--variants",
                         default="reference,kernels,eigenvalue step,quadrature geometry,safety 0.9,hand kernel,compiled contact,mass x4,mass x16",
                         help="wear: variants, comma-separated (fabricfem.benchmarks.wear_speed.VARIANTS)")
    p_bench.add_argument("--repeats", type=int, default=3, help="wear, commits, kernel: runs of every variant (medians)")
    p_bench.add_argument("--old", help="commits: the baseline commit (e.g. a sha or a tag)")
    p_bench.add_argument("--new", default="HEAD", help="commits: the commit compared with it")
    p_bench.add_argument("--scene", help="commits: the wear scene to time")
    p_bench.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                         help="commits: replace a dotted scene key (repeatable), e.g. motion.strides=1")
    p_bench.add_argument("--ranks", type=int, default=1, help="commits: MPI ranks of every run")
    p_study = sub.add_parser("study", help="parameter studies (CSV + PNG per figure)")
    p_study.add_argument("name", choices=["sleeve", "unit-cell", "fabric-link", "sleeve-fit", "sleeve-methods", "pants"],
                         help="study to run (sleeve: [Man2006, sec. 5.3]; unit-cell: [Man2006, sec. 4.3.5], Figs. 21-28, 32-33)")
    p_study.add_argument("--quick", action="store_true", help="coarse mesh and few angle steps (reduced)")
    p_study.add_argument("--out", default="results/sleeve_study")
    p_study.add_argument("--ranks-per-variant", type=int, default=1,
                         help="sleeve, sleeve-fit, sleeve-methods, unit-cell, pants: MPI ranks of each variant's group (the variants run as a "
                              "batch, as `fabricfem sweep`)")
    p_study.add_argument("--fine", choices=["I", "II", "III", "IV"], default="III",
                         help="sleeve: mesh of the parameter figures (friction, fit, thickness, fabrics)")
    p_study.add_argument("--meshes", default="I,II,III,IV", help="sleeve: meshes of the mesh series, e.g. I,II")
    p_study.add_argument("--fabrics", default="I,II,III", help="sleeve: fabric sets of the fabrics figure")
    p_study.add_argument("--compare-with", default=None,
                         help="sleeve: after the run, compare its torque curves with the figure CSVs in this folder "
                              "(e.g. docs/figures/sleeve): comparison.csv, RMS over 10 deg to the end")
    p_study.add_argument("--mesh-frictions", default="0.1,0.5", help="sleeve: mu of the mesh series run, e.g. 0.5")
    p_study.add_argument("--only", default=None,
                         help="sleeve: run only these figures, e.g. mesh_mu0.5,fit (default: all)")
    p_study.add_argument("--mesh", choices=["I", "II", "III", "IV"], default="II", help="sleeve-fit: sleeve mesh")
    p_study.add_argument("--scales", default=None, help="sleeve-fit: arm girth scales (default 1,1.04,1.0771)")
    p_study.add_argument("--docs", default=None, help="sleeve-fit: also write fit_sensitivity.* into this folder")
    p_study.add_argument("--long-axis-factors", default=None,
                         help="sleeve-fit: arm long semi-axis / segment length, e.g. 0.5,0.6,0.7 (default 0.5; "
                              "other than 0.5 alone: docs files fit_sensitivity_elbow.*)")
    p_study.add_argument("--angular-velocity", type=float, default=None,
                         help="sleeve-fit: flexion speed [deg/s] of every run (default 45, SleeveConfig; other "
                              "speeds: files <prefix>_omega<speed>.*, a rate-convergence check)")
    p_study.add_argument("--full-quadrature", action="store_true",
                         help="sleeve-fit: full 3x3 quadrature (SleeveConfig.quadrature = (4, 4)) instead of the "
                              "default PSRI; files <prefix>_fullquad.*")
    p_study.add_argument("--methods", default="lagrange,penalty,augmented",
                         help="sleeve-methods: contact methods to run (shared over the MPI ranks)")
    p_study.add_argument("--al-budget", type=float, default=1800.0,
                         help="sleeve-methods: wall-time budget [s] of the augmented-Lagrangian (implicit) run")
    p_study.add_argument("--recompute-stopped", action="store_true",
                         help="unit-cell: solve again the curves of --out that stopped early (others are read back)")
    refinement = p_study.add_mutually_exclusive_group()
    refinement.add_argument("--coarse-only", action="store_true",
                            help="unit-cell: with --recompute-stopped, only the coarse cells' curves")
    refinement.add_argument("--fine-only", action="store_true",
                            help="unit-cell: with --recompute-stopped, only the fine cells' curves")
    p_study.add_argument("--budget", type=float, default=None,
                         help="unit-cell: wall-time budget [s] of each solved load case (default: by cell, "
                              "fabricfem.studies.unit_cell.TIME_BUDGET)")
    args = parser.parse_args(argv)
    args.argv = sys.argv[1:] if argv is None else list(argv)
    # FFCx's logging.basicConfig and the compiler's (setuptools) root-logger level print every JIT compilation at
    # INFO: hidden unless --verbose (global, since the level of the root logger is changed by those packages)
    logging.disable(logging.NOTSET if args.verbose else logging.INFO)
    try:
        return _command(args)
    except BatchError as exc:      # a study's variants that failed, named after the others ran (a rerun resumes)
        if args.debug:
            raise
        _print(f"fabricfem {args.command}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    except USER_ERRORS as exc:
        if args.debug:
            raise
        _print(f"fabricfem {args.command}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


def _command(args) -> int:
    if args.command in ("verify", "reproduce"):
        registry = load_cases() if args.command == "verify" else load_reproductions()
        if args.list:
            for name, fn in registry.items():
                _print(f"{name:<26} {(fn.__doc__ or '').strip().splitlines()[0]}")
            return 0
        return report(registry, args.cases, args.command, args.json, args.markdown)
    if args.command == "plan":
        scene = with_window(scene_module.load(args.scene), args.window)
        plan(scene, None if args.accuracy is None else parse_target(args.accuracy), args.quantity).require()
        return 0
    if args.command == "run":
        scene = with_window(scene_module.load(args.scene), args.window)
        target = None if args.accuracy is None else parse_target(args.accuracy)
        try:
            if (target is not None or args.quantity is not None or args.window is not None
                    or scene.get("accuracy", {}).get("target")):
                _, outcome = run_accurate(scene, target, args.quantity)
            else:
                outcome = run_scene(scene, out=None if args.out is None else Path(args.out), resume=args.resume)
        except (SolverError, DynamicsError) as exc:   # the run stopped: summary.json says "failed: ..."
            _print(f"fabricfem run: stopped: {' '.join(str(exc).split())}", file=sys.stderr)
            return 1
        if outcome.exit_code:
            _print(f"fabricfem run: {outcome.status}", file=sys.stderr)
        return outcome.exit_code
    if args.command == "sweep":
        scene = scene_module.load(args.scene)
        varies = [parse_vary(text) for text in args.vary]
        rows = run_sweep(scene, varies, args.out or f"results/{scene_name(scene)}_sweep", args.ranks_per_variant,
                         args.plot)
        return 0 if all(row["status"] == "completed" for row in rows) else 1
    if args.command == "scenes":
        text = scene_module.schema.reference_markdown()
        if args.markdown:
            Path(args.markdown).write_text(text + "\n")
        else:
            _print(text)
        return 0
    if args.command == "demo":
        rollup_demo(args.out)
        return 0
    if args.command == "study" and args.name in ("sleeve", "unit-cell", "pants", "sleeve-fit", "sleeve-methods"):
        groups_of(MPI.COMM_WORLD, args.ranks_per_variant)     # a bad --ranks-per-variant: a message, not a traceback
    if args.command == "study" and args.name == "pants":
        run_pants_study("results/pants_study" if args.out == "results/sleeve_study" else args.out, args.quick,
                        ranks_per_variant=args.ranks_per_variant)
        return 0
    if args.command == "study" and args.name == "fabric-link":
        meshes = ((10, 13),) if args.quick else ((10, 13), (20, 26))
        run_fabric_link(OUT_DIR if args.out == "results/sleeve_study" else args.out, sleeve_meshes=meshes)
        return 0
    if args.command == "study" and args.name == "sleeve-fit":
        try:
            scales = FIT_SCALES if args.scales is None else tuple(float(s) for s in args.scales.split(",") if s.strip())
            factors = ((DEFAULT_LONG_AXIS_FACTOR,) if args.long_axis_factors is None else
                       tuple(float(f) for f in args.long_axis_factors.split(",") if f.strip()))
            overrides = {} if args.angular_velocity is None else {"angular_velocity": args.angular_velocity}
            if args.full_quadrature:
                overrides["quadrature"] = (4, 4)
            for factor in factors:    # a scale not positive, an arm too thick, a factor outside [0.5, 1] or a
                fit_configs(scales, args.mesh, long_axis_factor=factor, **overrides)   # speed <= 0: a message
        except ValueError as exc:
            _print(f"fabricfem study sleeve-fit: --scales {args.scales} --long-axis-factors "
                   f"{args.long_axis_factors} --angular-velocity {args.angular_velocity}: {exc}", file=sys.stderr)
            return 2
        prefix = "fit_sensitivity" if factors == (DEFAULT_LONG_AXIS_FACTOR,) else "fit_sensitivity_elbow"
        if args.angular_velocity is not None:
            prefix += f"_omega{args.angular_velocity:g}"
        if args.full_quadrature:
            prefix += "_fullquad"
        if args.mesh != "II":                # the default mesh's files carry no mesh tag (docs/figures/sleeve)
            prefix += f".mesh{args.mesh}"
        run_fit_study("results/sleeve_fit" if args.out == "results/sleeve_study" else args.out, mesh=args.mesh,
                      scales=scales, docs=args.docs, long_axis_factors=factors, prefix=prefix,
                      ranks_per_variant=args.ranks_per_variant, **overrides)
        return 0
    if args.command == "study" and args.name == "sleeve-methods":
        # the three contact methods on the sleeve with gravity (fabricfem.studies.sleeve.run_methods); --mesh defaults to
        # III here (the sleeve-fit default is II)
        given = args.argv
        mesh = args.mesh if any(a == "--mesh" or a.startswith("--mesh=") for a in given) else "III"
        methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
        try:
            run_methods("results/sleeve_methods_gravity.csv" if args.out == "results/sleeve_study" else args.out,
                        mesh=mesh, methods=methods, al_budget=args.al_budget,
                        ranks_per_variant=args.ranks_per_variant)
        except ValueError as exc:
            _print(f"fabricfem study sleeve-methods: {exc}", file=sys.stderr)
            return 2
        return 0
    if args.command == "study" and args.name == "unit-cell":
        out = "results/unit_cell" if args.out == "results/sleeve_study" else args.out
        # --recompute-stopped: solve again the curves of `out` that stopped early (after a solver change or with
        # a larger --budget); --coarse-only / --fine-only: only those on coarse / fine cells
        if args.budget is not None and not (math.isfinite(args.budget) and args.budget > 0.0):
            _print(f"fabricfem study unit-cell: --budget must be a positive time [s], got {args.budget}",
                   file=sys.stderr)
            return 2
        skip = "fine" if args.coarse_only else "coarse" if args.fine_only else None
        stopped = ({key for key, run in unit_cell_study.previous_runs(out).items() if run.stopped and key.refinement != skip}
                   if args.recompute_stopped and os.path.isdir(out) else set())
        unit_cell_study.run_study(out, quick=args.quick, recompute=stopped, time_budget=args.budget,
                                  ranks_per_variant=args.ranks_per_variant)
        return 0
    if args.command == "study":
        options = dict(quick=args.quick, fine=args.fine,
                       meshes=tuple(m.strip() for m in args.meshes.split(",") if m.strip()),
                       fabrics=tuple(f.strip() for f in args.fabrics.split(",") if f.strip()))
        try:
            options["mesh_frictions"] = tuple(float(m) for m in args.mesh_frictions.split(",") if m.strip())
        except ValueError:
            _print(f"fabricfem study sleeve: --mesh-frictions must be numbers, got {args.mesh_frictions!r}",
                   file=sys.stderr)
            return 2
        if args.only is not None:
            options["only"] = tuple(f.strip() for f in args.only.split(",") if f.strip())
        try:
            variants(**options)   # bad --fine / --meshes / --fabrics: a message, not a traceback
            if args.compare_with is not None and not Path(args.compare_with).is_dir():
                raise ValueError(f"--compare-with: {args.compare_with!r} is not a folder of study figures")
        except ValueError as exc:
            _print(f"fabricfem study sleeve: {exc}", file=sys.stderr)
            return 2
        run_study(args.out, ranks_per_variant=args.ranks_per_variant, **options)
        if args.compare_with is not None:
            for figure, label, error, stored, final in compare_figures(args.out, args.compare_with):
                _print(f"{figure:11s} {label:22s} torque RMS difference {100 * error:6.2f} % over 10 deg to the end; "
                       f"final {final:.5g} N m (stored {stored:.5g})")
        return 0
    if args.command == "bench":
        if args.name == "unit-cell":
            unit_cell_perf("results/unit_cell_perf" if args.out == "results/bench" else args.out, quick=args.quick)
            return 0
        if args.name == "stability-map":
            stability_map(args.out, quick=args.quick)
            return 0
        if args.name == "speed-accuracy":
            speed_accuracy(args.out, quick=args.quick)
            return 0
        if args.name == "accuracy":
            accuracy_bench(args.out)
            return 0
        if args.name == "commits":
            try:
                if not (args.old and args.scene):
                    raise ValueError("--old and --scene are required")
                compare_commits(args.scene, args.old, args.new, tuple(args.set), args.repeats, args.ranks, args.out)
            except ValueError as exc:
                _print(f"fabricfem bench commits: {exc}", file=sys.stderr)
                return 2
            return 0
        if args.name == "wear":
            try:
                wear_bench(args.out, meshes=tuple(args.meshes.split(",")), variants=tuple(args.variants.split(",")),
                           repeats=args.repeats, quick=args.quick, duration=args.duration)
            except ValueError as exc:
                _print(f"fabricfem bench wear: {exc}", file=sys.stderr)
                return 2
            return 0
        if args.name == "sleeve-profile":
            sleeve_profile(args.out, quick=args.quick)
            return 0
        if args.name == "kernel":
            try:
                internal_force_bench(args.out, meshes=tuple(args.meshes.split(",")), repeats=args.repeats)
            except ValueError as exc:
                _print(f"fabricfem bench kernel: {exc}", file=sys.stderr)
                return 2
            return 0
        rollup_profile(args.out)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())
