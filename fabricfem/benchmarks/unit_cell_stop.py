"""Where a unit-cell load path stops, and whether the usual remedies move the stop.

`python -m fabricfem.benchmarks.unit_cell_stop [--option full] [--out results/unit_cell_stop]`

Runs the study's load case (TI yarns, biaxial extension to Phi = 1.2 in `steps` steps, thesis end faces
u_z = 0) until it converges or stops, then, from the last converged state, tries one sub-increment of
1/32 of a study step (each try may halve it twice more) with one remedy at a time:

* `max_it 80`: 80 Newton iterations per solve instead of 25;
* `growth 3`: penalty growth factor 3 instead of 10 (ContactParameters.penalty_growth);
* `no growth, 40 aug`: no penalty growth, 40 Uzawa updates;
* `friction 0`: frictionless contact (no stick/slip switches);
* `no active set`: closest facet at every evaluation instead of the fixed facet sets.

A remedy that converges is kept and the path continued with it to Phi = 1.2. Writes one CSV row per
try (remedy, converged, E11 reached, wall time [s], message) to `out`/unit_cell_stop_<option>.csv.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np
from mpi4py import MPI

import fabricfem.weave.unit_cell as ucc
from fabricfem.io import write_csv
from fabricfem.meshes.unit_cell import unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.solvers.newton import SolverError
from fabricfem.studies.unit_cell import MATERIALS, THESIS_END_FACES, load_targets

TRY_CUTS = 2  # halvings of a remedy's 1/32 sub-increment (smallest 1/128 of a study step)


def _say(comm: MPI.Comm, text: str) -> None:
    if comm.rank == 0:
        print(text, flush=True)


def probe_stop(option: str = "full", refinement: str = "coarse", steps: int = 10, scale: float = 1.0,
               out: str = "results/unit_cell_stop", comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Run the TI biaxial path on the `option`/`refinement` cell (`scale` shortens it, see load_targets)
    and, if it stops, try the remedies of the module docstring from its last converged state. Returns the
    rows written to the CSV: first the path itself (remedy "study settings"), then one per remedy tried."""
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps: must be an integer >= 1, got {steps!r}")
    cell = unit_cell(PlainWeave.balanced(), option, refinement, comm)
    model = ucc.ContactUnitCell(cell, MATERIALS["ti"], contact=True, end_faces=THESIS_END_FACES)
    (target, _), = load_targets("biaxial", scale)
    t0 = time.perf_counter()

    def path(start: np.ndarray, n: int) -> str:
        try:
            for k in range(1, n + 1):
                model.solve(start + k / n * (target - start), 1)
                _say(comm, f"E11 {model.steps[-1].E[0, 0]:.4f} S11 {model.steps[-1].S[0, 0]:.4e} Pa "
                           f"({time.perf_counter() - t0:.0f} s)")
        except SolverError as exc:
            return str(exc)
        return ""

    stopped = path(np.eye(3), steps)
    rows = [dict(remedy="study settings", converged=int(not stopped), E11=model.steps[-1].E[0, 0] if model.steps
                 else 0.0, wall_s=time.perf_counter() - t0, message=stopped[:400])]
    if stopped:
        c, newton = model.contact, model.problem.newton
        base, cuts, max_it, active_set = c.params, ucc.MAX_CUTS, newton.max_it, model.active_set

        def with_params(**kw):
            return lambda: setattr(c, "params", dataclasses.replace(base, **kw))
        remedies = [("max_it 80", lambda: setattr(newton, "max_it", 80)),
                    ("growth 3", with_params(penalty_growth=3.0)),
                    ("no growth, 40 aug", with_params(penalty_growth=1.0, max_augmentations=40)),
                    ("friction 0", with_params(friction=0.0)),
                    ("no active set", lambda: setattr(model, "active_set", False))]
        step = (target - np.eye(3)) / steps
        for name, apply in remedies:
            apply()
            ucc.MAX_CUTS = TRY_CUTS
            t = time.perf_counter()
            try:
                model.solve(model.Phi + step / 32.0, 1)
                failed = ""
            except SolverError as exc:
                failed = str(exc)
            finally:
                ucc.MAX_CUTS = cuts
            if not failed:  # keep the remedy and go on along the study path
                failed = path(model.Phi.copy(), max(1, int(np.ceil((target[0, 0] - model.Phi[0, 0]) / step[0, 0]))))
            rows.append(dict(remedy=name, converged=int(not failed), E11=model.steps[-1].E[0, 0],
                             wall_s=time.perf_counter() - t, message=failed[:400]))
            _say(comm, f"[{name}] {'converged' if not failed else 'FAILED: ' + failed[:300]}")
            if not failed:
                break
            c.params, newton.max_it, model.active_set = base, max_it, active_set
    write_csv(os.path.join(out, f"unit_cell_stop_{option}.csv"), list(rows[0]), [list(r.values()) for r in rows], comm)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--option", choices=["quarter", "full"], default="full")
    parser.add_argument("--refinement", choices=["coarse", "fine"], default="coarse")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--out", default="results/unit_cell_stop")
    a = parser.parse_args()
    probe_stop(a.option, a.refinement, a.steps, out=a.out)
