"""An independent check of the pressure between two garments (fabricfem.wear.layers): two concentric tubes, the
outer one pressed onto the held inner one by a uniform inward pressure.

Setup (SI units): the tubes of fabricfem.meshes.layers.concentric_tubes, radius R and R + g, the same cells around
and along (so that every node of the outer tube lies radially above one of the inner tube), the cotton of the
self-contact cases (fabricfem.verify.self_contact.cotton, 1 mm), the contact distance d_c the thickness and g just
above it. The inner tube is held (u and rotations); every node i of the outer tube carries the inward radial force
p A_i (A_i its lumped reference area), switched on at t = 0; mass-proportional damping settles the tube.

Reference: in static equilibrium the radial load on the outer tube, F = p sum A_i, is carried by the contact with
the inner tube and by the outer tube's hoop compression. The outer tube moves in by its start gap above d_c plus the
penalty's penetration p / k_N (k_N = 10 E t / h^2 twice over: each node of either tube is a vertex against the
other's triangles), Delta r = 3 um here; its hoop force E t Delta r / R per length carries the pressure
E t Delta r / R^2 ([Timoshenko1959]: a cylinder's membrane force N = p R), 0.35 % of p in this setup. So
the layer monitor's load of the outer tube on the inner one, F_contact = sum over the inner nodes of |f_i| (the
normal contact forces between the two garments, `SelfContact.between`), must equal F within 1 %, time-averaged over
the last third of the run. Measured (3000 steps, 2400 dofs, 3 s): -0.10 %; the mean pressure over the contact
101.4 Pa. A larger load (1000 Pa, or a start gap of 1.01 d_c) compresses the outer tube's hoop enough to wrinkle it
(lobes 13 mm out): the outer tube then no longer is a membrane on a rigid core and the check does not apply.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.self_contact import SelfContact
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.stability import critical_time_step
from fabricfem.meshes.layers import TubeLayer, concentric_tubes
from fabricfem.shell import ShellModel
from fabricfem.verify.self_contact import ROTARY_SCALE, THICKNESS, cotton
from fabricfem.wear.layers import LayerMonitor, layer_labels

RADIUS = 0.1                 # m, the inner tube
LENGTH = 0.05                # m
CELLS = (24, 2)              # Q2 cells around and along, both tubes
GAP = 1.0001 * THICKNESS     # m between the tubes at the start (d_c = the thickness): 0.1 um to close
PRESSURE = 100.0             # Pa, inward on the outer tube
RAYLEIGH = (200.0, 0.0)      # mass-proportional damping a [1/s]


class RadialLoad:
    """An explicit hook adding the inward radial force `pressure` [Pa] x the lumped reference area to the nodes of
    `surface` whose reference radius about the x axis exceeds `radius` [m]."""

    def __init__(self, surface: ClothSurface, radius: float, pressure: float):
        X = surface.nodes.reference
        r = np.hypot(X[:, 1], X[:, 2])
        self.surface, self.mask = surface, r > radius
        radial = np.zeros_like(X)
        radial[:, 1:] = X[:, 1:] / r[:, None]
        self.force = -pressure * surface.nodes.area[:, None] * radial
        self.area = surface.comm.allreduce(float(surface.nodes.area[self.mask].sum()), op=MPI.SUM)
        self.pressure = float(pressure)

    def total(self) -> float:
        """The applied radial load F = p sum A_i [N]."""
        return self.pressure * self.area

    def forces(self, integrator, t, rhs) -> None:
        rows = self.surface.nodes.dofs[self.mask]
        rhs.getArray()[rows] += self.force[self.mask]

    def correct(self, integrator, t) -> None:
        """Nothing after the division."""


def pressed_tubes(steps: int = 3000, comm=MPI.COMM_WORLD) -> dict:
    """The outer tube pressed onto the held inner one (module docstring): {"contact": the monitor's mean load of
    the outer tube on the inner one over the last third of `steps` [N], "load": F [N], "peak_Pa", "mean_Pa": the
    monitor's pressures at the end, "gap": the mean radial gap at the end [m], "ndofs"}."""
    layers = [TubeLayer("inner", LENGTH, RADIUS, *CELLS), TubeLayer("outer", LENGTH, RADIUS + GAP, *CELLS)]
    fmesh = concentric_tubes(layers, comm=comm)
    model = ShellModel(fmesh, cotton())
    model.constrain(lambda x: np.hypot(x[1], x[2]) < RADIUS + 0.5 * GAP, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0))
    model.compile()
    contact = SelfContact(model)
    labels = layer_labels(contact.surface, fmesh)
    contact.layer = labels
    monitor = LayerMonitor(("inner", "outer"), labels, contact)
    load = RadialLoad(contact.surface, RADIUS + 0.5 * GAP, PRESSURE)
    omega = 2.0 / critical_time_step(model, rotary_inertia_scale=ROTARY_SCALE)
    dt = 0.8 * critical_time_step(model, RAYLEIGH, omega_max=np.hypot(omega, contact.penalty_frequency()))
    integrator = CentralDifference(model, dt, rayleigh=RAYLEIGH, rotary_inertia_scale=ROTARY_SCALE,
                                   contact=[load, contact], energy_bound=None)
    total, counted = 0.0, 0
    for step in range(steps):
        integrator.step()
        if step >= 2 * steps // 3:
            total += monitor.layer_values()["outer_on_inner_force_N"]
            counted += 1
    values = monitor.layer_values()
    x = contact.surface.positions(integrator.d.getArray(readonly=True))
    r = np.hypot(x[:, 1], x[:, 2])
    out = {"contact": total / counted, "load": load.total(), "peak_Pa": values["outer_on_inner_peak_Pa"],
           "mean_Pa": values["outer_on_inner_mean_Pa"], "gap": float(r[labels == 1].mean() - r[labels == 0].mean()),
           "ndofs": model.ndofs}
    integrator.destroy()
    return out
