"""The disk cache of the critical step's eigenvalue (fabricfem.dynamics.eigen_cache): a rerun reads the value the
solve returns, bit for bit; a changed operator or settings solves again; a broken cache file is passed by."""
import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.dynamics import discrete_max_frequency, eigen_cache
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.shell import ShellModel
from fabricfem.verify.dynamics import STRIP


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("FABRICFEM_EIGEN_CACHE", raising=False)
    return tmp_path / "fenics" / "fabricfem" / "omega_max"


def _strip(n: int = 8) -> ShellModel:
    model = ShellModel(plate(0.2, 0.02, n, 1), Fabric.isotropic(STRIP["E"], 0.0, STRIP["t"], density=STRIP["rho"]))
    return model.clamp("left")


def _counting(monkeypatch) -> list:
    """Count the SLEPc solves behind discrete_max_frequency (each call of the cache's `solve`)."""
    calls = []
    original = eigen_cache.largest_eigenvalue

    def counted(operator, settings, comm, solve):
        return original(operator, settings, comm, lambda: calls.append(1) or solve())
    monkeypatch.setattr(eigen_cache, "largest_eigenvalue", counted)
    return calls


def test_rerun_reads_the_solved_value_bit_for_bit(cache, monkeypatch):
    model = _strip()
    monkeypatch.setenv("FABRICFEM_EIGEN_CACHE", "0")
    uncached = discrete_max_frequency(model)
    monkeypatch.delenv("FABRICFEM_EIGEN_CACHE")
    calls = _counting(monkeypatch)
    first, second = discrete_max_frequency(model), discrete_max_frequency(model)
    assert len(calls) == 1                     # the second call read the cache
    assert first == uncached and second == uncached
    assert len(list(cache.glob("*.json"))) == 1


def test_changed_operator_or_settings_solve_again(cache, monkeypatch):
    calls = _counting(monkeypatch)
    model = _strip()
    base = discrete_max_frequency(model)
    heavier = discrete_max_frequency(model, rotary_inertia_scale=100.0)   # another mass: another operator
    looser = discrete_max_frequency(model, rtol=1e-3)                      # another setting
    finer = discrete_max_frequency(_strip(10))                             # another mesh
    assert len(calls) == 4
    assert heavier < base and np.isclose(looser, base, rtol=2e-3)
    assert len(list(cache.glob("*.json"))) == 4 and finer > 0.0


def test_broken_cache_file_is_passed_by(cache, monkeypatch):
    model = _strip()
    value = discrete_max_frequency(model)
    for path in cache.glob("*.json"):
        path.write_text("{not json")
    calls = _counting(monkeypatch)
    assert discrete_max_frequency(model) == value
    assert len(calls) == 1


@pytest.mark.mpi
def test_ranks_share_the_cached_value(cache):
    comm = MPI.COMM_WORLD
    model = _strip(12)
    first, second = discrete_max_frequency(model), discrete_max_frequency(model)
    assert first == second
    assert len(set(comm.allgather(first))) == 1
