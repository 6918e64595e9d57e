"""C compiler flags of the kernels on the hot path (the shell's internal forces, assembled once per explicit step),
and the build of hand-written C modules (`compile_c`).

dolfinx compiles generated kernels with `-O2` by default; `-O3 -march=native` vectorises the quadrature
loops for the machine that runs them (the kernels are compiled on it, at first use, and cached by flags).
No `-ffast-math`: IEEE semantics are kept, results differ from `-O2` only by the contraction of
multiply-adds (round-off). The tangent keeps dolfinx's flags: `-O3` doubles its compile time (13.7 -> 24.3 s)
for a kernel assembled once per Newton iteration. Measured in docs/findings/2026-11-25-wear-speed.md.
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Iterator, Sequence

import cffi

DOLFINX_DEFAULT_FLAGS = ("-O2", "-g0")           # dolfinx.jit's default cffi_extra_compile_args
KERNEL_FLAGS = ("-O3", "-march=native", "-g0")
# the loops that must round as numpy does: no contraction of multiply-adds into fused ones
ROUNDING_FLAGS = ("-O3", "-march=native", "-ffp-contract=off", "-g0")
KERNEL_JIT: dict = {"cffi_extra_compile_args": list(KERNEL_FLAGS)}


@contextmanager
def kernel_flags(flags: Sequence[str]) -> Iterator[None]:
    """Compile the hot-path forms created inside the block with `flags` (e.g. DOLFINX_DEFAULT_FLAGS, for a
    benchmark's baseline); the flags in use are restored after it."""
    old = KERNEL_JIT["cffi_extra_compile_args"]
    KERNEL_JIT["cffi_extra_compile_args"] = list(flags)
    try:
        yield
    finally:
        KERNEL_JIT["cffi_extra_compile_args"] = old


_LOADED: list[ModuleType] = []   # compiled modules stay loaded while forms and callers point into them


def compile_c(prefix: str, cdef: str, source: str, comm, flags: Sequence[str],
              libraries: Sequence[str] = ("m",)) -> ModuleType:
    """Compile C `source` declaring `cdef` with cffi (as dolfinx compiles FFCx's kernels) into the dolfinx cache
    folder (XDG_CACHE_HOME/fenics/fabricfem), once per source and flags, and load it: rank 0 of `comm` builds, the
    others wait. Processes that build the same module at once (a study's variants, one per rank) each build in
    their own folder and move the library into place atomically. `libraries`: linked (libm; libmvec for vector
    sin and cos). Returns the cffi module (`.ffi`, `.lib`)."""
    linked = "" if tuple(libraries) == ("m",) else " ".join(libraries)      # the default keeps the cached names
    digest = hashlib.sha1((cdef + source + " ".join(flags) + linked).encode()).hexdigest()[:16]
    name = f"{prefix}_{digest}"
    cache = Path(os.getenv("XDG_CACHE_HOME", Path.home() / ".cache")) / "fenics" / "fabricfem"
    library = cache / (name + importlib.machinery.EXTENSION_SUFFIXES[0])
    if comm.rank == 0 and not library.exists():
        cache.mkdir(parents=True, exist_ok=True)
        build = Path(tempfile.mkdtemp(prefix=f"{name}-", dir=cache))
        try:
            ffi = cffi.FFI()
            ffi.cdef(cdef)
            ffi.set_source(name, source, extra_compile_args=list(flags), libraries=list(libraries))
            os.replace(ffi.compile(tmpdir=str(build)), library)
        finally:
            shutil.rmtree(build, ignore_errors=True)
    comm.barrier()
    if not library.exists():
        raise RuntimeError(f"the compiled module {library} was not built")
    spec = importlib.util.spec_from_file_location(name, library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    _LOADED.append(module)
    return module


_BUILT: dict[str, ModuleType] = {}   # the modules of `built_once`, by prefix


def built_once(prefix: str, cdef: str, source: str, comm, flags: Sequence[str]) -> tuple[object, object]:
    """(lib, ffi) of `compile_c(prefix, ...)`, built on the first call of this process and kept (a module whose
    source is fixed: the contact loops, the cloth-cloth search and response)."""
    if prefix not in _BUILT:
        _BUILT[prefix] = compile_c(prefix, cdef, source, comm, flags)
    module = _BUILT[prefix]
    return module.lib, module.ffi


def pointer(ffi, array, ctype: str):
    """cffi pointer of `ctype` into a C-contiguous numpy array of the matching dtype (no copy)."""
    if not array.flags.c_contiguous:
        raise ValueError("compiled kernels: arrays must be C-contiguous")
    return ffi.from_buffer(ctype + "[]", array)
