"""Every object a scene builds, from its validated, parsed data: the fabric, the mesh, the static and dynamic
scenes' shell model (supports, loads), obstacles, integrator and monitors, the wear scenes' runs (the tube sleeve
by its route, the compression sleeve, any garment on the engine) and the sleeve's configuration, and the checks
that need objects before meshing (the explicit critical step, the wear scene's body, motion and pattern). `load`
and `validate` are the entry points of fabricfem.scenes; scenes.static, scenes.dynamic and scenes.run only run."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem.body.arm import ArmDimensions
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.skin import Skin
from fabricfem.contact.obstacles import Plane, RoundedBox, table_top
from fabricfem.contact.sewing_lines import sewn_through
from fabricfem.dynamics import CentralDifference, NewmarkIntegrator, critical_time_step, node_monitor, stability
from fabricfem.dynamics.ts import GeneralizedAlphaIntegrator
from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.meshes import plate, tube
from fabricfem.scenes import schema, wear
from fabricfem.scenes.contract import WearScene
from fabricfem.scenes.garments import attach_layers, check_layer_gaps
from fabricfem.scenes.schema import ALL_NODES, Scene, SceneError
from fabricfem.scenes.sections import (
    DynamicsSection,
    FabricSection,
    MeshSection,
    ModelSection,
    MonitorSection,
    OutputSection,
    SceneSection,
    section,
)
from fabricfem.shell import ShellModel
from fabricfem.solvers.system import base_model
from fabricfem.wear.compression import compression_run
from fabricfem.wear.config import SECTIONS, FabricSpec, SleeveConfig, TubeSpec, check_fit
from fabricfem.wear.garment import GarmentRun, build_garment_run
from fabricfem.wear.run import ROUTES
from fabricfem.wear.sleeve import tube_flexion_run


def build_fabric(spec: dict) -> Fabric:
    """The Fabric of a [fabric] table (FabricSection); SceneError naming the key."""
    f = section(FabricSection, spec)
    law = None
    if f.bending_law == "kawabata":
        if f.kawabata_coefficients is None:
            raise SceneError("fabric: bending_law = 'kawabata' needs kawabata_coefficients")
        law = KawabataBending(tuple(float(a) for a in f.kawabata_coefficients))
    elif f.bending_law == "square_root":
        if f.B0 is None or f.kappa0 is None:
            raise SceneError("fabric: bending_law = 'square_root' needs B0 and kappa0")
        law = SquareRootBending(float(f.B0), float(f.kappa0))
    elif f.bending_law is not None:
        raise SceneError(f"fabric.bending_law: unknown law {f.bending_law!r}; allowed: 'kawabata', 'square_root'")
    try:
        return Fabric(E1=float(f.E1), E2=float(f.E2), G12=float(f.G12), nu12=float(f.nu12),
                      thickness=float(f.thickness), density=float(f.density), G13=f.G13,
                      bending_rigidity=tuple(f.bending_rigidity) if f.bending_rigidity else None,
                      bending_law=law, name=f.name)
    except ValueError as exc:
        raise SceneError(f"fabric: {exc}") from None


def mesh_section(spec: dict) -> MeshSection:
    """The MeshSection of a [mesh] table (a sleeve's tube keys, TubeSpec's, are left to sleeve_config)."""
    return section(MeshSection, {k: v for k, v in spec.items() if k in MeshSection.__dataclass_fields__})


def build_mesh(spec: dict, comm):
    """The FabricMesh of a [mesh] table (MeshSection): a plate or a tube."""
    m = mesh_section(spec)
    if m.type == "plate":
        return plate(m.lx, m.ly, m.nx, m.ny, cell=m.cell, structured=m.structured, comm=comm)
    return tube(m.length, m.radius, m.n_around, m.n_along, cell=m.cell, order=m.order, comm=comm)


def mesh_spacing(mesh: dict) -> float | None:
    """Smallest edge length h_min [m] of a structured mesh from its spec (None when unknown before meshing):
    plate min(lx / nx, ly / ny) (triangle diagonals are longer), tube min(chord 2 R sin(pi / n_around),
    length / n_along)."""
    if mesh["type"] == "plate":
        if not mesh_section(mesh).structured:
            return None
        return min(mesh["lx"] / mesh["nx"], mesh["ly"] / mesh["ny"])
    return min(2.0 * mesh["radius"] * math.sin(math.pi / mesh["n_around"]), mesh["length"] / mesh["n_along"])


def critical_time_step_estimate(data: dict) -> float | None:
    """dt_crit [s] of central differences before meshing: fabricfem.dynamics.stability's estimate (thesis
    eqs. 2.86-2.87 extended) with h_min from the mesh spec; None when h_min is unknown (unstructured)."""
    h_min = mesh_spacing(data["mesh"])
    if h_min is None:
        return None
    omega = stability.element_frequency(build_fabric(data["fabric"]), mesh_section(data["mesh"]).cell, h_min,
                                        section(ModelSection, data.get("model")).kind)
    rayleigh = section(DynamicsSection, data["dynamics"]).rayleigh
    return stability.critical_time_step(None, tuple(rayleigh), omega_max=omega)  # eq. 2.86


# the part of SleeveConfig each parameter belongs to -> the wear scene's section that sets it
_SLEEVE_SECTION_OF = {"tube": "garment", "material": "fabric", "motion": "motion", "contact": "contact",
                      "route": "route"}


def tube_spec(wear: WearScene) -> TubeSpec:
    """The TubeSpec of a tube garment: [garment] length, radius, n_around, n_along, quadrature, hold_rotations
    (ValueError naming a refused value)."""
    g = wear.garment
    return TubeSpec(length=g.length, radius=g.radius, n_around=g.n_around, n_along=g.n_along,
                    quadrature=tuple(g.quadrature) if g.quadrature else TubeSpec.quadrature,
                    hold_rotations=g.hold_rotations)


def fitting_tube(wear: WearScene) -> TubeSpec:
    """The TubeSpec of an arm-in-tube scene whose arm starts inside the tube (SceneError naming garment.radius or
    the arm's girth otherwise)."""
    try:
        tube = tube_spec(wear)
        check_fit(tube.radius, wear.arm)
    except ValueError as exc:
        raise SceneError(f"garment.{exc}") from None
    return tube


def sleeve_config(wear: WearScene) -> SleeveConfig:
    """The SleeveConfig of an arm-in-tube wear scene (WearScene.is_tube_flexion) for the sleeve's Newton routes
    (quasistatic, implicit: E1 = E2); its checks (fabricfem.wear.config) become SceneErrors naming the section and
    key."""
    fabric = wear.fabric
    if wear.catalogue is not None:
        material = FabricSpec(fabric_name=wear.catalogue)
    else:
        build_fabric(dict(fabric))                    # the values' own checks first (sign, range, finite)
        if fabric["E1"] != fabric["E2"]:
            raise SceneError(f"fabric.E2: the sleeve's Newton routes use E1 = E2 [Man2006, sec. 5.3], got E1 = "
                             f"{fabric['E1']} and E2 = {fabric['E2']} (the explicit route takes any fabric)")
        material = FabricSpec(E=fabric["E1"], G=fabric["G12"], nu12=fabric["nu12"], thickness=fabric["thickness"],
                              density=section(FabricSection, dict(fabric)).density)
    try:
        return SleeveConfig(tube=tube_spec(wear), material=material, motion=wear.flexion, contact=wear.contact,
                            route=wear.route, arm=wear.arm, name=wear.scene.name or "sleeve")
    except ValueError as exc:
        message = str(exc)
        key = message.split(" ")[0].rstrip(":")
        part = next((p for p, cls in SECTIONS.items() if key in cls.__dataclass_fields__), None)
        where = (f"{_SLEEVE_SECTION_OF[part]}.{key}" if part else
                 f"body.{key.split('.')[-1]}" if key.startswith("arm.") or key in ArmDimensions.__dataclass_fields__
                 else "body" if "arm" in message else "scene")
        raise SceneError(f"{where}: {message}") from None


# bytes per degree of freedom of a shell solve (assembly, MUMPS LU fill, outputs): an order-of-magnitude bound used
# only to refuse meshes far too large for the machine before meshing
BYTES_PER_DOF = 20e3


def estimated_dofs(mesh: dict, model_kind: str = "naghdi") -> int:
    """Degrees of freedom of a plate or tube scene before meshing: P2 nodes x (5 naghdi, 3 membrane)."""
    if mesh["type"] == "plate":
        nodes = (2 * mesh["nx"] + 1) * (2 * mesh["ny"] + 1)
    else:
        nodes = 2 * mesh["n_around"] * (2 * mesh["n_along"] + 1)
    return int(nodes * (5 if model_kind == "naghdi" else 3))


def estimated_cost(scene: Scene) -> float | None:
    """Relative cost of a scene before meshing: dofs x time steps (dynamic: end_time / dt, dt = "auto" scaled
    by the cell size / dt_fraction), dofs^1.5 for a static solve (direct solver); None when unknown (wear)."""
    data = scene.data
    if scene.kind not in ("static", "dynamic"):
        return None
    dofs = estimated_dofs(data["mesh"], section(ModelSection, data.get("model")).kind)
    if scene.kind == "static":
        return dofs ** 1.5
    d = section(DynamicsSection, data["dynamics"])
    if d.dt != "auto":
        return dofs * d.end_time / d.dt
    m = mesh_section(data["mesh"])
    cells = max(m.nx or 0, m.ny or 0, m.n_around or 0, m.n_along or 0)
    return dofs * d.end_time * cells / d.dt_fraction


def check_size(data: dict) -> None:
    """Refuse, with the numbers, a mesh whose estimated memory exceeds the machine's physical memory (unless
    mesh.allow_large)."""
    mesh = data["mesh"]
    dofs = estimated_dofs(mesh, section(ModelSection, data.get("model")).kind)
    need, have = dofs * BYTES_PER_DOF, os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    if need > have and not mesh_section(mesh).allow_large:
        raise SceneError(f"mesh: about {dofs:.3g} dofs need about {need / 2**30:.0f} GiB, more than this machine's "
                         f"{have / 2**30:.0f} GiB; use fewer cells or set mesh.allow_large = true")


def check_objects(scene: Scene) -> None:
    """Checks that need objects: an explicit dynamic scene's numeric dt must not exceed the critical time step
    (unless dynamics.force = true); a wear scene's fabric, body, motion (the file is read), monitors and pattern
    (read and checked, not meshed) are built (relative file names from the scene's path)."""
    if scene.kind == "wear":
        check_wear_objects(scene.parsed, scene.path)
        return
    data = scene.data
    check_size(data)
    build_fabric(data["fabric"])                      # every fabric value checked before meshing
    if scene.kind != "dynamic":
        return
    d = scene.parsed.dynamics
    if d.integrator != "explicit" or isinstance(d.dt, str) or d.force:
        return
    dt, dt_crit = d.dt, critical_time_step_estimate(data)
    if dt_crit is not None and dt > dt_crit:
        raise SceneError(f"dynamics.dt: {dt:.6g} s exceeds the critical time step {dt_crit:.6g} s of the explicit "
                         f"integrator (ratio {dt / dt_crit:.3g}, [Man2006, eqs. 2.86-2.87]); use a smaller dt, "
                         f"dt = \"auto\", or force = true")


def validate(data: dict, source: str = "scene", path: Path | None = None) -> Scene:
    """schema.validate, then the object checks (`path`: the scene file, for relative file names); SceneError
    names the key."""
    scene = dataclasses.replace(schema.validate(data, source), path=path)
    check_objects(scene)
    return scene


def load(path: str | Path) -> Scene:
    """Read a scene file and validate it completely (data and objects) before anything is meshed."""
    scene = schema.load(path)
    check_objects(scene)
    return scene


def check_wear_objects(wear_scene: WearScene, path: Path | None) -> None:
    """The object checks of a wear scene before meshing (module docstring of fabricfem.scenes.wear)."""
    if wear_scene.route.solver != "explicit":
        sleeve_config(wear_scene)                     # the Newton routes' configuration and its checks
        return
    if wear_scene.is_tube_flexion:
        fitting_tube(wear_scene)
    fabric = wear.wear_fabric(wear_scene, build_fabric)
    if not fabric.density > 0.0:
        raise SceneError(f"fabric.density: the explicit engine needs a positive density [kg/m^3], got {fabric.density}")
    if wear_scene.layered:
        check_layer_gaps(wear_scene, fabric.thickness)
    wear.check_window(wear_scene, wear.plan(wear_scene, fabric, path))
    wear.check_garment(wear_scene, path)


def scene_name(scene: Scene) -> str:
    """[scene] name, else the file's stem, else "scene"."""
    return section(SceneSection, scene.get("scene")).name or (scene.path.stem if scene.path is not None else "scene")


def output_dir(scene: Scene) -> Path:
    """[output] dir, else results/<scene name>."""
    return Path(section(OutputSection, scene.get("output")).dir or f"results/{scene_name(scene)}")


def scene_sha256(scene: Scene) -> str:
    """SHA-256 of the scene's data (canonical JSON): identifies the scene a summary belongs to."""
    return hashlib.sha256(json.dumps(scene.data, sort_keys=True, default=str).encode()).hexdigest()


# steps between the explicit route's estimates of the current largest frequency (CentralDifference
# step_check_every): 20 kept the corner-pinned cloth with bending (16 x 16) stable at dt_fraction 0.9, 50 did not
# (docs/findings/2026-11-27-safe-step.md); off with force = true (a step above the limit asked for, e.g. to study
# the blow-up check)
STEP_CHECK_EVERY = 20


def _components(values, n: int, where: str):
    if values is None:
        return None
    if len(values) != n:
        raise SceneError(f"{where}: expected {n} components, got {values!r}")
    out = []
    for v in values:
        if v == "free":
            out.append(None)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(float(v))
        else:
            raise SceneError(f"{where}: components are numbers or \"free\", got {v!r}")
    return out


def _node_locator(model: ShellModel, point, where: str):
    """Geometric locator of the mesh node at `point` (SceneError naming `where` if there is none)."""
    try:
        model.owned_node_dof(point, "u", 0)
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None
    p = np.asarray(point, dtype=float)
    return lambda x: np.linalg.norm(x.T - p, axis=1) < 1e-8 * max(1.0, float(np.abs(p).max()))


def build_model(scene: Scene, comm=MPI.COMM_WORLD) -> ShellModel:
    fabric = build_fabric(scene["fabric"])
    model_spec = section(ModelSection, scene.get("model"))
    kind = model_spec.kind
    fmesh = build_mesh(scene["mesh"], comm)
    model = ShellModel(fmesh, fabric, model=kind, rebase=model_spec.rebase, psri_degrees=model_spec.psri_degrees)
    for i, support in enumerate(scene.get("support", [])):
        if "point" in support:
            where = _node_locator(model, support["point"], f"support[{i}].point")
        elif support["edge"] == ALL_NODES:
            where = lambda x: np.full(x.shape[1], True)   # noqa: E731 (every node)
        elif support["edge"] not in fmesh.tags:
            raise SceneError(f"support[{i}].edge: unknown edge {support['edge']!r}; available: {sorted(fmesh.tags)}")
        else:
            where = support["edge"]
        try:
            model.constrain(where, u=_components(support.get("u"), 3, f"support[{i}].u"),
                            theta=_components(support.get("theta"), 2, f"support[{i}].theta"))
        except ValueError as exc:
            if isinstance(exc, SceneError):
                raise
            raise SceneError(f"support[{i}]: {exc}") from None
    if "gravity" in scene.get("dynamics", {}):
        model.add_gravity(scene["dynamics"]["gravity"])
    for i, load in enumerate(scene.get("load", [])):
        where = f"load[{i}]"
        kind, value = load["type"], load.get("value")
        edge = load.get("edge")
        if kind in ("edge_traction", "edge_moment") and edge not in fmesh.tags:
            raise SceneError(f"{where}.edge: unknown edge {edge!r}; available: {sorted(fmesh.tags)}")
        if kind == "gravity":
            model.add_gravity(value if value is not None else (0.0, 0.0, -9.81))
        elif kind == "body_force":
            model.add_body_force(value)
        elif kind == "edge_traction":
            model.add_edge_traction(edge, value)
        elif kind == "pressure":
            model.add_pressure(float(value))
        elif kind == "edge_moment":
            model.add_edge_moment(edge, value)
        elif kind == "point":
            if "point" not in load:
                raise SceneError(f"{where}: a point load needs 'point' = [x, y, z]")
            model.add_point_load(load["point"], value)
    return model


def build_obstacles(spec: list[dict]) -> list:
    """Plane / RoundedBox obstacles of [[dynamics.obstacles]] (validated by fabricfem.scenes.schema), SI units."""
    out = []
    for i, o in enumerate(spec):
        try:
            if o["type"] == "plane":
                out.append(Plane(o["point"], o["normal"]))
            elif o["type"] == "box":
                out.append(RoundedBox(o["lower"], o["upper"], float(o["radius"])))
            else:
                out.append(table_top(o["center"], float(o["half_x"]), float(o["half_y"]), float(o["height"]),
                                     float(o["fillet_radius"])))
        except ValueError as exc:
            raise SceneError(f"dynamics.obstacles[{i}]: {exc}") from None
    return out


def _load_function(ramp_time: float):
    """lambda(t) = min(t / ramp_time, 1) (1 at once when ramp_time = 0)."""
    if ramp_time > 0.0:
        return lambda t: min(t / ramp_time, 1.0)
    return 1.0


# [dynamics] integrator -> its class (build_integrator)
INTEGRATORS = {"explicit": CentralDifference, "newmark": NewmarkIntegrator,
               "generalized-alpha": GeneralizedAlphaIntegrator}


def build_integrator(spec: dict, model):
    """(integrator, n_steps, dt [s], dt_crit [s] or None) for a [dynamics] section; dt is end_time / n_steps.
    `model`: the ShellModel or a CompositeSystem of it (fabricfem.solvers.system, e.g. with obstacle contact)."""
    d = section(DynamicsSection, spec)
    kind = d.integrator
    end_time = float(d.end_time)
    rayleigh = tuple(float(c) for c in d.rayleigh)
    common = dict(load_factor=_load_function(float(d.ramp_time)), rayleigh=rayleigh, air_drag=float(d.air_drag))
    dt_crit = critical_time_step(base_model(model), rayleigh) if kind == "explicit" else None
    dt = float(d.dt_fraction) * dt_crit if d.dt == "auto" else float(d.dt)
    n_steps = max(1, math.ceil(end_time / dt * (1.0 - 1e-12)))
    dt = end_time / n_steps
    if kind == "explicit":
        force = bool(d.force)
        if dt > dt_crit and not force:
            raise SceneError(f"dynamics.dt: {dt:.6g} s exceeds the critical time step {dt_crit:.6g} s of this mesh "
                             f"(ratio {dt / dt_crit:.3g}, [Man2006, eqs. 2.86-2.87]); use a smaller dt or force = true")
        integrator = CentralDifference(model, dt, force=force, dt_crit=dt_crit,
                                       step_check_every=None if force else STEP_CHECK_EVERY, **common)
    elif kind == "newmark":
        integrator = NewmarkIntegrator(model, dt, beta=float(d.beta), gamma=float(d.gamma), lumped=bool(d.lumped),
                                       **common)
    else:
        integrator = GeneralizedAlphaIntegrator(model, dt, rho_inf=float(d.rho_inf), lumped=bool(d.lumped), **common)
    return integrator, n_steps, dt, dt_crit


class StrainMeter:
    """Vertex Green strains (patch averages of fabricfem.dynamics.strain_limit) once per recorded step."""

    def __init__(self, projection, integrator):
        self.projection, self.integrator = projection, integrator
        self._step, self._summary = None, None

    def summary(self) -> dict[str, float]:
        if self._step != self.integrator.step_count:
            self._summary = self.projection.strain_summary()
            self._step = self.integrator.step_count
        return self._summary

    def max_strain(self) -> float:
        s = self.summary()
        return max(s["max_warp"], s["max_weft"])


def _max_displacement(model: ShellModel) -> float:
    """max over nodes of |u| [m], all ranks."""
    u = model.displacement().x.array.reshape(-1, 3)
    local = float(np.linalg.norm(u, axis=1).max(initial=0.0))
    return model.comm.allreduce(local, op=MPI.MAX)


def monitor_unit(table: dict) -> str:
    """The unit of a [[dynamics.monitors]] table's values: a strain's "-", a displacement's (u, max_displacement)
    "m", a rotation's (theta) "rad"."""
    m = section(MonitorSection, table)
    if m.quantity is not None:
        return "m" if m.quantity == "max_displacement" else "-"
    return "m" if m.field == "u" else "rad"


def build_monitors(spec: list[dict], model: ShellModel, meter: StrainMeter) -> dict:
    """{name: callable} of [[dynamics.monitors]] (point values on all ranks, global quantities)."""
    quantities = {"max_warp_strain": lambda: meter.summary()["max_warp"],
                  "max_weft_strain": lambda: meter.summary()["max_weft"],
                  "mean_warp_strain": lambda: meter.summary()["mean_warp"],
                  "mean_weft_strain": lambda: meter.summary()["mean_weft"],
                  "max_displacement": lambda: _max_displacement(model)}
    monitors = {}
    for i, table in enumerate(spec):
        m = section(MonitorSection, table)
        if m.quantity is not None:
            monitors[m.name] = quantities[m.quantity]
            continue
        try:
            monitors[m.name] = node_monitor(model, m.point, m.field,
                                            m.component if m.component is not None else 2 if m.field == "u" else 0)
        except ValueError as exc:
            raise SceneError(f"dynamics.monitors[{i}].point: {exc}") from None
    return monitors


def build_wear_run(scene: Scene, comm=MPI.COMM_WORLD):
    """The WearRun of a wear scene, its headline, the render coordinates and [output]: an arm in a tube flexing at
    the elbow by its [route] solver (fabricfem.wear.sleeve.tube_flexion_run on the explicit engine, the Newton
    routes of fabricfem.wear.run.ROUTES), any other garment on the explicit engine (`build_garment_run`)."""
    parsed = scene.parsed
    if parsed.is_tube_flexion and not parsed.layered:
        run = tube_scene_run(scene, comm)
    elif parsed.is_tube_on_limb and not parsed.layered:
        run = limb_scene_run(scene, comm)
    else:
        run = garment_scene_run(scene, comm)
    if isinstance(run, GarmentRun):
        run.sensor_diameter = parsed.output.sensor_diameter
    render_at = parsed.output.render_at
    if render_at is None and isinstance(run, GarmentRun):
        start, end = run.motion_start, run.duration
        render_at = [run.axis_at(start + f * (end - start)) if run.axis is not None else f * end
                     for f in (1 / 3, 2 / 3, 1.0)]
    elif render_at is None:
        render_at = [f * parsed.flexion.final_angle for f in (1 / 3, 2 / 3, 1.0)]
    headline = (f"{run.name}: {run.model.ndofs} dofs, body {list(run.body.segments)}, {comm.size} rank(s); "
                f"mu = {parsed.contact.friction}; {run.describe()}")
    return run, headline, render_at, parsed.output


def tube_scene_run(scene: Scene, comm):
    """The arm-in-tube sleeve of a wear scene by its [route] solver: the explicit engine's run of the scene's
    sections (any fabric) or a Newton route of its SleeveConfig (E1 = E2); both on the arm's blended skin of the
    scene's [body] blend_width [m]."""
    parsed = scene.parsed
    if parsed.route.solver != "explicit":
        return ROUTES[parsed.route.solver](sleeve_config(parsed), comm, blend_width=parsed.body.blend_width)
    return tube_flexion_run(scene_name(scene), wear.wear_fabric(parsed, build_fabric), fitting_tube(parsed), parsed.arm,
                            parsed.flexion, parsed.contact, parsed.route, comm, blend_width=parsed.body.blend_width)


def scene_limb(parsed: WearScene) -> Ellipsoid:
    """The limb of a limb body: one ellipsoid along x with [body] center and radii [m]."""
    return Ellipsoid(np.array(parsed.body.center, dtype=float), np.eye(3), np.array(parsed.body.radii, dtype=float))


def limb_scene_run(scene: Scene, comm) -> GarmentRun:
    """A tube grown onto a limb (the compression sleeve, fabricfem.wear.compression.compression_run): the limb
    grows from [donning] start over [donning] time [s], then [motion] duration [s] of rest."""
    parsed = scene.parsed
    fabric = wear.wear_fabric(parsed, build_fabric)
    plan = wear.plan(parsed, fabric, scene.path)
    if parsed.donning.method != "grow" or parsed.donning.start is None:
        raise SceneError("donning.method: a tube on a limb is put on by growing the limb: write [donning] method = "
                         "\"grow\" with start (its starting size) and time [s]")
    fmesh = wear.garment_mesh(parsed, scene.path, comm)[0]
    try:
        return compression_run(fmesh, fabric, scene_limb(parsed), parsed.donning.start, parsed.donning.time,
                               plan.timeline.motion_length(plan.body.kinematics), plan.timeline.record_time, comm,
                               scene_name(scene), plan.settings)
    except ValueError as exc:
        raise SceneError(f"body: {exc}") from None


def refuse_sewing_through(fmesh, seams, scene_path: Path | None, comm) -> None:
    """With self-contact, a seam sewn through another panel cannot close (fabricfem.contact.sewing_lines): SceneError
    naming the seams and their counts, before the time loop."""
    crossed = [(seam.name, int(c.sum()), len(c)) for seam, c in zip(seams, sewn_through(fmesh, seams, comm)) if c.any()]
    if crossed:
        listed = ", ".join(f"{name} ({n} of {total})" for name, n, total in crossed)
        raise SceneError(f"garment: with contact.self_contact, stitches of {listed} are sewn through another panel, "
                         f"so the seams cannot close; place the panels so that each seam closes in the open (e.g. "
                         f"garment.wrap; python -m fabricfem.studies.sewing_paths {scene_path or 'SCENE'} lists them)")


def garment_scene_run(scene: Scene, comm, skin: Skin | None = None) -> GarmentRun:
    """The explicit engine's GarmentRun of a wear scene (fabricfem.scenes.wear.plan and garment_mesh); `skin`: a
    Skin of the scene's body (fabricfem.body.skin) instead of the scene's own (a benchmark's variant)."""
    parsed = scene.parsed
    fabric = wear.wear_fabric(parsed, build_fabric)
    plan = wear.plan(parsed, fabric, scene.path)
    fmesh, seams, holds, pattern_garment = wear.garment_mesh(parsed, scene.path, comm)
    if plan.handles and pattern_garment is None:
        raise SceneError("donning: pull_edges and belt_edges name pattern edges; this garment is a tube")
    handles = wear.edge_handles(plan.handles, pattern_garment) if plan.handles else []
    if plan.contact.self_contact and seams and parsed.garment.sewing_time > 0.0:
        refuse_sewing_through(fmesh, seams, scene.path, comm)
    garment = parsed.garment
    run = build_garment_run(scene_name(scene), fmesh, fabric, plan.body, seams=seams, holds=holds,
                            torques=plan.torques, timeline=plan.timeline, settings=plan.settings,
                            contact_method=plan.contact.method or "lagrange", friction=plan.contact.friction,
                            penalty=plan.contact.penalty,
                            psri_degrees=tuple(garment.quadrature) if garment.quadrature else (4, 2),
                            axis=plan.axis, handles=handles, blend_width=parsed.body.blend_width,
                            skin=plan.skin if skin is None else skin,
                            self_contact=plan.contact.self_contact,
                            self_contact_distance=plan.contact.self_contact_distance,
                            self_friction=plan.contact.self_friction,
                            self_contact_passes=plan.contact.self_contact_passes,
                            impact_zones=plan.contact.impact_zones)
    if parsed.layered:           # several garments: their monitors, after the start state's checks
        attach_layers(run, parsed)
    return run
