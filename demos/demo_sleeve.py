"""Elbow torque of a sleeve: a cotton tube on a flexing two-ellipsoid arm [Man2006, sec. 5.3].

    .venv/bin/python demos/demo_sleeve.py [--out results/demos/sleeve] [--quick]
    mpirun -n 2 .venv/bin/python demos/demo_sleeve.py

The same scene as a file: `fabricfem run scenes/sleeve.toml`.

Data flow: configuration (wear.config.SleeveConfig: the tube, the fabric, the flexion, the contact, the route)
-> mesh (meshes.tube, Q2) -> forms (Naghdi shell) -> route (wear.run.build_run: the garment engine's explicit central differences
with lumped mass, the sleeve's weight and Lagrange-multiplier contact with Coulomb friction [Man2006, Box 5])
-> outputs (wear.recorder.WearRecorder: cloth.xdmf and cloth_pressure.xdmf per degree, torque.sto,
body.pvd, torque.csv, torque.png, pressure renders). The torque is the resisting torque of the contact forces
on the forearm about the elbow, positive when the sleeve opposes the flexion.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from mpi4py import MPI

from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.recorder import WearRecorder
from fabricfem.wear.run import build_run


def main(out: Path, quick: bool = False, comm=MPI.COMM_WORLD):
    """Run into `out`; returns the history (fabricfem.wear.contract.WearHistory)."""
    config = SleeveConfig.of(n_around=10, n_along=13, name="sleeve",                           # mesh I
                             **(dict(final_angle=6.0, output_angle_step=3.0, angle_steps=2) if quick else {}))
    run = build_run(config, comm)                                                               # mesh, forms
    recorder = WearRecorder(run, out, render_at=[config.motion.final_angle], render=not quick)
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    say(f"sleeve demo: {run.model.ndofs} dofs, {run.describe()}")
    history = run.run(on_step=lambda step: (recorder.record(step), say(f"  {step.phase:6s} {step.coordinate:5.1f} deg: "
                                                                       f"torque {step.torques['elbow']:+.4e} N m")))
    recorder.close(history)                                                                     # outputs
    run.destroy()
    angle, torque = history.motion_curve("elbow")
    say(f"done: torque at {angle[-1]:.0f} deg {torque[-1]:.4e} N m; wrote {out}")
    return history


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/sleeve"))
    parser.add_argument("--quick", action="store_true", help="to 6 degrees, no renders")
    args = parser.parse_args()
    main(args.out, args.quick)
