"""The environment of a child process that starts MPI (a `fabricfem` command, or `mpirun` of one).

A process that has started MPI as a singleton (mpi4py's import in a plain `python`, a pytest worker) carries the
variables of its own one-rank job (PMIX_*, OMPI_MCA_ess, ...) in its C environment, and a process started under
mpirun carries its rank's. A child that inherits them takes itself for a rank of that job: it then fails with exit
code 1 and nothing on stderr, or not, depending on the timing (docs/findings/2026-11-28-child-environment.md).
"""
from __future__ import annotations

import os
from typing import Mapping

# the prefixes of the variables that describe a running MPI job (Open MPI, PMIx, PRRTE)
JOB_PREFIXES = ("OMPI_", "PMIX_", "OPAL_", "PRTE_")
# what a child mpirun needs on our machines: run as root in containers, more ranks than cores if asked
MPIRUN_SETTINGS = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                   "OMPI_MCA_rmaps_base_oversubscribe": "1"}


def child_environment(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """This process's environment (os.environ, read at start) without any variable of the prefixes JOB_PREFIXES,
    with MPIRUN_SETTINGS and `extra` added: pass it as `env=` to subprocess for any child that imports mpi4py or is
    mpirun. The job's variables cannot be told from a user's own Open MPI settings (OMPI_MCA_btl, ...) by their
    names, so those are dropped too: pass them in `extra` if a child needs them."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(JOB_PREFIXES)}
    return {**env, **MPIRUN_SETTINGS, **(extra or {})}
