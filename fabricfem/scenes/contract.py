"""The scene contract: a scene file parsed once, by kind, into a frozen dataclass of typed sections.

`parse(data, kind)` turns the validated TOML data of a scene into a `StaticScene`, `DynamicScene` or `WearScene`
whose fields are the section dataclasses (fabricfem.scenes.sections, fabricfem.scenes.wear_sections,
fabricfem.wear.config, fabricfem.body): every parameter, its type, default and unit declared once, there. The
builders (fabricfem.scenes.build, fabricfem.scenes.wear, fabricfem.scenes.static, fabricfem.scenes.dynamic) read
these, not the raw tables. Which sections a kind has, and which dataclasses declare each one's keys, is the one
schema table `SECTIONS_OF`; fabricfem.scenes.schema checks a file against it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Mapping

from fabricfem.body.arm import ArmDimensions
from fabricfem.body.human import HUMAN_DIMENSIONS
from fabricfem.body.lower_body import LowerBodyDimensions
from fabricfem.scenes.errors import SceneError
from fabricfem.scenes.sections import (
    AccuracySection,
    DynamicsSection,
    FabricSection,
    LoadSection,
    MeshSection,
    ModelSection,
    MonitorSection,
    ObstacleSection,
    OutputSection,
    SceneSection,
    SolverSection,
    SupportSection,
    from_table,
)
from fabricfem.scenes.wear_sections import (
    GarmentSection,
    TorqueSection,
    WearBodySection,
    WearDonningSection,
    WearFabricSection,
    WearMotionSection,
    WearRouteSection,
    first_garment,
    garment_tables,
)
from fabricfem.wear.config import ContactSpec, FlexionSpec, RouteSpec
from fabricfem.wear.verdict import Bounds

_COMMON = {"scene": (SceneSection,), "fabric": (FabricSection,), "output": (OutputSection,),
           "accuracy": (AccuracySection,)}
# kind -> section -> the dataclasses that declare its keys (a key belongs to the first that has it)
SECTIONS_OF: dict[str, dict[str, tuple]] = {
    "static": {**_COMMON, "mesh": (MeshSection,), "model": (ModelSection,), "support": (SupportSection,),
               "load": (LoadSection,), "solver": (SolverSection,)},
    "dynamic": {**_COMMON, "mesh": (MeshSection,), "model": (ModelSection,), "support": (SupportSection,),
                "load": (LoadSection,), "dynamics": (DynamicsSection,), "dynamics.obstacles": (ObstacleSection,),
                "dynamics.monitors": (MonitorSection,)},
    "wear": {**_COMMON, "fabric": (FabricSection, WearFabricSection), "garment": (GarmentSection,),
             "body": (WearBodySection, ArmDimensions, LowerBodyDimensions),
             "motion": (WearMotionSection, FlexionSpec), "donning": (WearDonningSection,), "contact": (ContactSpec,),
             "route": (RouteSpec, WearRouteSection), "torque": (TorqueSection,), "checks": (Bounds,)},
}
LIST_SECTIONS = {"support", "load", "torque"}           # arrays of tables ([[load]])
TABLE_OR_LIST = {"garment"}                            # a table or an array of tables ([garment] or [[garment]])
REQUIRED_OF = {"static": ("scene", "mesh", "fabric", "solver"), "dynamic": ("scene", "mesh", "fabric", "dynamics"),
               "wear": ("scene", "garment", "fabric", "body", "motion")}


def _own(cls, table: Mapping) -> dict:
    """The keys of `table` that are fields of dataclass `cls`."""
    return {k: v for k, v in table.items() if k in cls.__dataclass_fields__}


def _part(cls, table: Mapping | None, where: str):
    """`cls` from its own keys of `table` (SceneError naming the section when the dataclass refuses a value)."""
    try:
        return from_table(cls, _own(cls, table or {}))
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class ShellScene:
    """What static and dynamic scenes share: a shell meshed from [mesh], of [fabric], supported and loaded."""

    scene: SceneSection
    mesh: MeshSection
    fabric: Mapping                 # the [fabric] table (fabricfem.scenes.build.build_fabric)
    model: ModelSection
    supports: tuple[SupportSection, ...]
    loads: tuple[LoadSection, ...]
    output: OutputSection
    accuracy: AccuracySection


@dataclass(frozen=True)
class StaticScene(ShellScene):
    """A static scene: the shell solved by load stepping to [solver]'s targets."""

    solver: SolverSection


@dataclass(frozen=True)
class DynamicScene(ShellScene):
    """A dynamic scene: the shell integrated in time from rest ([dynamics], obstacles, monitors)."""

    dynamics: DynamicsSection


@dataclass(frozen=True)
class WearScene:
    """A wear scene: a garment on a moving wearer. `arm` / `lower_body`: the body's dimensions when it is that
    preset; `flexion`: the elbow flexion's parameters when the motion is one; `end_time` [s]: where the explicit
    engine stops (None: the whole scene)."""

    scene: SceneSection
    garment: GarmentSection
    fabric: Mapping
    catalogue: str | None
    body: WearBodySection
    arm: ArmDimensions | None
    lower_body: LowerBodyDimensions | None
    motion: WearMotionSection
    flexion: FlexionSpec | None
    settle_time: float              # s, rest of the body in its start pose before the motion
    donning: WearDonningSection
    contact: ContactSpec
    route: RouteSpec
    end_time: float | None
    torques: tuple[TorqueSection, ...]
    output: OutputSection
    accuracy: AccuracySection
    checks: Bounds                  # the bounds of the run's plausibility checks (fabricfem.wear.verdict)
    failure_strain: float           # [fabric] failure_strain: the strain check's bound [-]
    garments: tuple[GarmentSection, ...] = ()   # every garment, inside out (`garment`: the first, the innermost)

    @property
    def layered(self) -> bool:
        """Several garments worn one over the other ([[garment]] with more than one entry)."""
        return len(self.garments) > 1

    @property
    def is_tube_flexion(self) -> bool:
        """An arm in a tube sleeve flexing at the elbow (the sleeve of [Man2006, sec. 5.3])."""
        return self.garment.builder == "tube" and self.arm is not None and self.flexion is not None

    @property
    def is_tube_on_limb(self) -> bool:
        """A tube grown onto a limb (the compression sleeve, fabricfem.wear.compression)."""
        return self.garment.builder == "tube" and self.body.type == "limb"


def _frozen(table: Mapping | None) -> Mapping:
    return MappingProxyType(dict(table or {}))


def _shell_parts(data: Mapping) -> dict:
    return {"scene": _part(SceneSection, data.get("scene"), "scene"),
            "mesh": _part(MeshSection, data["mesh"], "mesh"), "fabric": _frozen(data["fabric"]),
            "model": _part(ModelSection, data.get("model"), "model"),
            "supports": tuple(_part(SupportSection, t, f"support[{i}]") for i, t in enumerate(data.get("support", []))),
            "loads": tuple(_part(LoadSection, t, f"load[{i}]") for i, t in enumerate(data.get("load", []))),
            "output": _part(OutputSection, data.get("output"), "output"),
            "accuracy": _part(AccuracySection, data.get("accuracy"), "accuracy")}


def _skeleton(body: Mapping) -> str:
    """The segments of [body]: its preset's, or those a mesh skin is rigged to (`skeleton`)."""
    if body["type"] == "mesh":
        return str(body.get("skeleton"))
    return "arm" if body["type"] == "default_arm" else str(body["type"])


def _lower_body(body: Mapping) -> LowerBodyDimensions:
    """The lower body's dimensions of [body]: its keys over the ANSUR II defaults, or over the Debian human's
    (fabricfem.body.human) for a mesh with rest_positions = "human"."""
    if body["type"] == "mesh" and body.get("rest_positions") == "human":
        try:
            return replace(HUMAN_DIMENSIONS, **_own(LowerBodyDimensions, body))
        except (TypeError, ValueError) as exc:
            raise SceneError(f"body: {exc}") from None
    return _part(LowerBodyDimensions, body, "body")


def _wear(data: Mapping) -> WearScene:
    body, motion = data["body"], data["motion"]
    route = data.get("route", {})
    return WearScene(
        scene=_part(SceneSection, data.get("scene"), "scene"),
        garment=_part(GarmentSection, first_garment(data), "garment"), fabric=_frozen(data["fabric"]),
        catalogue=data["fabric"].get("catalogue"), body=_part(WearBodySection, body, "body"),
        arm=_part(ArmDimensions, body, "body") if _skeleton(body) == "arm" else None,
        lower_body=_lower_body(body) if _skeleton(body) == "lower_body" else None,
        motion=_part(WearMotionSection, motion, "motion"),
        flexion=_part(FlexionSpec, motion, "motion") if motion["type"] == "elbow_flexion" else None,
        settle_time=float(motion.get("settle_time", FlexionSpec.settle_time if motion["type"] == "elbow_flexion"
                                     else 0.0)),
        donning=_part(WearDonningSection, data.get("donning"), "donning"),
        contact=_part(ContactSpec, data.get("contact"), "contact"), route=_part(RouteSpec, route, "route"),
        end_time=route.get("end_time"),
        torques=tuple(_part(TorqueSection, t, f"torque[{i}]") for i, t in enumerate(data.get("torque", []))),
        output=_part(OutputSection, data.get("output"), "output"),
        accuracy=_part(AccuracySection, data.get("accuracy"), "accuracy"),
        checks=_part(Bounds, data.get("checks"), "checks"),
        failure_strain=float(data["fabric"].get("failure_strain", FabricSection.failure_strain)),
        garments=tuple(_part(GarmentSection, t, f"garment[{i}]") for i, t in enumerate(garment_tables(data))))


def parse(data: Mapping, kind: str) -> StaticScene | DynamicScene | WearScene:
    """The frozen scene of validated `data` of `kind` (SceneError naming the section of a refused value)."""
    if kind == "wear":
        return _wear(data)
    parts = _shell_parts(data)
    if kind == "dynamic":
        return DynamicScene(**parts, dynamics=_part(DynamicsSection, data["dynamics"], "dynamics"))
    return StaticScene(**parts, solver=_part(SolverSection, data["solver"], "solver"))
