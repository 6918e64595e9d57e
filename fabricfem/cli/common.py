"""What the command-line modules share (fabricfem.cli and its scene, verify, study and bench modules): the global
flags, the subcommand builder that sets every parser's `handler` and `command`, output on rank 0, JSON on stdout
and comma-separated option values."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Callable, Iterator

from mpi4py import MPI

Handler = Callable[[argparse.Namespace], int]
Subparsers = argparse._SubParsersAction


def say(*args, **kw) -> None:
    """print on rank 0 only, flushed (every rank runs the same command)."""
    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kw, flush=True)


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
