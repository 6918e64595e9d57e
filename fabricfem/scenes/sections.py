"""Scene-file keys derived from config dataclasses: a parameter, its type and its default are declared once, in
the dataclass; the schema of the TOML section that sets it is read from `dataclasses.fields`."""
from __future__ import annotations

import dataclasses
import types
import typing

from fabricfem.parameters import param as doc

# annotation -> the TOML value types it accepts (TOML has no None: an optional parameter is simply left out)
_TOML_TYPES = {float: (int, float), int: int, bool: bool, str: str, tuple: list, list: list, dict: dict}


def _is_union(annotation) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _toml_types(annotation) -> type | tuple:
    if _is_union(annotation):
        accepted: tuple = ()
        for arg in typing.get_args(annotation):
            if arg is not type(None):
                t = _toml_types(arg)
                accepted += t if isinstance(t, tuple) else (t,)
        return accepted[0] if len(accepted) == 1 else tuple(dict.fromkeys(accepted))
    origin = typing.get_origin(annotation)
    return _TOML_TYPES[origin or annotation]


def schema_of(cls, exclude: tuple[str, ...] = ()) -> dict[str, tuple[type | tuple, bool]]:
    """{key: (TOML types, required)} of the fields of dataclass `cls` (required: no default)."""
    hints = typing.get_type_hints(cls)
    return {f.name: (_toml_types(hints[f.name]),
                     f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING)
            for f in dataclasses.fields(cls) if f.name not in exclude and not f.name.startswith("_")}


def from_table(cls, table: dict, exclude: tuple[str, ...] = ()):
    """An instance of dataclass `cls` from a validated TOML table (lists become tuples where the field is a
    tuple); keys in `exclude` (e.g. a section's `type`) are left out."""
    hints = typing.get_type_hints(cls)
    values = {}
    for key, value in table.items():
        if key in exclude:
            continue
        annotation = hints[key]
        if _is_union(annotation):
            annotation = typing.get_args(annotation)[0]
        target = typing.get_origin(annotation) or annotation
        values[key] = tuple(value) if target is tuple and isinstance(value, list) else value
    return cls(**values)


# ------------------------------------------------------------------------------------------ the sections
@dataclasses.dataclass(frozen=True)
class SceneSection:
    """[scene]: what the scene is."""

    name: str | None = doc("name of the run (default: the file's stem); outputs go to results/<name>", None)
    description: str | None = doc("free text", None)
    kind: str | None = doc("static | dynamic | wear (required: every scene names its kind)", None)


@dataclasses.dataclass(frozen=True)
class MeshSection:
    """[mesh]: a structured plate or a tube (fabricfem.meshes)."""

    type: str = doc("plate | tube")
    lx: float | None = doc("plate length along x [m]", None)
    ly: float | None = doc("plate width along y [m]", None)
    nx: int | None = doc("plate cells along x", None)
    ny: int | None = doc("plate cells along y", None)
    structured: bool = doc("plate: structured grid", True)
    length: float | None = doc("tube length along x [m]", None)
    radius: float | None = doc("tube radius [m]", None)
    n_around: int | None = doc("tube cells around", None)
    n_along: int | None = doc("tube cells along", None)
    cell: str = doc("quadrilateral | triangle", "quadrilateral")
    order: int = doc("geometry order of the tube (1 or 2)", 1)
    allow_large: bool = doc("run a mesh whose estimated memory exceeds the machine's (refused otherwise)", False)


@dataclasses.dataclass(frozen=True)
class FabricSection:
    """[fabric]: orthotropic St. Venant-Kirchhoff membrane in the warp/weft frame, optional bending laws."""

    E1: float = doc("warp Young's modulus [Pa]")
    E2: float = doc("weft Young's modulus [Pa]")
    G12: float = doc("in-plane shear modulus [Pa]")
    nu12: float = doc("Poisson ratio [-]")
    thickness: float = doc("thickness t [m]")
    density: float = doc("density [kg/m^3] (areal density = density x thickness)", 0.0)
    G13: float | None = doc("transverse shear modulus [Pa] (default G12)", None)
    name: str = doc("label", "fabric")
    bending_rigidity: list | None = doc("[B1, B2] bending rigidities [N m] (default E t^3 / 12 per direction)", None)
    bending_law: str | None = doc("kawabata | square_root (nonlinear bending)", None)
    kawabata_coefficients: list | None = doc("coefficients of the Kawabata law", None)
    B0: float | None = doc("square-root law: B0 [N m]", None)
    kappa0: float | None = doc("square-root law: kappa0 [1/m]", None)
    failure_strain: float = doc("Green strain above which a run's fabric strain is implausible (the fabric would "
                                "fail; woven fabrics break at 10-35 % engineering strain): the strain check of the "
                                "run's verdict", 0.3)


@dataclasses.dataclass(frozen=True)
class ModelSection:
    """[model]: which fabric model."""

    kind: str = doc("naghdi (shell) | membrane", "naghdi")
    rebase: bool = doc("re-base the director after converged steps", True)
    quadrature: tuple | str = doc("naghdi: [full, reduced] quadrature degrees of the membrane and shear energy's "
                                  "partial selective reduced integration, weight min(1, t_eq^2 / h^2) on the full "
                                  "rule (docs/shell.md, \"Locking\"), or \"full\": no reduced integration "
                                  "([4, 4])", (4, 2))

    def __post_init__(self) -> None:
        """ValueError naming `quadrature` for anything but "full" or two positive integer degrees, full >= reduced."""
        q = self.quadrature
        if q == "full":
            return
        if not (isinstance(q, tuple) and len(q) == 2 and all(type(n) is int and n > 0 for n in q) and q[0] >= q[1]):
            raise ValueError(f"quadrature: [full, reduced] positive integer degrees with full >= reduced, or "
                             f"\"full\", got {list(q) if isinstance(q, tuple) else q!r}")

    @property
    def psri_degrees(self) -> tuple[int, int]:
        """(full, reduced) quadrature degrees of the shell's PSRI split (fabricfem.shell.ShellModel)."""
        return (4, 4) if self.quadrature == "full" else self.quadrature


@dataclasses.dataclass(frozen=True)
class SupportSection:
    """[[support]]: a held edge or node."""

    edge: str | None = doc("edge tag of the mesh, or \"all\": every node (e.g. u = [\"free\", \"free\", 0] "
                           "for an in-plane problem)", None)
    point: list | None = doc("[x, y, z] of a mesh node [m] (instead of edge)", None)
    u: list | None = doc("[ux, uy, uz] [m] or \"free\" per component", None)
    theta: list | None = doc("[theta1, theta2] [rad] or \"free\"", None)


@dataclasses.dataclass(frozen=True)
class LoadSection:
    """[[load]]: a load scaled by the load factor."""

    type: str = doc("gravity | body_force | edge_traction | pressure | edge_moment | point")
    edge: str | None = doc("edge tag (edge loads)", None)
    value: float | list | None = doc("by type: body force per area [N/m^2], edge traction [N/m], pressure [Pa], edge moment "
                                      "vector (x, y, z) [N m/m], point force [N]", None)
    point: list | None = doc("[x, y, z] [m] of a point load", None)


@dataclasses.dataclass(frozen=True)
class SolverSection:
    """[solver]: load stepping of a static scene."""

    targets: float | list = doc("load factors to reach and write")
    initial_step: float | None = doc("first load step (default: the first target)", None)
    min_step: float = doc("smallest load step before giving up", 1e-6)
    petsc_options: dict | None = doc("PETSc options of the Newton solver", None)


@dataclasses.dataclass(frozen=True)
class OutputSection:
    """[output]: where and what to write."""

    dir: str | None = doc("output folder (default results/<name>)", None)
    probe: list | None = doc("[x, y, z] [m] of a node whose displacement is reported", None)
    render: bool = doc("write PNG renders", True)
    body_samples: int = doc("wear: points per ellipsoid ring of the body surfaces", 24)
    windows: list | None = doc("wear: windows [[a, b], ...] of the motion on the run's axis (elbow or knee angle "
                               "[deg], else body time [s]) for the windowed means of the monitors (default: an angle "
                               "axis 20 deg to the end, else the whole motion)", None)
    render_at: list | None = doc("wear: record coordinates (angle [deg] or time [s]) of the pressure renders "
                                 "(default: the thirds of the motion)", None)
    sensor_diameter: float = doc("wear: diameter [m] of the disc over which the records' sensor pressure is the "
                                 "mean contact pressure (fabricfem.wear.sensor)", 0.03)


@dataclasses.dataclass(frozen=True)
class DynamicsSection:
    """[dynamics]: time integration from rest."""

    integrator: str = doc("newmark | explicit | generalized-alpha")
    dt: float | str = doc("time step [s], or \"auto\" (explicit): dt_fraction x the critical step")
    end_time: float = doc("end time [s]")
    dt_fraction: float = doc("fraction of the critical step for dt = \"auto\", in (0, 1]", 0.9)
    force: bool = doc("explicit: allow dt above the critical step", False)
    beta: float = doc("Newmark beta", 0.25)
    gamma: float = doc("Newmark gamma", 0.5)
    rho_inf: float = doc("generalized-alpha spectral radius at infinite step, in [0, 1]", 1.0)
    lumped: bool = doc("lumped mass (newmark / generalized-alpha; explicit always lumps)", False)
    rayleigh: list = doc("[a [1/s], b [s]] of C = a M + b K", default_factory=lambda: [0.0, 0.0])
    air_drag: float = doc("eta [kg/(m^2 s)], drag -eta v per unit area", 0.0)
    strain_limit: float | None = doc("max warp/weft Green strain (fast projection)", None)
    strain_limit_tol: float = doc("projection tolerance [-]", 1e-4)
    gravity: list | None = doc("[gx, gy, gz] [m/s^2]", None)
    ramp_time: float = doc("load factor min(t / ramp_time, 1) [s]", 0.0)
    output_every: int | None = doc("record every N steps (default n_steps / 100)", None)
    obstacles: list = doc("[[dynamics.obstacles]] rigid obstacles", default_factory=list)
    monitors: list = doc("[[dynamics.monitors]] CSV columns", default_factory=list)
    contact_penalty: float | None = doc("obstacle penalty [Pa/m] (default 10 E t / h^2)", None)
    checkpoint_every: int | None = doc("records between checkpoints (default 25; fabricfem run --resume)", None)


@dataclasses.dataclass(frozen=True)
class ObstacleSection:
    """[[dynamics.obstacles]]: plane (point, normal), box (lower, upper, radius) or table (center, half_x, half_y,
    height, fillet_radius)."""

    type: str = doc("plane | box | table")
    point: list | None = doc("plane: a point [m]", None)
    normal: list | None = doc("plane: outward normal", None)
    lower: list | None = doc("box: lower corner [m] (bounds may be inf)", None)
    upper: list | None = doc("box: upper corner [m]", None)
    radius: float | None = doc("box: edge rounding [m]", None)
    center: list | None = doc("table: [cx, cy] [m]", None)
    half_x: float | None = doc("table: half length [m]", None)
    half_y: float | None = doc("table: half width [m]", None)
    height: float | None = doc("table: top height [m]", None)
    fillet_radius: float | None = doc("table: edge fillet [m]", None)


@dataclasses.dataclass(frozen=True)
class MonitorSection:
    """[[dynamics.monitors]]: a node value or a strain/displacement summary as a CSV column."""

    name: str = doc("column name")
    point: list | None = doc("[x, y, z] [m] of a mesh node", None)
    field: str = doc("u [m] | theta [rad]", "u")
    component: int | None = doc("component index (default 2 for u, 0 for theta)", None)
    quantity: str | None = doc("max_warp_strain | max_weft_strain | mean_warp_strain | mean_weft_strain | "
                               "max_displacement", None)


@dataclasses.dataclass(frozen=True)
class AccuracySection:
    """[accuracy]: run the cheapest mesh level whose estimated error of a monitored quantity is below a target
    (fabricfem.scenes.accuracy; static, dynamic and wear scenes)."""

    quantity: str | None = doc("static: probe_ux_m | probe_uy_m | probe_uz_m (needs output.probe); dynamic: a "
                               "[[dynamics.monitors]] name (its value at end_time) or kinetic_J | strain_J | "
                               "max_strain_final; wear: torque_<monitor>_peak_Nm | torque_<monitor>_final_Nm | "
                               "torque_<monitor>_window_mean_Nm (its windowed mean) | pressure_peak_Pa | pressure_mean_Pa | "
                               "max_strain", None)
    target: float | None = doc("relative error target, in (0, 1) (e.g. 0.02)", None)
    finer_levels: int = doc("levels finer than the scene's mesh that may be chosen (cell counts x 2, x 4, ...; "
                            "wear: x ratio, x ratio^2, ...; a wear scene's windowed statistic: the mesh ladder's "
                            "levels above the scene's mesh, the finest the reference)", 2)
    membrane: bool = doc("a shell scene: also solve the membrane model at the pilot levels and choose it where its "
                         "difference to the shell's extrapolated value meets the target (not with edge moments or "
                         "rotation monitors)", True)
    particles: bool = doc("a static plate scene: also solve the particle model ([Eischen2000]) on the pilot grids "
                          "and offer it where its error floor (the finest particle pilot's difference to the shell's "
                          "extrapolated value) meets the target (not with edge moments, pressure, fixed rotations, "
                          "tubes or dynamics)", True)
    window: float | None = doc("wear, explicit engine: the pilots run only the first `window` seconds of body time "
                               "(donning, settling and motion phases as scheduled, cut there) [s]; the estimate is "
                               "that of the window's quantity; the chosen level then runs the whole scene "
                               "(default: the whole scene)", None)
    ratio: float | None = doc("wear: refinement ratio between levels, in (1, 4]: tube cell counts x ratio^k "
                              "(rounded), pattern element size h / ratio^k (default: 2 where the coarsest pilot "
                              "keeps 6 cells around a tube, else the largest ratio that does; 2 for a pattern; "
                              "1.5 on the mesh ladder of a windowed statistic)", None)


def section(cls, table: dict | None):
    """The section dataclass of a validated table (None or {} gives the defaults)."""
    return from_table(cls, table or {})
