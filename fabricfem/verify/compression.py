"""`compression-laplace`: a compression sleeve pulled over a rigid cylinder presses on it with Laplace's
pressure p = T / r (fabricfem.wear.compression), for the axial stretch held and for the axial force free, on the
explicit wear engine (`compression.compression_run`, the route of the compression sleeve).

The tube (relaxed radius R0, Q2 on the quadratic circle: the uniform stretch is exactly representable) is
put on by growing the cylinder from 0.8 r (inside the tube) to r = 1.2 R0 over DONNING_TIME and letting it settle
for SETTLE_TIME (frictionless Lagrange contact, mass damping SETTINGS, no gravity: Laplace's state is weightless);
u_x = 0 on the end0 ring (both end rings for "held", `compression.AxialHold`); the uniform state satisfies both.
The pressure is the engine's, per unit deformed cloth area, mean over the last record interval.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.nodal import CurrentAreas
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.verify import Timer, case, result
from fabricfem.wear.compression import compression_run, laplace_pressure
from fabricfem.wear.garment import ExplicitSettings

RELAXED_RADIUS = 0.04    # m
TUBE_LENGTH = 0.1        # m
HOOP_STRETCH = 1.2       # r / R0
START = 0.8              # the cylinder's starting radius over r
DONNING_TIME = 0.1       # s
SETTLE_TIME = 0.1        # s
RECORD_TIME = 0.01       # s
SETTINGS = ExplicitSettings(mass_damping=100.0, gravity=None)
# knit-like orthotropic fabric, weft (E2) around the tube [Pa, m]
KNIT = Fabric(E1=0.3e6, E2=0.15e6, G12=0.05e6, nu12=0.3, thickness=6e-4, density=300.0, name="knit")


def sleeve_on_cylinder(axial: str, n_around: int = 24, n_along: int = 6, comm=MPI.COMM_WORLD) -> dict:
    """Put the tube on the cylinder of radius HOOP_STRETCH R0 along x and let it settle; returns the run, its
    history, the cylinder's radius [m] and the owned contact nodes' pressure [Pa] (per unit deformed area),
    lumped current and reference areas [m^2]."""
    fmesh = tube(TUBE_LENGTH, RELAXED_RADIUS, n_around, n_along, cell="quadrilateral", order=2, comm=comm)
    radius = HOOP_STRETCH * RELAXED_RADIUS
    cylinder = Ellipsoid(np.array([0.5 * TUBE_LENGTH, 0.0, 0.0]), np.eye(3), np.array([100.0, radius, radius]))
    holds = (0.0, TUBE_LENGTH) if axial == "held" else (0.0,)
    run = compression_run(fmesh, KNIT, cylinder, START, DONNING_TIME, SETTLE_TIME, RECORD_TIME, comm,
                          name=f"compression-laplace-{axial}", settings=SETTINGS, axial_holds=holds)
    history = run.run()
    contact = run.contact
    pressure = run.pressure_field().x.array[contact.nodes.node_index[contact.moving]]
    areas = CurrentAreas(run.model, contact.nodes)()[contact.moving]
    return {"run": run, "history": history, "radius": radius, "pressure": pressure, "areas": areas,
            "reference_areas": contact.area}


@case("compression-laplace", mpi=True)
def compression_laplace() -> list:
    """Mean and spread of the pressure on the cylinder and the area stretch against Laplace's law.

    Tolerances: 1e-3 on the mean pressure and the area stretch, 1e-2 on the spread, 1e-6 on the kinetic / strain
    energy (settled). A priori error sources, all below 1e-4: the settled state's dynamics (kinetic / strain energy
    at the last record 4e-21 held, 2e-11 free, measured; the damping force alpha M v vanishes with v), bending of
    the curvature change (t^2 / (12 r^2) = 1.3e-5 of the membrane energy), the Q2 circle against the exact cylinder
    (radial error ~ R a^4 / 8 with a = pi / 24, 4e-5 R); the contact is exact (projection onto the cylinder, no
    penalty or penetration tolerance); the spread also sees the nodal normals of the body against the element
    normals. Measured (1 and 2 ranks): mean 1.7e-5 and 1.8e-5, spread 5.5e-4 and 6.0e-4, area 5e-8 and 3e-8 (the
    quasi-static route before: 1.6e-5 and 1.7e-5, 5.6e-4 and 6.1e-4, 2e-7)."""
    out = []
    for axial in ("held", "free"):
        with Timer() as timer:
            r = sleeve_on_cylinder(axial)
        run = r["run"]
        comm, ndofs = run.comm, run.model.ndofs
        last = r["history"].steps[-1]
        run.destroy()
        exact = laplace_pressure(KNIT, RELAXED_RADIUS, r["radius"], axial)
        force = comm.allreduce(float(np.sum(r["areas"] * r["pressure"])), op=MPI.SUM)
        area = comm.allreduce(float(np.sum(r["areas"])), op=MPI.SUM)
        reference_area = comm.allreduce(float(np.sum(r["reference_areas"])), op=MPI.SUM)
        mean = force / area
        spread = comm.allreduce(float(np.max(np.abs(r["pressure"] / mean - 1.0), initial=0.0)), op=MPI.MAX)
        label = f"tube R0 = 40 mm on r = 48 mm, axial {axial}, explicit engine"
        out.append(result("compression-laplace", f"{label}: mean pressure on the cylinder [Pa] vs Laplace T / r",
                          mean, exact.pressure, 1e-3, ndofs, timer.elapsed))
        out.append(result("compression-laplace", f"{label}: max |p_i / mean - 1| over the nodes", spread, 0.0,
                          1e-2, ndofs, timer.elapsed, scale=1.0))
        out.append(result("compression-laplace", f"{label}: current / reference area vs lambda_h lambda_a",
                          area / reference_area, exact.hoop_stretch * exact.axial_stretch, 1e-3, ndofs,
                          timer.elapsed))
        out.append(result("compression-laplace", f"{label}: kinetic / strain energy at the last record",
                          last.kinetic_energy / last.strain_energy, 0.0, 1e-6, ndofs, timer.elapsed, scale=1.0))
    return out
