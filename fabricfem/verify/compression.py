"""`compression-laplace`: a compression sleeve pulled over a rigid cylinder presses on it with Laplace's
pressure p = T / r (fabricfem.wear.compression), for the axial stretch held and for the axial force free.

The tube (relaxed radius R0, Q2 on the quadratic circle: the uniform stretch is exactly representable) is
put on by growing the cylinder from R0 (plus 4 um of interference, so that the contact holds the tube
from the first Newton step) to r = 1.2 R0 (`compression.don`, frictionless augmented Lagrangian); u_x = 0
on one end ring (both for "held"), u_y = 0 on the generatrix y = 0, z > 0 against the rotation about
the axis; both constraints hold in the uniform state.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.shell import ShellModel
from fabricfem.verify import Timer, case, result
from fabricfem.wear.compression import don, laplace_pressure

RELAXED_RADIUS = 0.04    # m
TUBE_LENGTH = 0.1        # m
HOOP_STRETCH = 1.2       # r / R0
INTERFERENCE = 4e-6      # m
# knit-like orthotropic fabric, weft (E2) around the tube [Pa, m]
KNIT = Fabric(E1=0.3e6, E2=0.15e6, G12=0.05e6, nu12=0.3, thickness=6e-4, density=300.0, name="knit")


def sleeve_on_cylinder(axial: str, n_around: int = 24, n_along: int = 6, comm=MPI.COMM_WORLD) -> dict:
    """Don the tube onto the cylinder of radius HOOP_STRETCH R0 along x; returns the problem and the
    owned nodes' current pressure [Pa], lumped current and reference areas [m^2]."""
    fmesh = tube(TUBE_LENGTH, RELAXED_RADIUS, n_around, n_along, order=2, comm=comm)
    model = ShellModel(fmesh, KNIT)
    model.constrain("end0", u=(0.0, None, None))
    if axial == "held":
        model.constrain("end1", u=(0.0, None, None))
    model.constrain(lambda x: np.isclose(x[1], 0.0, atol=1e-9) & (x[2] > 0.0), u=(None, 0.0, None))
    radius = HOOP_STRETCH * RELAXED_RADIUS
    limb = Ellipsoid(np.zeros(3), np.eye(3), np.array([100.0, radius, radius]))   # a cylinder along x
    problem = ContactProblem(model, [limb], method="augmented")
    steps = don(problem, [limb], start=(RELAXED_RADIUS + INTERFERENCE) / radius, steps=8, tolerance=1e-8)
    current = problem.contact_pressure()
    return {"problem": problem, "pressure": current, "areas": problem._current_areas(),
            "reference_areas": problem.nodes.area, "steps": steps, "radius": radius}


@case("compression-laplace", mpi=True)
def compression_laplace() -> list:
    """Mean and spread of the pressure on the cylinder and the area stretch against Laplace's law.

    Tolerances: 1e-3 on the mean pressure and the area stretch, 1e-2 on the spread. A priori error sources,
    all below 1e-4: penetration < 1e-8 m on r = 48 mm, bending of the curvature change (t^2 / (12 r^2) =
    1.3e-5 of the membrane energy), the Q2 circle against the exact cylinder (radial error ~ R a^4 / 8 with
    a = pi / 24, 4e-5 R); the spread also sees the nodal normals of the body against the element normals."""
    out = []
    for axial in ("held", "free"):
        with Timer() as timer:
            r = sleeve_on_cylinder(axial)
        problem = r["problem"]
        comm = problem.comm
        exact = laplace_pressure(KNIT, RELAXED_RADIUS, r["radius"], axial)
        force = comm.allreduce(float(np.sum(r["areas"] * r["pressure"])), op=MPI.SUM)
        area = comm.allreduce(float(np.sum(r["areas"])), op=MPI.SUM)
        reference_area = comm.allreduce(float(np.sum(r["reference_areas"])), op=MPI.SUM)
        mean = force / area
        spread = comm.allreduce(float(np.max(np.abs(r["pressure"] / mean - 1.0), initial=0.0)), op=MPI.MAX)
        label = f"tube R0 = 40 mm on r = 48 mm, axial {axial}"
        out.append(result("compression-laplace", f"{label}: mean pressure on the cylinder [Pa] vs Laplace T / r",
                          mean, exact.pressure, 1e-3, problem.ndofs, timer.elapsed))
        out.append(result("compression-laplace", f"{label}: max |p_i / mean - 1| over the nodes", spread, 0.0,
                          1e-2, problem.ndofs, timer.elapsed, scale=1.0))
        out.append(result("compression-laplace", f"{label}: current / reference area vs lambda_h lambda_a",
                          area / reference_area, exact.hoop_stretch * exact.axial_stretch, 1e-3, problem.ndofs,
                          timer.elapsed))
    return out
