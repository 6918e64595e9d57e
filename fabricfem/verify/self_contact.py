"""Cloth-cloth contact (fabricfem.contact.self_contact) in the explicit engine: a fold that lies on itself, two
stacked sheets pressed together, one sheet sliding over another.

The fabric is the cotton of the tablecloth cases ([Eischen2000, sec. 4.4]: E = 118.1 gf/mm^2, nu = 0.3, weight
0.2384 mg/mm^2 per area) at 1 mm thickness (the areal density kept); the contact distance is the thickness.
Checks:

* fold: a 0.5 m sheet folded in a U (radius 3.2 cm) whose lower leg lies held on a table; the upper leg falls
  onto it under gravity. At every record the independent count of intersecting triangle pairs
  (fabricfem.contact.intersections: a k-d tree broad phase, Moller's interval test and libigl's triangle test) is
  0, and the smallest distance between a vertex and a non-neighbouring triangle (ipctk's candidates, the numpy
  closest point) is at least half the thickness. The same fold without self-contact must show intersecting pairs (the check bites).
* press: a 0.2 m sheet pressed by a uniform pressure onto a held 0.3 m sheet: the contact force between them equals
  the applied load (static equilibrium of the upper sheet, time-averaged over the last part of the run).
* slide: the upper sheet, pressed as before, pulled by a tangential load 2 mu p per area: while it slides, the
  friction force from its momentum balance, F_pull - m dv/dt (the mean velocity over the sliding interval),
  equals mu N with N the applied normal load.
SI units.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fabricfem.contact.cloth_surface import ClothSurface
from fabricfem.contact.intersections import intersecting_pairs
from fabricfem.contact.proximity import ipctk_pairs
from fabricfem.contact.self_contact import EXCLUSION, SelfContact
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.stability import critical_time_step
from fabricfem.materials import Fabric
from fabricfem.meshes import plate
from fabricfem.meshes.fabric_mesh import FabricMesh
from fabricfem.meshes.gmsh_io import mesh_from_gmsh
from fabricfem.shell import ShellModel
from fabricfem.verify import CaseResult, Timer, case, result
from fabricfem.verify.particles_cases import CLOTH_E, CLOTH_NU, CLOTH_WEIGHT

STANDARD_GRAVITY = 9.80665                   # m/s^2
THICKNESS = 1e-3                             # m
SIDE = 0.5                                   # m, the folded sheet's length
ROTARY_SCALE = 100.0                         # rotary-inertia scaling of the wear runs (wear/config.py)
PRESSURE = 10.0                              # Pa on the upper sheet
FRICTION = 0.3                               # mu between the sheets
PULL = 1.5                                   # the pull per area / (mu p)
PULL_START = 0.03                            # s: the pull starts once the pressed sheet has settled
RAYLEIGH = (50.0, 0.0)                       # mass-proportional damping a [1/s] (settles the floppy sheets)


def cotton(thickness: float = THICKNESS) -> Fabric:
    """The tablecloth's cotton ([Eischen2000, sec. 4.4]) at `thickness` [m], its weight per area kept."""
    return Fabric.isotropic(CLOTH_E, CLOTH_NU, thickness, density=CLOTH_WEIGHT / STANDARD_GRAVITY / thickness)


class NodalLoad:
    """An explicit hook adding the force `per_area` [N/m^2] times the lumped reference area to the nodes with
    `select(X)` true (X the (n, 3) reference positions [m] of the owned nodes of `surface`) from the time `start`
    [s] on."""

    def __init__(self, surface: ClothSurface, select, per_area, start: float = 0.0):
        self.surface = surface
        self.start = float(start)
        self.mask = np.asarray(select(surface.nodes.reference), dtype=bool)
        self.per_area = np.asarray(per_area, dtype=float)
        self.area = surface.comm.allreduce(float(surface.nodes.area[self.mask].sum()), op=MPI.SUM)

    def total(self) -> np.ndarray:
        """The applied force [N] (3,)."""
        return self.area * self.per_area

    def forces(self, integrator, t, rhs) -> None:
        if t < self.start:
            return
        rows = self.surface.nodes.dofs[self.mask]
        rhs.getArray()[rows] += self.surface.nodes.area[self.mask, None] * self.per_area

    def correct(self, integrator, t) -> None:
        """Nothing after the division."""


def _two_rectangles(model, n_bottom: int, n_top: int, gap: float) -> None:
    """gmsh: the lower sheet [-0.15, 0.15]^2 at z = 0, the upper [-0.1, 0.1]^2 at z = gap (structured quads)."""
    _rectangles(model, [(-0.15, 0.15, -0.15, 0.15, 0.0, n_bottom, n_bottom),
                        (-0.095, 0.095, -0.095, 0.095, gap, n_top, n_top)])


def _rectangles(model, rectangles: list[tuple[float, float, float, float, float, int, int]]) -> None:
    """gmsh: the rectangles [x0, x1] x [y0, y1] at height z [m] of nx x ny structured quads each, (x0, x1, y0, y1,
    z, nx, ny)."""
    geo = model.geo
    surfaces, lines = [], []
    for x0, x1, y0, y1, z, nx, ny in rectangles:
        corners = [geo.addPoint(x, y, z) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
        edges = [geo.addLine(corners[i], corners[(i + 1) % 4]) for i in range(4)]
        surface = geo.addPlaneSurface([geo.addCurveLoop(edges)])
        for e, n in zip(edges, (nx, ny, nx, ny)):
            geo.mesh.setTransfiniteCurve(e, n + 1)
        geo.mesh.setTransfiniteSurface(surface, "Left", corners)
        geo.mesh.setRecombine(2, surface)
        surfaces.append(surface)
        lines += edges
    geo.synchronize()
    model.setPhysicalName(1, model.addPhysicalGroup(1, lines), "edges")
    model.setPhysicalName(2, model.addPhysicalGroup(2, surfaces), "fabric")
    model.mesh.generate(2)


def stacked_sheets(friction: float, comm=MPI.COMM_WORLD, n_bottom: int = 6, n_top: int = 4):
    """The held lower sheet, the free upper one just outside the contact distance, the contact hook, the pressure
    load and the pull (zero without friction). Returns (model, contact, press, pull)."""
    fmesh = mesh_from_gmsh(lambda m: _two_rectangles(m, n_bottom, n_top, 1.05 * THICKNESS), (1.0, 0.0, 0.0),
                           (0.0, 0.0, 1.0), comm, name="two-sheets")
    model = ShellModel(fmesh, cotton())
    model.constrain(lambda x: x[2] < 0.5 * THICKNESS, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0))
    model.compile()
    contact = SelfContact(model, friction=friction)
    upper = lambda X: X[:, 2] > 0.5 * THICKNESS  # noqa: E731
    press = NodalLoad(contact.surface, upper, (0.0, 0.0, -PRESSURE))
    pull = NodalLoad(contact.surface, upper, (PULL * friction * PRESSURE, 0.0, 0.0), start=PULL_START)
    return model, contact, press, pull


def _integrator(model, hooks, rayleigh=(0.0, 0.0)) -> CentralDifference:
    dt = 0.8 * critical_time_step(model, rayleigh, rotary_inertia_scale=ROTARY_SCALE)
    return CentralDifference(model, dt, rayleigh=rayleigh, rotary_inertia_scale=ROTARY_SCALE, contact=hooks,
                             energy_bound=None)


def upper_contact_force(contact: SelfContact, parts: str = "force") -> np.ndarray:
    """Sum [N] (3,) of the last step's contact forces (`parts`: force, normal_force, friction_force) on the upper
    sheet's nodes."""
    upper = contact.surface.reference[:, 2] > 0.5 * THICKNESS
    return getattr(contact, parts)[upper].sum(axis=0)


def press(steps: int = 1500, comm=MPI.COMM_WORLD) -> dict:
    """The upper sheet pressed onto the lower one (module docstring): the mean contact force on it over the last
    third of `steps`, the applied load [N] and the smallest pair distance [m]."""
    model, contact, load, _ = stacked_sheets(0.0, comm)
    integrator = _integrator(model, [load, contact], RAYLEIGH)
    mean = np.zeros(3)
    counted = 0
    for step in range(steps):
        integrator.step()
        if step >= 2 * steps // 3:
            mean += upper_contact_force(contact)
            counted += 1
    out = {"contact": mean / counted, "load": load.total(), "ndofs": model.W.dofmap.index_map.size_global * 5,
           "min_distance": float(contact.pairs.distance.min()) if len(contact.pairs) else np.inf}
    integrator.destroy()
    return out


def _mean_velocity(model, integrator, load: NodalLoad) -> float:
    """Mass-weighted mean x velocity [m/s] of the loaded (upper) sheet's nodes."""
    nodes = load.surface.nodes
    rows = nodes.dofs[load.mask, 0]
    mass = integrator.ops.mass_diag.getArray(readonly=True)[rows]
    v = integrator.v.getArray(readonly=True)[rows]
    local = np.array([float(mass @ v), float(mass.sum())])
    total = model.comm.allreduce(local, op=MPI.SUM)
    return total[0] / total[1], total[1]


def slide(steps: int = 1500, comm=MPI.COMM_WORLD) -> dict:
    """The pressed upper sheet pulled by PULL mu p per area from PULL_START on (module docstring): the friction
    force [N] from its momentum balance from one sixth of the sliding on to the end, F_pull - m dv/dt - a m v_mean
    (the Rayleigh damping's force on the mean velocity), mu N, and the contact's own friction sum (mean)."""
    model, contact, load, pull = stacked_sheets(FRICTION, comm)
    integrator = _integrator(model, [load, pull, contact], RAYLEIGH)
    first = int(PULL_START / integrator.dt)
    start = first + (steps - first) // 6
    friction_sum, normal_sum, velocity_sum, counted = np.zeros(3), np.zeros(3), 0.0, 0
    for step in range(steps):
        integrator.step()
        if step == start:
            v0, t0 = _mean_velocity(model, integrator, load)[0], integrator.t
        if step > start:
            friction_sum += upper_contact_force(contact, "friction_force")
            normal_sum += upper_contact_force(contact, "normal_force")
            velocity_sum += _mean_velocity(model, integrator, load)[0]
            counted += 1
    v1, mass = _mean_velocity(model, integrator, load)
    acceleration = (v1 - v0) / (integrator.t - t0)
    drag = RAYLEIGH[0] * mass * velocity_sum / counted
    out = {"momentum_friction": pull.total()[0] - mass * acceleration - drag,
           "mu_N": FRICTION * PRESSURE * load.area, "contact_friction": -friction_sum[0] / counted, "speed": v1,
           "contact_normal": normal_sum[2] / counted,
           "ndofs": model.W.dofmap.index_map.size_global * 5}
    integrator.destroy()
    return out


# ---------------------------------------------------------------------------- crossed strips
STRIP_WIDTH = 0.005                          # m, one cell across
STRIP_HALF = 0.02                            # m, half length of every strip (two cells of 0.02 m along)
RAIL_Y = 0.015                               # m, the rails' centre lines at y = +-RAIL_Y
STRIP_STEPS, STRIP_RECORDS = 6000, 30
STRIP_RAYLEIGH = (200.0, 0.0)                # 1/s: about half the critical damping of the strip's bending between the rails


def crossed_strips(edges: bool, comm=MPI.COMM_WORLD):
    """Two held rails along x (x in [-0.02, 0.02] m, y in +-[0.0125, 0.0175] m, z = 0) and a free strip along y across
    them (x in [0.0025, 0.0075] m, y in [-0.02, 0.02] m, z = 1.05 t), all 1 cell wide and 2 cells long: the Q2 nodes
    lie every 0.01 m along a strip, so no node of either lies within 2.5 mm (2.5 d_c) of the other's triangles, and
    only their edges cross (module docstring). Returns (model, contact with or without `edges`, the pressure load
    on the free strip)."""
    w, L = STRIP_WIDTH, STRIP_HALF
    rails = [(-L, L, y - 0.5 * w, y + 0.5 * w, 0.0, 2, 1) for y in (-RAIL_Y, RAIL_Y)]
    free = (0.5 * w, 1.5 * w, -L, L, 1.05 * THICKNESS, 1, 2)
    fmesh = mesh_from_gmsh(lambda m: _rectangles(m, rails + [free]), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), comm,
                           name="crossed-strips")
    model = ShellModel(fmesh, cotton())
    model.constrain(lambda x: x[2] < 0.5 * THICKNESS, u=(0.0, 0.0, 0.0), theta=(0.0, 0.0))
    model.compile()
    contact = SelfContact(model, edges=edges)
    load = NodalLoad(contact.surface, lambda X: X[:, 2] > 0.5 * THICKNESS, (0.0, 0.0, -PRESSURE))
    return model, contact, load


def strips(edges: bool = True, steps: int = STRIP_STEPS, records: int = STRIP_RECORDS, comm=MPI.COMM_WORLD) -> dict:
    """The free strip pressed onto the rails (`crossed_strips`): the mean contact force [N] on it over the last third
    of `steps`, the applied load [N], the intersecting triangle pairs at every record (fabricfem.contact.intersections),
    the most vertex-triangle and edge-edge pairs of a step, the free strip's lowest node height at the end [m]."""
    model, contact, load = crossed_strips(edges, comm)
    integrator = _integrator(model, [load, contact], STRIP_RAYLEIGH)
    upper = contact.surface.reference[:, 2] > 0.5 * THICKNESS
    mean, counted, counts, most = np.zeros(3), 0, [], [0, 0]
    for step in range(1, steps + 1):
        integrator.step()
        most = [max(most[0], len(contact.pairs)), max(most[1], len(contact.edge_pairs))]
        if step > 2 * steps // 3:
            mean += contact.force[upper].sum(axis=0)
            counted += 1
        if step % (steps // records) == 0:
            x = contact.surface.positions(integrator.d.getArray(readonly=True))
            counts.append(intersecting_pairs(x, contact.surface.triangles))
    out = {"contact": mean / counted, "load": load.total(), "intersections": counts, "vertex_pairs": most[0],
           "edge_pairs": most[1], "lowest": float(x[upper, 2].min()),
           "ndofs": model.W.dofmap.index_map.size_global * 5}
    integrator.destroy()
    return out


def strip_rows(name: str) -> list[CaseResult]:
    """The crossed strips' rows of the case: with the edge-edge term the load balance (1 %), no intersecting pair,
    no vertex-triangle pair at all (only the edges hold); without it the free strip falls through the rails."""
    with Timer() as timer:
        held, loose = strips(True), strips(False)
    wall = timer.elapsed
    n = held["ndofs"]
    return [
        result(name, "crossed strips: contact force on the free strip [N] = the applied pressure load, only edge-edge "
               f"pairs acting (most vertex-triangle pairs of a step: {held['vertex_pairs']}, edge-edge: "
               f"{held['edge_pairs']}; mean over the last third; 1 %)", held["contact"][2], -held["load"][2], 0.01, n,
               wall),
        CaseResult(name, f"crossed strips: most intersecting triangle pairs over {STRIP_RECORDS} records (0) and no "
                   "vertex-triangle pair (the edges alone hold)", max(held["intersections"]) + held["vertex_pairs"],
                   0.0, float("nan"), 0.0, max(held["intersections"]) == 0 and held["vertex_pairs"] == 0, n, wall),
        CaseResult(name, "crossed strips without the edge-edge term: the free strip's lowest node at the end [m] < "
                   "-t (it fell through the rails; flat strips crossing flat rails intersect only at the instant "
                   f"they pass, so the count, {max(loose['intersections'])}, cannot show it)", loose["lowest"],
                   -THICKNESS, float("nan"), float("nan"), loose["lowest"] < -THICKNESS, n, wall),
    ]


# ---------------------------------------------------------------------------- the fold
FOLD_CELLS = (20, 6)                         # cells along the length and across
FOLD_LEG = 8                                 # cells of each leg (the bend has the 4 between them)
FOLD_STEPS, FOLD_RECORDS = 2400, 24
FOLD_RAYLEIGH = (10.0, 0.0)


def folded_sheet(comm=MPI.COMM_WORLD) -> FabricMesh:
    """The SIDE x SIDE sheet folded in a U about the y axis (reference, stress-free): the lower leg at z = 0 for
    s < a, a half circle of radius R, the upper leg at z = 2 R back over the lower one (s the length along x, a =
    FOLD_LEG cells, R from the 4 bend cells)."""
    nx, ny = FOLD_CELLS
    fmesh = plate(SIDE, SIDE, nx, ny, cell="quadrilateral", comm=comm)
    a = FOLD_LEG * SIDE / nx
    radius = (nx - 2 * FOLD_LEG) * SIDE / nx / np.pi
    x = fmesh.mesh.geometry.x
    s = x[:, 0].copy()
    phi = np.clip((s - a) / radius, 0.0, np.pi)
    upper = s > a + np.pi * radius
    x[:, 0] = np.where(upper, a - (s - a - np.pi * radius), np.where(s < a, s, a + radius * np.sin(phi)))
    x[:, 2] = radius * (1.0 - np.cos(phi))

    def angle(points: np.ndarray) -> np.ndarray:
        """The bend angle phi of reference points (3, n) (0 on the lower leg, pi on the upper)."""
        return np.where(points[0] <= a, np.where(points[2] < radius, 0.0, np.pi),
                        np.arctan2(points[0] - a, radius - points[2]))

    def warp(points: np.ndarray) -> np.ndarray:
        p = angle(points)
        return np.stack([np.cos(p), np.zeros_like(p), np.sin(p)])

    def normal(points: np.ndarray) -> np.ndarray:
        p = angle(points)
        return np.stack([-np.sin(p), np.zeros_like(p), np.cos(p)])

    return FabricMesh(mesh=fmesh.mesh, facet_tags=fmesh.facet_tags, tags=fmesh.tags, warp=warp, normal=normal,
                      cell_tags=fmesh.cell_tags)


def fold_model(comm=MPI.COMM_WORLD) -> ShellModel:
    """The folded cotton sheet under gravity, its lower leg held (lying on a table)."""
    model = ShellModel(folded_sheet(comm), cotton())
    leg = FOLD_LEG * SIDE / FOLD_CELLS[0]
    model.constrain(lambda x: (x[0] <= leg + 1e-9) & (x[2] < 1e-9), u=(0.0, 0.0, 0.0), theta=(0.0, 0.0))
    model.add_gravity((0.0, 0.0, -STANDARD_GRAVITY))
    model.compile()
    return model


def fold(self_contact: bool = True, steps: int = FOLD_STEPS, records: int = FOLD_RECORDS,
         comm=MPI.COMM_WORLD) -> dict:
    """The upper leg falling onto the lower (module docstring), with or without self-contact. At every record: the
    intersecting triangle pairs and the smallest vertex-triangle distance between non-neighbours (independent of
    the contact: ipctk and libigl, numpy); the upper leg's mean height at the end [m]."""
    model = fold_model(comm)
    surface = ClothSurface(model)
    contact = SelfContact(model) if self_contact else None
    integrator = _integrator(model, [contact] if contact else None, FOLD_RAYLEIGH)
    neighbours = _reference_neighbours(surface)
    counts, distances = [], []
    for step in range(1, steps + 1):
        integrator.step()
        if step % (steps // records) == 0:
            x = surface.positions(integrator.d.getArray(readonly=True))
            counts.append(intersecting_pairs(x, surface.triangles))
            distances.append(_smallest_distance(surface, x, neighbours))
    upper = surface.reference[:, 2] > 1.5 * np.max(surface.reference[:, 2]) / 2.0
    out = {"intersections": counts, "min_distance": distances, "upper_height": float(np.mean(x[upper, 2])),
           "ndofs": model.W.dofmap.index_map.size_global * 5}
    integrator.destroy()
    return out


def _reference_neighbours(surface: ClothSurface) -> np.ndarray:
    """Sorted keys p T + t of the vertex-triangle pairs closer than EXCLUSION t in the reference (ipctk)."""
    pairs = ipctk_pairs(surface.reference, surface.triangles, surface.triangle_index, surface.triangles,
                        EXCLUSION * THICKNESS)
    return np.sort(pairs.vertex * len(surface.triangles) + pairs.triangle)


def _smallest_distance(surface: ClothSurface, x: np.ndarray, neighbours: np.ndarray) -> float:
    """Smallest distance [m] of a vertex to a triangle that is not its neighbour at the positions x (ipctk's
    candidates, the numpy closest point), THICKNESS if none is closer."""
    pairs = ipctk_pairs(x, surface.triangles, surface.triangle_index, surface.triangles, THICKNESS)
    far = ~np.isin(pairs.vertex * len(surface.triangles) + pairs.triangle, neighbours)
    return float(pairs.distance[far].min()) if far.any() else THICKNESS


@case("self-contact", mpi=True)
def self_contact_case() -> list[CaseResult]:
    """The fold, the press and the slide of the module docstring, and the fold without self-contact."""
    name = "self-contact"
    with Timer() as timer:
        folded, loose = fold(True), fold(False)
        pressed, slid = press(), slide()
    wall = timer.elapsed
    rows = [
        CaseResult(name, f"fold: most intersecting triangle pairs over {FOLD_RECORDS} records (k-d tree, Moller, libigl; a "
                   f"contact that holds the layers apart leaves none)", max(folded["intersections"]), 0.0,
                   float(max(folded["intersections"])), 0.0, max(folded["intersections"]) == 0, folded["ndofs"],
                   wall),
        CaseResult(name, "fold: smallest distance of a vertex to a non-neighbouring triangle over the records [m] >= "
                   "half the thickness (the contact keeps d_c = t; penetration of the penalty << t / 2)",
                   min(folded["min_distance"]), 0.5 * THICKNESS, float("nan"), float("nan"),
                   min(folded["min_distance"]) >= 0.5 * THICKNESS, folded["ndofs"], wall),
        CaseResult(name, "fold: mean height of the upper leg at the end [m] < a quarter of its start 2 R (it lies on "
                   "the lower leg)", folded["upper_height"], 0.5 * _fold_radius(), float("nan"), float("nan"),
                   folded["upper_height"] < 0.5 * _fold_radius(), folded["ndofs"], wall),
        result(name, "press: contact force on the upper sheet [N] = the applied pressure load (static equilibrium, "
               "mean over the last third; 1 %)", pressed["contact"][2], -pressed["load"][2], 0.01, pressed["ndofs"],
               wall),
        result(name, "slide: friction from the upper sheet's momentum balance [N] = mu N (Coulomb while sliding; "
               "2 %)", slid["momentum_friction"], slid["mu_N"], 0.02, slid["ndofs"], wall),
        CaseResult(name, "fold without self-contact: most intersecting triangle pairs > 0 (the check bites)",
                   max(loose["intersections"]), 0.0, float("nan"), float("nan"), max(loose["intersections"]) > 0,
                   loose["ndofs"], wall),
    ]
    return rows + strip_rows(name)


def _fold_radius() -> float:
    """R [m] of the reference fold."""
    return (FOLD_CELLS[0] - 2 * FOLD_LEG) * SIDE / FOLD_CELLS[0] / np.pi
