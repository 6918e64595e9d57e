"""The shell's internal force alone, per implementation: `fabricfem bench kernel`.

On a sleeve mesh (default III: 20 x 26 Q2 cells, the thesis's mesh III), at a perturbed state (displacements
~1 mm, rotations ~0.01 rad), one evaluation = zero the vector, refresh the state, assemble, add the ghosts (what an
explicit step calls), for

* `per evaluation`: FFCx's derivative of `naghdi_energy`, the reference geometry recomputed from the P2 fields;
* `quadrature, FFCx`: FFCx's derivative of `naghdi_energy_on_reference` (the geometry at the quadrature points);
* `hand kernel`: the hand-written C kernel (fabricfem.forms.naghdi_kernel), the default;
* `assembly floor`: the hand kernel's batched loop over the cells (gathering, scattering) around an empty
  kernel, on the same space and coefficients, which no kernel can go below.

All with fabricfem.forms.jit.KERNEL_FLAGS. Times are medians over `repeats` blocks of `evaluations` evaluations,
the implementations alternating; the force of each against `per evaluation`'s (max-norm relative difference).
Writes internal_force.csv and internal_force.png under `out` (rank 0). Milliseconds per evaluation.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fabricfem import io as fio
from fabricfem.benchmarks.wear_speed import MESHES
from fabricfem.forms import naghdi_kernel
from fabricfem.forms.jit import KERNEL_FLAGS
from fabricfem.shell_reference import PrepackedForms, cell_kernel_form, naghdi_source
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import sleeve_shell

# name -> ShellModel.use_internal_force's choice
IMPLEMENTATIONS = {"per evaluation": "ffcx", "quadrature, FFCx": "ffcx-quadrature", "hand kernel": "kernel"}
FLOOR = "assembly floor"
COLUMNS = ("mesh", "implementation", "cells", "dofs", "ms_per_evaluation", "speedup", "max_relative_difference")


def floor_evaluation(model):
    """An evaluation of the empty kernel (fabricfem.forms.naghdi_kernel.empty_source: the same batched loop, no
    arithmetic) on the hand kernel's space and coefficients (model: its internal force already built)."""
    source = naghdi_kernel.empty_source(naghdi_source(model)[0])
    addresses = naghdi_kernel.compile_kernel(source, model.comm, KERNEL_FLAGS)
    packed = PrepackedForms([cell_kernel_form(model, model.quadrature_reference, addresses, [])], model.w)
    b = model.create_vector()

    def evaluate():
        with b.localForm() as local:
            local.set(0.0)
        packed.assemble(b)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return evaluate


def internal_force_bench(out: str | Path, meshes: tuple[str, ...] = ("I", "III"), evaluations: int = 300,
                         repeats: int = 5, comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Time the implementations (module docstring) on each mesh; returns the CSV rows."""
    unknown = [m for m in meshes if m not in MESHES]
    if unknown or not meshes:
        raise ValueError(f"meshes: {unknown or 'none'} given, known {list(MESHES)}")
    if evaluations < 1 or repeats < 1:
        raise ValueError(f"evaluations and repeats must be >= 1, got {evaluations}, {repeats}")
    rows = [row for mesh in meshes for row in _mesh_rows(mesh, evaluations, repeats, comm)]
    if comm.rank == 0:
        _write(Path(out), rows)
    return rows


def _mesh_rows(mesh: str, evaluations: int, repeats: int, comm: MPI.Comm) -> list[dict]:
    """The CSV rows of one mesh."""
    n_around, n_along = MESHES[mesh]
    config = SleeveConfig().with_(n_around=n_around, n_along=n_along)
    evaluate, forces, cells, dofs = {}, {}, 0, 0
    for name, choice in IMPLEMENTATIONS.items():
        model = sleeve_shell(config, comm)
        model.use_internal_force(choice)
        model.compile()
        x = model.create_vector()
        x.getArray()[:] = np.where(np.arange(x.getLocalSize()) % 5 < 3, 1e-3, 1e-2) * np.sin(
            0.37 * (x.getOwnershipRange()[0] + np.arange(x.getLocalSize())))
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        b = model.create_vector()
        model.internal_force(x, b)
        forces[name] = b.copy()
        evaluate[name] = (lambda m=model, x=x, b=b: m.internal_force(x, b))
        if name == "hand kernel":
            evaluate[FLOOR] = floor_evaluation(model)
        cells = comm.allreduce(model.mesh.topology.index_map(2).size_local, op=MPI.SUM)
        dofs = x.getSize()
    times: dict[str, list[float]] = {name: [] for name in evaluate}
    for _ in range(repeats):
        for name, run in evaluate.items():
            comm.Barrier()
            tic = time.perf_counter()
            for _ in range(evaluations):
                run()
            times[name].append(comm.allreduce(time.perf_counter() - tic, op=MPI.MAX) / evaluations * 1e3)
    base = statistics.median(times["per evaluation"])
    norm = forces["per evaluation"].norm(PETSc.NormType.NORM_INFINITY)
    rows = []
    for name, values in times.items():
        difference = float("nan")
        if name in forces:
            diff = forces[name].copy()
            diff.axpy(-1.0, forces["per evaluation"])
            difference = diff.norm(PETSc.NormType.NORM_INFINITY) / norm
        median = statistics.median(values)
        rows.append({"mesh": mesh, "implementation": name, "cells": cells, "dofs": dofs, "ms_per_evaluation": median,
                     "speedup": base / median, "max_relative_difference": difference})
    return rows


def _write(out: Path, rows: list[dict]) -> None:
    import matplotlib  # noqa: PLC0415 (optional plotting package)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 (optional plotting package)

    out.mkdir(parents=True, exist_ok=True)
    fio.write_csv(out / "internal_force.csv", COLUMNS, rows, MPI.COMM_SELF)
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    fig, axes = plt.subplots(len(meshes), 1, figsize=(6.4, 2.2 * len(meshes) + 0.4), squeeze=False)
    for ax, mesh in zip(axes[:, 0], meshes):
        part = [r for r in rows if r["mesh"] == mesh]
        values = [r["ms_per_evaluation"] for r in part]
        ax.barh([r["implementation"] for r in part], values, color=["0.6", "0.45", "tab:blue", "0.85"][:len(part)])
        for k, v in enumerate(values):
            ax.text(v, k, f" {v:.3f} ms", va="center", fontsize=8)
        ax.invert_yaxis()
        ax.set_xlim(0, 1.3 * max(values))
        ax.set_title(f"sleeve mesh {mesh}: {part[0]['cells']} Q2 cells, {part[0]['dofs']} dofs", fontsize=9)
    axes[-1, 0].set_xlabel("ms per evaluation of the shell's internal force")
    fig.tight_layout()
    fig.savefig(out / "internal_force.png", dpi=120)
    plt.close(fig)
