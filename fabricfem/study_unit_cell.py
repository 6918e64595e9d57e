"""Unit-cell study of thesis 000 sec. 4.3.5 (Figs. 21-28, 32-33): `fabricfem study unit-cell`.

Load cases (macroscopic Phi applied in equal increments, thesis sec. 4.3.5):
  biaxial      Phi11 = Phi22 -> 1.2
  uniaxial     Phi11 -> 1.2, Phi22 = 1
  shear        biaxial pre-stretch Phi11 = Phi22 = 1.02 (one step), then Phi12 = Phi21 -> 0.2
  compression  Phi11 = Phi22 -> 0.9
Yarns: isotropic (lambda = 48.82, mu = 32.55 GPa) or transversely isotropic (thesis parameters),
with or without yarn contact, quarter (option B) or full (option A) cell, coarse or fine mesh, yarn
end faces exactly periodic or with the thesis' u_z = 0 (ContactUnitCell end_faces; Fig. 27 shows both).
Every figure gets a CSV (one row per converged step and curve) and a PNG under the output folder.
A run that stops (Newton/augmentation failure) keeps its converged steps; the CSV column `stopped`
holds the reason, so a curve shorter than its load case is visible, never silently extrapolated.
Units: S in Pa, E dimensionless, forces in N, lengths in m, times in s.
"""
from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from fabricfem.materials_yarn import THESIS_ISOTROPIC, THESIS_TRANSVERSELY_ISOTROPIC, YarnMaterial
from fabricfem.meshes.unit_cell import unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.solvers.newton import SolverError
from fabricfem.unit_cell_contact import ContactUnitCell, contact_table

MATERIALS: dict[str, YarnMaterial] = {"iso": THESIS_ISOTROPIC, "ti": THESIS_TRANSVERSELY_ISOTROPIC}
PRESTRETCH = 1.02  # Phi11 = Phi22 before shear ("a small biaxial pre-stretching", sec. 4.3.5.1)


def load_targets(load: str, scale: float = 1.0) -> list[tuple[np.ndarray, int]]:
    """[(Phi target, share of the steps)] of a load case; `scale` in (0, 1] shortens the path."""
    I = np.eye(3)
    if load == "biaxial":
        return [(I + scale * np.diag([0.2, 0.2, 0.0]), 1)]
    if load == "uniaxial":
        return [(I + scale * np.diag([0.2, 0.0, 0.0]), 1)]
    if load == "compression":
        return [(I - scale * np.diag([0.1, 0.1, 0.0]), 1)]
    if load == "shear":
        pre = np.diag([PRESTRETCH, PRESTRETCH, 1.0])
        sheared = pre.copy()
        sheared[0, 1] = sheared[1, 0] = 0.2 * scale
        return [(pre, 0), (sheared, 1)]
    raise ValueError(f"load must be biaxial, uniaxial, shear or compression, got {load!r}")


@dataclass(frozen=True)
class RunKey:
    material: str  # "iso" | "ti"
    load: str
    contact: bool = True
    option: str = "quarter"
    refinement: str = "coarse"
    end_faces: str = "periodic"  # "periodic" | "uz_fixed" (thesis sec. 4.3.5.3), see ContactUnitCell

    @property
    def label(self) -> str:
        return (f"{self.material} {self.load} {'contact' if self.contact else 'no contact'} "
                f"{self.option} {self.refinement}" + ("" if self.end_faces == "periodic" else f" {self.end_faces}"))


@dataclass
class Run:
    key: RunKey
    rows: list[dict]
    stopped: str  # "" if the whole load path converged
    wall_s: float
    ndofs: int
    table: str


def run_case(key: RunKey, steps: int, scale: float = 1.0, weave: PlainWeave | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, time_budget: float = math.inf) -> Run:
    """Solve one load case; returns the converged steps (rows) and why it stopped, if it did (solver
    failure after the bisections, or `time_budget` [s] of wall time used up: no new step is started)."""
    if key.material not in MATERIALS:
        raise ValueError(f"material must be one of {sorted(MATERIALS)}, got {key.material!r}")
    t0 = time.perf_counter()
    cell = unit_cell(PlainWeave.balanced() if weave is None else weave, key.option, key.refinement, comm)
    model = ContactUnitCell(cell, MATERIALS[key.material], contact=key.contact, end_faces=key.end_faces)
    stopped = ""
    try:
        for target, share in load_targets(key.load, scale):
            start, n = model.Phi.copy(), max(1, steps * share)
            for k in range(1, n + 1):
                if time.perf_counter() - t0 > time_budget:
                    raise TimeoutError(f"time budget {time_budget:.0f} s used up")
                model.solve(start + k / n * (target - start), 1)
    except (SolverError, TimeoutError) as exc:
        stopped = str(exc).split(";")[0]
    rows = []
    for s in model.steps:
        c = s.contact
        rows.append(dict(E11=s.E[0, 0], E22=s.E[1, 1], E12=s.E[0, 1], S11=s.S[0, 0], S22=s.S[1, 1], S12=s.S[0, 1],
                         newton=sum(s.newton_iterations), augmentations=s.augmentations,
                         penetration=0.0 if c is None else c.max_penetration,
                         normal_force=0.0 if c is None else c.normal_force,
                         tangential_force=0.0 if c is None else c.tangential_force,
                         active=0 if c is None else c.active, wall_s=s.wall_s, contact_s=s.contact_s,
                         pin_reaction=s.pin_reaction))
    return Run(key, rows, stopped, time.perf_counter() - t0, model.ndofs, contact_table(model.steps))


# figure -> (title, x quantity, y quantities, runs)
def figures(quick: bool) -> dict[str, tuple[str, str, list[str], list[RunKey]]]:
    K = RunKey
    figs = {
        "fig21": ("isotropic yarns: biaxial and uniaxial extension", "E11", ["S11", "S22"],
                  [K("iso", "biaxial"), K("iso", "uniaxial")]),
        "fig22": ("isotropic yarns: in-plane shear", "E12", ["S12"], [K("iso", "shear")]),
        "fig24": ("TI yarns: biaxial and uniaxial extension, with and without contact", "E11", ["S11", "S22"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", contact=False),
                   K("ti", "uniaxial", contact=False)]),
        "fig25": ("TI yarns: biaxial extension and compression", "E11", ["S11", "S22"],
                  [K("ti", "biaxial"), K("ti", "compression")]),
        "fig26": ("TI yarns: in-plane shear", "E12", ["S12"], [K("ti", "shear")]),
        "fig27": ("quarter vs full cell: biaxial and uniaxial extension (end faces periodic / u_z = 0)", "E11",
                  ["S11"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", option="full"),
                   K("ti", "uniaxial", option="full"), K("ti", "biaxial", end_faces="uz_fixed"),
                   K("ti", "biaxial", option="full", end_faces="uz_fixed")]),
        "fig28": ("quarter vs full cell: in-plane shear", "E12", ["S12"],
                  [K("ti", "shear"), K("ti", "shear", option="full")]),
        "fig32": ("coarse vs fine mesh: biaxial and uniaxial extension", "E11", ["S11"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", refinement="fine"),
                   K("ti", "uniaxial", refinement="fine")]),
        "fig33": ("coarse vs fine mesh: in-plane shear", "E12", ["S12"],
                  [K("ti", "shear"), K("ti", "shear", refinement="fine")]),
    }
    if quick:
        keep = {"fig21", "fig24", "fig25", "fig26"}
        figs = {k: v for k, v in figs.items() if k in keep}
        figs["fig24"] = (figs["fig24"][0], "E11", ["S11", "S22"],
                         [K("ti", "biaxial"), K("ti", "biaxial", contact=False)])
    return figs


def _write_csv(path: str, runs: list[Run]) -> None:
    fields = ["curve", "material", "load", "contact", "option", "refinement", "end_faces", "E11", "E22", "E12", "S11", "S22",
              "S12", "newton", "augmentations", "penetration", "normal_force", "tangential_force", "active", "wall_s",
              "contact_s", "pin_reaction", "stopped"]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for run in runs:
            k = run.key
            base = dict(curve=k.label, material=k.material, load=k.load, contact=int(k.contact), option=k.option,
                        refinement=k.refinement, end_faces=k.end_faces, stopped=run.stopped)
            for row in run.rows:
                w.writerow({**base, **{q: f"{v:.10g}" for q, v in row.items()}})


def _plot(path: str, title: str, x: str, ys: list[str], runs: list[Run]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for run in runs:
        xs = [0.0] + [r[x] for r in run.rows]
        for y in ys:
            ax.plot(xs, [0.0] + [r[y] / 1e6 for r in run.rows], marker=".",
                    label=f"{y} {run.key.label}" + (" (stopped)" if run.stopped else ""))
    ax.set_xlabel(x)
    ax.set_ylabel("S [MPa]")
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def previous_runs(folder: str) -> dict[str, Run]:
    """{curve label: Run} read back from the fig*.csv and contact_reports.txt of an earlier run_study
    output folder (rows, stopped reason, wall time, dofs and the report table as written then)."""
    import glob
    import re
    runs: dict[str, Run] = {}
    fields = ("E11", "E22", "E12", "S11", "S22", "S12", "newton", "augmentations", "penetration", "normal_force",
              "tangential_force", "active", "wall_s", "contact_s", "pin_reaction")
    for path in sorted(glob.glob(os.path.join(folder, "fig*.csv"))):
        with open(path) as f:
            rows_by_curve: dict[str, list[dict]] = {}
            meta: dict[str, dict] = {}
            for row in csv.DictReader(f):
                rows_by_curve.setdefault(row["curve"], []).append({q: float(row[q]) for q in fields})
                meta[row["curve"]] = row
        for label, rows in rows_by_curve.items():
            r = meta[label]
            key = RunKey(r["material"], r["load"], bool(int(r["contact"])), r["option"], r["refinement"],
                         r.get("end_faces") or "periodic")
            runs.setdefault(label, Run(key, rows, r["stopped"], sum(x["wall_s"] for x in rows), 0, ""))
    report = os.path.join(folder, "contact_reports.txt")
    if os.path.exists(report):
        for block in open(report).read().split("## ")[1:]:
            head, _, table = block.partition("\n")
            m = re.match(r"(.*) \((\d+) dofs, ([\d.]+) s\)", head)
            if m and m.group(1) in runs:
                run = runs[m.group(1)]
                run.ndofs, run.wall_s, run.table = int(m.group(2)), float(m.group(3)), table.strip()
    return runs


def run_study(out: str = "results/unit_cell", quick: bool = False, steps: int | None = None,
              comm: MPI.Comm = MPI.COMM_WORLD, time_budget: float | None = None,
              recompute: set[RunKey] | None = None, previous: str | None = None) -> dict[RunKey, Run]:
    """Run the figures' load cases (each once, shared between figures), write fig*.csv / fig*.png and
    contact_reports.txt under `out`. quick: only Figs. 21, 24, 25, 26 on the coarse quarter cell, 3 steps
    to 1/4 of the thesis strains (a smoke test of the whole chain). time_budget [s] per load case
    (default: none for quick, 240 s on the coarse quarter cell and 420 s on the full or fine cells).
    recompute + previous: only the load cases in `recompute` are solved; every other curve is read
    back from the earlier output folder `previous` (previous_runs), so that a change touching a few
    cases regenerates all figures without rerunning the rest (ValueError if a curve is missing there)."""
    old = previous_runs(previous) if previous is not None else {}
    n_steps = (3 if quick else 10) if steps is None else int(steps)
    scale = 0.25 if quick else 1.0
    figs = figures(quick)
    runs: dict[RunKey, Run] = {}
    if comm.rank == 0:
        os.makedirs(out, exist_ok=True)
    for name, (title, x, ys, keys) in figs.items():
        for key in keys:
            if key not in runs and recompute is not None and key not in recompute:
                if key.label not in old:
                    raise ValueError(f"previous: no curve {key.label!r} in {previous!r} to reuse")
                runs[key] = old[key.label]
            if key not in runs:
                budget = time_budget if time_budget is not None else (
                    math.inf if quick else 240.0 if (key.option, key.refinement) == ("quarter", "coarse") else 420.0)
                runs[key] = run_case(key, n_steps, scale, comm=comm, time_budget=budget)
                r = runs[key]
                if comm.rank == 0:
                    print(f"[{name}] {key.label}: {len(r.rows)} steps, {r.wall_s:.1f} s"
                          + (f", STOPPED: {r.stopped[:160]}" if r.stopped else ""), flush=True)
        if comm.rank == 0:
            _write_csv(os.path.join(out, f"{name}.csv"), [runs[k] for k in keys])
            _plot(os.path.join(out, f"{name}.png"), f"thesis {name}: {title}", x, ys, [runs[k] for k in keys])
    if comm.rank == 0:
        with open(os.path.join(out, "contact_reports.txt"), "w") as f:
            for key, run in runs.items():
                f.write(f"## {key.label} ({run.ndofs} dofs, {run.wall_s:.1f} s){' STOPPED: ' + run.stopped if run.stopped else ''}\n")
                f.write(run.table + "\n\n")
    return runs


# ------------------------------------------------------------------ fitted membrane law (issue 5, item 5)
def contact_grid_paths(max_stretch: float = 1.06, shear: float = 0.1) -> list[list[np.ndarray]]:
    """Load paths of the fitting grid: biaxial stretches in ratios 1:1, 1:0, 0:1, 1:0.5, 0.5:1 up to
    `max_stretch` (the TI contact cell converges to Phi = 1.13 biaxially, measured) and three shear
    paths (pre-stretches (PRESTRETCH, PRESTRETCH), (max, max), (max, PRESTRETCH), then Phi12 = Phi21 =
    shear): shear at several stretches is needed to determine the stretch-shear coupling terms."""
    d = max_stretch - 1.0
    paths = [[np.diag([1.0 + a * d, 1.0 + b * d, 1.0])] for a, b in
             ((1, 1), (1, 0), (0, 1), (1, 0.5), (0.5, 1))]
    for pre in (np.diag([PRESTRETCH, PRESTRETCH, 1.0]), np.diag([1.0 + d, 1.0 + d, 1.0]),
                np.diag([1.0 + d, PRESTRETCH, 1.0])):
        sheared = pre.copy()
        sheared[0, 1] = sheared[1, 0] = shear
        paths.append([pre, sheared])
    return paths


def fit_contact_law(material: str = "ti", steps: int = 3, degree: int = 4, name: str | None = None,
                    comm: MPI.Comm = MPI.COMM_WORLD):
    """Fit W(E11, E22, 2 E12) (fabricfem.fitted_law, degree `degree`) to the homogenized S of the coarse
    quarter cell WITH contact on the contact_grid_paths grid (every converged step a sample; N = t S with
    t = the fabric thickness 2 (A + b) [m]). Returns (law, samples, fabric or None); the fabric is
    written to fabricfem/fabrics/<name>.json only if `name` is given, the fit is convex on the data
    hull (min Hessian eigenvalue > 0) and its relative RMS residual is at most 5%."""
    from pathlib import Path

    from fabricfem.fabrics import FABRICS_DIR, save_fabric
    from fabricfem.fitted_law import fit_membrane_law, fitted_fabric, samples_from_steps
    weave = PlainWeave.balanced()
    thickness = 2.0 * weave.half_thickness()
    collected = []
    for path in contact_grid_paths():
        model = ContactUnitCell(unit_cell(weave, "quarter", "coarse", comm), MATERIALS[material], contact=True)
        for k, target in enumerate(path):
            model.solve(target, 1 if (len(path) > 1 and k == 0) else steps)
        collected.extend(model.steps)
    samples = samples_from_steps(collected, thickness)
    law = fit_membrane_law(samples, degree=degree)
    fabric = None
    if name is not None and law.min_eigenvalue > 0 and law.relative_rms_residual <= 0.05:
        fabric = fitted_fabric(law, thickness, name=name)
        if comm.rank == 0:
            save_fabric(fabric, Path(FABRICS_DIR) / f"{name}.json",
                        description=f"plain weave (thesis sec. 4.3.5 geometry), {MATERIALS[material].name} yarns, "
                                    f"homogenized with yarn contact (quarter cell, coarse)",
                        source="fabricfem.study_unit_cell.fit_contact_law")
    return law, samples, fabric
