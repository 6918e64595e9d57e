"""Compression sleeve on a forearm: the pressure a knitted tube puts on the skin.

    .venv/bin/python demos/demo_compression_sleeve.py [--out results/demos/compression_sleeve]
    mpirun -n 2 .venv/bin/python demos/demo_compression_sleeve.py

Data flow: mesh (meshes.tube, relaxed radius 34 mm) -> forms (Naghdi shell, orthotropic St. Venant-Kirchhoff,
weft around the limb) -> solver (fabricfem.compression.don: the forearm, an ellipsoid 88 x 72 mm across at
its widest, grows inside the tube; frictionless augmented Lagrangian) -> outputs:

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
from dolfinx import io
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.compression import PA_PER_MMHG, don
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.shell import ShellModel
from fabricfem.sleeve import body_surface

LENGTH, RELAXED_RADIUS = 0.24, 0.034                     # m
FOREARM = Ellipsoid(np.array([0.12, 0.0, 0.0]), np.eye(3), np.array([0.32, 0.044, 0.036]))   # m
KNIT = Fabric(E1=0.8e6, E2=0.5e6, G12=0.1e6, nu12=0.3, thickness=7e-4, density=400.0, name="compression knit")


def section_curvature(points: np.ndarray) -> np.ndarray:
    """Curvature [1/m] of the forearm's cross-section ellipse x = const through each point (on the surface)."""
    local = FOREARM.to_local(points)
    scale = np.sqrt(np.clip(1.0 - (local[:, 0] / FOREARM.radii[0]) ** 2, 1e-12, None))
    a, b = FOREARM.radii[1] * scale, FOREARM.radii[2] * scale
    y, z = local[:, 1], local[:, 2]
    return 1.0 / (a ** 2 * b ** 2 * (y ** 2 / a ** 4 + z ** 2 / b ** 4) ** 1.5)


def main(out: Path, comm=MPI.COMM_WORLD) -> dict | None:
    """Run the demo into `out`; returns (rank 0) the pressure range and the widest section's Laplace fit."""
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    fmesh = tube(LENGTH, RELAXED_RADIUS, 32, 16, order=2, comm=comm)
    model = ShellModel(fmesh, KNIT)
    model.constrain("end0", u=(0.0, None, None))                               # cuff held along the axis
    # mirror symmetry of tube and forearm about y = 0 and z = 0 (holds the rigid modes before contact)
    model.constrain(lambda x: np.isclose(x[1], 0.0, atol=1e-9), u=(None, 0.0, None))
    model.constrain(lambda x: np.isclose(x[2], 0.0, atol=1e-9), u=(None, None, 0.0))
    problem = ContactProblem(model, [FOREARM], method="augmented")
    say(f"compression sleeve: {model.ndofs} dofs on {comm.size} rank(s), relaxed radius "
        f"{RELAXED_RADIUS * 1e3:.0f} mm, forearm {2e3 * FOREARM.radii[1]:.0f} x {2e3 * FOREARM.radii[2]:.0f} mm")
    don(problem, [FOREARM], start=0.7, steps=12, tolerance=1e-7,
        on_step=lambda s: say(f"  forearm at {s.factor:5.3f} of its size: {s.augmentations} augmentations, "
                              f"{s.newton_iterations} Newton iterations, penetration {s.max_penetration:.1e} m"))

    pressure = problem.pressure_field()
    pressure.x.array[:] /= PA_PER_MMHG
    pressure.name = "pressure_mmHg"
    with io.XDMFFile(comm, str(out / "sleeve.xdmf"), "w") as xdmf:
        xdmf.write_mesh(model.mesh)
        xdmf.write_function(model.displacement(), 0.0)
        xdmf.write_function(pressure, 0.0)
    surface = fio.gather_surface(model.mesh, model.displacement())
    values = fio.gather_field(model.mesh, pressure)
    if comm.rank == 0:
        fio.render_field(out / "pressure.png", surface, values, "compression sleeve on a forearm, pressure [mmHg]",
                         bodies=[body_surface([FOREARM])], camera="iso", zoom=1.8)

    # owned nodes of all ranks: deformed position and pressure [mmHg]
    s = problem.evaluate()
    p_mmhg = problem.contact_pressure() / PA_PER_MMHG
    gathered = [comm.gather(a, root=0) for a in (s.position, problem.nodes.reference, p_mmhg)]
    if comm.rank != 0:
        return None
    x, X, p = (np.concatenate(a) for a in gathered)
    rings = np.round(X[:, 0] / (LENGTH / 32)).astype(int)                     # the 33 node rings of the Q2 tube
    ring_x = np.array([x[rings == k, 0].mean() for k in np.unique(rings)])
    ring_p = np.array([p[rings == k].mean() for k in np.unique(rings)])
    widest = rings == int(round(FOREARM.center[0] / (LENGTH / 32)))
    kappa = section_curvature(x[widest])
    tension = float(np.sum(p[widest] * kappa) / np.sum(kappa ** 2))            # least squares p = T kappa
    residual = float(np.max(np.abs(p[widest] - tension * kappa)) / np.max(p[widest]))
    fio.write_csv(out / "pressure_profile.csv", ["x_m", "ring_mean_pressure_mmHg"],
                  np.column_stack([ring_x, ring_p]), comm)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    left.plot(ring_x * 1e3, ring_p, "o-")
    left.set(xlabel="x along the forearm [mm]", ylabel="ring-mean pressure [mmHg]", title="graduation")
    order = np.argsort(kappa)
    right.plot(kappa, p[widest], "o", label="computed (nodes of the widest section)")
    right.plot(kappa[order], tension * kappa[order], "-",
               label=f"Laplace p = T kappa, T = {tension * PA_PER_MMHG:.1f} N/m")
    right.set(xlabel="section curvature kappa [1/m]", ylabel="pressure [mmHg]", title="widest section")
    right.legend()
    fig.tight_layout()
    fig.savefig(out / "pressure_profile.png", dpi=120)
    say(f"done: pressure {p.min():.1f}-{p.max():.1f} mmHg (ring means {ring_p.min():.1f}-{ring_p.max():.1f}); "
        f"widest section: p = T kappa with T = {tension * PA_PER_MMHG:.1f} N/m, largest deviation "
        f"{100 * residual:.2f}% of the peak; wrote {out}/sleeve.xdmf, pressure.png, pressure_profile.csv/.png")
    return {"min_mmHg": float(p.min()), "max_mmHg": float(p.max()), "hoop_tension": tension * PA_PER_MMHG,
            "laplace_deviation": residual}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/demos/compression_sleeve"))
    args = parser.parse_args()
    if MPI.COMM_WORLD.rank == 0:
        args.out.mkdir(parents=True, exist_ok=True)
    MPI.COMM_WORLD.barrier()
    main(args.out)
