"""Compression sleeve on a forearm: the pressure a knitted tube puts on the skin.

    .venv/bin/python demos/demo_compression_sleeve.py [--out results/demos/compression_sleeve]
    mpirun -n 2 .venv/bin/python demos/demo_compression_sleeve.py

The same scene as a file: `fabricfem run scenes/compression_sleeve.toml`.

Data flow: mesh (meshes.tube, relaxed radius 34 mm) -> forms (Naghdi shell, orthotropic St. Venant-Kirchhoff,
weft around the limb) -> solver (fabricfem.wear.compression.fit_sleeve: the forearm, an ellipsoid 88 x 72 mm
across at its widest, grows inside the tube; frictionless augmented Lagrangian) -> outputs
(compression.pressure_report):

* sleeve.xdmf: displacement [m] and pressure on the skin [mmHg] (ParaView);
* pressure.png: the sleeve coloured by pressure; pressure_profile.csv / .png: the ring-mean pressure along
  the forearm (the graduation of the garment) and, at the widest section, the pressure against the
  curvature of the section: Laplace's law p = T kappa with one hoop tension T around the ring, so the
  pressure is highest where the limb is most curved (the flanks of the forearm here).

Pressures are per unit deformed area (ContactProblem.contact_pressure), in mmHg (1 mmHg = 133.32 Pa).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.wear.compression import fit_sleeve, pressure_report

LENGTH, RELAXED_RADIUS = 0.24, 0.034                     # m
FOREARM = Ellipsoid(np.array([0.12, 0.0, 0.0]), np.eye(3), np.array([0.32, 0.044, 0.036]))   # m
KNIT = Fabric(E1=0.8e6, E2=0.5e6, G12=0.1e6, nu12=0.3, thickness=7e-4, density=400.0, name="compression knit")


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD) -> dict | None:
    """Run the demo into `out` (`quick`: a 16 x 8 tube instead of 32 x 16); returns (rank 0) the summary of
    compression.pressure_report."""
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    fmesh = tube(LENGTH, RELAXED_RADIUS, *((16, 8) if quick else (32, 16)), order=2, comm=comm)   # mesh
    say(f"compression sleeve: relaxed radius {RELAXED_RADIUS * 1e3:.0f} mm on a forearm "
        f"{2e3 * FOREARM.radii[1]:.0f} x {2e3 * FOREARM.radii[2]:.0f} mm, {comm.size} rank(s)")
    problem = fit_sleeve(fmesh, KNIT, FOREARM, start=0.7, steps=12, tolerance=1e-7,           # forms + solver
                         on_step=lambda s: say(f"  forearm at {s.factor:5.3f} of its size: {s.augmentations} "
                                               f"augmentations, {s.newton_iterations} Newton iterations, "
                                               f"penetration {s.max_penetration:.1e} m"))
    summary = pressure_report(problem, FOREARM, out, "compression sleeve on a forearm")        # outputs
    if summary is not None:
        say(f"done: pressure {summary['min_mmHg']:.1f}-{summary['max_mmHg']:.1f} mmHg (ring means "
            f"{summary['ring_min_mmHg']:.1f}-{summary['ring_max_mmHg']:.1f}); widest section: p = T kappa with "
            f"T = {summary['hoop_tension']:.1f} N/m, largest deviation {100 * summary['laplace_deviation']:.2f}% "
            f"of the peak; wrote {out}/sleeve.xdmf, pressure.png, pressure_profile.csv/.png")
    return summary


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/compression_sleeve"))
    parser.add_argument("--quick", action="store_true", help="a coarser tube")
    args = parser.parse_args()
    main(args.out, args.quick)
