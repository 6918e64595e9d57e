"""Verification cases: each compares a computed quantity with an independent reference.

A case is a function returning a list of CaseResult; `fabricfem verify` and the test suite run the same
functions (registered in CASES by the @case decorator). Reproductions of the source papers' figures and tables
(registered in REPRODUCTIONS by @reproduction) are reports run by `fabricfem reproduce`: they compare with a
paper's numbers or claims, not with an independent reference.
"""
from __future__ import annotations

import importlib
import pkgutil
import time
from dataclasses import asdict, dataclass
from typing import Callable

CASES: dict[str, Callable[[], list["CaseResult"]]] = {}          # verification against independent references
REPRODUCTIONS: dict[str, Callable[[], list["CaseResult"]]] = {}  # the papers' figures and tables beside ours


@dataclass
class CaseResult:
    case: str
    quantity: str
    value: float
    reference: float
    rel_error: float
    tolerance: float
    passed: bool
    ndofs: int
    wall_s: float

    def as_dict(self) -> dict:
        return asdict(self)


def result(case: str, quantity: str, value: float, reference: float, tolerance: float, ndofs: int,
           wall_s: float, scale: float | None = None) -> CaseResult:
    """Relative error |value - reference| / |scale or reference| against `tolerance`."""
    denom = abs(scale if scale is not None else reference)
    rel = abs(value - reference) / denom if denom > 0 else abs(value - reference)
    return CaseResult(case, quantity, float(value), float(reference), float(rel), float(tolerance),
                      bool(rel <= tolerance), int(ndofs), float(wall_s))


def case(name: str, mpi: bool = False, in_tests: bool = True):
    """Register a verification case (a comparison with an independent reference: closed form, ODE solution,
    conservation law); `mpi=True` also runs it under `mpirun -n 2` in the tests. `fabricfem verify` runs them
    and exits 0 only when every row passes. `in_tests=False`: a long computation (minutes) whose parts the tests
    cover; only `fabricfem verify` runs it."""
    def register(fn):
        CASES[name] = fn
        fn.case_name, fn.mpi, fn.deviation, fn.in_tests = name, mpi, None, in_tests
        return fn
    return register


def reproduction(name: str, mpi: bool = False, deviation: str | None = None, in_tests: bool = True):
    """Register a reproduction of a source paper's figure or table: our numbers beside the paper's, a report,
    not a gate (`fabricfem reproduce`). `deviation` states, for rows that differ from the paper, the measured
    cause and where it is documented; the test suite marks such a case xfail(strict=True), so a row that starts
    to agree is noticed. `in_tests=False`: a long computation whose parts the tests cover; only `fabricfem
    reproduce` runs it whole."""
    def register(fn):
        REPRODUCTIONS[name] = fn
        fn.case_name, fn.mpi, fn.deviation, fn.in_tests = name, mpi, deviation, in_tests
        return fn
    return register


class Timer:
    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def __exit__(self, *exc):
        return False


def load_cases() -> dict[str, Callable[[], list[CaseResult]]]:
    """Import every module of this package (cases register themselves with @case on import)."""
    for module in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{module.name}")
    return CASES


def load_reproductions() -> dict[str, Callable[[], list[CaseResult]]]:
    """The registered reproductions (@reproduction), after importing every module of this package."""
    load_cases()
    return REPRODUCTIONS
