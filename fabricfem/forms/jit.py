"""C compiler flags of the FFCx kernels on the hot path: the shell's residual (internal forces), assembled once
per explicit step.

dolfinx compiles generated kernels with `-O2` by default; `-O3 -march=native` vectorises the quadrature
loops for the machine that runs them (the kernels are compiled on it, at first use, and cached by flags).
No `-ffast-math`: IEEE semantics are kept, results differ from `-O2` only by the contraction of
multiply-adds (round-off). The tangent keeps dolfinx's flags: `-O3` doubles its compile time (13.7 -> 24.3 s)
for a kernel assembled once per Newton iteration. Measured in docs/findings/2026-11-25-wear-speed.md.
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator, Sequence

DOLFINX_DEFAULT_FLAGS = ("-O2", "-g0")           # dolfinx.jit's default cffi_extra_compile_args
KERNEL_FLAGS = ("-O3", "-march=native", "-g0")
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
