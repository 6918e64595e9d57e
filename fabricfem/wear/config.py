"""The configuration of an arm-in-sleeve run [Man2006, sec. 5.3]: one frozen, self-validating dataclass per
part of the scene, each parameter and its default declared once (the scene schema of fabricfem.scenes derives
the keys of [mesh], [fabric], [motion], [contact] and [route] of a sleeve scene from these fields).

SI units; angles in degrees for readability. Defaults: [Man2006, sec. 5.3] (L = 0.5 m, R = 0.06 m, t = 1 mm,
E = 1.2 MPa, G = 0.1 MPa, rho = 436 kg/m^3, mu = 0.1, 57 degrees); nu12 = 0 (the thesis gives none); mesh III
(20 x 26). Every ValueError names the parameter.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields, replace

from fabricfem.body.arm import DEFAULT_ARM, ArmDimensions
from fabricfem.contact.body_frame import DAMPING_FRAMES
from fabricfem.dynamics.stability import CRITICAL_STEP_METHODS, plane_stress_wave_speed, step_safety
from fabricfem.fabrics import load_fabric
from fabricfem.materials import Fabric
from fabricfem.parameters import param

# route -> its contact methods, the first the default
ROUTE_METHODS = {"explicit": ("lagrange", "penalty"), "quasistatic": ("penalty", "augmented"),
                 "implicit": ("augmented", "penalty")}


def _positive(obj, *keys: str) -> None:
    for key in keys:
        v = getattr(obj, key)
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
            raise ValueError(f"{key} must be a positive number, got {v!r}")


def _non_negative(obj, unit: str, *keys: str) -> None:
    for key in keys:
        v = getattr(obj, key)
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
            raise ValueError(f"{key} must be a number >= 0{unit}, got {v!r}")


def _positive_int(obj, *keys: str) -> None:
    for key in keys:
        v = getattr(obj, key)
        if isinstance(v, bool) or not (isinstance(v, int) and v >= 1):
            raise ValueError(f"{key} must be a positive integer, got {v!r}")


@dataclass(frozen=True)
class TubeSpec:
    """The sleeve: a tube along +x, shoulder end (end0) held; Q2 quadrilaterals."""

    length: float = param("tube length along x [m]", 0.5)
    radius: float = param("tube radius [m]", 0.06)
    n_around: int = param("Q2 cells around (mesh I: 10, III: 20)", 20)
    n_along: int = param("Q2 cells along (mesh I: 13, III: 26)", 26)
    quadrature: tuple[int, int] = param("(full, reduced) PSRI quadrature degrees; (4, 4) = no reduction", (4, 2))
    hold_rotations: bool = param("also clamp the director rotations at the shoulder", False)

    def __post_init__(self):
        _positive(self, "length", "radius")
        _positive_int(self, "n_around", "n_along")
        q = self.quadrature
        degrees_ok = isinstance(q, tuple) and len(q) == 2 and all(isinstance(d, int) and d >= 1 for d in q)
        if not (degrees_ok and q[0] >= q[1]):
            raise ValueError(f"quadrature must be (full, reduced) positive integer degrees with full >= reduced, "
                             f"got {q!r}")


@dataclass(frozen=True)
class FabricSpec:
    """The sleeve's fabric: orthotropic St. Venant-Kirchhoff with E1 = E2 = E, or a stored fabric `fabric_name`
    (fabricfem.fabrics.load_fabric) replacing E, G, nu12, thickness and density."""

    E: float = param("Young's modulus E1 = E2 [Pa]", 1.2e6)
    G: float = param("shear modulus G12 (and G13) [Pa]", 1e5)
    nu12: float = param("Poisson ratio [-] (the thesis gives none)", 0.0)
    thickness: float = param("thickness [m]", 1e-3)
    density: float = param("density [kg/m^3]", 436.0)
    fabric_name: str | None = param("a stored fabric (fabricfem.fabrics) replacing E, G, nu12, thickness, density",
                                    None)

    def __post_init__(self):
        _positive(self, "E", "G", "thickness")
        _non_negative(self, " [kg/m^3]", "density")
        if self.fabric_name is not None:
            for key in ("E", "G", "nu12", "thickness", "density"):   # the stored fabric gives them: not ignored
                if getattr(self, key) != type(self).__dataclass_fields__[key].default:
                    raise ValueError(f"{key}: given together with fabric_name {self.fabric_name!r}, whose stored "
                                     f"fabric sets it; give one or the other")
            if not (isinstance(self.fabric_name, str) and self.fabric_name):
                raise ValueError(f"fabric_name must be the name of a stored fabric (or a .json path) or None, "
                                 f"got {self.fabric_name!r}")
            try:
                stored = load_fabric(self.fabric_name)
            except (ValueError, OSError, KeyError, TypeError) as exc:
                raise ValueError(f"fabric_name: cannot load the stored fabric {self.fabric_name!r} ({exc})") from exc
            object.__setattr__(self, "_stored_fabric", stored)      # loaded once, cached on the frozen instance

    def fabric(self, name: str) -> Fabric:
        """The Fabric: the stored one (a fitted membrane law keeps its small-strain E1, E2, G12) or the SVK fabric
        of the fields."""
        if self.fabric_name is not None:
            return self.__dict__["_stored_fabric"]
        return Fabric(E1=self.E, E2=self.E, G12=self.G, nu12=self.nu12, thickness=self.thickness,
                      density=self.density, name=name)


@dataclass(frozen=True)
class FlexionSpec:
    """Elbow flexion at constant angular velocity from rest (after settle_time) to final_angle."""

    final_angle: float = param("final elbow angle [deg], in (0, 180)", 57.0)
    angular_velocity: float = param("flexion speed [deg/s] (body time t = alpha / omega)", 45.0)
    settle_time: float = param("rest before the flexion while the sleeve settles under gravity [s] (whole records)",
                               0.4)
    output_angle_step: float = param("record interval [deg] (the torque is averaged over it)", 1.0)
    angle_steps: int = param("quasistatic and implicit routes: equal steps to the final angle", 57)
    min_angle_step: float = param("a failed step is halved down to this [deg]", 0.05)

    def __post_init__(self):
        _positive(self, "final_angle", "angular_velocity", "output_angle_step", "min_angle_step")
        _non_negative(self, " [s]", "settle_time")
        _positive_int(self, "angle_steps")
        if self.final_angle >= 180.0:
            raise ValueError(f"final_angle must be below 180 degrees, got {self.final_angle!r}")


@dataclass(frozen=True)
class ContactSpec:
    """Contact of the sleeve with the arm and the Newton devices of the implicit routes."""

    method: str | None = param("contact method; explicit: lagrange (default) | penalty; quasistatic: penalty (default)"
                               " | augmented; implicit: augmented (default) | penalty", None)
    friction: float = param("Coulomb coefficient mu [-]", 0.1)
    penalty: float | None = param("k_N [Pa/m]; default 10 E t / h^2", None)
    augmentation_tolerance: float = param("largest penetration after Uzawa updates (augmented) [m]", 1e-5)
    active_set: bool = param("fixed contact set per Newton solve, updated until stable", True)
    stabilization: float = param("c / (E t / R^2): viscous regularisation of unstable steps (Stabilized)", 1e-2)
    predictor: bool = param("forearm contact nodes follow the forearm's rotation", True)
    relaxation_steps: int = param("pseudo-time relaxations at one angle after a stabilised solve", 40)
    drag_tolerance: float = param("accept a relaxed state when sum|drag| < this * sum|contact force|", 1e-3)
    self_contact: bool = param("explicit engine: the cloth's contact with itself, so that folds and layers do not "
                               "pass through each other (fabricfem.contact.self_contact)", False)
    self_contact_distance: float | None = param("explicit, self_contact: contact distance between cloth layers [m], "
                                                "0 < d_c <= the mesh size; default the fabric's thickness", None)
    self_friction: float = param("explicit, self_contact: Coulomb coefficient mu between cloth layers [-]", 0.0)
    self_contact_passes: int = param("explicit, self_contact: Gauss-Seidel passes of the inelastic impulses that stop "
                                     "approaching cloth-cloth pairs after each step (fabricfem.contact.impulses); "
                                     "0: the penalty alone", 0)
    impact_zones: bool = param("explicit, self_contact: after the impulses, continuous collision detection of the "
                               "step and rigid impact zones for the colliding cloth-cloth pairs "
                               "(fabricfem.contact.impact_zones, [Bridson2002, sec. 7.3-7.4])", False)

    def __post_init__(self):
        _non_negative(self, "", "friction", "self_friction")
        _positive(self, "augmentation_tolerance")
        if self.penalty is not None:
            _positive(self, "penalty")
        if not isinstance(self.self_contact, bool):
            raise ValueError(f"self_contact must be true or false, got {self.self_contact!r}")
        if self.self_contact_distance is not None:
            _positive(self, "self_contact_distance")
        passes = self.self_contact_passes
        if isinstance(passes, bool) or not (isinstance(passes, int) and passes >= 0):
            raise ValueError(f"self_contact_passes must be an integer >= 0, got {passes!r}")
        if not isinstance(self.impact_zones, bool):
            raise ValueError(f"impact_zones must be true or false, got {self.impact_zones!r}")


@dataclass(frozen=True)
class RouteSpec:
    """How the flexion is integrated: the route and its numerical parameters."""

    solver: str = param("explicit (central differences) | quasistatic (Newton per angle) | implicit (backward Euler"
                        " + Newton)", "explicit")
    gravity: bool | None = param("the sleeve's weight along -y (default: on for explicit and implicit, off for"
                                 " quasistatic)", None)
    mass_damping: float = param("Rayleigh alpha of C = alpha M [1/s] (a drag on rigid motion too, unless "
                                "damping_frame = \"body\")", 10.0)
    stiffness_damping: float = param("explicit: Rayleigh beta of C = beta K_M(d) [s], a damping of the deformation "
                                     "only (no drag on rigid motion); shortens the critical step", 0.0)
    damping_frame: str = param("explicit: the mass damping acts on the velocity relative to the ground (C v, also a "
                               "drag on rigid motion) or to the body (C (v - v_body), v_body the rigid velocity of "
                               "the body's segments at each node: deformation and sliding only)", "ground")
    rotary_inertia_scale: float = param("explicit: factor >= 1 on the rotational lumped masses", 100.0)
    time_step_safety: float | None = param(
        "explicit: dt = safety x critical step, in (0, 1); default 0.9 with the eigenvalue step, 0.8 with the "
        "element formula", None)
    critical_step: str | None = param(
        "explicit: the critical step from the largest eigenvalue of the assembled system (eigenvalue) or from the "
        "element formula (estimate, shorter); default: eigenvalue for the sleeve's flexion route, estimate for the "
        "garment engine of wear scenes (docs/garments.md)",
        None)
    mass_scale: float = param("explicit: factor >= 1 on every lumped mass (not on the weight nor the damping), dt x "
                              "sqrt(factor); check the kinetic / strain energy ratio of the run", 1.0)
    dynamic_similarity: bool = param("explicit: flex at omega c / c_ref with damping alpha c / c_ref", False)
    similarity_reference: tuple[float, float] = param("(E_ref [Pa], rho_ref [kg/m^3]): fabric I", (1.2e6, 436.0))
    newton_max_iterations: int = param("Newton iterations per solve", 60)
    max_rotation_step: float = param("largest director-angle change per Newton iteration [rad]", 0.3)
    max_displacement_step: float = param("largest displacement change per Newton iteration [m]", 5e-3)

    def __post_init__(self):
        if self.solver not in ROUTE_METHODS:
            raise ValueError(f"solver must be one of {tuple(ROUTE_METHODS)}, got {self.solver!r}")
        if self.gravity is None:
            object.__setattr__(self, "gravity", self.solver in ("explicit", "implicit"))
        _positive(self, "max_rotation_step", "max_displacement_step")
        if self.time_step_safety is not None:
            _positive(self, "time_step_safety")
            if self.time_step_safety >= 1.0:
                raise ValueError(f"time_step_safety must lie in (0, 1), got {self.time_step_safety!r}")
        if self.critical_step is not None and self.critical_step not in CRITICAL_STEP_METHODS:
            raise ValueError(f"critical_step must be one of {CRITICAL_STEP_METHODS}, got {self.critical_step!r}")
        _non_negative(self, " [1/s]", "mass_damping")
        _non_negative(self, " [s]", "stiffness_damping")
        if self.damping_frame not in DAMPING_FRAMES:
            raise ValueError(f"damping_frame must be one of {DAMPING_FRAMES}, got {self.damping_frame!r}")
        if self.damping_frame == "body" and self.solver != "explicit":
            raise ValueError(f"damping_frame = 'body' needs the explicit solver (the {self.solver} route damps "
                             f"against the ground)")
        if isinstance(self.rotary_inertia_scale, bool) or not (isinstance(self.rotary_inertia_scale, (int, float))
                                                              and self.rotary_inertia_scale >= 1.0):
            raise ValueError(f"rotary_inertia_scale must be a number >= 1, got {self.rotary_inertia_scale!r}")
        if isinstance(self.mass_scale, bool) or not (isinstance(self.mass_scale, (int, float))
                                                    and math.isfinite(self.mass_scale) and self.mass_scale >= 1.0):
            raise ValueError(f"mass_scale must be a number >= 1, got {self.mass_scale!r}")
        _positive_int(self, "newton_max_iterations")
        E_ref, rho_ref = self.similarity_reference
        if not (math.isfinite(E_ref) and E_ref > 0.0 and math.isfinite(rho_ref) and rho_ref > 0.0):
            raise ValueError(f"similarity_reference must be (E_ref > 0 [Pa], rho_ref > 0 [kg/m^3]), "
                             f"got {self.similarity_reference!r}")


# parameter -> default, of the parameters added after study runs were checkpointed (SleeveConfig.key_items)
# (critical_step: the runs stored before it used the element formula)
ADDED_LATER = {"mass_scale": 1.0, "critical_step": "estimate", "stiffness_damping": 0.0, "self_contact": False,
               "self_contact_distance": None, "self_friction": 0.0, "damping_frame": "ground",
               "self_contact_passes": 0, "impact_zones": False}

SECTIONS = {"tube": TubeSpec, "material": FabricSpec, "motion": FlexionSpec, "contact": ContactSpec,
            "route": RouteSpec}


def check_fit(radius: float, arm: ArmDimensions = DEFAULT_ARM) -> float:
    """Clearance [m] between the sleeve radius and the thickest arm segment (circle-equivalent radius
    girth / (2 pi), ArmDimensions); ValueError naming `radius` and the girth (arm.upper_arm_girth or
    arm.forearm_girth) when the arm does not fit inside the undeformed sleeve (it must start without
    penetration)."""
    key, thickest = max((("upper_arm_girth", arm.upper_arm_radius), ("forearm_girth", arm.forearm_radius)),
                        key=lambda item: item[1])
    if radius <= thickest:
        raise ValueError(f"radius: the sleeve radius {radius} m must exceed the arm's largest radius "
                         f"{thickest:.4f} m = arm.{key} / (2 pi) (arm.{key} = {getattr(arm, key)} m; the arm must "
                         f"start inside the sleeve without penetration)")
    return radius - thickest


@dataclass(frozen=True)
class SleeveConfig:
    """All parameters of one sleeve computation, by part: `tube`, `material` (the fabric's parameters; `fabric` is
    the Fabric built from them), `motion`, `contact`, `route`, the
    wearer's `arm` (lengths and girths [m], default ANSUR II medians) and a `name`. Cross-part checks: the contact
    method must suit the route (its default when None), the arm must fit inside the sleeve, the explicit route and
    dynamic similarity need a positive density. `SleeveConfig.of(n_around=10, friction=0.5)` builds one from
    parameter names (each routed to the part that declares it)."""

    tube: TubeSpec = field(default_factory=TubeSpec)
    material: FabricSpec = field(default_factory=FabricSpec)
    motion: FlexionSpec = field(default_factory=FlexionSpec)
    contact: ContactSpec = field(default_factory=ContactSpec)
    route: RouteSpec = field(default_factory=RouteSpec)
    arm: ArmDimensions = DEFAULT_ARM
    name: str = "sleeve"

    def __post_init__(self):
        for key, cls in SECTIONS.items():
            if not isinstance(getattr(self, key), cls):
                raise ValueError(f"{key} must be a {cls.__name__}, got {type(getattr(self, key)).__name__}")
        methods = ROUTE_METHODS[self.route.solver]
        if self.contact.method is None:
            object.__setattr__(self, "contact", replace(self.contact, method=methods[0]))
        if self.contact.method not in methods:
            raise ValueError(f"method must be one of {methods} for solver {self.route.solver!r}, "
                             f"got {self.contact.method!r}")
        if not isinstance(self.arm, ArmDimensions):
            raise ValueError(f"arm must be a fabricfem.body.ArmDimensions, got {type(self.arm).__name__}")
        check_fit(self.tube.radius, self.arm)
        if self.material.fabric_name is not None and self.route.solver == "explicit" and self.fabric.density <= 0.0:
            raise ValueError(f"fabric_name: the stored fabric {self.material.fabric_name!r} has no positive density, "
                             f"which the explicit sleeve needs")
        if self.route.dynamic_similarity and self.fabric.density <= 0.0:
            raise ValueError("dynamic_similarity needs a positive density (c = sqrt(E / rho))")

    # ---------------------------------------------------------------------------- building from names
    @staticmethod
    def _split(changes: dict) -> tuple[dict[str, dict], dict]:
        """{part: {field: value}} of parameter names and the top-level ones (arm, name); ValueError naming an
        unknown parameter."""
        owner = {f.name: part for part, cls in SECTIONS.items() for f in fields(cls)}
        top = {f.name for f in fields(SleeveConfig)} - set(SECTIONS)
        parts: dict[str, dict] = {}
        rest = {}
        for key, value in changes.items():
            if key in owner:
                parts.setdefault(owner[key], {})[key] = value
            elif key in top:
                rest[key] = value
            else:
                raise ValueError(f"{key}: not a sleeve parameter (known: {sorted(owner) + sorted(top)})")
        return parts, rest

    @classmethod
    def of(cls, **parameters) -> "SleeveConfig":
        """A configuration from parameter names (defaults for the rest)."""
        parts, rest = cls._split(parameters)
        return cls(**{part: SECTIONS[part](**values) for part, values in parts.items()}, **rest)

    def with_(self, **changes) -> "SleeveConfig":
        """A copy with the named parameters changed; changing the solver without naming a method (or gravity)
        takes that solver's default contact method (and gravity)."""
        if "solver" in changes and changes["solver"] != self.route.solver:
            changes.setdefault("method", None)
            changes.setdefault("gravity", None)
        parts, rest = self._split(changes)
        return replace(self, **{part: replace(getattr(self, part), **values) for part, values in parts.items()},
                       **rest)

    def flat(self) -> dict:
        """{parameter: value} of every part (the keys of `of`), for tables and checkpoint keys."""
        out = {}
        for part in SECTIONS:
            out.update(dataclasses.asdict(getattr(self, part)))
        out.update(arm=dataclasses.asdict(self.arm), name=self.name)
        return out

    def key_items(self) -> dict:
        """`flat()` without the parameters added after runs were stored under their configuration's hash
        (ADDED_LATER) where they hold their default: such runs keep their checkpoint names."""
        items = self.flat()
        for name, default in ADDED_LATER.items():
            if items.get(name) == default:
                del items[name]
        items["time_step_safety"] = self.time_step_safety   # its default became per method: the value used
        return items

    # ---------------------------------------------------------------------------- derived quantities
    @property
    def critical_step(self) -> str:
        """How the sleeve's flexion route sets its critical step: `[route] critical_step`, by default from the
        largest eigenvalue of the assembled system (docs/findings/2026-11-26-critical-step.md)."""
        return self.route.critical_step or "eigenvalue"

    @property
    def time_step_safety(self) -> float:
        """dt / dt_crit of the explicit route: `[route] time_step_safety` or the default of its critical-step method
        (fabricfem.dynamics.stability.STEP_SAFETY)."""
        return step_safety(self.route.time_step_safety, self.critical_step)

    @property
    def fabric(self) -> Fabric:
        """The sleeve's Fabric (FabricSpec.fabric): the stored fabric or the SVK fabric of `material`."""
        return self.material.fabric(self.name)

    @property
    def wave_speed(self) -> float:
        """c = sqrt(E_max / (rho (1 - nu12 nu21))) [m/s], the membrane wave speed of the fabric [Man2006, eq. 2.87]."""
        fabric = self.fabric
        return plane_stress_wave_speed(fabric) if fabric.density > 0.0 else math.inf

    @property
    def membrane_modulus(self) -> float:
        """max(E1, E2) [Pa] of the fabric used (the stored fabric's small-strain value when fabric_name is set)."""
        fabric = self.fabric
        return max(fabric.E1, fabric.E2)

    @property
    def similarity_factor(self) -> float:
        """c / c_ref with dynamic similarity, 1 without (see `flexion_speed`)."""
        if not self.route.dynamic_similarity:
            return 1.0
        E_ref, rho_ref = self.route.similarity_reference
        return self.wave_speed / math.sqrt(E_ref / rho_ref)

    @property
    def flexion_speed(self) -> float:
        """Angular velocity [deg/s] of the flexion actually run: omega c / c_ref with dynamic similarity.

        Dynamic similarity (explicit route; for stiff fabrics, whose explicit step shrinks like h / c): with all
        moduli proportional to E, the sleeve's equation of motion in the flexion angle a = omega t,
        rho t omega^2 u'' + alpha rho t omega u' + E f(u) = f_c(u), divided by E reads
        (omega / c)^2 t u'' + (alpha omega / c^2) t u' + f(u) = f_c / E (c^2 = E / rho). Running fabric k at
        omega_k = omega c_k / c_ref with damping alpha_k = alpha c_k / c_ref keeps both coefficients those of the
        reference fabric at omega, so u(a) is the same and the torque scales with E exactly (verify case
        sleeve-similarity)."""
        return self.motion.angular_velocity * self.similarity_factor

    @property
    def damping(self) -> float:
        """Mass damping alpha [1/s] actually used: alpha c / c_ref with dynamic similarity (`flexion_speed`)."""
        return self.route.mass_damping * self.similarity_factor
