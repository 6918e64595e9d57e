"""The pants of the thesis's walking study [Man2006, sec. 5.4]: four panels (left/right x front/back) with a crotch
cut, sized from the lower body with ordinary trouser ease, written as a GarmentCode pattern [Korosteleva2021].

Topology and placement conventions are those of the four-panel trousers of Garment-Pattern-Generator
(fabricfem/patterns/pants_straight_sides.json: the same vertex order, edges, stitches, Euler rotations; its
frame is Y-up, front +z, left +x, centimetres). Each panel, in its own plane (outer side at x = 0 at the crotch
level, the centre towards -x for the left front panel), has the vertices

    v0 = (-a, 0)                  waistband, centre end     v3 = (-(T - H) / 2, -(r + L))   hem, outer end
    v1 = (-b, 0)                  waistband, side end       v4 = (-(T + H) / 2, -(r + L))   hem, inner end
    v2 = (0, -r)                  side at the crotch level  v5 = (-T, -r)                   crotch point

with the edges v5-v4 (inseam), v4-v3 (hem), v3-v2 (outer side), v2-v1 (hip side), v1-v0 (waistband) and v0-v5
(the crotch curve, a quadratic Bezier bulging as in the template), and the sizes, from LowerBodyDimensions and
PantsEase [m]:

    r = waist_height - crotch_height + ease.rise      rise (0.210 m for the ANSUR II median male, + 0.06 m)
    L = crotch_height - ankle_height - hem_clearance - ease.rise
                                                      inseam (0.632 m): the hem ends above the foot
    T = (thigh_girth + ease.thigh) / 2                half the thigh girth with ease: front + back panels
    H = (calf_girth + ease.knee) / 2                  the hem, straight from the knee down (the feet are off
                                                      while the pants go on, [Man2006, sec. 5.4])
    a - b = (waist_girth + ease.waist) / 4            a quarter of the waistband
    b = ease.side_inset                               the hip side's inset at the waistband

The leg tapers on both sides, so that the leg's centre line (x = -T / 2, the front crease of a trouser draft) is
straight from the crotch level to the hem. The panels are placed flat in front of and behind the body with that
centre line on the leg's axis (half the body's hip joint spacing from the midline); the left and right front (back) panels then
overlap near the crotch, so the right ones are placed `ease.layer_gap` farther from the body. Each panel is tilted
about its waistband line (the Euler angle about GarmentCode's x, the same for all four) so that its hem lies
`ease.hem_depth` in front of (behind) the leg's axis, while the waistband stays `ease.depth` off the pelvis:

    sin(tilt) = (pelvis_depth + depth - hem_depth) / (r + L)          (7.07 deg; the hem rises (r + L)(1 - cos) = 7 mm)

Placed upright, 0.18 m in front of and behind the thin shank, each pair of leg panels was drawn by its seams into a
slit a few centimetres wide through the shank, and on a fine mesh a trouser leg closed beside it. Placed with the
outer side straight and the crotch point at the midline instead (the template's way), the lower leg lay beside
the shank: the seams closed around no leg, and the shank stood outside the trousers after the sewing
(docs/findings/2026-11-28-pants-placement.md).

The seat (the panel's width half-way up the rise, four panels) comes out at
(a + T - b) / 2 x 4 = buttock girth + `seat_ease` (reported). Front and back panels have the same shape, so every
stitched pair of edges has the same length. The thesis's fabric is the sleeve's cotton (E = 1.2 MPa, G = 0.1 MPa,
rho = 436 kg/m^3) at 1 or 2 mm.
"""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

from fabricfem.body.lower_body import DEFAULT_LOWER_BODY, LowerBodyDimensions
from fabricfem.patterns import pattern_path

CM = 100.0   # GarmentCode units per metre
PANTS_BODY = replace(DEFAULT_LOWER_BODY, hip_spacing=0.22)   # scenes/pants_walk.toml's body (the shipped pattern's)


@dataclass(frozen=True)
class PantsEase:
    """Trouser ease [m] over the body's girths (ordinary men's trousers: thigh +3-5 cm, bent knee +4-6 cm,
    seat ~ +10 cm, the notes of the project)."""

    thigh: float = 0.04
    knee: float = 0.05
    waist: float = 0.02
    side_inset: float = 0.02
    depth: float = 0.03              # m between the body's pelvis and the placed front and back panels
    layer_gap: float = 0.01          # m between the left and the right panels where they overlap when placed
    rise: float = 0.06               # m added to the rise (the crotch curve's depth) and taken from the inseam: the
                                     # body's crotch length (pelvis, waist to waist between the legs) is 0.596 m
    hem_clearance: float = 0.08      # m between the ankle joint and the hem (the ellipsoid foot's top is 0.06-0.07
                                     # m above it where the hem goes round)
    hem_depth: float = 0.07          # m between the leg's axis and the placed hem, in front and behind: H / pi, the
                                     # radius of a hem as round as its girth allows


def pants_sizes(dims: LowerBodyDimensions = DEFAULT_LOWER_BODY, ease: PantsEase = PantsEase()) -> dict[str, float]:
    """The panel sizes [m] of the module docstring and the resulting seat ease."""
    r = dims.waist_height - dims.crotch_height + ease.rise
    L = dims.crotch_height - dims.ankle_height - ease.hem_clearance - ease.rise
    T = 0.5 * (dims.thigh_girth + ease.thigh)
    H = 0.5 * (dims.calf_girth + ease.knee)
    b = ease.side_inset
    a = b + 0.25 * (dims.waist_girth + ease.waist)
    if not (0.0 < H <= T and 0.0 < b < a and r > 0.0 and L > 0.0):
        raise ValueError(f"dimensions: the pants need 0 < hem <= thigh width and a positive rise and inseam, got "
                         f"rise {r:.3f}, inseam {L:.3f}, thigh {T:.3f}, hem {H:.3f} m")
    seat = 4.0 * 0.5 * (a + T - b)
    return {"rise": r, "inseam": L, "thigh": T, "hem": H, "a": a, "b": b, "seat_girth": seat,
            "seat_ease": seat - dims.buttock_girth}


def pants_garmentcode(dims: LowerBodyDimensions = PANTS_BODY, ease: PantsEase = PantsEase(),
                      pelvis_depth: float = 0.151) -> dict:
    """The GarmentCode JSON (a dict) of the pants (module docstring) for the body `dims` (its hip joint spacing
    places the legs); `pelvis_depth` [m] is the body's front-back semi-axis at the pelvis (the panels are placed
    `ease.depth` in front of and behind it)."""
    s = pants_sizes(dims, ease)
    r, L, T, H, a, b = (s[k] for k in ("rise", "inseam", "thigh", "hem", "a", "b"))
    axis = 0.5 * dims.hip_joint_spacing
    if not 0.0 < ease.hem_depth <= pelvis_depth + ease.depth:
        raise ValueError(f"ease.hem_depth must lie in (0, {pelvis_depth + ease.depth:.3f}] m (the waistband's distance "
                         f"from the leg's axis), got {ease.hem_depth!r}")
    template = json.loads(pattern_path("pants_straight_sides").read_text())
    out = copy.deepcopy(template)
    hem = r + L
    left = [[-a, 0.0], [-b, 0.0], [0.0, -r], [-0.5 * (T - H), -hem], [-0.5 * (T + H), -hem], [-T, -r]]
    x_shift = (axis + 0.5 * T) * CM                                # the leg's centre line on the leg's axis
    for name, panel in out["pattern"]["panels"].items():
        sign = -1.0 if panel["vertices"][0][0] < 0 else 1.0        # the template's mirrored panels
        panel["vertices"] = [[round((x if sign < 0 else -x) * CM, 6), round(y * CM, 6)] for x, y in left]
        side = 1.0 if name.startswith("L") else -1.0
        gap = ease.layer_gap if side < 0 else 0.0
        z = (pelvis_depth + ease.depth + gap) * CM
        panel["translation"] = [side * x_shift, 0.0, z if name.endswith("front") else -z]
        tilt = math.degrees(math.asin((pelvis_depth + ease.depth - ease.hem_depth) / hem))
        panel["rotation"] = [round(tilt, 6), 0.0 if name.endswith("front") else 180.0, 0.0]
    out["pattern"]["description"] = ("fabricfem pants [Man2006, sec. 5.4], four panels sized from the lower body "
                                     "(fabricfem.wear.pants)")
    return out


def pants_wraps(dims: LowerBodyDimensions = PANTS_BODY, ease: PantsEase = PantsEase(), waistband_height: float = 0.935,
                radius: float = 0.12, inseam_clearance: float = 0.005) -> dict[str, dict]:
    """The scene's `[garment.wrap]` (fabricfem.scenes.panel_placement) rolling each panel of `pants_garmentcode`
    onto a vertical cylinder of `radius` [m] round its own leg, in the body frame (x front, y left, z up):

        axis through (0, +-c, waistband_height), c = inseam_clearance + radius sin(T / (2 radius))
        zero_direction = +-y (the leg's outer side), angle0 = +-(pi / 2 - T / (2 radius))

    so that the leg's centre line (panel x = -+T / 2) lies straight in front of (behind) the axis, the outer side
    seam's two edges lie 2 (pi / 2 - T / (2 radius)) radius apart round the outside and the inseam ends
    `inseam_clearance` [m] from the midline on the leg's own side: no seam is sewn across the other leg. The panel's
    y = 0 (the waistband line) lies at `waistband_height` [m]. Needs T / pi <= radius (the panel goes at most
    half-way round)."""
    T = pants_sizes(dims, ease)["thigh"]
    if not (math.isfinite(radius) and radius >= T / math.pi):
        raise ValueError(f"radius: must be at least T / pi = {T / math.pi:.4f} m (a panel goes at most half-way "
                         f"round), got {radius!r}")
    if not (math.isfinite(inseam_clearance) and inseam_clearance > 0.0):
        raise ValueError(f"inseam_clearance: must be a positive length [m], got {inseam_clearance!r}")
    centre = inseam_clearance + radius * math.sin(0.5 * T / radius)
    start = math.degrees(0.5 * math.pi - 0.5 * T / radius)
    wraps = {}
    for name in ("Lfront", "Lback", "Rfront", "Rback"):
        side = 1.0 if name[0] == "L" else -1.0
        x_sign = 1.0 if name in ("Lback", "Rfront") else -1.0          # the panels' x runs from 0 to +-T
        wraps[name] = {"axis_point": [0.0, round(side * centre, 6), waistband_height], "axis": [0.0, 0.0, 1.0],
                       "radius": radius, "zero_direction": [0.0, side, 0.0], "angle0": round(x_sign * start, 6)}
    return wraps


def write_pants_pattern(path: str | Path, dims: LowerBodyDimensions = PANTS_BODY,
                        ease: PantsEase = PantsEase()) -> Path:
    """Write `pants_garmentcode(dims, ease)` to `path` (JSON, indent 1); the defaults write the shipped
    fabricfem/patterns/pants_four_panel.json."""
    path = Path(path)
    path.write_text(json.dumps(pants_garmentcode(dims, ease), indent=1) + "\n")
    return path
