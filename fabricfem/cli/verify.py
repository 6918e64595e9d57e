"""`fabricfem verify` (comparisons with independent references, a gate) and `fabricfem reproduce` (the papers'
figures and tables beside ours, a report): the same options over two registries of fabricfem.verify."""
from __future__ import annotations

import argparse
from collections.abc import Callable

from fabricfem.cli.common import Handler, Subparsers, add_command, print_json, say
from fabricfem.verify import load_cases, load_reproductions
from fabricfem.verify.report import report


def _registry_handler(load: Callable[[], dict[str, Callable]]) -> Handler:
    """The handler of verify / reproduce over the registry `load` returns: the cases named (default all) and the
    exit code of fabricfem.verify.report.report, or with --list the names and first docstring lines."""
    def handler(args: argparse.Namespace) -> int:
        registry = load()
        if not args.list:
            return report(registry, args.cases, args.command, args.json, args.markdown)
        described = {name: next(iter((fn.__doc__ or "").strip().splitlines()), "") for name, fn in registry.items()}
        if args.json:
            print_json([{"name": name, "description": text} for name, text in described.items()])
        else:
            for name, text in described.items():
                say(f"{name:<26} {text}")
        return 0
    return handler


def add_verify_commands(sub: Subparsers) -> None:
    """verify and reproduce (the same options, two registries)."""
    registries = {"verify": (load_cases, ("run verification cases against independent references (exit 0 when all "
                                         "pass)")),
                  "reproduce": (load_reproductions, ("the source papers' figures and tables beside ours, with each "
                                "deviation's measured cause (a report, not a gate)"))}
    for name, (load, text) in registries.items():
        parser = add_command(sub, name, _registry_handler(load), help=text)
        parser.add_argument("cases", nargs="*", help="case names (default: all)")
        parser.add_argument("--list", action="store_true", help="list the cases and exit")
        parser.add_argument("--markdown", metavar="PATH", help="also write the table as Markdown to PATH")
