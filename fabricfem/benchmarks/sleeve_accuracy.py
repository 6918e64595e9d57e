"""The accuracy choice on the sleeve study's stored mesh series (part of `fabricfem bench accuracy`): the elbow torque
at 57 degrees [Man2006, sec. 5.3] on meshes I-III (10x13, 15x20, 20x26 Q2 cells around x along) is the pilot
sequence, mesh IV (30x39) the reference ("true") value; read from docs/figures/sleeve/mesh_mu0.1.csv and
mesh_mu0.5.csv (written by `fabricfem study sleeve`, one row per variant and degree).

Cell size h = 1 / n_around (n_along / n_around = 1.3 on every mesh), so the refinement ratios are 1.5 and 1.33; the
observed order, the extrapolation and the estimates are fabricfem.scenes.richardson's with the plausible orders of
a dynamic scene (the explicit step follows the mesh), as `fabricfem plan` does. Work: dofs x time steps to
57 degrees (5 dofs per Q2 node, 2 n_around (2 n_along + 1) nodes; the time_steps column summed over the rest and
the flexion). The stored wall times [s] (column wall_s at 57 degrees, 2 ranks of a shared machine) are reported
but not compared: mesh II's exceeds mesh III's. For each target the level of least work whose estimate meets it
is chosen (none: refused), its true error is the distance to mesh IV, and brute force finds the cheapest level
whose true error meets the target. The estimates with a static scene's order range are reported beside them:
they show why an observed order above the formal 2 is taken as not asymptotic.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

from fabricfem.scenes.richardson import ORDERS, richardson

SLEEVE_FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures" / "sleeve"
ANGLE = 57.0                       # deg
PILOT_MESHES = ("I", "II", "III")
REFERENCE_MESH = "IV"
DOFS_PER_NODE = 5


def read_series(path: Path) -> dict[str, dict]:
    """{mesh name: {cells (n_around, n_along), torque [N m] and wall [s] at ANGLE, work}} of a stored mesh series;
    ValueError naming the file when it is missing or lacks a mesh or the angle."""
    if not path.is_file():
        raise ValueError(f"{path}: the sleeve study's mesh series is missing (fabricfem study sleeve writes it)")
    series: dict[str, dict] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            match = re.fullmatch(r"mesh (\w+) \((\d+)x(\d+)\)", row["variant"])
            if match is None or float(row["angle_deg"]) > ANGLE + 1e-6:
                continue
            name, around, along = match.group(1), int(match.group(2)), int(match.group(3))
            entry = series.setdefault(name, {"cells": (around, along), "steps": 0, "torque": None})
            entry["steps"] += int(row["time_steps"])
            if abs(float(row["angle_deg"]) - ANGLE) <= 1e-6:      # records carry the axis to 1e-9
                entry["torque"], entry["wall_s"] = float(row["torque_Nm"]), float(row["wall_s"])
    for name in (*PILOT_MESHES, REFERENCE_MESH):
        if series.get(name, {}).get("torque") is None:
            raise ValueError(f"{path}: no row of mesh {name} at {ANGLE:g} degrees")
        around, along = series[name]["cells"]
        series[name]["work"] = float(DOFS_PER_NODE * 2 * around * (2 * along + 1) * series[name]["steps"])
    return series


def sleeve_choices(targets, figures: Path = SLEEVE_FIGURES) -> list[dict]:
    """One row per friction coefficient and target: the estimate on meshes I-III, the chosen mesh (None: refused),
    its estimated and true errors, and the cheapest mesh meeting the target by brute force (None: none does)."""
    rows = []
    for mu in ("0.1", "0.5"):
        series = read_series(figures / f"mesh_mu{mu}.csv")
        pilots = [series[name] for name in PILOT_MESHES]
        estimate = richardson([p["torque"] for p in pilots], [1.0 / p["cells"][0] for p in pilots],
                              orders=ORDERS["dynamic"])
        static = richardson([p["torque"] for p in pilots], [1.0 / p["cells"][0] for p in pilots],
                            orders=ORDERS["static"])   # what a static scene's order range would have concluded
        exact = series[REFERENCE_MESH]["torque"]
        true = [abs(p["torque"] - exact) / abs(exact) for p in pilots]
        for target in targets:
            meeting = [i for i, e in enumerate(estimate.errors) if e <= target]
            chosen = min(meeting, key=lambda i: pilots[i]["work"]) if meeting else None
            brute = [i for i in range(len(pilots)) if true[i] <= target]
            brute = min(brute, key=lambda i: pilots[i]["work"]) if brute else None
            rows.append({"mu": float(mu), "target": target, "order": estimate.order,
                         "asymptotic": estimate.asymptotic, "note": estimate.note,
                         "torques_Nm": " ".join(f"{series[n]['torque']:.5f}" for n in (*PILOT_MESHES, REFERENCE_MESH)),
                         "walls_s": " ".join(f"{series[n]['wall_s']:.0f}" for n in (*PILOT_MESHES, REFERENCE_MESH)),
                         "estimated_errors": " ".join(f"{e:.3f}" for e in estimate.errors),
                         "true_errors": " ".join(f"{e:.3f}" for e in true),
                         "estimated_errors_static_orders": " ".join(f"{e:.3f}" for e in static.errors),
                         "chosen": None if chosen is None else PILOT_MESHES[chosen],
                         "estimated_error": None if chosen is None else estimate.errors[chosen],
                         "true_error": None if chosen is None else true[chosen],
                         "brute": None if brute is None else PILOT_MESHES[brute],
                         "work_ratio": None if chosen is None or brute is None else
                         pilots[chosen]["work"] / pilots[brute]["work"]})
    return rows


def verdict(row: dict) -> str:
    """One line per row: the choice and whether it holds against mesh IV, said plainly."""
    head = f"sleeve torque at {ANGLE:g} deg, mu = {row['mu']:g}, target {row['target']:.0%}: "
    why = "" if row["asymptotic"] else f"NOT ASYMPTOTIC ({row['note']}), conservative estimates; "
    if row["chosen"] is None:
        held = ("no mesh of I-III meets it against mesh IV either" if row["brute"] is None else
                f"conservative: mesh {row['brute']} meets it against mesh IV, which I-III cannot show")
        return head + why + f"refused (estimates {row['estimated_errors']}); {held}"
    ok = row["true_error"] <= row["target"] and row["work_ratio"] is not None and row["work_ratio"] <= 2.0
    return (head + why + f"mesh {row['chosen']}, estimated {row['estimated_error']:.3f}, true "
            f"{row['true_error']:.3f}; brute force mesh {row['brute']}: {'holds' if ok else 'FAILS'}")
