"""A real body nobody here made: the human of the Debian package assimp-testmodels, rigged to the lower body.

The file `models/Collada/human.zae` (HUMAN.blend (c) 2010 Tobias Rittig, "Redistribution and reuse allowed for any
purpose", `models/BLEND/HUMAN.source.txt` of the same package) is a standing adult in an A pose (arms hanging at
about 45 degrees, feet 0.37 m apart): COLLADA, metres, y up, facing +z, 1.66 m tall; its body is one closed surface
of 26756 triangles (13380 vertices), with four open eye shells beside it (read with `HUMAN_KEYS`:
`fabricfem.body.mesh_skin.read_skin` keeps the body, the largest part).

`HUMAN_REST` gives the lower body's joints (fabricfem.body.lower_body) in that mesh, in the body frame (x forward,
y left, z up, metres), measured on horizontal sections of the mesh (the centroids of the leg sections at the
narrowest knee and ankle heights, the hip joints on the line through them 2 cm above the crotch, the waist at the
narrowest trunk section); the markers are placed as `lower_body_points` places them (0.15 m laterally from the
thigh and shank midpoints, above the foot, in front of the waist and pelvis). `HUMAN_DIMENSIONS` are the lower
body's lengths between those joints and the girths of the same sections, so that a gait of these dimensions
moves the segments by the lengths the mesh has.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fabricfem.body.lower_body import MARKER_OFFSET, SIDES, LowerBodyDimensions

HUMAN_PATH = Path("/usr/share/assimp/models/Collada/human.zae")
HUMAN_KEYS = {"units": "m", "up": "y"}       # read_skin keys of the file

_TRUNK = {"waist": (0.04, 0.0, 1.04), "crotch": (0.02, 0.0, 0.81)}
_LEG = {"hip": (0.03, 0.10, 0.82), "knee": (0.03, 0.147, 0.46), "ankle": (0.025, 0.18, 0.065),
        "toe": (0.14, 0.19, 0.022)}          # left side (+y); the right side mirrors y


def human_rest() -> dict[str, np.ndarray]:
    """The lower body's joints and markers [m] in the human mesh's rest pose (module docstring)."""
    up, front = np.array([0.0, 0.0, 1.0]), np.array([MARKER_OFFSET, 0.0, 0.0])
    out = {name: np.array(p) for name, p in _TRUNK.items()}
    rise = out["waist"][2] - out["crotch"][2]
    out["chest"] = out["waist"] + rise * up
    out["trunk_marker"] = out["waist"] + front
    out["pelvis_marker"] = out["crotch"] + 0.5 * rise * up + front
    for s, sign in SIDES.items():
        mirror = np.array([1.0, sign, 1.0])
        side = np.array([0.0, sign, 0.0])
        p = {name: mirror * np.array(q) for name, q in _LEG.items()}
        out.update({f"{name}_{s}": q for name, q in p.items()})
        out[f"thigh_marker_{s}"] = 0.5 * (p["hip"] + p["knee"]) + MARKER_OFFSET * side
        out[f"shank_marker_{s}"] = 0.5 * (p["knee"] + p["ankle"]) + MARKER_OFFSET * side
        out[f"foot_marker_{s}"] = 0.5 * (p["ankle"] + p["toe"]) + MARKER_OFFSET * up
    return out


def _length(a: str, b: str) -> float:
    return float(np.linalg.norm(np.subtract(_LEG[a], _LEG[b])))


HUMAN_DIMENSIONS = LowerBodyDimensions(
    thigh_length=_length("hip", "knee"), shank_length=_length("knee", "ankle"), foot_length=0.233,
    foot_breadth=0.065, thigh_girth=0.51, calf_girth=0.353, ankle_girth=0.22, hip_breadth=0.32, waist_girth=0.70,
    buttock_girth=0.966, waist_height=_TRUNK["waist"][2], crotch_height=_TRUNK["crotch"][2],
    ankle_height=_LEG["ankle"][2], heel_fraction=1.0 - _length("ankle", "toe") / 0.233,
    hip_spacing=2.0 * _LEG["hip"][1])
