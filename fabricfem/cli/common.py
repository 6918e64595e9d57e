"""What the command-line modules share (fabricfem.cli and its scene, verify, study and bench modules): the global
flags, the subcommand builder that sets every parser's `handler` and `command`, output on rank 0, JSON on stdout,
comma-separated option values, and how the ranks of an MPI job leave after an error."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from collections.abc import Callable, Iterator

from mpi4py import MPI

Handler = Callable[[argparse.Namespace], int]
Subparsers = argparse._SubParsersAction


def say(*args, **kw) -> None:
    """print on rank 0 only, flushed (every rank runs the same command)."""
    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kw, flush=True)


LEAVE_WAIT = 10.0   # s a rank that stopped with an error waits for the others to stop too before it aborts the job


def leave_together(exit_comm: MPI.Comm | None, code: int, reason: str, wait: float = LEAVE_WAIT) -> int:
    """`code`, once every rank of `exit_comm` (a communicator kept for this alone, duplicated from COMM_WORLD at the
    start) has come here too. An error raised on one rank only would leave the others waiting in a collective and
    the job hanging in MPI_Finalize: after `wait` [s] without them this rank says so on stderr, naming `reason`,
    and aborts the MPI job with `code`. A non-blocking barrier on the kept communicator cannot be matched by the
    collectives the others are blocked in; it is freed once all have come. None (one rank): `code` at once."""
    if exit_comm is None or exit_comm.size == 1:
        return code
    request, deadline = exit_comm.Ibarrier(), time.monotonic() + wait
    while not request.Test():
        if time.monotonic() > deadline:
            print(f"fabricfem: rank {exit_comm.rank} stopped ({reason}) and the other ranks did not within "
                  f"{wait:g} s: aborting the MPI job", file=sys.stderr, flush=True)
            exit_comm.Abort(code)
        time.sleep(0.01)
    exit_comm.Free()
    return code


def split_list(text: str) -> tuple[str, ...]:
    """A comma-separated option value as its stripped, non-empty items: "I, III," -> ("I", "III")."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


def float_list(text: str, option: str) -> tuple[float, ...]:
    """A comma-separated option value as numbers; ValueError naming `option` when an item is not one."""
    try:
        return tuple(float(item) for item in split_list(text))
    except ValueError:
        raise ValueError(f"{option} must be comma-separated numbers, got {text!r}") from None


def global_flags(suppress: bool) -> argparse.ArgumentParser:
    """A parent parser with --debug, --verbose and --json: default False on the top-level parser (`suppress`
    False) and SUPPRESS on the copies every subcommand takes (`suppress` True), so that such a flag may follow the
    command without the subcommand's default resetting one given before it."""
    default = argparse.SUPPRESS if suppress else False
    flags = argparse.ArgumentParser(add_help=False)
    flags.add_argument("--debug", action="store_true", default=default,
                       help="show the Python traceback of an input error instead of one line")
    flags.add_argument("--verbose", action="store_true", default=default,
                       help="show the form compiler's and other libraries' INFO lines")
    flags.add_argument("--json", action="store_true", default=default,
                       help="verify, reproduce, plan: JSON instead of the table; run: its summary.json; sweep: its "
                            "rows (stdout holds the JSON alone); other commands: no effect")
    return flags


def add_command(sub: Subparsers, words: str, handler: Handler | None, **kw) -> argparse.ArgumentParser:
    """The parser of the subcommand named by the last of `words` ("study sleeve": `sleeve` under `study`): it takes
    the global flags and sets `command` = `words` (error messages begin "fabricfem <words>:") and `handler` (a
    function of the parsed arguments returning the exit code; None: its own subcommands set it)."""
    parser = sub.add_parser(words.split()[-1], parents=[global_flags(suppress=True)], **kw)
    parser.set_defaults(command=words, **({} if handler is None else {"handler": handler}))
    return parser


@contextlib.contextmanager
def json_stdout(as_json: bool) -> Iterator[None]:
    """With `as_json`, send what the work inside prints to stderr (stdout is kept for the JSON); else no change."""
    with contextlib.redirect_stdout(sys.stderr) if as_json else contextlib.nullcontext():
        yield


def _finite(value: object) -> object:
    """`value` with its non-finite floats (also inside lists and dicts) replaced by None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def print_json(data: object) -> None:
    """Print `data` as strict JSON on stdout (rank 0): non-finite numbers as null, other objects as their str."""
    say(json.dumps(_finite(data), indent=1, default=str))
