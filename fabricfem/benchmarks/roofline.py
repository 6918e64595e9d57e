"""Roofline of the shell's internal force on the explicit route: `python -m fabricfem.benchmarks.roofline`.

The roofline model [Williams2009]: a loop with arithmetic intensity I [FLOP/byte] (floating-point operations per
byte it must move from memory) runs at most at min(P, I B), P the core's peak floating-point rate [FLOP/s] and B
its memory bandwidth [byte/s]. For the hand-written Naghdi kernel (fabricfem.forms.naghdi_kernel) on a sleeve mesh
(default 60 x 78 Q2 cells):

* FLOPs per cell: the kernel's own C source compiled by g++ with `double` a counting type (each +, -, *, / of
  two numbers one FLOP, sqrt, pow and each of sin and cos one) and its lane type (LANES cells) a vector of them,
  run on one cell in every lane and divided by LANES: the operations as written (the compiler may fuse a multiply
  and an add into one instruction, which still counts as two).
* bytes per cell: what an evaluation must stream for each cell: the reference quantities at the quadrature points
  (unique to the cell; the kernel's loop reads the state from the state vector itself, no packed copy), its
  residual block and its dofmap (int32); the state gathered and the residual scattered are shared by neighbouring
  cells and mostly hit the cache.
* P and B of one core, measured: independent fused multiply-adds on 64 accumulators (the compiler vectorises
  them), and the triad a = b + s c over arrays of 128 MB each ([McCalpin1995], 24 bytes per element).
* the time per cell of the kernel: the internal force's evaluation (as an explicit step calls it, medians of
  blocks) minus the assembly floor (the kernel's batched loop around an empty kernel: gather, scatter and loop,
  fabricfem.forms.naghdi_kernel.empty_source), over the cells.

Writes <out>/roofline.csv and roofline.png (the roofs and the kernel's point). Serial.
"""
from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.benchmarks.internal_force import floor_evaluation
from fabricfem.forms.jit import KERNEL_FLAGS, compile_c, pointer
from fabricfem.shell_reference import naghdi_source
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import sleeve_shell

COUNTING_HEADER = r"""
#include <math.h>
#include <stdint.h>
#include <stdio.h>
static long long FLOPS = 0;
struct F {
  double v;
  F() : v(0.0) {}
  F(double x) : v(x) {}
  F& operator+=(F o) { ++FLOPS; v += o.v; return *this; }
  F& operator-=(F o) { ++FLOPS; v -= o.v; return *this; }
  F& operator*=(F o) { ++FLOPS; v *= o.v; return *this; }
  F& operator/=(F o) { ++FLOPS; v /= o.v; return *this; }
};
static inline F operator+(F a, F b) { ++FLOPS; return F(a.v + b.v); }
static inline F operator-(F a, F b) { ++FLOPS; return F(a.v - b.v); }
static inline F operator*(F a, F b) { ++FLOPS; return F(a.v * b.v); }
static inline F operator/(F a, F b) { ++FLOPS; return F(a.v / b.v); }
static inline F operator-(F a) { return F(-a.v); }
static inline bool operator<(F a, F b) { return a.v < b.v; }
static inline bool operator>(F a, F b) { return a.v > b.v; }
static inline bool operator<=(F a, F b) { return a.v <= b.v; }
static inline bool operator>=(F a, F b) { return a.v >= b.v; }
static inline F sqrt(F a) { ++FLOPS; return F(sqrt(a.v)); }
static inline F fabs(F a) { return F(fabs(a.v)); }
static inline F pow(F a, F b) { ++FLOPS; return F(pow(a.v, b.v)); }
static inline void sincos(F a, F* s, F* c) { FLOPS += 2; s->v = sin(a.v); c->v = cos(a.v); }
#define double F
#define restrict __restrict__
/* the kernel's lane type (LANES cells): each lane's operation counted */
#define COUNTING
struct vd {
  F x[LANES];
  F& operator[](int l) { return x[l]; }
  const F& operator[](int l) const { return x[l]; }
};
typedef vd vdu;
#define VD_OP(op)                                                                                    \
  static inline vd operator op(const vd& a, const vd& b)                                            \
  { vd r; for (int l = 0; l < LANES; ++l) r.x[l] = a.x[l] op b.x[l]; return r; }                     \
  static inline vd operator op(F a, const vd& b)                                                     \
  { vd r; for (int l = 0; l < LANES; ++l) r.x[l] = a op b.x[l]; return r; }                          \
  static inline vd operator op(const vd& a, F b)                                                     \
  { vd r; for (int l = 0; l < LANES; ++l) r.x[l] = a.x[l] op b; return r; }                          \
  static inline vd& operator op##=(vd& a, const vd& b)                                               \
  { for (int l = 0; l < LANES; ++l) a.x[l] = a.x[l] op b.x[l]; return a; }
VD_OP(+)
VD_OP(-)
VD_OP(*)
VD_OP(/)
static inline vd operator-(const vd& a) { vd r; for (int l = 0; l < LANES; ++l) r.x[l] = -a.x[l]; return r; }
"""

COUNTING_MAIN = r"""
int main(void)
{
  static F w[3 * NU + 2 * NT + NQF * SF + NQR * SR], A[3 * NU + 2 * NT], c[19 + NLAW + 1], x[3 * NU];
  for (int i = 0; i < (int)(sizeof(w) / sizeof(w[0])); ++i)
    w[i] = 0.01 * (1 + i % 7);
  for (int i = 0; i < (int)(sizeof(c) / sizeof(c[0])); ++i)
    c[i] = 1.0;
  naghdi_force(A, w, c, x, 0, 0);
  printf("%lld\n", FLOPS);
  return 0;
}
"""

PEAKS_CDEF = "double fma_loop(long n); double triad(long n, double* a, const double* b, const double* c, double s);"
PEAKS_SOURCE = r"""
#define ACCUMULATORS 64
double fma_loop(long n)
{
  double a[ACCUMULATORS], sum = 0.0;
  for (int i = 0; i < ACCUMULATORS; ++i)
    a[i] = 1.0 + 1e-9 * i;
  for (long k = 0; k < n; ++k)
    for (int i = 0; i < ACCUMULATORS; ++i)
      a[i] = a[i] * 0.9999999 + 1e-9;
  for (int i = 0; i < ACCUMULATORS; ++i)
    sum += a[i];
  return sum;
}
double triad(long n, double* a, const double* b, const double* c, double s)
{
  for (long i = 0; i < n; ++i)
    a[i] = b[i] + s * c[i];
  return a[n / 2];
}
"""
COLUMNS = ("mesh", "cells", "flops_per_cell", "bytes_per_cell", "intensity_flop_per_byte", "kernel_us_per_cell",
           "floor_us_per_cell", "kernel_gflops", "peak_gflops", "bandwidth_gbytes", "roof_gflops",
           "fraction_of_roof", "fraction_of_peak")


def defines(source: str) -> dict[str, int]:
    """The integer #defines of the kernel's source (NU, NT, NQF, NQR, SF, SR, NLAW, ...)."""
    return {k: int(v) for k, v in re.findall(r"#define (\w+) (-?\d+)\n", source)}


def counted_flops(source: str) -> int:
    """FLOPs of one cell's evaluation of the kernel `source` as written (module docstring), by g++: its one-cell
    entry computes LANES lanes (#define, 1 if absent) on the cell, counted and divided by LANES."""
    lanes = defines(source).get("LANES", 1)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "count.cpp"
        path.write_text(f"#define LANES {lanes}\n" + COUNTING_HEADER + source + COUNTING_MAIN)
        subprocess.run(["g++", "-O0", "-w", "-o", str(path.with_suffix("")), str(path)], check=True)
        out = subprocess.run([str(path.with_suffix(""))], check=True, capture_output=True, text=True)
    return int(out.stdout.strip()) // lanes


def cell_bytes(source: str) -> int:
    """Bytes an evaluation must stream per cell (module docstring): reference quantities read, residual written
    (8 bytes a number), the dofmap (4 bytes a dof)."""
    d = defines(source)
    dofs = 3 * d["NU"] + 2 * d["NT"]
    return 8 * (d["NQF"] * d["SF"] + d["NQR"] * d["SR"]) + 8 * dofs + 4 * dofs


def machine_peaks(repeats: int = 5) -> tuple[float, float]:
    """(peak FLOP rate [GFLOP/s], memory bandwidth [GB/s]) of one core (module docstring), medians of `repeats`."""
    module = compile_c("fabricfem_roofline", PEAKS_CDEF, PEAKS_SOURCE, MPI.COMM_SELF, KERNEL_FLAGS)
    lib, ffi = module.lib, module.ffi
    n_fma, n = 2_000_000, 16 * 1024 * 1024
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    flops, bandwidth = [], []
    for _ in range(repeats):
        tic = time.perf_counter()
        lib.fma_loop(n_fma)
        flops.append(2.0 * 64 * n_fma / (time.perf_counter() - tic) / 1e9)
        tic = time.perf_counter()
        lib.triad(n, pointer(ffi, a, "double"), pointer(ffi, b, "double"), pointer(ffi, c, "double"), 3.0)
        bandwidth.append(24.0 * n / (time.perf_counter() - tic) / 1e9)
    return statistics.median(flops), statistics.median(bandwidth)


def kernel_times(n_around: int, n_along: int, evaluations: int = 50, repeats: int = 7
                 ) -> tuple[float, float, int, str]:
    """(the internal force's evaluation, the assembly floor's) [s] and the cells, serial, medians of `repeats`
    blocks of `evaluations` evaluations, alternating; and the kernel's source."""
    model = sleeve_shell(SleeveConfig().with_(n_around=n_around, n_along=n_along), MPI.COMM_SELF)
    model.use_internal_force("kernel")
    model.compile()
    x, b = model.create_vector(), model.create_vector()
    x.getArray()[:] = 1e-3 * np.sin(0.37 * np.arange(x.getLocalSize()))
    model.internal_force(x, b)            # builds the kernel's form (and its reference quantities)
    runs = {"kernel": lambda: model.internal_force(x, b), "floor": floor_evaluation(model)}
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            tic = time.perf_counter()
            for _ in range(evaluations):
                run()
            times[name].append((time.perf_counter() - tic) / evaluations)
    cells = model.mesh.topology.index_map(2).size_local
    return statistics.median(times["kernel"]), statistics.median(times["floor"]), cells, naghdi_source(model)[0]


def roofline(n_around: int = 60, n_along: int = 78) -> dict:
    """The CSV row of the mesh (module docstring)."""
    evaluation, floor, cells, source = kernel_times(n_around, n_along)
    flops, nbytes = counted_flops(source), cell_bytes(source)
    peak, bandwidth = machine_peaks()
    kernel = (evaluation - floor) / cells
    intensity = flops / nbytes
    achieved = flops / kernel / 1e9
    roof = min(peak, intensity * bandwidth)
    return {"mesh": f"{n_around}x{n_along}", "cells": cells, "flops_per_cell": flops, "bytes_per_cell": nbytes,
            "intensity_flop_per_byte": intensity, "kernel_us_per_cell": 1e6 * kernel,
            "floor_us_per_cell": 1e6 * floor / cells, "kernel_gflops": achieved, "peak_gflops": peak,
            "bandwidth_gbytes": bandwidth, "roof_gflops": roof, "fraction_of_roof": achieved / roof,
            "fraction_of_peak": achieved / peak}


def plot(row: dict, path: Path) -> None:
    """The roofs (bandwidth slope and peak) and the kernel's point, log-log."""
    import matplotlib  # optional heavy package: imported only to draw

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package: imported only to draw

    intensity = np.logspace(-2, 3, 200)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(intensity, np.minimum(row["peak_gflops"], intensity * row["bandwidth_gbytes"]), "k-",
              label=f"roof: {row['peak_gflops']:.1f} GFLOP/s, {row['bandwidth_gbytes']:.1f} GB/s (one core)")
    ax.loglog([row["intensity_flop_per_byte"]], [row["kernel_gflops"]], "o", color="tab:blue",
              label=f"Naghdi kernel, mesh {row['mesh']}: {row['kernel_gflops']:.2f} GFLOP/s")
    ax.set(xlabel="arithmetic intensity [FLOP/byte]", ylabel="GFLOP/s", title="internal force: roofline")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="60x78", help="cells around x along of the sleeve")
    parser.add_argument("--out", default="results/roofline")
    args = parser.parse_args(argv)
    n_around, n_along = (int(v) for v in args.mesh.split("x"))
    row = roofline(n_around, n_along)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fio.write_csv(out / "roofline.csv", COLUMNS, [row], MPI.COMM_SELF)
    plot(row, out / "roofline.png")
    for key in COLUMNS:
        print(f"{key:>24}  {row[key]}")


if __name__ == "__main__":
    main()
