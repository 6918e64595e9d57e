"""Compression sleeve on a forearm: the pressure a knitted tube puts on the skin.

    .venv/bin/python demos/demo_compression_sleeve.py [--out results/demos/compression_sleeve] [--quick]
    mpirun -n 2 .venv/bin/python demos/demo_compression_sleeve.py

The same scene as a file: `fabricfem run scenes/compression_sleeve.toml`.

Data flow: mesh (meshes.tube, relaxed radius 34 mm) -> forms (Naghdi shell, orthotropic St. Venant-Kirchhoff,
weft around the limb) -> solver (the explicit wear engine, fabricfem.wear.compression.compression_run: the
forearm, an ellipsoid 88 x 72 mm across at its widest, starts at 0.7 of its transverse radii inside the tube,
grows to full size over 0.2 s and is held still for 0.1 s while the sleeve settles; frictionless contact; the
end0 ring held along the axis) -> outputs (compression.compression_report):

* sleeve.xdmf: displacement [m] and pressure on the skin [mmHg] (ParaView);
* pressure.png, skin_pressure.png: the sleeve and the skin coloured by pressure; pressure_profile.csv / .png: the
  ring-mean pressure along the forearm (the graduation of the garment) and, at the widest section, the pressure
  against the curvature of the section: Laplace's law p = T kappa with one hoop tension T around the ring, so
  the pressure is highest where the limb is most curved (the flanks of the forearm here).

Pressures are per unit deformed cloth area, the mean over the last record interval, in mmHg (1 mmHg = 133.32 Pa).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.wear.compression import compression_report, compression_run

LENGTH, RELAXED_RADIUS = 0.24, 0.034                     # m
FOREARM = Ellipsoid(np.array([0.12, 0.0, 0.0]), np.eye(3), np.array([0.32, 0.044, 0.036]))   # m
KNIT = Fabric(E1=0.8e6, E2=0.5e6, G12=0.1e6, nu12=0.3, thickness=7e-4, density=400.0, name="compression knit")
START, DONNING_TIME, SETTLE_TIME, RECORD_TIME = 0.7, 0.2, 0.1, 0.01     # -, s, s, s


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD, render: bool = True) -> dict | None:
    """Run the demo into `out` (`quick`: a 16 x 8 tube instead of 32 x 16); returns (rank 0) the summary of
    compression.compression_report with the run's largest kinetic / strain energy over the settling
    ("settle_ke_se")."""
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    fmesh = tube(LENGTH, RELAXED_RADIUS, *((16, 8) if quick else (32, 16)), cell="quadrilateral", order=2,
                 comm=comm)                                                                     # mesh
    say(f"compression sleeve: relaxed radius {RELAXED_RADIUS * 1e3:.0f} mm on a forearm "
        f"{2e3 * FOREARM.radii[1]:.0f} x {2e3 * FOREARM.radii[2]:.0f} mm, {comm.size} rank(s)")
    run = compression_run(fmesh, KNIT, FOREARM, START, DONNING_TIME, SETTLE_TIME, RECORD_TIME, comm,
                          name="compression sleeve on a forearm")                              # forms + solver
    say(f"  {run.model.ndofs} dofs; {run.describe()}")
    history = run.run(on_step=lambda s: say(f"  {s.line()}"))
    summary = compression_report(run, FOREARM, out, run.name, render)                         # outputs
    run.destroy()
    if summary is not None:
        settle = [s.kinetic_energy / s.strain_energy for s in history.steps if s.phase == "motion"]
        summary["settle_ke_se"] = max(settle)
        say(f"done in {history.wall:.1f} s: pressure {summary['min_mmHg']:.1f}-{summary['max_mmHg']:.1f} mmHg (ring "
            f"means {summary['ring_min_mmHg']:.1f}-{summary['ring_max_mmHg']:.1f}); widest section: p = T kappa with "
            f"T = {summary['hoop_tension']:.1f} N/m, largest deviation {100 * summary['laplace_deviation']:.2f}% "
            f"of the peak; kinetic / strain energy while settling <= {summary['settle_ke_se']:.1e}; wrote "
            f"{out}/sleeve.xdmf, pressure.png, skin_pressure.png, pressure_profile.csv/.png")
    return summary


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/compression_sleeve"))
    parser.add_argument("--quick", action="store_true", help="a coarser tube (16 x 8 cells)")
    args = parser.parse_args()
    main(args.out, args.quick)
