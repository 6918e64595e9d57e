"""The link back to the garment: a membrane law fitted to the woven unit cell WITH contact.

Steps (`fabricfem study fabric-link` runs them all; SI units: strains dimensionless, resultants N/m,
torques N m, lengths m):
  1. initial stiffness A0 [N/m] of the cell (coarse quarter cell of PlainWeave.balanced(), TI yarns) by
     central differences of small-strain runs about Phi = I (`measure_initial_stiffness`). Measured: the
     crimped yarns carry stretch by bending (A11 = A22 ~ 1.9e5 N/m, A12 ~ 0) but the in-plane shear
     stiffness at Phi = I is ZERO (|N12| < 1e-10 N/m): the yarns are separate bodies that do not touch
     below Phi ~ 1.01-1.02, so a pure shear is a rigid counter-rotation of warp and weft (trellis
     mechanism). The shear stiffness appears with the contact pressure at the crossovers; it is measured
     at the thesis' "small biaxial pre-stretching" Phi11 = Phi22 = 1.02 of its shear tests (sec. 4.3.5.1),
     the first state with the crossovers in contact. The fitted W has Hessian at E = 0 held to
     A0 = [[A11, A12, 0], [A12, A22, 0], [0, 0, A33(contact)]] (fit_contact_law),
     i.e. the fabric is modelled as woven with its crossovers in contact, as real woven fabric is.
  2. samples: `contact_grid_paths` (biaxial ratios and shear at three pre-stretches), each path opened
     by a small first increment (a small-strain sample), every converged step a sample; fit
     (`fit_contact_law`: by default the law convex at every strain by construction,
     fabricfem.materials.fitted.ConvexMembraneLaw), store as fabricfem/fabrics/plain-weave-ti-contact.json.
  3. strip comparison (`strip_against_unit_cell`): membrane strip in uniaxial tension with the fitted law,
     then the unit cell driven along the strip's strain path (E11, E22).
  4. sleeve flexion with the unit-cell fabric vs an orthotropic SVK fabric of the same small-strain
     constants (`sleeve_comparison`, needs SleeveConfig.fabric_name).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from mpi4py import MPI
from scipy.optimize import brentq

from fabricfem import io as fio
from fabricfem.fabrics import FABRICS_DIR, save_fabric
from fabricfem.materials import Fabric
from fabricfem.materials.fitted import (
    ConvexMembraneLaw,
    FittedMembraneLaw,
    MembraneSamples,
    fit_convex_law,
    fit_membrane_law,
    fitted_fabric,
    samples_from_steps,
)
from fabricfem.meshes import plate
from fabricfem.meshes.unit_cell import unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.shell import ShellModel
from fabricfem.solvers.loadstep import solve_load_path
from fabricfem.studies.sleeve import curve_rows
from fabricfem.studies.unit_cell import MATERIALS, PRESTRETCH
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.outputs import plot_torque
from fabricfem.wear.run import run_sleeve
from fabricfem.weave.unit_cell import ContactUnitCell

FABRIC_NAME = "plain-weave-ti-contact"
SVK_NAME = "plain-weave-ti-contact-svk"
OUT_DIR = Path(__file__).resolve().parents[2] / "docs" / "figures" / "fabric_link"
SAMPLES_CSV = "contact_samples.csv"
SMALL_FIRST = 0.05  # share of the first increment of every path (a small-strain sample: 0.3 % of 6 %)


def weave_thickness(weave: PlainWeave | None = None) -> float:
    """Fabric thickness t = 2 (A + b) = cell height [m] (N = t S, fabricfem.materials.fitted)."""
    return 2.0 * (weave or PlainWeave.balanced()).half_thickness()


def contact_cell(material: str = "ti", contact: bool = True, comm: MPI.Comm = MPI.COMM_WORLD) -> ContactUnitCell:
    """Coarse quarter cell (option B) of PlainWeave.balanced() with `material` yarns ("ti" | "iso")."""
    if material not in MATERIALS:
        raise ValueError(f"material must be one of {sorted(MATERIALS)}, got {material!r}")
    return ContactUnitCell(unit_cell(PlainWeave.balanced(), "quarter", "coarse", comm), MATERIALS[material],
                           contact=contact)


# ------------------------------------------------------------------------------ 1. initial stiffness
@dataclass(frozen=True)
class InitialStiffness:
    """Small-strain stiffness of the cell [N/m] (Voigt, eps = (E11, E22, 2 E12)).

    at_identity: central-difference tangent at Phi = I (3x3); shear_at_contact: dN12/d(2E12) at the
    pre-stretch `prestretch` (crossovers in contact); active_at_identity: contact nodes active at the
    small-strain states (0: the yarns do not touch); A0: the matrix the fit is held to.
    """

    at_identity: np.ndarray
    shear_at_contact: float
    prestretch: float
    active_at_identity: int
    active_at_prestretch: int

    @property
    def A0(self) -> np.ndarray:
        A = self.at_identity
        A12 = 0.5 * (A[0, 1] + A[1, 0])
        return np.array([[A[0, 0], A12, 0.0], [A12, A[1, 1], 0.0], [0.0, 0.0, self.shear_at_contact]])


def _resultant(model: ContactUnitCell, Phi: np.ndarray, thickness: float) -> tuple[np.ndarray, int]:
    step = model.solve(Phi, 1)[-1]
    N = thickness * np.array([step.S[0, 0], step.S[1, 1], step.S[0, 1]])
    return N, (0 if step.contact is None else step.contact.active)


def measure_initial_stiffness(material: str = "ti", contact: bool = True, strain: float = 5e-4,
                              prestretch: float = PRESTRETCH, comm: MPI.Comm = MPI.COMM_WORLD) -> InitialStiffness:
    """Tangent of the homogenized resultant N = t S at Phi = I by central differences, Phi = I +- strain
    (columns: E11, E22 and 2 E12 = 2 strain for the symmetric shear Phi12 = Phi21 = strain, so E = +-strain
    to O(strain^2); error O(strain^2)), each state from a fresh cell; plus dN12/d(2E12) at the pre-stretch
    Phi11 = Phi22 = prestretch (central difference in Phi12 = Phi21 = +-2e-3 from the pre-stretched state)."""
    if not (0.0 < strain <= 1e-2):
        raise ValueError(f"strain must lie in (0, 0.01], got {strain!r}")
    if not (1.0 < prestretch < 1.1):
        raise ValueError(f"prestretch must lie in (1, 1.1), got {prestretch!r}")
    t = weave_thickness()
    A = np.zeros((3, 3))
    active = 0
    for j in range(3):
        N_pm = []
        for sign in (1.0, -1.0):
            Phi = np.eye(3)
            if j < 2:
                Phi[j, j] += sign * strain
            else:
                Phi[0, 1] = Phi[1, 0] = sign * strain
            N, act = _resultant(contact_cell(material, contact, comm), Phi, t)
            N_pm.append(N)
            active = max(active, act)
        # exact strains of the states (Green-Lagrange): eps_j(+) - eps_j(-)
        d_eps = 2.0 * strain if j < 2 else 4.0 * strain  # E11 = s + s^2/2 (difference 2 s); 2 E12 = 2 s
        A[:, j] = (N_pm[0] - N_pm[1]) / d_eps
    shear, g = [], 2e-3
    act_pre = 0
    for sign in (1.0, -1.0):
        model = contact_cell(material, contact, comm)
        pre = np.diag([prestretch, prestretch, 1.0])
        model.solve(pre, 1)
        Phi = pre.copy()
        Phi[0, 1] = Phi[1, 0] = sign * g
        N, act = _resultant(model, Phi, t)
        shear.append(N[2])
        act_pre = max(act_pre, act)
    E12_pm = prestretch * g  # E12 = (Phi^T Phi - I)_12 / 2 = prestretch g for the symmetric shear
    shear_stiffness = (shear[0] - shear[1]) / (2.0 * 2.0 * E12_pm)
    return InitialStiffness(A, float(shear_stiffness), float(prestretch), int(active), int(act_pre))


# --------------------------------------------------------------------------------- 2. samples, fit
def contact_grid_paths(max_stretch: float = 1.06, shear: float = 0.1) -> list[list[np.ndarray]]:
    """Load paths of the fitting grid: biaxial stretches in ratios 1:1, 1:0, 0:1, 1:0.5, 0.5:1, 1:-0.25,
    -0.25:1 up to `max_stretch` (the TI contact cell converges to Phi = 1.133 biaxially, measured; the
    negative ratios cover the lateral contraction of uniaxial tension: with contact, pulling the warp at
    fixed weft stretch loads the weft, N22 > 0, so N22 = 0 needs E22 < 0) and three shear
    paths (pre-stretches (PRESTRETCH, PRESTRETCH), (max, max), (max, PRESTRETCH), then Phi12 = Phi21 =
    shear): shear at several stretches is needed to determine the stretch-shear coupling terms."""
    if not (1.0 < max_stretch <= 1.13):
        raise ValueError(f"max_stretch must lie in (1, 1.13] (the converged range), got {max_stretch!r}")
    if not (0.0 < shear <= 0.2):
        raise ValueError(f"shear must lie in (0, 0.2], got {shear!r}")
    d = max_stretch - 1.0
    paths = [[np.diag([1.0 + a * d, 1.0 + b * d, 1.0])] for a, b in
             ((1, 1), (1, 0), (0, 1), (1, 0.5), (0.5, 1), (1, -0.25), (-0.25, 1))]
    for pre in (np.diag([PRESTRETCH, PRESTRETCH, 1.0]), np.diag([1.0 + d, 1.0 + d, 1.0]),
                np.diag([1.0 + d, PRESTRETCH, 1.0])):
        sheared = pre.copy()
        sheared[0, 1] = sheared[1, 0] = shear
        paths.append([pre, sheared])
    return paths


def run_grid(material: str = "ti", steps: int = 3, max_stretch: float = 1.06, shear: float = 0.1,
             comm: MPI.Comm = MPI.COMM_WORLD, log: Callable[[str], None] | None = None) -> MembraneSamples:
    """Samples of the contact cell on contact_grid_paths: every path from a fresh cell; the last segment
    of a path opens with a small increment (SMALL_FIRST of it: a small-strain sample) then `steps` equal
    steps; a pre-stretch segment is one step. Every converged step is a sample (N = t S)."""
    collected = []
    for k, path in enumerate(contact_grid_paths(max_stretch, shear)):
        t0 = time.perf_counter()
        model = contact_cell(material, True, comm)
        for target in path[:-1]:
            model.solve(target, 1)
        start, target = model.Phi.copy(), path[-1]
        model.solve(start + SMALL_FIRST * (target - start), 1)
        model.solve(target, steps)
        collected.extend(model.steps)
        if log:
            log(f"path {k}: {len(model.steps)} steps to Phi = {np.round(target, 4).tolist()}, "
                f"{time.perf_counter() - t0:.1f} s")
    return samples_from_steps(collected, weave_thickness())


def save_samples(samples: MembraneSamples, path: str | Path) -> Path:
    """The samples as CSV at `path` (its folder made): E11, E22, gamma12 [-] and N11, N22, N12 [N/m], 10 digits."""
    p = Path(path)
    fio.write_csv(p, ["E11", "E22", "gamma12", "N11_N_per_m", "N22_N_per_m", "N12_N_per_m"],
                  [[f"{v:.10g}" for v in (*e, *n)] for e, n in zip(samples.strains, samples.resultants)], MPI.COMM_SELF)
    return p


def load_samples(path: str | Path) -> MembraneSamples:
    data = np.loadtxt(Path(path), delimiter=",", skiprows=1, ndmin=2)
    if data.shape[1] != 6:
        raise ValueError(f"path: {path} must have 6 columns (E11, E22, gamma12, N11, N22, N12)")
    return MembraneSamples(data[:, :3], data[:, 3:])


LAW_KINDS = ("convex", "polynomial")


def fit_contact_law(samples: MembraneSamples, stiffness: InitialStiffness | np.ndarray, kind: str = "convex",
                    degree: int = 5) -> FittedMembraneLaw | ConvexMembraneLaw:
    """W fitted to the samples with its Hessian at E = 0 held to A0 (stiffness.A0, or a 3x3 matrix [N/m]).

    kind "convex" (default, stored): fabricfem.materials.fitted.ConvexMembraneLaw, convex at every strain by
    construction (NNLS fit); "polynomial": FittedMembraneLaw of `degree`, convex only on the data hull
    (convexity repair), not outside it (the sleeve buckles into compressive, sheared states outside)."""
    A0 = stiffness.A0 if isinstance(stiffness, InitialStiffness) else np.asarray(stiffness, dtype=float)
    if kind == "convex":
        return fit_convex_law(samples, A0)
    if kind == "polynomial":
        return fit_membrane_law(samples, degree=degree, initial_stiffness=A0)
    raise ValueError(f"kind must be one of {LAW_KINDS}, got {kind!r}")


def law_summary(law: FittedMembraneLaw | ConvexMembraneLaw) -> str:
    """One line: type, samples, relative RMS residual and the convexity evidence of the law."""
    if isinstance(law, ConvexMembraneLaw):
        convexity = (f"convex everywhere by construction (Hessian >= A0, min eigenvalue of A0 "
                     f"{law.min_eigenvalue:.5g} N/m), {len(law.terms)} active terms")
    else:
        convexity = (f"Hessian eigenvalues on the data hull [{law.min_eigenvalue:.4g}, {law.max_eigenvalue:.4g}] "
                     f"N/m, repaired {law.repaired}")
    return (f"{law.to_dict()['type']}: {law.n_samples} samples, relative RMS residual "
            f"{law.relative_rms_residual:.4f}; {convexity}")


def save_contact_fabrics(law: FittedMembraneLaw | ConvexMembraneLaw, prestretch: float = PRESTRETCH,
                         samples_note: str = f"contact_grid_paths(1.06, 0.1) (docs/figures/fabric_link/{SAMPLES_CSV})"
                         ) -> Fabric:
    """Store the unit-cell fabric of `law` as fabricfem/fabrics/plain-weave-ti-contact.json and its SVK
    counterpart (same small-strain constants) as plain-weave-ti-contact-svk.json; returns the fabric."""
    fabric = contact_fabric(law)
    A0 = law.initial_stiffness
    what = ("W(E11, E22, 2E12) = 1/2 eps.A0.eps + non-negative sums of convex C2 ridge functions <l.eps - s>^n, "
            "(l.eps)^4, (l.eps)^6 (convex at every strain by construction), fitted by NNLS"
            if isinstance(law, ConvexMembraneLaw) else f"polynomial W(E11, E22, 2E12) of degree {law.degree}, fitted")
    save_fabric(fabric, FABRICS_DIR / f"{FABRIC_NAME}.json",
                description=(
                    f"Plain weave of [Man2006, sec. 4.3.5] (PlainWeave.balanced(), TI yarns), membrane energy {what} "
                    f"to the homogenized unit cell WITH yarn contact. "
                    f"Hessian at E = 0 held to the measured A0: A11 = A22 = {A0[0, 0]:.6g} N/m (crimp, by "
                    f"central differences at Phi = I, contact inactive), A12 = {A0[0, 1]:.3g} N/m; the shear "
                    f"stiffness at Phi = I is zero (trellis mechanism of the non-touching yarns), so A33 = "
                    f"{A0[2, 2]:.6g} N/m is the tangent at the thesis' shear pre-stretch Phi11 = Phi22 = "
                    f"{prestretch} with the crossovers in contact. Data: 0 <= E11, E22 <= 0.067 (down to -0.015 "
                    f"laterally), |2E12| <= 0.21. Density nominal (thesis fabric I); bending t^3/12 Q0."),
                source=(f"fabricfem.studies.fabric_link.fit_contact_law: coarse quarter cell, contact, "
                        f"{law.n_samples} samples on {samples_note}; {law_summary(law)}"))
    save_fabric(svk_counterpart(fabric), FABRICS_DIR / f"{SVK_NAME}.json",
                description=f"Orthotropic St. Venant-Kirchhoff fabric with the small-strain E1, E2, G12, nu12, "
                            f"thickness and density of {FABRIC_NAME} (the difference is the nonlinearity)",
                source="fabricfem.studies.fabric_link.svk_counterpart")
    return fabric


def contact_fabric(law: FittedMembraneLaw | ConvexMembraneLaw, name: str = FABRIC_NAME,
                   density: float = 436.0) -> Fabric:
    """The unit-cell fabric: thickness = cell height [m]; density nominal (thesis fabric I, 436 kg/m^3:
    the cell gives none)."""
    return fitted_fabric(law, weave_thickness(), density, name=name)


def svk_counterpart(fabric: Fabric, name: str = SVK_NAME) -> Fabric:
    """Orthotropic St. Venant-Kirchhoff fabric with the same thickness, density and small-strain
    E1, E2, G12, nu12 (and default bending rigidity t^3/12 Q) as `fabric`: the difference is the nonlinearity."""
    return Fabric(E1=fabric.E1, E2=fabric.E2, G12=fabric.G12, nu12=fabric.nu12, thickness=fabric.thickness,
                  density=fabric.density, G13=fabric.G13, name=name)


# ------------------------------------------------------------------------------- 3. strip vs cell
def uniaxial_reference(law: FittedMembraneLaw, E11: float) -> tuple[float, float]:
    """(E22, engineering N11 = lambda1 dW/dE11 [N/m]) of the law's uniaxial state dW/dE22 = 0, gamma12 = 0
    (brentq on N22(E22) = 0)."""
    def n22(E22):
        return law.resultants(np.array([E11, E22, 0.0]))[0, 1]
    # bracket from E22 = 0 outwards in steps of |E11| / 8: N22 increases with E22 where W is convex, so the
    # first sign change is the root (a fixed wide bracket can reach the extrapolated, non-convex range)
    step = -math.copysign(max(abs(E11), 1e-6) / 8.0, n22(0.0))
    a = 0.0
    for _ in range(64):
        b = a + step
        if n22(a) * n22(b) <= 0.0:
            break
        a = b
    else:
        raise ValueError(f"E11: no uniaxial state N22 = 0 found within |E22| <= 8 |E11| for E11 = {E11!r}")
    E22 = brentq(n22, min(a, b), max(a, b), xtol=1e-15, rtol=1e-15)
    N11 = law.resultants(np.array([E11, E22, 0.0]))[0, 0]
    return E22, math.sqrt(1.0 + 2.0 * E11) * N11


def uniaxial_strip(fabric: Fabric, tractions: Sequence[float], length: float = 0.1, width: float = 0.02):
    """Membrane strip [0, L] x [0, b] (4 x 2 quadrilaterals, in-plane), u_x = 0 on "left", u_y = 0 at the
    origin, dead traction (T, 0, 0) N/m on "right" raised through `tractions`; returns the measured
    (E11, E22) = ((lambda^2 - 1) / 2) from the displacement of the corner (L, b) at each traction, and the model."""
    model = ShellModel(plate(length, width, 4, 2, cell="quadrilateral"), fabric, model="membrane")
    model.constrain("left", u=(0.0, None, None))
    model.constrain(lambda x: np.isclose(x[0], 0.0) & np.isclose(x[1], 0.0), u=(None, 0.0, None))
    model.constrain(lambda x: np.full(x.shape[1], True), u=(None, None, 0.0))  # in-plane problem
    model.add_edge_traction("right", (tractions[-1], 0.0, 0.0))
    measured = []

    def record(lam):
        u = model.node_value((length, width, 0.0))
        l1, l2 = 1.0 + u[0] / length, 1.0 + u[1] / width
        measured.append((0.5 * (l1 ** 2 - 1.0), 0.5 * (l2 ** 2 - 1.0)))

    solve_load_path(model, [t / tractions[-1] for t in tractions], initial_step=0.25, on_target=record)
    return np.array(measured), model


@dataclass(frozen=True)
class StripRow:
    """One traction of the strip comparison: strip strains, applied traction T [N/m], the cell's
    engineering lambda1 N11 and N22 [N/m] at the strip's (E11, E22), contact nodes active."""

    E11: float
    E22: float
    traction: float
    cell_N11: float
    cell_N22: float
    active: int


def strip_against_unit_cell(law: FittedMembraneLaw, E11_targets: Sequence[float], material: str = "ti",
                            steps_per_state: int = 1, comm: MPI.Comm = MPI.COMM_WORLD) -> list[StripRow]:
    """Strip of the fitted fabric pulled to the uniaxial tractions of E11_targets, then ONE contact cell
    driven along the strip's strain path Phi = diag(lambda1, lambda2, 1) (the states in order,
    `steps_per_state` increments each; the path is monotone so the friction history matches)."""
    targets = sorted(float(e) for e in E11_targets)
    if not targets or targets[0] <= 0:
        raise ValueError(f"E11_targets must be positive strains, got {E11_targets!r}")
    tractions = [uniaxial_reference(law, e)[1] for e in targets]
    measured, _ = uniaxial_strip(contact_fabric(law), tractions)
    t = weave_thickness()
    model = contact_cell(material, True, comm)
    rows = []
    for T, (E11, E22) in zip(tractions, measured):
        l1, l2 = math.sqrt(1.0 + 2.0 * E11), math.sqrt(1.0 + 2.0 * E22)
        step = model.solve(np.diag([l1, l2, 1.0]), steps_per_state)[-1]
        rows.append(StripRow(float(E11), float(E22), float(T), l1 * t * step.S[0, 0], t * step.S[1, 1],
                             0 if step.contact is None else step.contact.active))
    return rows


def strip_table(rows: Sequence[StripRow]) -> str:
    """Markdown table of the strip comparison."""
    lines = ["| E11 (strip) | E22 (strip) | applied T = lambda1 N11 fit [N/m] | unit cell lambda1 N11 [N/m] "
             "| rel. diff | unit cell N22 [N/m] | N22 / T |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.E11:.4f} | {r.E22:.5f} | {r.traction:.4g} | {r.cell_N11:.4g} | "
                     f"{(r.cell_N11 - r.traction) / r.traction:+.3f} | {r.cell_N22:.4g} | {r.cell_N22 / r.traction:+.3f} |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ 4. sleeve
def sleeve_comparison(out_dir: str | Path = OUT_DIR, n_around: int = 10, n_along: int = 13, friction: float = 0.1,
                      fabrics: Sequence[str] = (FABRIC_NAME, SVK_NAME), comm: MPI.Comm = MPI.COMM_WORLD,
                      log: Callable[[str], None] | None = None) -> dict[str, "object"]:
    """Explicit sleeve flexion to 57 degrees (fabricfem.wear.sleeve, SleeveConfig.of(fabric_name=...)) for each stored
    fabric, with dynamic similarity (the unit-cell fabric is ~200 times stiffer than fabric I, E = 1.2 MPa,
    so at 45 deg/s it would need ~15 times the explicit steps; SleeveConfig.flexion_speed), friction mu.
    Writes sleeve_torque_<mesh>.csv (angle, torque per fabric) and .png to out_dir; returns the histories."""
    out = Path(out_dir)
    histories = {}
    for name in fabrics:
        config = SleeveConfig.of(n_around=n_around, n_along=n_along, friction=friction, fabric_name=name,
                              dynamic_similarity=True, name=name)
        t0 = time.perf_counter()
        history = run_sleeve(config, comm, stop_on_failure=False)
        histories[name] = history
        if log:
            log(f"sleeve {name} ({n_around}x{n_along}): {len(history.steps)} records, torque at 57 deg "
                f"{history.torque_at(57.0) if history.completed else float('nan'):.5g} N m, "
                f"failure {history.failure!r}, {time.perf_counter() - t0:.0f} s")
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        tag = f"{n_around}x{n_along}"
        fio.write_csv(out / f"sleeve_torque_{tag}.csv", ("fabric", "angle_deg", "torque_Nm", "torque_both_segments_Nm",
                                                         "contact_force_N", "strain_energy_J", "failure"),
                      [[name, *(row[k] for k in (0, 1, 2, 5, 10)), h.failure] for name, h in histories.items()
                       for row in curve_rows(h)])
        plot_torque(out / f"sleeve_torque_{tag}.png", {n: h.motion_curve() for n, h in histories.items()},
                    title=f"Sleeve, mesh {tag}, mu = {friction}: unit-cell fabric vs SVK (same A0)")
    return histories


# ------------------------------------------------------------------------------------- study
def run_fabric_link(out_dir: str | Path = OUT_DIR, resample: bool = True, sleeve_meshes: Sequence[tuple[int, int]] =
                    ((10, 13),), comm: MPI.Comm = MPI.COMM_WORLD, law_kind: str = "convex") -> None:
    """`fabricfem study fabric-link`: steps 1-4 of the module docstring. resample=False reuses the stored
    samples out_dir/contact_samples.csv (the unit-cell grid takes ~3 min) but re-measures A0. law_kind: see
    fit_contact_law ("convex" is the stored default)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def log(msg: str) -> None:
        if comm.rank == 0:
            print(msg, flush=True)
    stiffness = measure_initial_stiffness(comm=comm)
    log(f"A0 at Phi = I [N/m]: {np.array2string(stiffness.at_identity, precision=5)}; contact active: "
        f"{stiffness.active_at_identity}; A33 at pre-stretch {stiffness.prestretch}: {stiffness.shear_at_contact:.5g} "
        f"N/m ({stiffness.active_at_prestretch} contact nodes)")
    samples = run_grid(comm=comm, log=log) if resample else load_samples(out / SAMPLES_CSV)
    if resample and comm.rank == 0:
        save_samples(samples, out / SAMPLES_CSV)
    law = fit_contact_law(samples, stiffness, kind=law_kind)
    log(f"fit: {law_summary(law)}")
    if comm.rank == 0:
        save_contact_fabrics(law, stiffness.prestretch)
    rows = strip_against_unit_cell(law, (0.01, 0.02, 0.03, 0.04), comm=comm)  # E22 stays in the data (>= -0.015)
    log(strip_table(rows))
    if comm.rank == 0:
        (out / "strip_comparison.md").write_text(strip_table(rows) + "\n")
    for n_around, n_along in sleeve_meshes:
        sleeve_comparison(out, n_around, n_along, comm=comm, log=log)
