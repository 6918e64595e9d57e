"""The central-difference step's vector work by PETSc calls against the compiled passes, in one run.

`python -m fabricfem.benchmarks.step_passes SCENE [--pairs 16] [--block 100]` (a wear scene on the explicit engine,
e.g. the sleeve): builds the run, takes 50 steps, then `pairs` pairs of blocks of `block` steps, one block with
`CentralDifference.vector_passes` False (PETSc's calls) and one with True (fabricfem.dynamics.explicit_update), the
order alternating from pair to pair. Both take the same trajectory (the passes give the same values to the bit),
so the blocks differ only in how the step's vector work is done. Per block: ms per step of the whole step, of the
internal force, of the contact hooks and of the rest ("other": the vector work, the boundary values, Python);
printed as medians over the pairs and as pairwise ratios (passes / PETSc), which a shared machine's load shifts
less than the times. Wall time [ms]; under mpirun, rank 0's.
"""
from __future__ import annotations

import argparse
import statistics
import time

from mpi4py import MPI

from fabricfem.scenes.build import build_wear_run, load

PARTS = ("step", "internal", "contact", "other")


def _block(integ, steps: int, passes: bool, comm) -> tuple[float, ...]:
    """ms per step of (step, internal force, contact hooks, other) over `steps` steps."""
    integ.vector_passes = passes
    internal, contact = integ.timings["internal_forces"], integ.timings["contact"]
    comm.barrier()
    start = time.perf_counter()
    for _ in range(steps):
        integ.step()
        integ.step_count += 1
    total = time.perf_counter() - start
    internal = integ.timings["internal_forces"] - internal
    contact = integ.timings["contact"] - contact
    return tuple(1e3 * t / steps for t in (total, internal, contact, total - internal - contact))


def compare(scene_path: str, pairs: int = 16, block: int = 100, comm=MPI.COMM_WORLD) -> dict:
    """{"petsc": [(step, internal, contact, other) ms per step per block], "passes": [...]} (module docstring)."""
    run, *_ = build_wear_run(load(scene_path), comm)
    integ = run.integrator
    integ.initialize(t0=0.0)
    _block(integ, 50, True, comm)
    out = {"petsc": [], "passes": []}
    for k in range(pairs):
        for passes in ((False, True) if k % 2 == 0 else (True, False)):
            out["passes" if passes else "petsc"].append(_block(integ, block, passes, comm))
    run.destroy()
    return out


def report(times: dict) -> str:
    """Medians per part and the pairwise ratios passes / PETSc (median, range)."""
    lines = []
    for name, blocks in times.items():
        medians = [statistics.median(b[i] for b in blocks) for i in range(len(PARTS))]
        lines.append(f"{name:7s}" + "  ".join(f"{part} {m:.3f}" for part, m in zip(PARTS, medians)) + " ms/step")
    for i, part in enumerate(PARTS):
        ratios = [new[i] / old[i] for old, new in zip(times["petsc"], times["passes"]) if old[i] > 0]
        if ratios:
            lines.append(f"{part}: passes / PETSc {statistics.median(ratios):.3f} (pairs {min(ratios):.3f}-"
                         f"{max(ratios):.3f})")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--pairs", type=int, default=16)
    parser.add_argument("--block", type=int, default=100)
    args = parser.parse_args(argv)
    times = compare(args.scene, args.pairs, args.block)
    if MPI.COMM_WORLD.rank == 0:
        print(report(times), flush=True)


if __name__ == "__main__":
    main()
