"""Running registered cases and printing them: the table on stdout, JSON alone on stdout (`--json`; NaN and inf
as null), the Markdown file (docs/verification.md, docs/reproduction.md)."""
from __future__ import annotations

import contextlib
import datetime
import json
import math
import platform
import sys
from typing import Callable

from mpi4py import MPI

from fabricfem.verify import CaseResult

TITLES = {"verify": "Verification results", "reproduce": "Reproduction of the source papers"}


def _print(*args, **kw):
    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kw, flush=True)


def _finite_or_none(value):
    return value if not isinstance(value, float) or math.isfinite(value) else None


def run_cases(registry: dict[str, Callable], names: list[str], as_json: bool = False) -> list[CaseResult]:
    """Run the named cases (all when `names` is empty); a case that raises becomes one failed row naming the
    error. With `as_json`, whatever a case prints goes to stderr so that stdout holds the JSON alone."""
    results = []
    for name in names or list(registry):
        if not as_json:
            _print(f"running {name} ...")
        try:
            with contextlib.redirect_stdout(sys.stderr) if as_json else contextlib.nullcontext():
                results += registry[name]()
        except Exception as exc:  # a case that crashes fails, with its reason
            _print(f"  {name} raised {type(exc).__name__}: {exc}", file=sys.stderr)
            results.append(CaseResult(name, f"error: {type(exc).__name__}: {exc}", math.nan, math.nan, math.nan,
                                      0.0, False, 0, 0.0))
    return results


def json_text(results: list[CaseResult]) -> str:
    """The results as a JSON list (non-finite numbers as null: valid JSON)."""
    return json.dumps([{k: _finite_or_none(v) for k, v in r.as_dict().items()} for r in results], indent=1)


def table_text(results: list[CaseResult], command: str) -> str:
    """The results as a fixed-width table; the quantity column is as wide as its longest text (never cut)."""
    fail = "DEVIATES" if command == "reproduce" else "FAIL"
    width = max([len("quantity")] + [len(r.quantity) for r in results])
    header = (f"{'case':<26} {'quantity':<{width}} {'value':>12} {'reference':>12} {'rel_err':>9} {'tol':>8} "
              f"{'ok':>8} {'ndofs':>7} {'wall_s':>7}")
    lines = [header, "-" * len(header)]
    for r in results:
        lines.append(f"{r.case:<26} {r.quantity:<{width}} {r.value:>12.5g} {r.reference:>12.5g} {r.rel_error:>9.2e} "
                     f"{r.tolerance:>8.1e} {'PASS' if r.passed else fail:>8} {r.ndofs:>7d} {r.wall_s:>7.1f}")
    n_fail = sum(not r.passed for r in results)
    lines.append(f"\n{len(results) - n_fail} passed, {n_fail} {'deviate' if command == 'reproduce' else 'failed'}")
    return "\n".join(lines)


def deviations_text(registry: dict[str, Callable], results: list[CaseResult]) -> str:
    """For every reproduction with rows that deviate from the paper: its measured cause and where it is
    documented (the `deviation` of its registration)."""
    cases = dict.fromkeys(r.case for r in results if not r.passed)
    return "\n\n".join(f"{name}: {getattr(registry.get(name), 'deviation', None) or 'no cause recorded'}"
                       for name in cases)


def markdown_text(path: str, results: list[CaseResult], command: str, registry: dict[str, Callable]) -> str:
    """The table as Markdown, e.g. docs/verification.md or docs/reproduction.md."""
    fail = "deviates" if command == "reproduce" else "FAIL"
    lines = [f"# {TITLES[command]}\n",
             f"Produced by `fabricfem {command} --markdown {path}` on {datetime.date.today()} "
             f"({platform.node()}, {MPI.COMM_WORLD.size} rank(s)). A tolerance of inf marks a reported-only row.\n",
             "| case | quantity | value | reference | rel. error | tolerance | result | dofs | wall [s] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        quantity = r.quantity.replace("|", "\\|")
        lines.append(f"| {r.case} | {quantity} | {r.value:.6g} | {r.reference:.6g} | {r.rel_error:.2e} | "
                     f"{r.tolerance:.1e} | {'pass' if r.passed else fail} | {r.ndofs} | {r.wall_s:.1f} |")
    n_fail = sum(not r.passed for r in results)
    lines.append(f"\n{len(results) - n_fail} passed, {n_fail} {fail}\n")
    if command == "reproduce" and n_fail:
        lines += ["## Deviations, their measured causes and where they are documented\n",
                  deviations_text(registry, results), ""]
    return "\n".join(lines)


def report(registry: dict[str, Callable], names: list[str], command: str, as_json: bool,
           markdown: str | None) -> int:
    """`fabricfem verify|reproduce`: run, print and write; exit code 2 for an unknown case name, else (verify)
    0 when every row passes and 1 otherwise, (reproduce) 0 unless a case raised."""
    unknown = [n for n in names if n not in registry]
    if unknown:
        _print(f"fabricfem {command}: unknown case(s) {unknown}; available: {sorted(registry)}", file=sys.stderr)
        return 2
    results = run_cases(registry, names, as_json)
    if markdown and MPI.COMM_WORLD.rank == 0:
        with open(markdown, "w") as f:
            f.write(markdown_text(markdown, results, command, registry))
    if as_json:
        _print(json_text(results))
    else:
        _print(table_text(results, command))
        if command == "reproduce" and any(not r.passed for r in results):
            _print("\nDeviations from the papers, their measured causes and where they are documented:\n")
            _print(deviations_text(registry, results))
    if command == "reproduce":
        return 1 if any(r.quantity.startswith("error: ") for r in results) else 0
    return 0 if all(r.passed for r in results) else 1
