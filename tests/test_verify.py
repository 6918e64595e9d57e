"""Every `fabricfem verify` case, run as a test (tolerances are documented in each case)."""
import json

import pytest

from fabricfem.cli import main
from fabricfem.verify import load_cases

CASES = load_cases()


def _params():
    for name, fn in CASES.items():
        marks = [pytest.mark.mpi] if fn.mpi else []
        if fn.known_failure:
            marks.append(pytest.mark.xfail(reason=fn.known_failure, strict=False))
        yield pytest.param(name, marks=marks, id=name)


@pytest.mark.parametrize("name", list(_params()))
def test_case(name):
    results = CASES[name]()
    assert results, f"{name} returned no result"
    failed = [r for r in results if not r.passed]
    assert not failed, "\n".join(f"{r.quantity}: {r.value} vs {r.reference} (rel {r.rel_error:.2e} > "
                                 f"{r.tolerance:.1e})" for r in failed)


def test_cli_json(capsys):
    """`fabricfem verify CASE --json` prints the documented keys and exits 0 when the case passes."""
    code = main(["verify", "membrane-patch", "--json"])
    out = capsys.readouterr().out
    records = json.loads(out)
    assert code == 0
    assert set(records[0]) == {"case", "quantity", "value", "reference", "rel_error", "tolerance", "passed",
                               "ndofs", "wall_s"}


def test_cli_unknown_case(capsys):
    assert main(["verify", "no-such-case"]) == 2
    assert "available" in capsys.readouterr().err


def test_cli_exit_code_on_failure(monkeypatch, capsys):
    """A failing case makes the exit code non-zero."""
    from fabricfem import verify
    monkeypatch.setitem(verify.CASES, "always-fails",
                        lambda: [verify.result("always-fails", "x", 2.0, 1.0, 0.1, 0, 0.0)])
    assert main(["verify", "always-fails"]) == 1
    assert "FAIL" in capsys.readouterr().out
