"""The command line: `fabricfem [--debug] [--verbose] [--json] COMMAND ...`; `fabricfem COMMAND --help` lists a
command's options.

Commands: run, plan and sweep (scene files), verify and reproduce (comparisons with references and papers),
scenes (the scene-file reference), demo, study NAME (the parameter studies, fabricfem.cli.study) and bench [NAME]
(the benchmarks, fabricfem.cli.bench).

--debug, --verbose and --json may come before the command or after it. --json: verify and reproduce (also with
--list) and plan print JSON instead of their table, run prints its summary.json and sweep its rows; whatever else
they print goes to stderr, so that stdout holds the JSON alone. The other commands write files and ignore it.

Exit codes: 0 done; 1 a run that stopped early (its summary.json says why), a verification that failed or a
study's variants that failed (a rerun resumes); 2 an input error (one line on stderr naming the file, section and
key or the option; --debug: the Python traceback instead) or a command line argparse refuses.

Under mpirun every rank leaves through fabricfem.cli.common.leave_together: a rank that stops with an error the
others do not reach (they wait in a collective) aborts the job after LEAVE_WAIT seconds instead of hanging.
"""
from __future__ import annotations

import argparse
import logging
import sys

from mpi4py import MPI

from fabricfem import scenes as scene_module
from fabricfem.cli.bench import add_bench_command
from fabricfem.cli.common import global_flags, leave_together, say
from fabricfem.cli.scene import add_scene_commands
from fabricfem.cli.study import add_study_command
from fabricfem.cli.verify import add_verify_commands
from fabricfem.scenes.batch import BatchError

# errors a user can cause (bad scene values, files, folders): one line on stderr, exit code 2 (--debug: traceback)
USER_ERRORS = (scene_module.SceneError, ValueError, OSError, UnicodeDecodeError)


def build_parser() -> argparse.ArgumentParser:
    """The `fabricfem` parser: every command and subcommand sets `handler` and `command` (module docstring)."""
    parser = argparse.ArgumentParser(prog="fabricfem", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     parents=[global_flags(suppress=False)])
    sub = parser.add_subparsers(metavar="COMMAND", required=True)
    add_scene_commands(sub)
    add_verify_commands(sub)
    add_study_command(sub)
    add_bench_command(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The console entry point: parse `argv` (default sys.argv[1:]), run the command's handler, return its exit code
    (module docstring: user errors one line and 2, a study's failed variants 1)."""
    args = build_parser().parse_args(argv)
    # FFCx's logging.basicConfig and the compiler's (setuptools) root-logger level print every JIT compilation at
    # INFO: hidden unless --verbose (global, since the level of the root logger is changed by those packages)
    logging.disable(logging.NOTSET if args.verbose else logging.INFO)
    exit_comm = MPI.COMM_WORLD.Dup() if MPI.COMM_WORLD.size > 1 else None   # only for leave_together
    reason = "done"
    try:
        code = args.handler(args)
    except (BatchError, *USER_ERRORS) as exc:   # BatchError: failed variants, named after the others ran
        reason = " ".join(str(exc).split())
        if args.debug:
            leave_together(exit_comm, 2, reason)
            raise
        say(f"fabricfem {args.command}: {reason}", file=sys.stderr)
        code = 1 if isinstance(exc, BatchError) else 2
    except BaseException as exc:                 # a fault: its traceback, once the ranks leave together
        leave_together(exit_comm, 1, f"{type(exc).__name__}: {' '.join(str(exc).split())}")
        raise
    return leave_together(exit_comm, code, reason)   # every rank, also after success (module docstring)
