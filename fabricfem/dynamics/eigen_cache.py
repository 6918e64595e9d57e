"""A disk cache of the largest eigenvalue of an assembled operator, keyed by the operator itself.

The critical step of an explicit run needs omega_max^2, the largest eigenvalue of M^-1/2 K M^-1/2 of the model at
its start (fabricfem.dynamics.stability.discrete_max_frequency). A rerun of the same scene assembles the same K and
M and would solve the same eigenproblem again (0.7 s of the shipped sleeve's 2-rank start, 1.4 s serial). The
cache stores the eigenvalue under a digest of everything the solve sees: each rank's rows of the scaled operator
(its CSR arrays, bit for bit), the solver's settings and the number of ranks (the Krylov iteration's round-off
depends on the partition). A cached value is therefore the value the solve would return, bit for bit; any change of
mesh, fabric, state, boundary conditions or settings changes the digest. Like the forms' compiled code, it lives in
XDG_CACHE_HOME/fenics/fabricfem (here omega_max/); FABRICFEM_EIGEN_CACHE=0 switches it off.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np
from petsc4py import PETSc


def cache_folder() -> Path:
    """The folder of the cached eigenvalues (beside the compiled kernels of fabricfem.forms.jit)."""
    return Path(os.getenv("XDG_CACHE_HOME", Path.home() / ".cache")) / "fenics" / "fabricfem" / "omega_max"


def enabled() -> bool:
    """False when FABRICFEM_EIGEN_CACHE is "0" (every solve then runs)."""
    return os.getenv("FABRICFEM_EIGEN_CACHE", "1") != "0"


def operator_digest(operator: PETSc.Mat, settings: str, comm) -> str:
    """A digest of the assembled `operator` (every rank's CSR rows, bit for bit), the solver `settings` text and
    the number of ranks; the same on every rank."""
    indptr, indices, values = operator.getValuesCSR()
    local = hashlib.blake2b(digest_size=20)
    local.update(np.asarray(operator.getOwnershipRange(), dtype=np.int64).tobytes())
    for array in (indptr, indices, values):
        local.update(np.ascontiguousarray(array).tobytes())
    whole = hashlib.blake2b(digest_size=20)
    whole.update(f"{settings}|ranks={comm.size}".encode())
    for part in comm.allgather(local.hexdigest()):
        whole.update(part.encode())
    return whole.hexdigest()


def largest_eigenvalue(operator: PETSc.Mat, settings: str, comm, solve: Callable[[], float]) -> float:
    """The largest eigenvalue of `operator` from the cache, or `solve()` (collective) stored in it; the same value
    on every rank. A cache that cannot be read or written is passed by (the solve runs)."""
    if not enabled():
        return solve()
    digest = operator_digest(operator, settings, comm)
    path = cache_folder() / f"{digest}.json"
    cached = None
    if comm.rank == 0 and path.is_file():
        try:
            cached = float.fromhex(json.loads(path.read_text())["eigenvalue"])
        except (OSError, ValueError, KeyError, TypeError):
            cached = None
    cached = comm.bcast(cached, root=0)
    if cached is not None:
        return cached
    value = solve()
    if comm.rank == 0:
        _store(path, value, settings)
    return value


def _store(path: Path, value: float, settings: str) -> None:
    """Write {"eigenvalue": value as a hexadecimal float (every bit kept)} atomically (a temporary file renamed into place)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, delete=False, suffix=".tmp") as f:
            json.dump({"eigenvalue": float(value).hex(), "settings": settings}, f)
        os.replace(f.name, path)
    except OSError:
        pass


__all__ = ["cache_folder", "enabled", "operator_digest", "largest_eigenvalue"]
