"""Compression garments: putting a garment on by growing the body inside it, and Laplace's law.

Donning (`don`): the garment is meshed at its relaxed size (a tube of radius R0 smaller than the limb,
say); the body segments start with their transverse radii (r2, r3, across the long axis e1 of
fabricfem.body.pose) scaled by `start`, so that they fit inside, and grow to full size in `steps`
quasi-static increments, each solved by the augmented Lagrangian (ContactProblem.solve_augmented) to a
penetration below `tolerance`. With friction the end state depends on this path; frictionless contact
(the default of the scenes here) gives the state that a garment relaxed by wear settles to.

Laplace's law (`laplace_pressure`): a tube of relaxed radius R0 on a cylinder of radius r is stretched
uniformly, lambda_h = r / R0 around, and presses on it with

    p = T / r                                        (Laplace's law for a cylindrical membrane)
    T = t lambda_h S_hh / lambda_a                   (hoop force per unit deformed length [N/m], P = F S)
    S_hh = Q22 E_hh,  E_hh = (lambda_h^2 - 1) / 2    (axial stretch held, lambda_a = 1)
    S_hh = E2 E_hh,   E_aa = -nu21 E_hh              (axial force free, S_aa = 0)

for the orthotropic St. Venant-Kirchhoff fabric with the weft (E2) around the tube (meshes.tube) and the
contact on the mid-surface. Pressures are in Pa (1 mmHg = 133.322 Pa, the unit of compression classes).

A compression sleeve on a limb (`fit_sleeve`, `pressure_report`; `fabricfem run` of a scene with a [limb]
section, scenes/compression_sleeve.toml; demos/demo_compression_sleeve.py): a tube along x (meshes.tube,
n_around a multiple of 4) on one ellipsoid whose axes are x, y, z and whose centre is on the x axis, so that
tube and limb are mirror-symmetric about y = 0 and z = 0: those planes hold u_y and u_z of the nodes on them
(which also removes the rigid modes before the limb touches), and the end0 ring is held along the axis.
On a section x = const of the limb, p = T kappa (Laplace with the section curvature kappa, the hoop
tension T uniform around the ring without friction) up to the axial force times the limb's axial curvature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from dolfinx import io
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact.problem import ContactProblem
from fabricfem.materials import Fabric
from fabricfem.meshes._validate import choice, count, positive
from fabricfem.shell import ShellModel
from fabricfem.solvers.newton import NewtonSolver, SolverError
from fabricfem.wear.outputs import PA_PER_MMHG, body_surface, render_skin_pressure, skin_pressure


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


def grown(segment: Ellipsoid, factor: float) -> Ellipsoid:
    """The segment with its transverse radii r2, r3 scaled by `factor` (long axis e1 unchanged)."""
    return Ellipsoid(segment.center, segment.rotation, segment.radii * np.array([1.0, factor, factor]))


@dataclass
class DonningStep:
    factor: float              # transverse radius scale of the body
    augmentations: int
    newton_iterations: int
    max_penetration: float     # m


def don(problem: ContactProblem, segments: Sequence[Ellipsoid], start: float, steps: int = 10,
        tolerance: float = 1e-7, solver: NewtonSolver | None = None,
        on_step: Callable[[DonningStep], None] | None = None, max_cuts: int = 4) -> list[DonningStep]:
    """Grow `segments` from `start` x their transverse radii to full size in `steps` equal increments
    (module docstring). `problem` must use method="augmented". A failed increment is undone and retried at
    half size, up to `max_cuts` times in a row; then the model is left in the last converged state and
    SolverError names the growth factors reached and tried."""
    if not (isinstance(start, (int, float)) and 0.0 < start <= 1.0):
        raise ValueError(f"start must lie in (0, 1], got {start!r}")
    steps = count("steps", steps)
    solver = solver or NewtonSolver(problem.system)
    history: list[DonningStep] = []
    reached, increment = start, (1.0 - start) / steps
    for k in range(1, steps + 1):
        target = start + (1.0 - start) * k / steps
        h, cuts, augmentations, iterations, penetration = increment, 0, 0, 0, 0.0
        while reached < target - 1e-14:
            factor = min(target, reached + h)
            last_good, multipliers = problem.model.w.x.array.copy(), problem.multiplier.copy()
            problem.set_obstacles([grown(e, factor) for e in segments])
            try:
                report = problem.solve_augmented(solver, tolerance=tolerance)
            except SolverError as err:
                problem.model.w.x.array[:] = last_good
                problem.multiplier[:] = multipliers
                problem.set_obstacles([grown(e, reached) for e in segments])
                if cuts == max_cuts:
                    raise SolverError(f"donning: body grown to {reached:.4g} of its size; the increment to "
                                      f"{factor:.4g} failed after {cuts} cuts ({err}); the model holds the state "
                                      f"at {reached:.4g}", reason=getattr(err, "reason", "")) from err
                h, cuts = 0.5 * h, cuts + 1
                continue
            problem.system.after_converged_step()
            reached = factor
            augmentations += report.augmentations
            iterations += sum(report.newton_iterations)
            penetration = report.max_penetration
            cuts = 0
        history.append(DonningStep(target, augmentations, iterations, penetration))
        if on_step is not None:
            on_step(history[-1])
    return history


def check_symmetric_limb(limb: Ellipsoid) -> None:
    """ValueError unless the limb is mirror-symmetric about y = 0 and z = 0 (module docstring)."""
    if limb.center[1] != 0.0 or limb.center[2] != 0.0 or not np.allclose(np.abs(limb.rotation), np.eye(3)):
        raise ValueError("limb: its centre must lie on the tube axis (y = z = 0) and its axes along x, y, z")


def fit_sleeve(fmesh, fabric: Fabric, limb: Ellipsoid, start: float, steps: int = 10, tolerance: float = 1e-7,
               on_step: Callable[[DonningStep], None] | None = None) -> ContactProblem:
    """Naghdi shell of the tube `fmesh` (meshes.tube, n_around a multiple of 4) donned onto `limb` (module
    docstring: end0 held along the axis, mirror planes y = 0 and z = 0), frictionless augmented Lagrangian."""
    check_symmetric_limb(limb)
    x = fmesh.mesh.geometry.x
    planes = fmesh.mesh.comm.allreduce(np.array([np.sum(np.isclose(x[:, 1], 0.0, atol=1e-9) & (x[:, 2] > 0)),
                                                 np.sum(np.isclose(x[:, 2], 0.0, atol=1e-9) & (x[:, 1] > 0))]))
    if planes.min() == 0:
        raise ValueError("mesh: no tube nodes on the symmetry planes y = 0 and z = 0 (n_around must be a multiple "
                         "of 4)")
    model = ShellModel(fmesh, fabric)
    model.constrain("end0", u=(0.0, None, None))
    model.constrain(lambda x: np.isclose(x[1], 0.0, atol=1e-9), u=(None, 0.0, None))
    model.constrain(lambda x: np.isclose(x[2], 0.0, atol=1e-9), u=(None, None, 0.0))
    problem = ContactProblem(model, [limb], method="augmented", active_set=True, tie_tolerance=0.1 * tolerance)
    don(problem, [limb], start, steps, tolerance, on_step=on_step)
    return problem


def section_curvature(limb: Ellipsoid, points: np.ndarray) -> np.ndarray:
    """Curvature [1/m] of the limb's cross-section ellipse x = const (local e1 = const) through each point."""
    local = limb.to_local(points)
    scale = np.sqrt(np.clip(1.0 - (local[:, 0] / limb.radii[0]) ** 2, 1e-12, None))
    a, b = limb.radii[1] * scale, limb.radii[2] * scale
    y, z = local[:, 1], local[:, 2]
    return 1.0 / (a ** 2 * b ** 2 * (y ** 2 / a ** 4 + z ** 2 / b ** 4) ** 1.5)


def write_sleeve_xdmf(problem: ContactProblem, path: Path) -> None:
    """sleeve.xdmf: the fields "displacement" [m] and "pressure_mmHg" (pressure on the skin) at time 0 (all ranks)."""
    model = problem.model
    displacement = model.displacement()
    displacement.name = "displacement"
    pressure = problem.pressure_field()
    pressure.x.array[:] /= PA_PER_MMHG
    pressure.name = "pressure_mmHg"
    with io.XDMFFile(problem.comm, str(path), "w") as xdmf:
        xdmf.write_mesh(model.mesh)
        xdmf.write_function(displacement, 0.0)
        xdmf.write_function(pressure, 0.0)


def pressure_summary(position: np.ndarray, pressure: np.ndarray, area: np.ndarray) -> dict:
    """Peak and mean pressure on the skin of the nodes (positions (N, 3) [m], pressures (N,) [Pa], lumped
    reference areas (N,) [m^2]): peak in Pa, kPa and mmHg with its node's position [m]; mean over the nodes
    in contact (pressure > 0) weighted by their areas; the number of those nodes and their area [m^2]."""
    peak = int(np.argmax(pressure))
    touching = pressure > 0.0
    contact_area = float(np.sum(area[touching]))
    mean = float(np.sum(pressure[touching] * area[touching]) / contact_area) if contact_area > 0.0 else 0.0
    out = {"contact_nodes": int(np.sum(touching)), "contact_area_m2": contact_area,
           "peak_position_m": [float(c) for c in position[peak]]}
    for name, value in (("peak_pressure", float(pressure[peak])), ("mean_pressure", mean)):
        out.update({f"{name}_Pa": value, f"{name}_kPa": value / 1e3, f"{name}_mmHg": value / PA_PER_MMHG})
    return out


def plot_pressure_profile(path: Path, ring_x: np.ndarray, ring_p: np.ndarray, kappa: np.ndarray, p: np.ndarray,
                          ring_position: float, tension: float) -> None:
    """pressure_profile.png (rank 0): ring-mean pressure [mmHg] along x [m]; the pressure [mmHg] of the widest
    ring's nodes against their section curvature kappa [1/m] with the Laplace fit p = T kappa (T [mmHg m])."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    left.plot(ring_x * 1e3, ring_p, "o-")
    left.set(xlabel="x along the limb [mm]", ylabel="ring-mean pressure [mmHg]", title="along the limb")
    order = np.argsort(kappa)
    right.plot(kappa, p, "o", label=f"computed (nodes of the ring at x = {1e3 * ring_position:.0f} mm)")
    right.plot(kappa[order], tension * kappa[order], "-",
               label=f"Laplace p = T kappa, T = {tension * PA_PER_MMHG:.1f} N/m")
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


def pressure_report(problem: ContactProblem, limb: Ellipsoid, out: Path, title: str = "compression sleeve",
                    render: bool = True) -> dict | None:
    """Write into `out`: sleeve.xdmf (fields "displacement" [m] and "pressure_mmHg", the pressure on the skin),
    pressure.png (the sleeve coloured by it) and skin_pressure.png (the limb's skin coloured by it [kPa]) when
    `render`, pressure_profile.csv / .png (ring-mean pressure along x; p against the section curvature at the
    ring nearest the limb's centre, with the least-squares Laplace fit p = T kappa). Returns on rank 0 (None
    elsewhere) the summary: `pressure_summary` (peak with its position, mean; Pa, kPa, mmHg), the pressure range
    and ring means [mmHg], the hoop tension T [N/m] ("hoop_tension_N_per_m", also "hoop_tension") and the
    largest deviation from T kappa relative to the peak there ("laplace_deviation")."""
    comm, model = problem.comm, problem.model
    out = Path(out)
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    write_sleeve_xdmf(problem, out / "sleeve.xdmf")
    surface = fio.gather_surface(model.mesh, model.displacement())
    if render:
        field = problem.pressure_field()
        field.x.array[:] /= PA_PER_MMHG
        values = fio.gather_field(model.mesh, field)
        if comm.rank == 0:
            fio.render_field(out / "pressure.png", surface, values, f"{title}: pressure on the skin",
                             bodies=[body_surface([limb])], camera="iso", zoom=1.8,
                             scalar_bar_title="pressure on the skin [mmHg]")
    s = problem.evaluate()
    p_pa = problem.contact_pressure()
    gathered = [comm.gather(a, root=0) for a in (s.position, problem.nodes.reference[:, 0], p_pa,
                                                 problem.nodes.area)]
    if comm.rank != 0:
        return None
    x, X, p_pa, area = (np.concatenate(a) for a in gathered)
    p = p_pa / PA_PER_MMHG
    ring_X, rings = np.unique(np.round(X, 9), return_inverse=True)     # the node rings of the tube
    ring_x = np.bincount(rings, x[:, 0]) / np.bincount(rings)
    ring_p = np.bincount(rings, p) / np.bincount(rings)
    centre_ring = int(np.argmin(np.abs(ring_X - limb.center[0])))
    widest = rings == centre_ring
    kappa = section_curvature(limb, x[widest])
    tension = float(np.sum(p[widest] * kappa) / np.sum(kappa ** 2))    # least squares p = T kappa [mmHg m]
    deviation = float(np.max(np.abs(p[widest] - tension * kappa)) / np.max(p[widest]))
    fio.write_csv(out / "pressure_profile.csv", ["x_m", "ring_mean_pressure_mmHg"],
                  np.column_stack([ring_x, ring_p]), MPI.COMM_SELF)
    plot_pressure_profile(out / "pressure_profile.png", ring_x, ring_p, kappa, p[widest], ring_X[centre_ring],
                          tension)
    if render:
        render_limb_pressure(out / "skin_pressure.png", limb, x, p_pa, 1.5 * problem.nodes.element_size,
                             surface, f"{title}: contact pressure on the skin")
    return {**pressure_summary(x, p_pa, area), "min_mmHg": float(p.min()), "max_mmHg": float(p.max()),
            "ring_min_mmHg": float(ring_p.min()), "ring_max_mmHg": float(ring_p.max()),
            "hoop_tension_N_per_m": tension * PA_PER_MMHG, "hoop_tension": tension * PA_PER_MMHG,
            "laplace_deviation": deviation}
