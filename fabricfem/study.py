"""`fabricfem study sleeve`: the arm-sleeve parameter study of thesis sec. 5.3 (Figs. 37, 39, 42, 44-46).

Each variant is one flexion (fabricfem.sleeve, explicit dynamics by default) giving a resisting-torque-vs-angle curve;
each figure gets <out>/<figure>.csv (variant, angle_deg, torque_Nm, ...) and <out>/<figure>.png. Variants
that stop before the final angle (blow-up or Newton failure, see fabricfem.sleeve) keep their partial curve and the
reason is written to <out>/failures.csv. Independent variants are shared over the MPI ranks (each rank
runs its variants on COMM_SELF). `quick` runs mesh I only, to 6 degrees (records at 3 and 6; test suite):
its numbers are a reduced study, not the thesis's. `fine` / `meshes` choose the mesh of the parameter
figures (default III, as the thesis's "well-refined" sleeve) and of the mesh series (default I-IV); a
coarser choice is a reduced-resolution study and README.txt says so.
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

from mpi4py import MPI

from fabricfem.sleeve import SleeveConfig, SleeveHistory, plot_torque, run_sleeve

MESHES = {"I": (10, 13), "II": (15, 20), "III": (20, 26), "IV": (30, 39)}
FABRICS = {"I": dict(E=1.2e6, G=1.2e6 / 200, density=436.0),       # thesis sec. 5.3.5, G = E / 200
           "II": dict(E=350e6, G=350e6 / 200, density=436.0),
           "III": dict(E=7.2e9, G=7.2e9 / 200, density=700.0)}
FIGURE_TITLES = {"mesh_mu0.1": "mesh convergence, mu = 0.1 (Fig. 37)",
                 "mesh_mu0.5": "mesh convergence, mu = 0.5 (Fig. 39)",
                 "friction": "friction 0.1 vs 0.5 (Fig. 42)", "fit": "fit R = 0.06 vs 0.07 m, mu = 0.5 (Fig. 44)",
                 "thickness": "thickness 1 vs 2 mm, mu = 0.5 (Fig. 45)", "fabrics": "fabrics I-III, mu = 0.1 (Fig. 46)"}


def variants(quick: bool = False, fine: str = "III", meshes: tuple[str, ...] = ("I", "II", "III", "IV"),
             fabrics: tuple[str, ...] = ("I", "II", "III")) -> dict[str, dict[str, SleeveConfig]]:
    """figure -> {label: config}. Identical configurations appear in several figures (run once).

    `fabrics` selects the fabric sets of the fabrics figure: the explicit step scales with
    h / sqrt(E / rho), so fabrics II and III need 17 and 60 times the steps of fabric I."""
    for name in (fine, *meshes):
        if name not in MESHES:
            raise ValueError(f"fine / meshes: unknown mesh {name!r}, expected one of {sorted(MESHES)}")
    for name in fabrics:
        if name not in FABRICS:
            raise ValueError(f"fabrics: unknown fabric set {name!r}, expected one of {sorted(FABRICS)}")
    base = SleeveConfig()
    meshes = {"I": MESHES["I"]} if quick else {k: MESHES[k] for k in meshes}
    fine = MESHES["I"] if quick else MESHES[fine]
    if quick:
        base = base.with_(final_angle=6.0, angle_steps=2, output_angle_step=3.0)
    at = lambda mesh, **kw: base.with_(n_around=mesh[0], n_along=mesh[1], **kw)  # noqa: E731
    figures = {
        "mesh_mu0.1": {f"mesh {k} ({m[0]}x{m[1]})": at(m, friction=0.1) for k, m in meshes.items()},
        "mesh_mu0.5": {f"mesh {k} ({m[0]}x{m[1]})": at(m, friction=0.5) for k, m in meshes.items()},
        "friction": {"mu = 0.1": at(fine, friction=0.1), "mu = 0.5": at(fine, friction=0.5)},
        "fit": {"R = 0.06 m": at(fine, friction=0.5), "R = 0.07 m": at(fine, friction=0.5, radius=0.07)},
        "thickness": {"t = 1 mm": at(fine, friction=0.5), "t = 2 mm": at(fine, friction=0.5, thickness=2e-3)},
        "fabrics": {f"fabric {k}": at(fine, friction=0.1, **FABRICS[k]) for k in fabrics},
    }
    return figures


def run_study(out: str | Path = "results/sleeve_study", quick: bool = False,
              comm: MPI.Comm = MPI.COMM_WORLD, fine: str = "III",
              meshes: tuple[str, ...] = ("I", "II", "III", "IV"),
              fabrics: tuple[str, ...] = ("I", "II", "III")) -> dict[str, dict[str, SleeveHistory]]:
    """Run every distinct variant once (round-robin over the ranks), write CSV + PNG per figure."""
    out = Path(out)
    figures = variants(quick, fine, meshes, fabrics)
    unique: list[SleeveConfig] = []
    for fig in figures.values():
        for cfg in fig.values():
            if cfg not in unique:
                unique.append(cfg)
    say = (lambda m: print(m, flush=True)) if comm.rank == 0 else (lambda m: None)
    say(f"sleeve study{' (quick, reduced)' if quick else ''}: {len(unique)} variants on {comm.size} rank(s)")
    t0 = time.perf_counter()
    mine = {}
    for i, cfg in enumerate(unique):
        if i % comm.size != comm.rank:
            continue
        h = run_sleeve(cfg, MPI.COMM_SELF, stop_on_failure=False)
        mine[i] = h
        print(f"  [rank {comm.rank}] variant {i + 1}/{len(unique)}: {cfg.n_around}x{cfg.n_along} mu={cfg.friction} "
              f"R={cfg.radius} t={cfg.thickness} E={cfg.E:.3g}: reached {h.angles[-1]:.1f} deg, torque "
              f"{h.torques[-1]:.4e} N m, {h.wall:.0f} s ({time.perf_counter() - t0:.0f} s elapsed)"
              + (f" STOPPED: {h.failure}" if h.failure else ""), flush=True)
    gathered = comm.allgather(mine)
    histories = {k: v for d in gathered for k, v in d.items()}
    results = {name: {label: histories[unique.index(cfg)] for label, cfg in fig.items()}
               for name, fig in figures.items()}
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        failures = []
        for name, curves in results.items():
            with open(out / f"{name}.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["variant", *SleeveHistory.HEADER])
                for label, h in curves.items():
                    for row in h.rows():
                        w.writerow([label, *row])
                    if h.failure:
                        failures.append([name, label, h.failure])
            plot_torque(out / f"{name}.png", {label: (h.angles, h.torques) for label, h in curves.items()},
                        FIGURE_TITLES[name] + (" [quick]" if quick else ""))
        with open(out / "failures.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["figure", "variant", "reason"])
            w.writerows(failures)
        (out / "README.txt").write_text(
            ("QUICK (reduced) study: mesh I only, 6 degrees\n" if quick else
             "full study\n" if (fine, tuple(meshes), tuple(fabrics)) == ("III", tuple(MESHES), tuple(FABRICS)) else
             f"REDUCED study: parameter figures on mesh {fine}, mesh series {', '.join(meshes)}, "
             f"fabrics {', '.join(fabrics)}\n")
            + f"wall time {time.perf_counter() - t0:.0f} s on {comm.size} rank(s)\n")
    say(f"wrote {out}/<figure>.csv and .png for {sorted(results)} ({time.perf_counter() - t0:.0f} s)")
    return results
