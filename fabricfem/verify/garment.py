"""Verification of the garment engine: a tube sewn from two flat panels, pulled onto a cylinder (Laplace's law)."""
from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from fabricfem.body.pose import Body, Segment
from fabricfem.contact.seams import SeamSpec
from fabricfem.materials import Fabric
from fabricfem.meshes.pattern import Panel, Pattern, Stitch
from fabricfem.meshes.pattern_mesh import mesh_pattern, wrap_on_cylinder
from fabricfem.verify import Timer, case, result
from fabricfem.wear.compression import StillPose, laplace_pressure
from fabricfem.wear.garment import ExplicitSettings, Timeline, build_garment_run

WIDTHS = (0.12, 0.20)     # m, the two panels (unequal: the seams are not at opposite sides)
LENGTH = 0.15             # m, along the tube
STRETCH = 1.2             # cylinder circumference / (w1 + w2)
FABRIC = Fabric(E1=1.2e6, E2=0.8e6, G12=1e5, nu12=0.2, thickness=1e-3, density=436.0, name="sewn-tube fabric")


def sewn_tube(h: float = 0.03, comm=MPI.COMM_WORLD):
    """The garment: two rectangles (w1 x L, w2 x L; warp along the tube, the panels' vertical) rolled onto the
    cylinder of their relaxed radius R0 = (w1 + w2) / (2 pi) about the x axis, side by side, stitched along both
    long edges (started closed). Returns (GarmentMesh, R0)."""
    w1, w2 = WIDTHS
    r0 = (w1 + w2) / (2.0 * math.pi)
    panels = {name: Panel(name, np.array([[0.0, 0.0], [w, 0.0], [w, LENGTH], [0.0, LENGTH]]))
              for name, w in (("a", w1), ("b", w2))}
    pattern = Pattern(panels, [Stitch(("a", 1), ("b", 3)), Stitch(("b", 1), ("a", 3))])
    placements = {name: wrap_on_cylinder((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), r0, zero_direction=(0.0, 1.0, 0.0),
                                         angle0=angle)
                  for name, angle in (("a", 0.0), ("b", w1 / r0))}
    return mesh_pattern(pattern, h, order=2, placements=placements, comm=comm), r0


@case("sewn-tube-laplace", mpi=True)
def sewn_tube_laplace() -> list:
    """A tube sewn from two flat rectangles (widths 0.12 and 0.20 m, started closed on the cylinder of their
    relaxed radius R0) is pulled onto a rigid frictionless cylinder of circumference 1.2 (w1 + w2): the cylinder
    grows from 0.7 to 1 of its radius r = 1.2 R0 in 0.06 s and the tube settles for 0.2 s (explicit engine, mass
    damping 50 1/s). Checks: the seams stay closed (largest distance of stitched nodes, tolerance 1e-6 m); the
    mean contact pressure on the cylinder over the nodes more than two element sizes from the seams against
    Laplace's law p = T / r with the St. Venant-Kirchhoff hoop tension of the free tube
    (fabricfem.wear.compression.laplace_pressure, axial force free), tolerance 1 % (the discretisation of the
    circle by Q2 cells and the residual motion after settling, both far below it; measured 5e-5 on a 12 x 8
    mesh); the largest penetration below 1e-6 m."""
    with Timer() as timer:
        garment, r0 = sewn_tube()
        r = STRETCH * r0
        body = Body([Segment("cylinder", "p", "d", "m", (20.0, r, r))],
                    StillPose({"p": np.array([-19.9, 0.0, 0.0]), "d": np.array([20.1, 0.0, 0.0]),
                               "m": np.array([0.0, 1.0, 0.0])}))
        seams = [SeamSpec(s.name, s.points_a, s.panel_tag_a, s.points_b, s.panel_tag_b, float(np.mean(s.lengths)))
                 for s in garment.stitches]
        timeline = Timeline(record_time=0.02, donning_time=0.06, grow_from=0.7, settle_time=0.2, motion_time=0.0)
        run = build_garment_run("sewn-tube", garment.fabric, FABRIC, body, seams=seams, timeline=timeline,
                                settings=ExplicitSettings(mass_damping=50.0, gravity=None), friction=0.0)
        history = run.run()
        contact = run.contact
        pressure = run.pressure_field().x.array[contact.nodes.node_index[contact.moving]]
        theta = np.arctan2(contact.position[:, 2], contact.position[:, 1]) % (2.0 * math.pi)
        seam_angles = np.array([0.0, WIDTHS[0] / r0, 2.0 * math.pi])
        away = np.min(np.abs(theta[:, None] - seam_angles[None, :]), axis=1) * r > 2 * 0.03
        sums = run.comm.allreduce(np.array([float(pressure[away].sum()), float(away.sum())]), op=MPI.SUM)
        mean = sums[0] / sums[1]
        last = history.steps[-1]
        ndofs = run.model.ndofs
        run.destroy()
    reference = laplace_pressure(FABRIC, r0, r, axial="free").pressure
    return [result("sewn-tube-laplace", "largest seam gap [m]", last.seam_gap, 0.0, 1e-6, ndofs, timer.elapsed,
                   scale=1.0),
            result("sewn-tube-laplace", "mean pressure away from the seams [Pa] vs Laplace T / r", mean, reference,
                   1e-2, ndofs, timer.elapsed),
            result("sewn-tube-laplace", "largest penetration [m]", max(s.max_penetration for s in history.steps), 0.0,
                   1e-6, ndofs, timer.elapsed, scale=1.0)]
