"""The scripts in demos/ run and their outputs hold what their docstrings claim."""
import importlib.util
from pathlib import Path

import pytest
from mpi4py import MPI

DEMOS = Path(__file__).resolve().parents[1] / "demos"


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test (writes into a per-process temporary folder)")
def test_compression_sleeve_demo(tmp_path):
    """Outputs written; at the widest section p = T kappa (Laplace) within 2%: the hoop curvature kappa_h of
    the section is ~25 1/m, the axial curvature of the forearm b / a^2 ~ 0.43 1/m, so the axial force
    (at most the hoop force here) adds at most 0.43 / 25 < 2% to p = T_h kappa_h + T_a kappa_a."""
    summary = load("demo_compression_sleeve").main(tmp_path)
    for name in ("sleeve.xdmf", "pressure.png", "pressure_profile.csv", "pressure_profile.png"):
        assert (tmp_path / name).exists(), name
    assert summary["laplace_deviation"] < 0.02
    assert 0.0 < summary["min_mmHg"] < summary["max_mmHg"]
