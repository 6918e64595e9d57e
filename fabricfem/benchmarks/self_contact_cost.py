"""What the cloth's contact with itself adds to the explicit step: `python -m fabricfem.benchmarks.self_contact_cost`.

The sleeve (SleeveConfig: the shipped tube, arm, cotton, Lagrange contact with the arm, mu = 0.1) on a mesh
n_around x n_along (default 40 x 52) is built twice in one process, without and with self-contact
(fabricfem.contact.self_contact.SelfContact, the thickness as contact distance), and each runs `steps` explicit
steps from rest (the settling under gravity, the start of every sleeve run) after `warmup` untimed ones; the two
alternate `repeats` times so that the machine's load spreads over both. Reported: the median wall time per step
[ms] of each, their ratio (the acceptance: at most 1.5), the critical steps dt [s] (the self-contact's penalty
spring enters the step's frequency), the self-contact's own split (gather, search, response) per step and its
pair-list rebuilds, the last step's vertex-triangle and edge-edge pairs. `--passes` P > 0: the self-contact with P
passes of impulses (fabricfem.contact.impulses; their time is the `impulses` part). Units: seconds, milliseconds
where named.
"""
from __future__ import annotations

import argparse
import statistics
import time

from mpi4py import MPI

from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.sleeve import build_explicit


def timed_steps(n_around: int, n_along: int, self_contact: bool, steps: int, warmup: int,
                comm: MPI.Comm = MPI.COMM_WORLD, passes: int = 0) -> dict:
    """ms per step of `steps` explicit steps of the sleeve after `warmup` (module docstring), dt [s] and the
    self-contact's timings [ms per step] when on (with `passes` of impulses)."""
    config = SleeveConfig.of(n_around=n_around, n_along=n_along, self_contact=self_contact,
                             self_contact_passes=passes if self_contact else 0)
    run = build_explicit(config, comm)
    integrator = run.integrator
    integrator.initialize(t0=0.0)
    for _ in range(warmup):
        integrator.step()
    cloth = run.self_contact
    before = dict(cloth.timings) if cloth is not None else {}
    comm.barrier()
    tic = time.perf_counter()
    for _ in range(steps):
        integrator.step()
    comm.barrier()
    wall = time.perf_counter() - tic
    out = {"ms_per_step": 1e3 * wall / steps, "dt": run.dt}
    if cloth is not None:
        out.update({f"{k}_ms": 1e3 * (v - before.get(k, 0.0)) / steps for k, v in cloth.timings.items()})
        out["pairs"] = len(cloth.pairs)
        out["edge_pairs"] = len(cloth.edge_pairs)
    run.destroy()
    return out


def main(argv: list[str] | None = None) -> None:
    """Print the medians and the ratio (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default="40x52", help="n_around x n_along")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--passes", type=int, default=0, help="passes of impulses with the self-contact")
    args = parser.parse_args(argv)
    n_around, n_along = (int(v) for v in args.mesh.split("x"))
    runs: dict[bool, list[dict]] = {False: [], True: []}
    for _ in range(args.repeats):
        for on in (False, True):
            runs[on].append(timed_steps(n_around, n_along, on, args.steps, args.warmup, passes=args.passes))
    if MPI.COMM_WORLD.rank:
        return
    median = {on: statistics.median(r["ms_per_step"] for r in runs[on]) for on in runs}
    for on in (False, True):
        label = "with self-contact" if on else "without"
        extra = ""
        if on:
            parts = {k: statistics.median(r[k] for r in runs[on]) for k in runs[on][0] if k.endswith("_ms")}
            extra = ", " + ", ".join(f"{k[:-3]} {v:.3f} ms" for k, v in parts.items()) + \
                f", pairs {runs[on][-1]['pairs']} (edge-edge {runs[on][-1]['edge_pairs']})"
        print(f"{args.mesh} {label}: {median[on]:.3f} ms per step (runs {[round(r['ms_per_step'], 3) for r in runs[on]]}),"
              f" dt {runs[on][0]['dt']:.4g} s{extra}", flush=True)
    print(f"ratio {median[True] / median[False]:.3f} ({MPI.COMM_WORLD.size} rank(s))", flush=True)


if __name__ == "__main__":
    main()
