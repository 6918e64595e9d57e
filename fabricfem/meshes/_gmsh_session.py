"""Lifecycle of a temporary gmsh model on one MPI rank.

The mesh generators build their geometry in gmsh on a single rank and hand
the result to :func:`fabricfem.meshes.gmsh_io.model_to_mesh`.  This module
only manages gmsh itself: initialise it if nobody has, silence the terminal,
create a fresh model, set options for the duration of the block, and undo all
of that afterwards (finalize gmsh if we initialised it, otherwise remove our
model and restore the options we changed).

``gmsh`` is imported lazily: importing it replaces Python's SIGINT handler,
which we do not want as a side effect of ``import fabricfem.meshes``.
"""
from __future__ import annotations

import itertools
import os
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

from mpi4py import MPI

_counter = itertools.count()


def gmsh_is_initialized(gmsh: Any) -> bool:
    """Whether the gmsh API is initialised.

    gmsh >= 4.9 has ``gmsh.isInitialized``; gmsh 4.8 (Debian bookworm) does
    not, so fall back on ``General.AbortOnError``: it reads 0 before
    ``gmsh.initialize()``, is set to 2 by it, and raises after
    ``gmsh.finalize()``.
    """
    is_init = getattr(gmsh, "isInitialized", None)
    if is_init is not None:
        return bool(is_init())
    with _stderr_silenced():  # after finalize() gmsh prints "not been initialized"
        try:
            return gmsh.option.getNumber("General.AbortOnError") != 0
        except Exception:
            return False


@contextmanager
def _stderr_silenced() -> Iterator[None]:
    """Send file descriptor 2 (where gmsh's C++ messages go) to /dev/null."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


@contextmanager
def gmsh_model(comm: MPI.Comm, rank: int = 0, name: str = "fabricfem",
               options: Mapping[str, float] | None = None) -> Iterator[Any]:
    """Yield the ``gmsh.model`` module with a fresh current model on ``rank``.

    On every other rank this yields ``None`` and does nothing, so gmsh is
    never touched there.  ``options`` are numeric gmsh options set for the
    duration of the block (``General.Terminal`` is always set to 0).
    """
    if comm.rank != rank:
        yield None
        return
    import gmsh  # optional heavy package, loaded only when a mesh is generated

    owned = not gmsh_is_initialized(gmsh)
    if owned:
        gmsh.initialize()
    settings = {"General.Terminal": 0.0, **(options or {})}
    saved = {key: gmsh.option.getNumber(key) for key in settings}
    for key, value in settings.items():
        gmsh.option.setNumber(key, value)
    previous = gmsh.model.getCurrent()
    model_name = f"{name}-{next(_counter)}"
    gmsh.model.add(model_name)
    try:
        yield gmsh.model
    finally:
        if owned:
            gmsh.finalize()
        else:
            gmsh.model.setCurrent(model_name)
            gmsh.model.remove()
            if previous in gmsh.model.list():
                gmsh.model.setCurrent(previous)
            for key, value in saved.items():
                gmsh.option.setNumber(key, value)
