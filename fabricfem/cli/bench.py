"""`fabricfem bench [NAME]`: the benchmarks (CSV and PNG under --out), one subcommand per benchmark with its own
options and handler; `fabricfem bench` alone is `fabricfem bench rollup-profile`."""
from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import NamedTuple

from fabricfem.benchmarks import stability_map
from fabricfem.benchmarks.accuracy import accuracy_bench
from fabricfem.benchmarks.commits import compare_commits
from fabricfem.benchmarks.internal_force import internal_force_bench
from fabricfem.benchmarks.parallel_runs import parallel_bench
from fabricfem.benchmarks.rollup_profile import rollup_profile
from fabricfem.benchmarks.sleeve_profile import sleeve_profile
from fabricfem.benchmarks.speed_accuracy import speed_accuracy
from fabricfem.benchmarks.unit_cell_perf import unit_cell_perf
from fabricfem.benchmarks.wear_speed import VARIANTS, wear_bench
from fabricfem.cli.common import Handler, Subparsers, add_command, split_list

BENCH_OUT = "results/bench"
SLEEVE_MESHES = "I,III"    # wear, kernel: the default sleeve meshes


def _files(function: Callable, quick: bool) -> Handler:
    """The handler of a benchmark that writes its files into args.out (and takes args.quick when `quick`)."""
    def handler(args: argparse.Namespace) -> int:
        function(args.out, **({"quick": args.quick} if quick else {}))
        return 0
    return handler


class FileBench(NamedTuple):
    """A benchmark that writes its files into --out: `function(out)`, or `function(out, quick=...)` when it takes
    --quick (`quick` is then that option's help)."""

    function: Callable
    out: str
    help: str
    quick: str | None = None


FILE_BENCHES = {
    "rollup-profile": FileBench(rollup_profile, BENCH_OUT, "where the time of a nonlinear shell solve goes (the "
                                "rolled strip under cProfile on several meshes)"),
    "stability-map": FileBench(stability_map, BENCH_OUT, "largest stable explicit time step against in-plane "
                               "stiffness and mesh size", quick="one k/rho, the smallest mesh, short runs"),
    "speed-accuracy": FileBench(speed_accuracy, BENCH_OUT, "error of a dynamic quantity against wall time, per cloth "
                                "method", quick="t = 0.3 s, two levels per method, one timing"),
    "sleeve-profile": FileBench(sleeve_profile, BENCH_OUT, "wall-time breakdown of the explicit sleeve flexion",
                                quick="mesh I only, 6 degrees, 2 repeats, no full flexion"),
    "accuracy": FileBench(accuracy_bench, BENCH_OUT, "the level the accuracy plan chooses against the cheapest level "
                          "that meets the target by brute force"),
    "unit-cell": FileBench(unit_cell_perf, "results/unit_cell_perf", "cost of the contact unit cell (time per load "
                           "step, contact share, memory)", quick="quarter coarse cell only, 2 steps, one run"),
}


def _wear(args: argparse.Namespace) -> int:
    """bench wear: the wearer engine's speed against its accuracy (fabricfem.benchmarks.wear_speed)."""
    wear_bench(args.out, meshes=split_list(args.meshes), variants=split_list(args.variants), repeats=args.repeats,
               quick=args.quick, duration=args.duration)
    return 0


def _kernel(args: argparse.Namespace) -> int:
    """bench kernel: the shell's internal force alone, per implementation (fabricfem.benchmarks.internal_force)."""
    internal_force_bench(args.out, meshes=split_list(args.meshes), repeats=args.repeats)
    return 0


def _commits(args: argparse.Namespace) -> int:
    """bench commits: a wear scene timed at two commits, alternating (fabricfem.benchmarks.commits)."""
    compare_commits(args.scene, args.old, args.new, tuple(args.set), args.repeats, args.ranks, args.out)
    return 0


def _parallel(args: argparse.Namespace) -> int:
    """bench parallel: a wear scene on 1 and 2 ranks, alternating (fabricfem.benchmarks.parallel_runs)."""
    parallel_bench(args.scene, split_list(args.meshes), tuple(args.set), args.repeats, args.out)
    return 0


def _add_timed_benches(sub: Subparsers) -> None:
    """wear, kernel, commits and parallel (repeated runs, medians)."""
    wear = add_command(sub, "bench wear", _wear, help="the wearer engine's speed against its accuracy")
    kernel = add_command(sub, "bench kernel", _kernel, help="the shell's internal force alone, per implementation")
    for parser in (wear, kernel):
        pants = ", pants" if parser is wear else ""
        parser.add_argument("--meshes", default=SLEEVE_MESHES,
                            help=f"sleeve meshes, comma-separated (I, II, III, IV{pants}; default %(default)s)")
    wear.add_argument("--quick", action="store_true",
                      help="smoke test: mesh I to 15 deg, reference and kernels, one run each")
    wear.add_argument("--duration", type=float, default=None, help="the pants' walk [s] (default: the scene's strides)")
    wear.add_argument("--variants", default=",".join(VARIANTS),
                      help="variants, comma-separated (default: all, fabricfem.benchmarks.wear_speed.VARIANTS)")
    commits = add_command(sub, "bench commits", _commits, help="a wear scene timed at two commits, alternating")
    commits.add_argument("--old", required=True, help="the baseline commit (e.g. a sha or a tag)")
    commits.add_argument("--new", default="HEAD", help="the commit compared with it (default %(default)s)")
    commits.add_argument("--scene", required=True, help="the wear scene to time")
    commits.add_argument("--ranks", type=int, default=1, help="MPI ranks of every run")
    parallel = add_command(sub, "bench parallel", _parallel, help="a wear scene on 1 and 2 ranks, alternating")
    parallel.add_argument("--scene", default="scenes/sleeve.toml", help="the wear scene (default %(default)s)")
    parallel.add_argument("--meshes", default="10x13,20x26,30x39,44x57",
                          help="tube meshes AxB, comma-separated, or 'scene' (default %(default)s)")
    for parser in (commits, parallel):
        parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                            help="replace a dotted scene key (repeatable), e.g. motion.final_angle=20")
    for parser in (wear, kernel, commits, parallel):
        parser.add_argument("--repeats", type=int, default=3, help="runs of every variant (medians; default 3)")
        parser.add_argument("--out", default=BENCH_OUT, help="output folder (default %(default)s)")


def add_bench_command(sub: Subparsers) -> None:
    """`bench` and its subcommands (module docstring)."""
    bench = add_command(sub, "bench", _files(rollup_profile, quick=False),
                        help="benchmarks (CSV + PNG under --out; no NAME: rollup-profile)")
    bench.set_defaults(out=BENCH_OUT)
    names = bench.add_subparsers(metavar="NAME", required=False)
    for name, spec in FILE_BENCHES.items():
        parser = add_command(names, f"bench {name}", _files(spec.function, spec.quick is not None), help=spec.help)
        parser.add_argument("--out", default=spec.out, help="output folder (default %(default)s)")
        if spec.quick is not None:
            parser.add_argument("--quick", action="store_true", help=f"smoke test: {spec.quick}")
    _add_timed_benches(names)
