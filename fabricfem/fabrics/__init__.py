"""Named fabrics stored as JSON (SI units), e.g. fabricfem/fabrics/<name>.json.

A file holds one fabric:

    {"name": str, "description": str (optional), "source": str (optional, provenance),
     "thickness": t [m], "density": rho [kg/m^3],
     "membrane": {"type": "orthotropic-svk", "E1": Pa, "E2": Pa, "G12": Pa, "nu12": -}
              or {"type": "polynomial-even-shear", "exponents": [[a, b, p], ...],
                  "coefficients": [J/m^2, ...], "strain_min": [...], "strain_max": [...], ...}
                  (fabricfem.materials.fitted.FittedMembraneLaw.to_dict: W(E11, E22, 2 E12) fitted to
                   homogenized unit-cell data; N = dW/deps = t S, resultants in N/m)
              or {"type": "convex-ridge", "initial_stiffness": A0 [[N/m]], "directions": [[l1, l2, l3], ...],
                  "terms": [[direction index, "macaulay" | "even", power], ...], "coefficients": [J/m^2, >= 0],
                  ...} (fabricfem.materials.fitted.ConvexMembraneLaw.to_dict: W convex by construction),
     "bending": {"rigidity": [B1, B2] N m (optional),
                 "law": {"type": "kawabata", "coefficients": [...]} or
                        {"type": "square-root", "B0": N m, "kappa0": 1/m} (optional)},
     "transverse_shear": {"G13": Pa (optional), "shear_correction": - (optional)}}

`load_fabric(name)` reads a file of this folder (or any path ending in .json) and returns a
fabricfem.materials.Fabric (with membrane_law set for a fitted law); `save_fabric` writes one.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

from fabricfem.materials import Fabric, KawabataBending, SquareRootBending
from fabricfem.materials.fitted import MEMBRANE_LAW_TYPES, fitted_fabric, membrane_law_from_dict

FABRICS_DIR = Path(__file__).resolve().parent
SVK_TYPE = "orthotropic-svk"


def available_fabrics() -> list[str]:
    """Names of the fabrics stored in this folder."""
    return sorted(p.stem for p in FABRICS_DIR.glob("*.json"))


def _path(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".json":
        return p
    if not isinstance(name_or_path, str) or not name_or_path or "/" in name_or_path:
        raise ValueError(f"name must be a stored fabric name or a .json path, got {name_or_path!r}")
    p = FABRICS_DIR / f"{name_or_path}.json"
    if not p.exists():
        raise ValueError(f"name: no stored fabric {name_or_path!r}; available: {available_fabrics()}")
    return p


def _bending_to_dict(fabric: Fabric) -> dict:
    out: dict = {}
    if fabric.bending_rigidity is not None:
        out["rigidity"] = list(fabric.bending_rigidity)
    law = fabric.bending_law
    if isinstance(law, KawabataBending):
        out["law"] = {"type": "kawabata", "coefficients": list(law.coefficients)}
    elif isinstance(law, SquareRootBending):
        out["law"] = {"type": "square-root", "B0": law.B0, "kappa0": law.kappa0}
    return out


def _bending_law(data: dict | None):
    if not data:
        return None
    kind = data.get("type")
    if kind == "kawabata":
        return KawabataBending(tuple(data["coefficients"]))
    if kind == "square-root":
        return SquareRootBending(data["B0"], data["kappa0"])
    raise ValueError(f"bending.law.type must be 'kawabata' or 'square-root', got {kind!r}")


def fabric_to_dict(fabric: Fabric, description: str = "", source: str = "") -> dict:
    """JSON-ready description of a Fabric (see the module docstring)."""
    if fabric.membrane_law is not None:
        membrane = fabric.membrane_law.to_dict()
    else:
        membrane = {"type": SVK_TYPE, "E1": fabric.E1, "E2": fabric.E2, "G12": fabric.G12, "nu12": fabric.nu12}
    out = {"name": fabric.name, "description": description, "source": source, "thickness": fabric.thickness,
           "density": fabric.density, "membrane": membrane, "bending": _bending_to_dict(fabric),
           "transverse_shear": {"shear_correction": fabric.shear_correction}}
    if fabric.G13 is not None:
        out["transverse_shear"]["G13"] = fabric.G13
    return out


def fabric_from_dict(data: dict) -> Fabric:
    """Fabric from a dictionary written by fabric_to_dict; ValueError naming a missing or bad key."""
    for key in ("name", "thickness", "membrane"):
        if key not in data:
            raise ValueError(f"fabric description: missing key {key!r}")
    bending = data.get("bending") or {}
    shear = data.get("transverse_shear") or {}
    rigidity = bending.get("rigidity")
    common = dict(density=float(data.get("density", 0.0)), G13=shear.get("G13"),
                  bending_rigidity=tuple(rigidity) if rigidity is not None else None,
                  bending_law=_bending_law(bending.get("law")), name=str(data["name"]))
    membrane = data["membrane"]
    kind = membrane.get("type")
    if kind in MEMBRANE_LAW_TYPES:
        fabric = fitted_fabric(membrane_law_from_dict(membrane), data["thickness"], **common)
    elif kind == SVK_TYPE:
        for key in ("E1", "E2", "G12", "nu12"):
            if key not in membrane:
                raise ValueError(f"membrane: missing key {key!r}")
        fabric = Fabric(E1=membrane["E1"], E2=membrane["E2"], G12=membrane["G12"], nu12=membrane["nu12"],
                        thickness=data["thickness"], **common)
    else:
        raise ValueError(f"membrane.type must be one of {[SVK_TYPE, *sorted(MEMBRANE_LAW_TYPES)]}, got {kind!r}")
    if "shear_correction" in shear:
        sc = float(shear["shear_correction"])
        if not (math.isfinite(sc) and sc > 0):
            raise ValueError(f"transverse_shear.shear_correction must be positive, got {sc!r}")
        fabric = Fabric(**{**{f: getattr(fabric, f) for f in fabric.__dataclass_fields__}, "shear_correction": sc})
    return fabric


def load_fabric(name_or_path: str | Path) -> Fabric:
    """The fabric stored as fabricfem/fabrics/<name>.json, or in the given .json file."""
    path = _path(name_or_path)
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"name: {path} is not valid JSON ({err})") from err
    return fabric_from_dict(data)


def save_fabric(fabric: Fabric, path: str | Path, description: str = "", source: str = "") -> Path:
    """Write the fabric as JSON to `path` (a .json file) and return the path."""
    p = Path(path)
    if p.suffix != ".json":
        raise ValueError(f"path must end in .json, got {str(path)!r}")
    if not isinstance(fabric, Fabric):
        raise ValueError(f"fabric must be a fabricfem.materials.Fabric, got {type(fabric).__name__}")
    text = json.dumps(fabric_to_dict(fabric, description, source), indent=1)
    # one line per innermost list (exponent triples, terms, coefficients, ranges)
    text = re.sub(r"\[[-+\w.,\s\"]*\]", lambda m: re.sub(r"\s+", " ", m.group(0)).replace("[ ", "[")
                  .replace(" ]", "]"), text)
    p.write_text(text + "\n")
    return p
