"""From validated scene data to objects: fabric, mesh, and the checks that need them (the explicit
critical time step before meshing). `load` and `validate` are the entry points of fabricfem.scenes."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from pathlib import Path

from fabricfem.body.arm import ArmDimensions
from fabricfem.dynamics import stability
from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.meshes import plate, tube
from fabricfem.scenes import schema, wear
from fabricfem.scenes.contract import WearScene
from fabricfem.scenes.schema import Scene, SceneError
from fabricfem.scenes.sections import (
    DynamicsSection,
    FabricSection,
    MeshSection,
    ModelSection,
    OutputSection,
    SceneSection,
    section,
)
from fabricfem.wear.config import SECTIONS, FabricSpec, SleeveConfig, TubeSpec, check_fit


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
        try:
            check_fit(tube_spec(wear_scene).radius, wear_scene.arm)   # the arm starts inside the tube
        except ValueError as exc:
            raise SceneError(f"garment.{exc}") from None
    fabric = wear.wear_fabric(wear_scene, build_fabric)
    if not fabric.density > 0.0:
        raise SceneError(f"fabric.density: the explicit engine needs a positive density [kg/m^3], got {fabric.density}")
    wear.check_window(wear_scene, wear.plan(wear_scene, fabric, path))
    wear.check_garment(wear_scene, path)


def scene_name(scene: Scene) -> str:
    """[scene] name, else the file's stem, else "scene"."""
    return section(SceneSection, scene.get("scene")).name or (scene.path.stem if scene.path is not None else "scene")


def output_dir(scene: Scene) -> Path:
    """[output] dir, else results/<scene name>."""
    return Path(section(OutputSection, scene.get("output")).dir or f"results/{scene_name(scene)}")


# ---------------------------------------------------------------------------------------- dynamic scenes


def scene_sha256(scene: Scene) -> str:
    """SHA-256 of the scene's data (canonical JSON): identifies the scene a summary belongs to."""
    return hashlib.sha256(json.dumps(scene.data, sort_keys=True, default=str).encode()).hexdigest()
