"""`fabricfem study NAME`: the parameter studies (CSV + PNG per figure), one subcommand per study with its own
options, default output folder and handler:

    study sleeve          [Man2006, sec. 5.3]: the sleeve's elbow torque over mesh, friction, fit, thickness, fabric
    study sleeve-fit      how the sleeve's fit and thickness trends depend on the arm's girth and elbow taper
    study sleeve-methods  the three contact methods on the sleeve with gravity
    study unit-cell       [Man2006, sec. 4.3.5], Figs. 21-28, 32-33: the woven unit cell
    study fabric-link     a membrane law fitted to the unit cell with contact, used on the sleeve
    study pants           [Man2006, sec. 5.4]: 1 and 2 mm pants, mu 0.1 and 0.5, on a walk
    study convergence     a wear scene on a ladder of garment meshes: differences to the finest, extrapolation

The studies with --ranks-per-variant run their variants as one batch (as `fabricfem sweep`; a rerun resumes);
option values are checked before any run (ValueError naming the option: exit 2).
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.cli.common import Subparsers, add_command, float_list, say, split_list
from fabricfem.scenes.batch import groups_of
from fabricfem.scenes.build import scene_name
from fabricfem.studies import unit_cell as unit_cell_study
from fabricfem.studies.convergence import run_convergence
from fabricfem.studies.fabric_link import OUT_DIR, run_fabric_link
from fabricfem.studies.pants import run_pants_study
from fabricfem.studies.sleeve import compare_figures, run_methods, run_study, variants
from fabricfem.studies.sleeve_fit import DEFAULT_LONG_AXIS_FACTOR, FIT_SCALES, fit_configs, run_fit_study

MESHES = ["I", "II", "III", "IV"]    # the sleeve meshes of [Man2006, sec. 5.3]: 10x13, 15x20, 20x26, 30x39
FIT_MESH = "II"                      # sleeve-fit's default mesh: its files carry no mesh tag (docs/figures/sleeve)


def _check_groups(args: argparse.Namespace) -> None:
    """A bad --ranks-per-variant: ValueError (a message, not a traceback) before any run."""
    groups_of(MPI.COMM_WORLD, args.ranks_per_variant)


def _sleeve(args: argparse.Namespace) -> int:
    """study sleeve: fabricfem.studies.sleeve.run_study, then with --compare-with the RMS differences of its torque
    curves from the stored figures."""
    _check_groups(args)
    options = {"quick": args.quick, "fine": args.fine, "meshes": split_list(args.meshes),
               "fabrics": split_list(args.fabrics),
               "mesh_frictions": float_list(args.mesh_frictions, "--mesh-frictions")}
    if args.only is not None:
        options["only"] = split_list(args.only)
    variants(**options)   # bad --fine / --meshes / --fabrics / --only: ValueError before any run
    if args.compare_with is not None and not Path(args.compare_with).is_dir():
        raise ValueError(f"--compare-with: {args.compare_with!r} is not a folder of study figures")
    run_study(args.out, ranks_per_variant=args.ranks_per_variant, **options)
    if args.compare_with is not None:
        for figure, label, error, stored, final in compare_figures(args.out, args.compare_with):
            say(f"{figure:11s} {label:22s} torque RMS difference {100 * error:6.2f} % over 10 deg to the end; "
                f"final {final:.5g} N m (stored {stored:.5g})")
    return 0


def _fit_prefix(args: argparse.Namespace, factors: tuple[float, ...]) -> str:
    """The file prefix of a sleeve-fit run: fit_sensitivity (default arm) or fit_sensitivity_elbow (other long-axis
    factors), then _omega<speed>, _fullquad and .mesh<M> for a mesh other than FIT_MESH."""
    prefix = "fit_sensitivity" if factors == (DEFAULT_LONG_AXIS_FACTOR,) else "fit_sensitivity_elbow"
    if args.angular_velocity is not None:
        prefix += f"_omega{args.angular_velocity:g}"
    if args.full_quadrature:
        prefix += "_fullquad"
    return prefix if args.mesh == FIT_MESH else f"{prefix}.mesh{args.mesh}"


def _sleeve_fit(args: argparse.Namespace) -> int:
    """study sleeve-fit: fabricfem.studies.sleeve_fit.run_fit_study once the arms and speeds are checked."""
    _check_groups(args)
    scales = FIT_SCALES if args.scales is None else float_list(args.scales, "--scales")
    factors = ((DEFAULT_LONG_AXIS_FACTOR,) if args.long_axis_factors is None
               else float_list(args.long_axis_factors, "--long-axis-factors"))
    overrides = {} if args.angular_velocity is None else {"angular_velocity": args.angular_velocity}
    if args.full_quadrature:
        overrides["quadrature"] = (4, 4)
    try:   # a scale not positive, an arm too thick, a factor outside [0.5, 1] or a speed <= 0
        for factor in factors:
            fit_configs(scales, args.mesh, long_axis_factor=factor, **overrides)
    except ValueError as exc:
        raise ValueError(f"--scales {args.scales} --long-axis-factors {args.long_axis_factors} --angular-velocity "
                         f"{args.angular_velocity}: {exc}") from exc
    run_fit_study(args.out, mesh=args.mesh, scales=scales, docs=args.docs, long_axis_factors=factors,
                  prefix=_fit_prefix(args, factors), ranks_per_variant=args.ranks_per_variant, **overrides)
    return 0


def _sleeve_methods(args: argparse.Namespace) -> int:
    """study sleeve-methods: fabricfem.studies.sleeve.run_methods (bad --methods / --al-budget: ValueError)."""
    _check_groups(args)
    run_methods(args.out, mesh=args.mesh, methods=split_list(args.methods), al_budget=args.al_budget,
                ranks_per_variant=args.ranks_per_variant)
    return 0


def _unit_cell(args: argparse.Namespace) -> int:
    """study unit-cell: fabricfem.studies.unit_cell.run_study; with --recompute-stopped the curves of --out that
    stopped early are solved again (--coarse-only / --fine-only: those on coarse / fine cells only)."""
    _check_groups(args)
    if args.budget is not None and not (math.isfinite(args.budget) and args.budget > 0.0):
        raise ValueError(f"--budget must be a positive time [s], got {args.budget}")
    skip = "fine" if args.coarse_only else "coarse" if args.fine_only else None
    stopped = ({key for key, run in unit_cell_study.previous_runs(args.out).items()
                if run.stopped and key.refinement != skip}
               if args.recompute_stopped and os.path.isdir(args.out) else set())
    unit_cell_study.run_study(args.out, quick=args.quick, recompute=stopped, time_budget=args.budget,
                              ranks_per_variant=args.ranks_per_variant)
    return 0


def _fabric_link(args: argparse.Namespace) -> int:
    """study fabric-link: fabricfem.studies.fabric_link.run_fabric_link on sleeve mesh 10x13 (and 20x26 unless
    --quick)."""
    run_fabric_link(args.out, sleeve_meshes=((10, 13),) if args.quick else ((10, 13), (20, 26)))
    return 0


def _pants(args: argparse.Namespace) -> int:
    """study pants: fabricfem.studies.pants.run_pants_study."""
    _check_groups(args)
    run_pants_study(args.out, args.quick, ranks_per_variant=args.ranks_per_variant)
    return 0


def _add_sleeve_studies(names: Subparsers) -> dict[str, argparse.ArgumentParser]:
    """sleeve, sleeve-fit and sleeve-methods with their own options; returns them by name."""
    sleeve = add_command(names, "study sleeve", _sleeve, help="[Man2006, sec. 5.3]: the sleeve's elbow torque")
    sleeve.add_argument("--fine", choices=MESHES, default="III",
                        help="mesh of the parameter figures (friction, fit, thickness, fabrics; default %(default)s)")
    sleeve.add_argument("--meshes", default=",".join(MESHES), help="meshes of the mesh series (default %(default)s)")
    sleeve.add_argument("--fabrics", default="I,II,III", help="fabric sets of the fabrics figure (default %(default)s)")
    sleeve.add_argument("--mesh-frictions", default="0.1,0.5", help="mu of the mesh series (default %(default)s)")
    sleeve.add_argument("--only", default=None, help="run only these figures, e.g. mesh_mu0.5,fit (default: all)")
    sleeve.add_argument("--compare-with", default=None,
                        help="after the run, compare its torque curves with the figure CSVs in this folder (e.g. "
                             "docs/figures/sleeve): comparison.csv, RMS over 10 deg to the end")
    fit = add_command(names, "study sleeve-fit", _sleeve_fit,
                      help="the sleeve's fit and thickness trends against the arm's girth and elbow taper")
    fit.add_argument("--mesh", choices=MESHES, default=FIT_MESH, help="sleeve mesh (default %(default)s)")
    fit.add_argument("--scales", default=None, help="arm girth scales (default 1,1.04,1.0771)")
    fit.add_argument("--docs", default=None, help="also write fit_sensitivity.* into this folder")
    fit.add_argument("--long-axis-factors", default=None,
                     help="arm long semi-axis / segment length, e.g. 0.5,0.6,0.7 (default 0.5; other than 0.5 "
                          "alone: files fit_sensitivity_elbow.*)")
    fit.add_argument("--angular-velocity", type=float, default=None,
                     help="flexion speed [deg/s] of every run (default 45; other speeds: files "
                          "<prefix>_omega<speed>.*)")
    fit.add_argument("--full-quadrature", action="store_true",
                     help="full 3x3 quadrature instead of the default PSRI; files <prefix>_fullquad.*")
    methods = add_command(names, "study sleeve-methods", _sleeve_methods,
                          help="the three contact methods on the sleeve with gravity")
    methods.add_argument("--mesh", choices=MESHES, default="III", help="sleeve mesh (default %(default)s)")
    methods.add_argument("--methods", default="lagrange,penalty,augmented",
                         help="contact methods to run (default %(default)s)")
    methods.add_argument("--al-budget", type=float, default=1800.0,
                         help="wall-time budget [s] of the augmented-Lagrangian (implicit) run (default %(default)s)")
    return {"sleeve": sleeve, "sleeve-fit": fit, "sleeve-methods": methods}


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.4e}"


def _convergence(args: argparse.Namespace) -> int:
    """study convergence: fabricfem.studies.convergence.run_convergence of a wear scene."""
    _check_groups(args)
    scene = scene_module.load(args.scene)
    out = args.out or f"results/{scene_name(scene)}_convergence"
    rows = run_convergence(scene, out, args.levels, args.ratio, args.quick, ranks_per_variant=args.ranks_per_variant)
    for row in rows:
        say(f"  level {row['level']} ({row['mesh']}) {row['monitor']}: curve {100 * row['curve_rms_difference']:.2f} % "
            f"RMS from the finest, window mean {row['window_mean_Nm']:.4e} N m ({row['note']}), p95 |T| "
            f"{_number(row['p95_abs_Nm'])} N m ({row['p95_note']})")
    say(f"wrote {out}/convergence.csv and convergence.png")
    return 0


def _add_other_studies(names: Subparsers) -> dict[str, argparse.ArgumentParser]:
    """unit-cell, fabric-link and pants with their own options; returns them by name."""
    cell = add_command(names, "study unit-cell", _unit_cell,
                       help="[Man2006, sec. 4.3.5], Figs. 21-28, 32-33: the woven unit cell")
    cell.add_argument("--recompute-stopped", action="store_true",
                      help="solve again the curves of --out that stopped early (the others are read back)")
    refinement = cell.add_mutually_exclusive_group()
    refinement.add_argument("--coarse-only", action="store_true",
                            help="with --recompute-stopped, only the coarse cells' curves")
    refinement.add_argument("--fine-only", action="store_true",
                            help="with --recompute-stopped, only the fine cells' curves")
    cell.add_argument("--budget", type=float, default=None,
                      help="wall-time budget [s] of each solved load case (default: by cell, "
                           "fabricfem.studies.unit_cell.TIME_BUDGET)")
    link = add_command(names, "study fabric-link", _fabric_link,
                       help="a membrane law fitted to the unit cell with contact, used on the sleeve")
    pants = add_command(names, "study pants", _pants, help="[Man2006, sec. 5.4]: pants on a walk")
    convergence = add_command(names, "study convergence", _convergence,
                              help="a wear scene on a ladder of garment meshes: differences to the finest, "
                                   "extrapolation (error bars)")
    convergence.add_argument("scene", help="the wear scene file (TOML); its mesh is the coarsest level")
    convergence.add_argument("--levels", type=int, default=3, help="mesh levels (default %(default)s)")
    convergence.add_argument("--ratio", type=float, default=1.5,
                             help="refinement ratio between levels (default %(default)s)")
    return {"unit-cell": cell, "fabric-link": link, "pants": pants, "convergence": convergence}


# study -> (default --out, takes --quick, takes --ranks-per-variant)
COMMON = {"sleeve": ("results/sleeve_study", True, True),
          "sleeve-fit": ("results/sleeve_fit", False, True),
          "sleeve-methods": ("results/sleeve_methods_gravity.csv", False, True),
          "unit-cell": ("results/unit_cell", True, True),
          "fabric-link": (OUT_DIR, True, False),
          "pants": ("results/pants_study", True, True),
          "convergence": (None, True, True)}


def add_study_command(sub: Subparsers) -> None:
    """`study` and its subcommands (module docstring)."""
    study = add_command(sub, "study", None, help="parameter studies (CSV + PNG per figure)",
                        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    names = study.add_subparsers(metavar="NAME", required=True)
    parsers = {**_add_sleeve_studies(names), **_add_other_studies(names)}
    for name, (out, quick, ranks) in COMMON.items():
        parser = parsers[name]
        parser.add_argument("--out", default=out, help="output (default %(default)s)")
        if quick:
            parser.add_argument("--quick", action="store_true", help="coarse mesh and few steps (reduced)")
        if ranks:
            parser.add_argument("--ranks-per-variant", type=int, default=1,
                                help="MPI ranks of each variant's group (the variants run as a batch, as "
                                     "`fabricfem sweep`)")
