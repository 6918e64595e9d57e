"""Unit-cell study of [Man2006, sec. 4.3.5] (Figs. 20-28, 32-33): `fabricfem study unit-cell`.

Load cases (macroscopic Phi applied in equal increments, [Man2006, sec. 4.3.5]):
  biaxial      Phi11 = Phi22 -> 1.2
  uniaxial     Phi11 -> 1.2, Phi22 = 1
  shear        biaxial pre-stretch Phi11 = Phi22 = 1.02 (one step), then Phi12 = Phi21 -> 0.2
  compression  Phi11 = Phi22 -> 0.9
Yarns: isotropic (lambda = 48.82, mu = 32.55 GPa) or transversely isotropic (thesis parameters),
with or without yarn contact, quarter (option B) or full (option A) cell, coarse or fine mesh.

Yarn end faces (ContactUnitCell end_faces). The thesis' figures all use u*_z = 0 on the yarn end
faces ("uz_fixed", the default here): sec. 4.3.5.3 [Man2006, line 2207] explains the quarter/full
difference of Fig. 27 by "the boundary conditions applied here. In both unit cell models, the local
vertical displacements on the end faces of a yarn are restricted. [...] as an end face, the section
is restricted in the quarter model", and the quarter model is the one of all earlier figures ("The
previous computations are based the quarter unit cell model", same section); sec. 4.3.5 (line 2149)
"Periodic boundary conditions are specified on the pair of end faces of each yarn" is met by u*_x,
u*_y periodic and u*_z = 0 on both faces. The exact periodicity ("periodic") is kept as an extra,
labelled curve where it is cheap (coarse quarter cell; full-cell biaxial for the Fig. 27 check that
the quarter cell is then an exact reduction of the full one).

Every figure gets a CSV (one row per converged step and curve) and a PNG under the output folder;
Figs. 20 and 23 (undeformed and deformed yarns, biaxial extension) are renders (PNG) of the
deformed surface plus the deformed mesh as XDMF (out/snapshots/, for ParaView: WarpByVector with
`displacement`). A run that stops (Newton/augmentation failure, time budget) keeps its converged
steps; the CSV column `stopped` holds the reason, so a curve shorter than its load case is
visible, never silently extrapolated.
Units: S in Pa, E dimensionless, forces in N, lengths in m, times in s.
"""
from __future__ import annotations

import csv
import dataclasses
import glob
import json
import math
import os
import re
import time

import numpy as np
from dolfinx import fem, io, plot
from mpi4py import MPI

from fabricfem import io as fio
from fabricfem.materials.yarn import THESIS_ISOTROPIC, THESIS_TRANSVERSELY_ISOTROPIC, YarnMaterial
from fabricfem.meshes.unit_cell import unit_cell
from fabricfem.meshes.yarn_geometry import PlainWeave
from fabricfem.scenes.batch import Job, check, run_batch
from fabricfem.solvers.newton import SolverError
from fabricfem.weave.unit_cell import ContactUnitCell, contact_table

MATERIALS: dict[str, YarnMaterial] = {"iso": THESIS_ISOTROPIC, "ti": THESIS_TRANSVERSELY_ISOTROPIC}
PRESTRETCH = 1.02  # Phi11 = Phi22 before shear ("a small biaxial pre-stretching", sec. 4.3.5.1)
THESIS_END_FACES = "uz_fixed"  # sec. 4.3.5.3, see the module docstring
# wall-time budget [s] of one load case by (option, refinement); the fine cell costs ~40 s per step; the full coarse
# cell's budget was 420 s while its TI biaxial path stopped at E11 = 0.127 anyway (Uzawa divergence, fixed by the
# penalty growth of fabricfem.contact.yarn.solve_with_contact), 1200 s lets that path go on
TIME_BUDGET = {("quarter", "coarse"): 600.0, ("full", "coarse"): 1200.0, ("quarter", "fine"): 300.0,
               ("full", "fine"): 300.0}


def curve_xy(rows: list[dict], x: str, y: str) -> tuple[np.ndarray, np.ndarray]:
    """Curve with the origin prepended (the unloaded cell has S = 0 at E = 0)."""
    return np.array([0.0] + [r[x] for r in rows]), np.array([0.0] + [r[y] for r in rows])


def secant_spread(rows: list[dict]) -> float:
    """max |S11/E11 / mean - 1| over the steps."""
    E, S = curve_xy(rows, "E11", "S11")
    sec = S[1:] / E[1:]
    return float(np.max(np.abs(sec / sec.mean() - 1.0)))


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


@dataclasses.dataclass(frozen=True)
class RunKey:
    material: str  # "iso" | "ti"
    load: str
    contact: bool = True
    option: str = "quarter"
    refinement: str = "coarse"
    end_faces: str = THESIS_END_FACES  # "uz_fixed" [Man2006, sec. 4.3.5.3] | "periodic", see ContactUnitCell

    @property
    def label(self) -> str:
        ends = "u_z=0" if self.end_faces == "uz_fixed" else self.end_faces
        return (f"{self.material} {self.load} {'contact' if self.contact else 'no contact'} "
                f"{self.option} {self.refinement}, ends {ends}")

    @property
    def slug(self) -> str:
        """File-name form of the key."""
        return "_".join((self.material, self.load, "contact" if self.contact else "nocontact", self.option,
                         self.refinement, self.end_faces))


@dataclasses.dataclass
class Run:
    key: RunKey
    rows: list[dict]
    stopped: str  # "" if the whole load path converged
    wall_s: float
    ndofs: int
    table: str


def write_snapshot(model: ContactUnitCell, path: str) -> None:
    """Deformed state of a solved cell: `path`.xdmf (mesh, `displacement` = (Phi - I) X + u* [m] and
    the fluctuation u* [m]; collective) and, in serial runs, `path`.npz with the yarn boundary surface
    (reference points [m], displacement [m], VTK faces, yarn tag per face) for render_configuration."""
    u = model.problem.u
    V = u.function_space
    Phi = np.asarray(model.Phi, dtype=float)
    X = V.tabulate_dof_coordinates()  # (local + ghost nodes, 3), the order of u's blocks
    disp = fem.Function(V, name="displacement")
    disp.x.array[:] = (X @ (Phi - np.eye(3)).T + u.x.array.reshape(-1, 3)).reshape(-1)  # y - Y, eq. 4.52
    mesh = V.mesh
    with io.XDMFFile(mesh.comm, path + ".xdmf", "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_function(disp)
        xdmf.write_function(u)
    if mesh.comm.size > 1:
        return  # the surface render is serial only (no gather of the distributed surface)
    import pyvista  # optional heavy package, loaded only when a render is made
    topology, cell_types, points = plot.create_vtk_mesh(V)
    grid = pyvista.UnstructuredGrid(topology, cell_types, points)
    n_cells = mesh.topology.index_map(3).size_local
    yarn = np.zeros(n_cells, dtype=np.int32)
    tags = model.cell.cell_tags
    own = tags.indices < n_cells
    yarn[tags.indices[own]] = tags.values[own]
    grid.cell_data["yarn"] = yarn
    grid.point_data["displacement"] = disp.x.array.reshape(-1, 3)
    surface = grid.extract_surface(algorithm="dataset_surface")
    np.savez(path + ".npz", points=np.asarray(surface.points), faces=np.asarray(surface.faces),
             displacement=np.asarray(surface.point_data["displacement"]),
             yarn=np.asarray(surface.cell_data["yarn"]), Phi=Phi)


def render_configuration(npz_path: str, png_path: str, title: str) -> str:
    """Undeformed (left) and deformed (right) yarn surfaces of a write_snapshot .npz as a PNG; pyvista
    off-screen, else (no OpenGL context) a matplotlib 3-D plot of the same faces. Returns the renderer
    used ("pyvista" | "matplotlib")."""
    data = np.load(npz_path)
    points, faces, disp, yarn = data["points"], data["faces"], data["displacement"], data["yarn"]
    Phi = data["Phi"]
    title = f"{title} (Phi11 = {Phi[0, 0]:.4f}, Phi22 = {Phi[1, 1]:.4f}, Phi12 = {Phi[0, 1]:.4f})"
    try:
        import pyvista  # optional heavy package, loaded only when a render is made
        pyvista.OFF_SCREEN = True
        plotter = pyvista.Plotter(off_screen=True, shape=(1, 2), window_size=(1400, 650))
        for col, (name, pts) in enumerate((("undeformed", points), ("deformed", points + disp))):
            plotter.subplot(0, col)
            surf = pyvista.PolyData(pts, faces)
            surf.cell_data["yarn"] = yarn
            plotter.add_mesh(surf, scalars="yarn", cmap="coolwarm", show_edges=True, edge_color="grey",
                             show_scalar_bar=False)
            plotter.add_text(f"{title}: {name}", font_size=9)
            plotter.view_isometric()
        plotter.link_views()
        plotter.subplot(0, 1)
        plotter.reset_camera()  # the shared camera fits the (larger) deformed cell
        plotter.screenshot(png_path)
        plotter.close()
        return "pyvista"
    except Exception as exc:  # no rendering context: matplotlib fallback
        print(f"render_configuration: pyvista failed ({exc}); matplotlib fallback")
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # optional heavy package, loaded only when a plot is drawn
    quads = faces.reshape(-1, 5)[:, 1:] if np.all(faces[::5] == 4) else None
    if quads is None:
        raise ValueError(f"npz_path: {npz_path} holds non-quadrilateral faces")
    fig = plt.figure(figsize=(12, 5.5))
    for col, (name, pts) in enumerate((("undeformed", points), ("deformed", points + disp))):
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        colours = np.where(yarn == yarn.min(), "tab:blue", "tab:red")
        ax.add_collection3d(Poly3DCollection(pts[quads], facecolors=colours, edgecolor="grey", linewidth=0.2))
        lo, hi = (points + disp).min(0), (points + disp).max(0)
        ax.set_xlim(lo[0], hi[0]); ax.set_ylim(lo[1], hi[1]); ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.set_title(f"{title}: {name}", fontsize=9)
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return "matplotlib"


def run_case(key: RunKey, steps: int, scale: float = 1.0, weave: PlainWeave | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, time_budget: float = math.inf, snapshot: str | None = None) -> Run:
    """Solve one load case; returns the converged steps (rows) and why it stopped, if it did (solver
    failure after the bisections, or `time_budget` [s] of wall time used up: no new step is started).
    snapshot: path prefix for write_snapshot of the last converged state (None: none written)."""
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
        stopped = str(exc).split(";")[0]  # ContactUnitCell restores its last converged state itself
    rows = []
    for s in model.steps:
        c = s.contact
        rows.append(dict(E11=s.E[0, 0], E22=s.E[1, 1], E12=s.E[0, 1], S11=s.S[0, 0], S22=s.S[1, 1], S12=s.S[0, 1],
                         newton=sum(s.newton_iterations), augmentations=s.augmentations,
                         penetration=0.0 if c is None else c.max_penetration,
                         normal_force=0.0 if c is None else c.normal_force,
                         tangential_force=0.0 if c is None else c.tangential_force,
                         active=0 if c is None else c.active, wall_s=s.wall_s, contact_s=s.contact_s,
                         pin_reaction=s.pin_reaction, min_det_F=s.min_det_F, sub_increments=s.sub_increments))
    if snapshot is not None and model.steps:
        write_snapshot(model, snapshot)
    return Run(key, rows, stopped, time.perf_counter() - t0, model.ndofs, contact_table(model.steps))


# figure -> (title, x quantity, y quantities, runs)
def figures(quick: bool) -> dict[str, tuple[str, str, list[str], list[RunKey]]]:
    """The plotted figures; every curve has the thesis' end faces u_z = 0 unless labelled periodic."""
    K = RunKey

    def P(*args, **kw) -> RunKey:  # the exact periodicity, extra curve
        return K(*args, end_faces="periodic", **kw)
    figs = {
        "fig21": ("isotropic yarns: biaxial and uniaxial extension", "E11", ["S11", "S22"],
                  [K("iso", "biaxial"), K("iso", "uniaxial"), P("iso", "biaxial"), P("iso", "uniaxial")]),
        "fig22": ("isotropic yarns: in-plane shear", "E12", ["S12"], [K("iso", "shear"), P("iso", "shear")]),
        "fig24": ("TI yarns: biaxial and uniaxial extension, with and without contact", "E11", ["S11", "S22"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", contact=False),
                   K("ti", "uniaxial", contact=False), P("ti", "biaxial"), P("ti", "uniaxial")]),
        "fig25": ("TI yarns: biaxial extension and compression", "E11", ["S11", "S22"],
                  [K("ti", "biaxial"), K("ti", "compression"), P("ti", "compression")]),
        "fig26": ("TI yarns: in-plane shear", "E12", ["S12"], [K("ti", "shear"), P("ti", "shear")]),
        "fig27": ("quarter vs full cell: biaxial and uniaxial extension", "E11", ["S11"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", option="full"),
                   K("ti", "uniaxial", option="full"), P("ti", "biaxial"), P("ti", "biaxial", option="full")]),
        "fig28": ("quarter vs full cell: in-plane shear", "E12", ["S12"],
                  [K("ti", "shear"), K("ti", "shear", option="full")]),
        "fig32": ("coarse vs fine mesh: biaxial and uniaxial extension", "E11", ["S11"],
                  [K("ti", "biaxial"), K("ti", "uniaxial"), K("ti", "biaxial", refinement="fine"),
                   K("ti", "uniaxial", refinement="fine")]),
        "fig33": ("coarse vs fine mesh: in-plane shear", "E12", ["S12"],
                  [K("ti", "shear"), K("ti", "shear", refinement="fine")]),
    }
    if quick:
        figs = {"fig21": (figs["fig21"][0], "E11", ["S11", "S22"], [K("iso", "biaxial"), K("iso", "uniaxial")]),
                "fig24": (figs["fig24"][0], "E11", ["S11", "S22"],
                          [K("ti", "biaxial"), K("ti", "biaxial", contact=False)]),
                "fig25": figs["fig25"][:3] + ([K("ti", "biaxial"), K("ti", "compression")],),
                "fig26": figs["fig26"][:3] + ([K("ti", "shear")],)}
    return figs


# render figure -> (caption, load case): [Man2006, Figs. 20] and 23, (a) undeformed, (b) biaxial extension
RENDERS: dict[str, tuple[str, RunKey]] = {
    "fig20": ("balanced weave, isotropic yarns, biaxial extension", RunKey("iso", "biaxial")),
    "fig23": ("balanced weave, TI yarns, biaxial extension", RunKey("ti", "biaxial")),
}


def _write_csv(path: str, runs: list[Run]) -> None:
    """One line per load step of every run (the figure's curves): the run's key, E, S [Pa] and its counters."""
    fields = ["curve", "material", "load", "contact", "option", "refinement", "end_faces", "E11", "E22", "E12", "S11", "S22",
              "S12", "newton", "augmentations", "penetration", "normal_force", "tangential_force", "active", "wall_s",
              "contact_s", "pin_reaction", "min_det_F", "sub_increments", "stopped"]
    rows = []
    for run in runs:
        k = run.key
        base = dict(curve=k.label, material=k.material, load=k.load, contact=int(k.contact), option=k.option,
                    refinement=k.refinement, end_faces=k.end_faces, stopped=run.stopped)
        rows += [{**base, **{q: f"{v:.10g}" for q, v in row.items()}} for row in run.rows]
    fio.write_csv(path, fields, rows, MPI.COMM_SELF)


def _plot(path: str, title: str, x: str, ys: list[str], runs: list[Run]) -> None:
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    colours = plt.cm.tab10.colors
    for k, run in enumerate(runs):  # one colour per load case; S11/S12 dots, S22 crosses
        xs = [0.0] + [r[x] for r in run.rows]
        dashed = run.key.end_faces == "periodic"  # the extra curves: dashed
        for y, marker in zip(ys, (".", "x")):
            ax.plot(xs, [0.0] + [r[y] / 1e6 for r in run.rows], marker=marker, linestyle="--" if dashed else "-",
                    color=colours[k % len(colours)], markersize=4,
                    label=f"{y} {run.key.label}" + (" (stopped)" if run.stopped else ""))
    ax.set_xlabel(x)
    ax.set_ylabel("S [MPa]")
    ax.set_title(title + "\n(solid: thesis end faces u_z = 0; dashed: exact periodicity)", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=5.5)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def previous_runs(folder: str) -> dict[RunKey, Run]:
    """{RunKey: Run} read back from the fig*.csv and contact_reports.txt of an earlier run_study output
    folder (rows, stopped reason, wall time, dofs and the report table as written then). Keys come from
    the CSV columns (end_faces missing = "periodic", the only condition of the oldest studies), so
    curves are found whatever label format wrote them."""
    by_label: dict[str, Run] = {}
    fields = ("E11", "E22", "E12", "S11", "S22", "S12", "newton", "augmentations", "penetration", "normal_force",
              "tangential_force", "active", "wall_s", "contact_s", "pin_reaction", "min_det_F", "sub_increments")
    for path in sorted(glob.glob(os.path.join(folder, "fig*.csv"))):
        with open(path) as f:
            rows_by_curve: dict[str, list[dict]] = {}
            meta: dict[str, dict] = {}
            for row in csv.DictReader(f):
                rows_by_curve.setdefault(row["curve"], []).append(
                    {q: float(row[q]) for q in fields if row.get(q) not in (None, "")})  # older CSVs lack some
                meta[row["curve"]] = row
        for label, rows in rows_by_curve.items():
            r = meta[label]
            key = RunKey(r["material"], r["load"], bool(int(r["contact"])), r["option"], r["refinement"],
                         r.get("end_faces") or "periodic")
            by_label.setdefault(label, Run(key, rows, r["stopped"], sum(x["wall_s"] for x in rows), 0, ""))
    report = os.path.join(folder, "contact_reports.txt")
    if os.path.exists(report):
        for block in open(report).read().split("## ")[1:]:
            head, _, table = block.partition("\n")
            m = re.match(r"(.*) \((\d+) dofs, ([\d.]+) s\)", head)
            if m and m.group(1) in by_label:
                run = by_label[m.group(1)]
                run.ndofs, run.wall_s, run.table = int(m.group(2)), float(m.group(3)), table.strip()
    return {run.key: run for run in by_label.values()}


# relative size of a cell (the full cell is four quarters; the fine mesh halves the element size in 3-D)
CELL_SIZE = {"quarter": 1.0, "full": 4.0, "coarse": 1.0, "fine": 8.0}


def case_cost(key: RunKey, steps: int) -> float:
    """Estimated relative cost of a load case for the batch's schedule: (cell size)^1.5 (direct solver) x steps,
    twice that with yarn contact (augmentations) and with the shear's pre-stretch step."""
    return ((CELL_SIZE[key.option] * CELL_SIZE[key.refinement]) ** 1.5 * (steps + (key.load == "shear"))
            * (2.0 if key.contact else 1.0))


def _variant_path(out: str, key: RunKey) -> str:
    """Checkpoint of one finished load case: <out>/variants/<slug>.json."""
    return os.path.join(out, "variants", key.slug + ".json")


def _save_run(out: str, run: Run, config: dict) -> None:
    """Write a finished load case (its key, the path settings `config`, rows, stop reason, wall time, dofs and
    contact table; floats round trip) so that an interrupted study resumes without solving it again."""
    rows = [{q: int(v) if isinstance(v, (int, np.integer)) else float(v) for q, v in row.items()} for row in run.rows]
    data = dict(key=dataclasses.asdict(run.key), config=config, rows=rows, stopped=run.stopped, wall_s=run.wall_s,
                ndofs=int(run.ndofs), table=run.table)
    fio.write_text_whole(_variant_path(out, run.key), json.dumps(data))


def _load_run(out: str, key: RunKey, config: dict) -> Run | None:
    """The load case saved by `_save_run` for exactly this key and `config`, or None."""
    try:
        with open(_variant_path(out, key)) as f:
            data = json.load(f)
    except (OSError, ValueError):
        return None
    if data.get("key") != dataclasses.asdict(key) or data.get("config") != config:
        return None
    return Run(key, data["rows"], data["stopped"], data["wall_s"], data["ndofs"], data["table"])


def run_study(out: str = "results/unit_cell", quick: bool = False, steps: int | None = None,
              comm: MPI.Comm = MPI.COMM_WORLD, time_budget: float | None = None,
              recompute: set[RunKey] | None = None, previous: str | None = None,
              reuse: bool | None = None, ranks_per_variant: int = 1) -> dict[RunKey, Run]:
    """Run the figures' load cases (each once, shared between figures), write fig*.csv / fig*.png,
    the renders fig20.png / fig23.png (+ snapshots/*.xdmf) and contact_reports.txt under `out`.
    quick: only Figs. 21, 24, 25, 26 (+ 20, 23) on the coarse quarter cell, 3 steps to 1/4 of the
    thesis strains (a smoke test of the whole chain). time_budget [s] per load case (default: none for
    quick, else TIME_BUDGET by cell).
    The load cases run as one batch (fabricfem.scenes.batch.run_batch, the machinery of `fabricfem sweep`):
    groups of `ranks_per_variant` ranks, longest first (`case_cost`) to the least loaded group. Each finished
    case is saved to <out>/variants/<slug>.json and a rerun reads it back instead of solving it (an interrupted
    study resumes), unless reuse is False or the key is in `recompute`; a case saved with other steps or
    scale is solved again.
    reuse (default: not quick) also reads back a load case whose curve is in the CSVs of the earlier output
    folder `previous` (default `out`; previous_runs, matched by RunKey, so a changed key reruns). A render whose
    snapshot is missing reruns its load case. Delete the folder (or pass the keys in `recompute`) to recompute
    after a solver change."""
    legacy = (not quick) if reuse is None else bool(reuse)
    folder = out if previous is None else previous
    old = previous_runs(folder) if (legacy and os.path.isdir(folder)) else {}
    recompute = set() if recompute is None else set(recompute)
    n_steps = (3 if quick else 10) if steps is None else int(steps)
    scale = 0.25 if quick else 1.0
    config = {"steps": n_steps, "scale": scale}
    figs = figures(quick)
    snap_dir = os.path.join(out, "snapshots")
    snapshots = {key: os.path.join(snap_dir, key.slug) for _, key in RENDERS.values()}
    if comm.rank == 0:
        os.makedirs(snap_dir, exist_ok=True)
    comm.barrier()
    keys = list(dict.fromkeys([k for _, _, _, ks in figs.values() for k in ks] + [k for _, k in RENDERS.values()]))

    def saved(key: RunKey) -> Run | None:
        """The finished case to read back (checkpoint first, then an earlier folder's CSVs), or None."""
        snap = snapshots.get(key)
        have_snap = snap is None or (os.path.exists(snap + ".xdmf") and (  # no .npz from a case solved on > 1 rank
            ranks_per_variant > 1 or os.path.exists(snap + ".npz")))
        if key in recompute or not have_snap or reuse is False:
            return None
        return _load_run(out, key, config) or old.get(key)

    def solve(key: RunKey, sub: MPI.Comm) -> str:
        budget = time_budget if time_budget is not None else (
            math.inf if quick else TIME_BUDGET[(key.option, key.refinement)])
        run = run_case(key, n_steps, scale, comm=sub, time_budget=budget, snapshot=snapshots.get(key))
        if sub.rank == 0:
            _save_run(out, run, config)
        return f"{len(run.rows)} steps" + (f", STOPPED: {run.stopped[:160]}" if run.stopped else "")

    jobs = [Job(key.label, case_cost(key, n_steps), lambda sub, key=key: solve(key, sub),
                lambda key=key: saved(key) is not None) for key in keys]
    check(run_batch(jobs, comm, ranks_per_variant, "unit-cell study"), "unit-cell study", f"{out}/variants")
    runs = {key: _load_run(out, key, config) or old[key] for key in keys}
    if comm.rank == 0:
        for name, (title, x, ys, fig_keys) in figs.items():
            _write_csv(os.path.join(out, f"{name}.csv"), [runs[k] for k in fig_keys])
            _plot(os.path.join(out, f"{name}.png"), f"thesis {name}: {title}", x, ys, [runs[k] for k in fig_keys])
        for name, (caption, key) in RENDERS.items():
            run = runs[key]
            if run.rows and os.path.exists(snapshots[key] + ".npz"):   # the surface of a serial solve
                render_configuration(snapshots[key] + ".npz", os.path.join(out, f"{name}.png"),
                                     f"thesis {name}: {caption}" + (" (stopped early)" if run.stopped else ""))
        with open(os.path.join(out, "contact_reports.txt"), "w") as f:
            for key, run in runs.items():
                f.write(f"## {key.label} ({run.ndofs} dofs, {run.wall_s:.1f} s){' STOPPED: ' + run.stopped if run.stopped else ''}\n")
                f.write(run.table + "\n\n")
    comm.barrier()
    return runs


# ------------------------------------------------------------------ geometry sensitivity
# 0.04 is infeasible with phi = 0.4 and aspect ratio 1.5 (the yarns would interpenetrate at the
# crossing; the smallest feasible crimp is ~0.062), so 0.065 is the lowest crimp that can be built
SENSITIVITY_CRIMPS = (0.04, 0.065, 0.08, 0.10, 0.12)


def geometry_sensitivity(out: str = "docs/figures/unit_cell", crimps: tuple[float, ...] = SENSITIVITY_CRIMPS,
                         end_faces: tuple[str, ...] = ("uz_fixed", "periodic"), steps: int = 10,
                         comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict]:
    """Checks 1-2 of unit-cell-trends (isotropic secant-modulus spread, uniaxial S22/S11 at the last
    step) against the ASSUMED crimp ratio of PlainWeave.balanced (the thesis gives none): coarse quarter
    cell with contact, isotropic yarns, biaxial and uniaxial extension to E11 = 0.22, for each crimp
    and end-face condition. Writes out/geometry_sensitivity.csv (one row per run: geometry, checks,
    E11 at first contact) and .png; returns the rows. A map, not a calibration: the study keeps the
    default crimp."""
    rows = []
    nan = math.nan
    for crimp in crimps:
        try:
            weave = PlainWeave.balanced(crimp=crimp)
        except ValueError as exc:  # e.g. crimp 0.04: phi = 0.4 then needs yarns that interpenetrate
            rows.extend(dict(crimp=crimp, amplitude_m=nan, semi_width_m=nan, semi_height_m=nan, crossing_gap_m=nan,
                             end_faces=ends, load=load, steps=0, last_E11=nan, secant_spread=nan, S22_over_S11=nan,
                             first_contact_E11=nan, wall_s=0.0, stopped=f"geometry infeasible: {exc}", curve_E11="",
                             curve_S11="", curve_S22="") for ends in end_faces for load in ("biaxial", "uniaxial"))
            if comm.rank == 0:
                print(f"crimp {crimp}: geometry infeasible ({exc})", flush=True)
            continue
        yarn = weave.warp
        for ends in end_faces:
            for load in ("biaxial", "uniaxial"):
                key = RunKey("iso", load, end_faces=ends)
                run = run_case(key, steps, weave=weave, comm=comm)
                touching = [r["E11"] for r in run.rows if r["normal_force"] > 0]
                last = run.rows[-1] if run.rows else None
                rows.append(dict(
                    crimp=crimp, amplitude_m=yarn.amplitude, semi_width_m=yarn.semi_width,
                    semi_height_m=yarn.semi_height, crossing_gap_m=2.0 * (yarn.amplitude - yarn.semi_height),
                    end_faces=ends, load=load, steps=len(run.rows), last_E11=math.nan if last is None else last["E11"],
                    secant_spread=secant_spread(run.rows) if run.rows else math.nan,
                    S22_over_S11=math.nan if last is None else last["S22"] / last["S11"],
                    first_contact_E11=touching[0] if touching else math.nan,
                    wall_s=run.wall_s, stopped=run.stopped,
                    curve_E11=" ".join(f"{r['E11']:.5g}" for r in run.rows),
                    curve_S11=" ".join(f"{r['S11']:.5g}" for r in run.rows),
                    curve_S22=" ".join(f"{r['S22']:.5g}" for r in run.rows)))
                if comm.rank == 0:
                    r = rows[-1]
                    print(f"crimp {crimp} {ends} {load}: spread {r['secant_spread']:.3f}, S22/S11 "
                          f"{r['S22_over_S11']:.4f}, contact from E11 {r['first_contact_E11']:.3f}, "
                          f"{r['wall_s']:.0f} s {r['stopped'][:80]}", flush=True)
    if comm.rank == 0:
        os.makedirs(out, exist_ok=True)
        fio.write_csv(os.path.join(out, "geometry_sensitivity.csv"), list(rows[0]),
                      [{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows], comm)
        _plot_sensitivity(os.path.join(out, "geometry_sensitivity.png"), rows)
    return rows


def _plot_sensitivity(path: str, rows: list[dict]) -> None:
    """Checks 1-2 against the crimp (left, middle) and the S11(E11) curves (right: colour = crimp,
    solid = ends u_z = 0, dashed = periodic, circle = biaxial, square = uniaxial); infeasible crimps
    are named in the title."""
    import matplotlib  # optional heavy package, loaded only when a plot is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional heavy package, loaded only when a plot is drawn
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.6))
    styles = {"uz_fixed": "-", "periodic": "--"}
    markers = {"biaxial": "o", "uniaxial": "s"}
    feasible = [r for r in rows if not str(r["stopped"]).startswith("geometry infeasible")]
    infeasible = sorted({r["crimp"] for r in rows} - {r["crimp"] for r in feasible})
    crimps = sorted({r["crimp"] for r in feasible})
    colours = dict(zip(crimps, plt.cm.viridis(np.linspace(0.0, 0.85, max(len(crimps), 1)))))
    for ends in sorted({r["end_faces"] for r in feasible}):
        lab_ends = "u_z=0" if ends == "uz_fixed" else ends
        for load in ("biaxial", "uniaxial"):
            sel = sorted((r for r in feasible if r["end_faces"] == ends and r["load"] == load),
                         key=lambda r: r["crimp"])
            lab = f"{load}, ends {lab_ends}"
            axes[0].plot([r["crimp"] for r in sel], [r["secant_spread"] for r in sel], styles[ends],
                         marker=markers[load], label=lab)
            if load == "uniaxial":
                axes[1].plot([r["crimp"] for r in sel], [r["S22_over_S11"] for r in sel], styles[ends],
                             marker=markers[load], label=lab)
            for r in sel:
                E = [0.0] + [float(v) for v in str(r["curve_E11"]).split()]
                S = [0.0] + [float(v) / 1e6 for v in str(r["curve_S11"]).split()]
                axes[2].plot(E, S, styles[ends], marker=markers[load], markersize=3, color=colours[r["crimp"]],
                             label=f"crimp {r['crimp']}" if (ends, load) == ("uz_fixed", "biaxial") else None)
    axes[0].axhline(0.25, color="k", lw=0.8, ls=":", label="check 1 bound 0.25")
    axes[1].axhline(0.05, color="k", lw=0.8, ls=":", label="check 2 bound 0.05")
    for ax in axes[:2]:
        ax.axvline(0.08, color="grey", lw=0.8, ls="-.", label="default crimp 0.08 (assumed)")
    axes[0].set(xlabel="crimp ratio (assumed)", ylabel="max |secant S11/E11 / mean - 1|",
                title="check 1: isotropic S11 linearity")
    axes[1].set(xlabel="crimp ratio (assumed)", ylabel="S22 / S11 at E11 = 0.22",
                title="check 2: uniaxial S22/S11")
    axes[2].set(xlabel="E11", ylabel="S11 [MPa]", title="S11(E11): solid u_z=0, dashed periodic; o biaxial, s uniaxial")
    axes[2].title.set_fontsize(9)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    fig.suptitle("Isotropic yarns, coarse quarter cell with contact, phi = 0.4, section ratio 1.5: checks 1-2 of "
                 "unit-cell-trends vs the assumed crimp (the thesis gives none)"
                 + (f"; crimp {', '.join(map(str, infeasible))} infeasible (yarns interpenetrate)" if infeasible
                    else ""), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_sensitivity(path: str) -> list[dict]:
    """Rows of a geometry_sensitivity CSV with the numbers as floats (for re-plotting)."""
    text = ("end_faces", "load", "stopped", "curve_E11", "curve_S11", "curve_S22")
    with open(path) as f:
        return [{k: (v if k in text else float(v)) for k, v in row.items()} for row in csv.DictReader(f)]
