"""Compression garments: a tube put on a limb by growing the limb inside it (the explicit wear engine), and
Laplace's law.

Laplace's law (`laplace_pressure`): a tube of relaxed radius R0 on a cylinder of radius r is stretched
uniformly, lambda_h = r / R0 around, and presses on it with

    p = T / r                                        (Laplace's law for a cylindrical membrane)
    T = t lambda_h S_hh / lambda_a                   (hoop force per unit deformed length [N/m], P = F S)
    S_hh = Q22 E_hh,  E_hh = (lambda_h^2 - 1) / 2    (axial stretch held, lambda_a = 1)
    S_hh = E2 E_hh,   E_aa = -nu21 E_hh              (axial force free, S_aa = 0)

for the orthotropic St. Venant-Kirchhoff fabric with the weft (E2) around the tube (meshes.tube) and the
contact on the mid-surface. Pressures are in Pa (1 mmHg = 133.322 Pa, the unit of compression classes).

A compression sleeve on a limb (`compression_run`, `compression_report`; scenes/compression_sleeve.toml, a wear
scene whose body is a "limb"; demos/demo_compression_sleeve.py): a tube along x (meshes.tube) on one ellipsoid
whose axes are x, y, z and whose centre is on the x axis, run by the explicit wear engine
(fabricfem.wear.garment.GarmentRun, central differences with mass damping [Man2006, ch. 5]): the limb
(`limb_body`, held still) starts with its transverse radii scaled by `start`, inside the tube, grows to full size
over the donning phase (Timeline.grow_from, smoothstep) and is held still for the settling time (the still body's
motion phase). Frictionless contact: the state the sleeve settles to does not depend on the growth path.

Holds: the end0 ring is held along the axis, u_x = 0 (`AxialHold`). Without friction a tube stretched over a limb
that tapers towards both ends is in an unstable equilibrium: its stored energy falls as it slides towards a
thinner end (E'' = 2 e'(r) r' < 0 at the ends, e the stored energy per unit length, r' the taper), which on the
shipped forearm grows like exp(45 t / s), estimated. The hold is a forward-increment constraint on u_x applied
before the body contact ([Man2006, Box 5], as fabricfem.contact.handles.EdgeGrip), not a ShellModel constraint: the
explicit contact takes no contact at nodes with a held component (fabricfem.contact.explicit), and the end ring
must touch the limb. There are no symmetry planes (the quasi-static route held u_y on y = 0 and u_z on z = 0): the grown
limb centres the tube, and its turn about the axis, a rigid mode of frictionless contact with no load to drive
it, is damped by the mass damping. The Poisson contraction along the axis draws the free end1 towards end0.

On a section x = const of the limb, p = T kappa (Laplace with the section curvature kappa, the hoop tension T
uniform around the ring without friction) up to the axial force times the limb's axial curvature and the
sleeve's weight (rho t g, 2.7 Pa on the shipped scene's 2.9 kPa). `compression_report` checks it at the node ring
nearest the limb's centre: T by least squares and the largest deviation relative to the ring's peak.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dolfinx import io
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.pose import Body, Segment
from fabricfem.contact.nodal import contact_nodes
from fabricfem.materials import Fabric
from fabricfem.meshes import FabricMesh
from fabricfem.meshes._validate import choice, positive
from fabricfem.shell import ShellModel
from fabricfem.wear.garment import ExplicitSettings, GarmentRun, Timeline, build_garment_run
from fabricfem.wear.outputs import PA_PER_MMHG, body_surface, render_skin_pressure, skin_pressure

# mass damping C = alpha M [1/s] of the compression runs: well above the sleeve's 10 / s (a settled state is wanted,
# not the motion); measured in docs/garments.md ("Compression sleeve")
COMPRESSION_DAMPING = 100.0


@dataclass
class LaplaceSolution:
    pressure: float        # p [Pa] on the body
    tension: float         # T [N/m] hoop force per unit deformed axial length
    hoop_stretch: float    # lambda_h
    axial_stretch: float   # lambda_a


def laplace_pressure(fabric: Fabric, relaxed_radius: float, radius: float, axial: str = "held") -> LaplaceSolution:
    """Uniform state of a tube of relaxed radius R0 [m] on a cylinder of radius r [m] (module docstring);
    `axial` = "held" (lambda_a = 1) or "free" (no axial force)."""
    R0 = positive("relaxed_radius", relaxed_radius)
    r = positive("radius", radius)
    choice("axial", axial, ("held", "free"))
    Q = fabric.plane_stress_matrix
    lam_h = r / R0
    E_hh = 0.5 * (lam_h ** 2 - 1.0)
    if axial == "held":
        S_hh, lam_a = Q[1, 1] * E_hh, 1.0
    else:
        S_hh, lam_a = fabric.E2 * E_hh, math.sqrt(1.0 - 2.0 * fabric.nu21 * E_hh)
    T = fabric.thickness * lam_h * S_hh / lam_a
    return LaplaceSolution(pressure=T / r, tension=T, hoop_stretch=lam_h, axial_stretch=lam_a)


class StillPose:
    """A kinematics source that holds the given joint and marker positions [m] for `duration` [s]."""

    def __init__(self, positions: dict[str, np.ndarray], duration: float = 0.0):
        self._positions = {k: np.asarray(v, dtype=float) for k, v in positions.items()}
        self.names = tuple(self._positions)
        self.time_range = (0.0, float(duration))

    def positions(self, t: float) -> dict[str, np.ndarray]:
        return self._positions


def limb_body(center: Sequence[float] | np.ndarray, radii: Sequence[float] | np.ndarray, duration: float = 0.0) -> Body:
    """One ellipsoid segment "limb" along x (centre [m]; semi-axes r1 along x, r2 along y, r3 along z [m]) held
    still for `duration` [s]."""
    c, r = np.asarray(center, dtype=float), np.asarray(radii, dtype=float)
    points = {"proximal": c - np.array([r[0], 0.0, 0.0]), "distal": c + np.array([r[0], 0.0, 0.0]),
              "marker": c + np.array([0.0, 1.0, 0.0])}
    return Body([Segment("limb", "proximal", "distal", "marker", tuple(r))], StillPose(points, duration))


class AxialHold:
    """Hold u_x = 0 at the garment nodes whose reference positions X [m] satisfy `where(X)` (a locator on the
    (3, N) array, as ShellModel.constrain's): an explicit hook (fabricfem.dynamics.explicit) that sets the x
    component of the predictor of step n+2 of those nodes to their reference x, a^{n+1}_x += (X_x - y_x) / dt^2
    ([Man2006, Box 5], a forward-increment constraint). Applied before the body contact, so the nodes keep their
    contact (the contact's projection may move them along x by the limb's slope within the step; the next step
    pulls them back). `force` [N]: the hold's axial force on the garment in the last step (this rank's nodes)."""

    def __init__(self, model: ShellModel, where: Callable[[np.ndarray], np.ndarray]):
        nodes = contact_nodes(model)
        mask = np.asarray(where(nodes.reference.T), dtype=bool)
        self.rows = nodes.dofs[mask, 0]
        if model.comm.allreduce(int(mask.sum()), op=MPI.SUM) == 0:
            raise ValueError("hold: no garment node satisfies the locator")
        self.force = 0.0

    def forces(self, integrator, t: float, rhs) -> None:
        """No force before the division: the hold is a forward-increment constraint (`correct`)."""

    def state(self) -> dict:
        """Nothing to keep across a checkpoint (the hold is stateless; `force` is the last step's)."""
        return {}

    def restore(self, state: dict) -> None:
        """Nothing to restore (`state`)."""

    def correct(self, integrator, t: float) -> None:
        dt, rows = integrator.dt, self.rows
        d = integrator.d.getArray(readonly=True)
        v = integrator.velocity_predictor.getArray(readonly=True)
        a = integrator.a.getArray()
        change = -(d[rows] + dt * v[rows] + dt ** 2 * a[rows])       # u_x of the predictor back to 0
        a[rows] += change / dt ** 2
        m = integrator.denominator.getArray(readonly=True)[rows]
        self.force = float(np.sum(m * change)) / dt ** 2


def check_limb_on_axis(limb: Ellipsoid) -> None:
    """ValueError unless the limb's centre lies on the tube's axis (y = z = 0) and its axes along x, y, z (the
    tube's node rings x = const are then the limb's sections)."""
    if limb.center[1] != 0.0 or limb.center[2] != 0.0 or not np.allclose(np.abs(limb.rotation), np.eye(3)):
        raise ValueError("limb: its centre must lie on the tube axis (y = z = 0) and its axes along x, y, z")


def compression_run(fmesh: FabricMesh, fabric: Fabric, limb: Ellipsoid, start: float, donning_time: float,
                    settle_time: float, record_time: float, comm: MPI.Comm = MPI.COMM_WORLD, name: str = "compression",
                    settings: ExplicitSettings | None = None, axial_holds: Sequence[float] = (0.0,)) -> GarmentRun:
    """The GarmentRun of the tube `fmesh` (meshes.tube along x, Q2 quadrilaterals, end0 at x = 0) of `fabric` put on
    `limb` (module docstring): the limb grows from `start` in (0, 1) x its transverse radii to full size over
    `donning_time` [s], then is held still for `settle_time` [s] (the run's motion phase); records every
    `record_time` [s] (means over the interval); frictionless Lagrange contact; the node rings at the reference
    x [m] of `axial_holds` held along the axis (`AxialHold`; default end0). `settings`: default ExplicitSettings
    with mass damping COMPRESSION_DAMPING [1/s] and gravity along -z. `comm` must be the mesh's communicator.
    ValueError for a limb off the tube's axis, a `start` outside (0, 1) or a tube that does not clear the limb at
    `start`."""
    check_limb_on_axis(limb)
    if MPI.Comm.Compare(comm, fmesh.mesh.comm) not in (MPI.IDENT, MPI.CONGRUENT):
        raise ValueError("comm: the run's communicator must be the mesh's")
    if not (isinstance(start, (int, float)) and 0.0 < start < 1.0):
        raise ValueError(f"start must lie in (0, 1), got {start!r}")
    for key, value in (("donning_time", donning_time), ("settle_time", settle_time), ("record_time", record_time)):
        positive(key, value)
    settings = settings or ExplicitSettings(mass_damping=COMPRESSION_DAMPING)
    body = limb_body(limb.center, limb.radii, settle_time)
    timeline = Timeline(record_time=record_time, donning_time=donning_time, grow_from=start, motion_time=settle_time)
    rings = np.asarray(axial_holds, dtype=float)

    def on_rings(x: np.ndarray) -> np.ndarray:
        return np.isclose(x[0][:, None], rings, atol=1e-9).any(axis=1)

    run = build_garment_run(name, fmesh, fabric, body, timeline=timeline, settings=settings,
                            handles=[lambda model: AxialHold(model, on_rings)])
    d = run.integrator.d.getArray(readonly=True)
    if run.contact.min_gap(d, 0.0) <= 0.0:
        run.destroy()
        raise ValueError(f"start: the limb at {start:g} of its transverse radii does not fit inside the tube")
    return run


def section_curvature(limb: Ellipsoid, points: np.ndarray) -> np.ndarray:
    """Curvature [1/m] of the limb's cross-section ellipse x = const (local e1 = const) through each point."""
    local = limb.to_local(points)
    scale = np.sqrt(np.clip(1.0 - (local[:, 0] / limb.radii[0]) ** 2, 1e-12, None))
    a, b = limb.radii[1] * scale, limb.radii[2] * scale
    y, z = local[:, 1], local[:, 2]
    return 1.0 / (a ** 2 * b ** 2 * (y ** 2 / a ** 4 + z ** 2 / b ** 4) ** 1.5)


def pressure_summary(position: np.ndarray, pressure: np.ndarray, area: np.ndarray) -> dict:
    """Peak and mean pressure on the skin of the nodes (positions (N, 3) [m], pressures (N,) [Pa] per unit deformed
    cloth area, lumped deformed areas (N,) [m^2]): peak in Pa, kPa and mmHg with its node's position [m]; mean over
    the nodes in contact (pressure > 0) weighted by their areas (the normal force over the contact area); the
    number of those nodes and their area [m^2]."""
    peak = int(np.argmax(pressure))
    touching = pressure > 0.0
    contact_area = float(np.sum(area[touching]))
    mean = float(np.sum(pressure[touching] * area[touching]) / contact_area) if contact_area > 0.0 else 0.0
    out = {"contact_nodes": int(np.sum(touching)), "contact_area_m2": contact_area,
           "peak_position_m": [float(c) for c in position[peak]]}
    for name, value in (("peak_pressure", float(pressure[peak])), ("mean_pressure", mean)):
        out.update({f"{name}_Pa": value, f"{name}_kPa": value / 1e3, f"{name}_mmHg": value / PA_PER_MMHG})
    return out


@dataclass
class LaplaceCheck:
    """The ring profile and Laplace's law at the ring nearest the limb's centre (`laplace_check`)."""

    ring_x: np.ndarray           # (R,) mean current x [m] of each node ring
    ring_p: np.ndarray           # (R,) ring-mean pressure [mmHg]
    ring_position: float         # reference x [m] of the checked ring
    kappa: np.ndarray            # (K,) section curvature [1/m] at the checked ring's nodes
    p: np.ndarray                # (K,) their pressures [mmHg]
    tension: float               # T [mmHg m] of the least-squares fit p = T kappa
    deviation: float             # max |p - T kappa| / max p over the ring


def laplace_check(limb: Ellipsoid, x: np.ndarray, X: np.ndarray, p: np.ndarray) -> LaplaceCheck:
    """Group the nodes (current positions x (N, 3) [m], reference axial coordinates X (N,) [m], pressures p (N,)
    [mmHg]) into the tube's node rings X = const, and fit p = T kappa (least squares) at the ring nearest the
    limb's centre (module docstring)."""
    ring_X, rings = np.unique(np.round(X, 9), return_inverse=True)
    counts = np.bincount(rings)
    ring_x, ring_p = np.bincount(rings, x[:, 0]) / counts, np.bincount(rings, p) / counts
    centre_ring = int(np.argmin(np.abs(ring_X - limb.center[0])))
    on = rings == centre_ring
    kappa = section_curvature(limb, x[on])
    tension = float(np.sum(p[on] * kappa) / np.sum(kappa ** 2))
    deviation = float(np.max(np.abs(p[on] - tension * kappa)) / np.max(p[on]))
    return LaplaceCheck(ring_x, ring_p, float(ring_X[centre_ring]), kappa, p[on], tension, deviation)


def plot_pressure_profile(path: Path, check: LaplaceCheck) -> None:
    """pressure_profile.png (rank 0): ring-mean pressure [mmHg] along x [m]; the pressure [mmHg] of the checked
    ring's nodes against their section curvature kappa [1/m] with the Laplace fit p = T kappa."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    left.plot(check.ring_x * 1e3, check.ring_p, "o-")
    left.set(xlabel="x along the limb [mm]", ylabel="ring-mean pressure [mmHg]", title="along the limb")
    order = np.argsort(check.kappa)
    right.plot(check.kappa, check.p, "o",
               label=f"computed (nodes of the ring at X = {1e3 * check.ring_position:.0f} mm)")
    right.plot(check.kappa[order], check.tension * check.kappa[order], "-",
               label=f"Laplace p = T kappa, T = {check.tension * PA_PER_MMHG:.1f} N/m")
    right.set(xlabel="section curvature kappa [1/m]", ylabel="pressure [mmHg]", title="around the widest ring")
    right.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_limb_pressure(path: Path, limb: Ellipsoid, position: np.ndarray, pressure: np.ndarray,
                         radius: float, garment_surface, title: str, samples: int = 96) -> None:
    """skin_pressure.png (rank 0): the limb's skin coloured by the sleeve's pressure [kPa] (skin_pressure of the
    nodes' positions (N, 3) [m] and pressures (N,) [Pa] within `radius` [m]), colour range 0 to the nodes' peak,
    the sleeve as a translucent grey surface."""
    points, triangles, values = skin_pressure([limb], samples, position, pressure, radius)
    top = max(float(np.max(pressure, initial=0.0)) / 1e3, 1e-9)
    render_skin_pressure(path, points, triangles, values / 1e3, title, (0.0, top), garment_surface, camera="iso",
                         zoom=1.6)


def write_sleeve(run: GarmentRun, limb: Ellipsoid, out: Path, title: str, render: bool) -> tuple | None:
    """sleeve.xdmf (fields "displacement" [m] and "pressure_mmHg", the pressure on the skin, at time 0) and, when
    `render`, pressure.png (the sleeve coloured by it); returns the gathered deformed surface on rank 0."""
    model = run.model
    displacement = model.displacement()
    displacement.name = "displacement"
    pressure = run.pressure_field()
    pressure.x.array[:] /= PA_PER_MMHG
    pressure.name = "pressure_mmHg"
    with io.XDMFFile(run.comm, str(out / "sleeve.xdmf"), "w") as xdmf:
        xdmf.write_mesh(model.mesh)
        xdmf.write_function(displacement, 0.0)
        xdmf.write_function(pressure, 0.0)
    surface = fio.gather_surface(model.mesh, displacement)
    if render:
        values = fio.gather_field(model.mesh, pressure)
        if run.comm.rank == 0:
            fio.render_field(out / "pressure.png", surface, values, f"{title}: pressure on the skin",
                             bodies=[body_surface([limb])], camera="iso", zoom=1.8,
                             scalar_bar_title="pressure on the skin [mmHg]")
    return surface


def compression_report(run: GarmentRun, limb: Ellipsoid, out: Path, name: str = "compression sleeve",
                       render: bool = True) -> dict | None:
    """Write into `out`, from the run's final state (the pressure per unit deformed cloth area, mean over the last
    record interval): sleeve.xdmf (fields "displacement" [m] and "pressure_mmHg"), pressure.png (the sleeve
    coloured by it) and skin_pressure.png (the limb's skin coloured by it [kPa]) when `render`,
    pressure_profile.csv / .png (ring-mean pressure along x; p against the section curvature at the ring nearest
    the limb's centre, with the least-squares Laplace fit p = T kappa). All ranks call it; returns on rank 0 (None
    elsewhere) the summary: `pressure_summary` (peak with its position, mean over the contact area, contact area on
    the deformed cloth; Pa, kPa, mmHg), the pressure range and ring means [mmHg], the hoop tension T [N/m]
    ("hoop_tension_N_per_m", also "hoop_tension") and the largest deviation from T kappa relative to the peak
    there ("laplace_deviation")."""
    comm, contact = run.comm, run.contact
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    surface = write_sleeve(run, limb, out, name, render)
    p_pa = run.pressure_field().x.array[contact.nodes.node_index[contact.moving]]
    areas = contact.current_areas()
    radius = 1.5 * contact.nodes.element_size
    gathered = [comm.gather(a, root=0) for a in (contact.position, contact.reference[:, 0], p_pa, areas)]
    if comm.rank != 0:
        return None
    x, X, p_pa, areas = (np.concatenate(a) for a in gathered)
    p = p_pa / PA_PER_MMHG
    check = laplace_check(limb, x, X, p)
    fio.write_csv(out / "pressure_profile.csv", ["x_m", "ring_mean_pressure_mmHg"],
                  np.column_stack([check.ring_x, check.ring_p]), MPI.COMM_SELF)
    plot_pressure_profile(out / "pressure_profile.png", check)
    if render:
        render_limb_pressure(out / "skin_pressure.png", limb, x, p_pa, radius, surface,
                             f"{name}: contact pressure on the skin")
    return {**pressure_summary(x, p_pa, areas), "min_mmHg": float(p.min()), "max_mmHg": float(p.max()),
            "ring_min_mmHg": float(check.ring_p.min()), "ring_max_mmHg": float(check.ring_p.max()),
            "hoop_tension_N_per_m": check.tension * PA_PER_MMHG, "hoop_tension": check.tension * PA_PER_MMHG,
            "laplace_deviation": check.deviation}
