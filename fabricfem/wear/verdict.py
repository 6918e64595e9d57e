"""The verdict of a wear run: plausibility checks of its records, each with its value and its bound.

A run that reaches its end can still be implausible: skin pressures of MPa where real garments press with a few kPa,
Green strains of 3 in a woven fabric, a seam left 0.14 m open, a body that never touches the garment. Each check
compares one measured quantity of the history (fabricfem.wear.contract.WearHistory) with a bound (`Bounds`, the
wear scene's [checks] section; the strain bound is the fabric's `failure_strain`):

    penetration        largest penetration of the cloth into the body after the sewing [m]  <= max_penetration
    seam gap           largest distance of stitched nodes after the sewing [m]              <= max_seam_gap
    fabric strain      largest warp/weft Green strain of a vertex (the average over its patch of cells, the
                       strain limiter's measure) after the sewing [-]                      <= failure_strain
    local strain       largest warp/weft Green strain at a quadrature point after the sewing [-]: information
                       (never fails; singular at point pins and at the corners where seams meet, so it grows
                       with refinement there)
    skin pressure      largest contact pressure on the body during the motion [Pa]         <= max_skin_pressure
    kinetic energy     largest kinetic / strain energy ratio during the motion [-], the cloth's kinetic energy
                       relative to the body's motion where the record has it (fabricfem.wear.relative_motion:
                       a garment moving with a walking body is not flapping)           <= max_kinetic_ratio
    start distance     smallest garment-body gap at the start [m], for a garment that is not sewn, pulled or
                       grown onto the body first                                            <= max_start_gap
    contact            the body touches the garment during the motion (largest contact force > 0 [N])
    intersecting       the largest number of intersecting triangle pairs of the cloth over the records
    triangle pairs     (fabricfem.contact.intersections; counted by the explicit engine)    <= 0 with self-contact
                       on; without it the count is reported as information (never fails)

A failed check is one console line and an entry of summary.json's "verdict"; the run's status becomes
"completed with warnings" and `fabricfem run` exits with EXIT_WARNINGS (3), distinct from success (0), a run that
stopped early (1) and an input error (2).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from fabricfem.parameters import param as doc
from fabricfem.wear.contract import WearHistory, largest_local_strain
from fabricfem.wear.engine import kinetic_ratio

EXIT_WARNINGS = 3                  # exit code of a run that completed with failed checks
DEFAULT_FAILURE_STRAIN = 0.3       # Green strain; woven fabrics break at 10-35 % engineering strain


@dataclass(frozen=True)
class Bounds:
    """[checks]: the bounds of a wear run's plausibility checks (SI units)."""

    max_penetration: float = doc("largest penetration of the cloth into the body after the sewing [m]", 1e-3)
    max_seam_gap: float = doc("largest distance of stitched nodes after the sewing [m]", 2e-3)
    max_skin_pressure: float = doc("largest contact pressure on the body during the motion [Pa] (garments press "
                                   "with a few kPa; compression classes reach 6-8 kPa)", 100e3)
    max_kinetic_ratio: float = doc("largest kinetic (relative to the body) / strain energy ratio during the motion "
                                   "[-] (a worn garment moves quasi-statically: the shipped sleeve's whole flexion "
                                   "reached 0.26 on 44 x 57 in the ground frame, in the start-up of the flexion)", 0.5)
    max_start_gap: float = doc("largest garment-body distance at the start [m] (farther: the motion file or the "
                               "garment is misplaced)", 0.05)
    require_contact: bool = doc("warn when the body never touches the garment during the motion", True)

    def __post_init__(self):
        for key in ("max_penetration", "max_seam_gap", "max_skin_pressure", "max_kinetic_ratio", "max_start_gap"):
            value = getattr(self, key)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a positive finite bound, got {value!r}")


@dataclass(frozen=True)
class Check:
    """One plausibility check: `value` against `bound` (`passed` when value <= bound), in `unit`."""

    name: str
    what: str
    value: float
    bound: float
    unit: str
    passed: bool

    def line(self) -> str:
        """The console line of a failed check."""
        unit = f" {self.unit}" if self.unit else ""
        return (f"CHECK FAILED {self.name}: {self.what} {self.value:.4g}{unit} above its bound {self.bound:.4g}{unit}"
                if self.name != "contact" else f"CHECK FAILED contact: {self.what}")


def bounded_check(name: str, what: str, value: float, bound: float, unit: str) -> Check:
    """The Check of `value` <= `bound` (a non-finite value fails)."""
    return Check(name, what, float(value), float(bound), unit, bool(math.isfinite(value) and value <= bound))


def wear_checks(history: WearHistory, bounds: Bounds = Bounds(),
                failure_strain: float = DEFAULT_FAILURE_STRAIN) -> list[Check]:
    """The checks of a history (module docstring); none when it has no records."""
    steps = history.steps
    if not steps:
        return []
    sewn = [s for s in steps if s.phase != "sew"] or steps
    motion = [s for s in steps if s.phase == "motion"] or steps
    checks = [
        bounded_check("penetration", "largest penetration after the sewing", max(s.max_penetration for s in sewn),
               bounds.max_penetration, "m"),
        bounded_check("seam gap", "largest seam gap after the sewing", max(s.seam_gap for s in sewn), bounds.max_seam_gap,
               "m"),
        bounded_check("fabric strain", "largest Green strain of a vertex (its patch's average) after the sewing "
                      "(fabric failure_strain)", max(s.max_strain for s in sewn), failure_strain, ""),
        bounded_check("skin pressure", "largest contact pressure on the body during the motion",
               max(s.peak_pressure for s in motion), bounds.max_skin_pressure, "Pa"),
    ]
    if any(s.time_steps for s in motion):
        kinetic = np.array([s.kinetic_energy if math.isnan(s.relative_kinetic_energy) else s.relative_kinetic_energy
                            for s in motion])
        ratio = kinetic_ratio(kinetic, np.array([s.strain_energy for s in motion]))
        checks.append(bounded_check("kinetic energy", "largest kinetic (relative to the body) / strain energy ratio "
                                    "during the motion", ratio, bounds.max_kinetic_ratio, ""))
    dressed = any(s.phase in ("sew", "pull", "don") for s in steps)   # panels placed apart, a body grown into it
    if math.isfinite(history.initial_gap) and not dressed:
        checks.append(bounded_check("start distance", "smallest garment-body gap at the start", history.initial_gap,
                             bounds.max_start_gap, "m"))
    checks.extend(_intersection_checks(history))
    local = largest_local_strain(sewn)
    if local is not None:
        checks.append(Check("local strain", "largest Green strain at a quadrature point after the sewing "
                            "(information, the bound not applied)", local, failure_strain, "", passed=True))
    if bounds.require_contact:
        force = max(s.contact_force for s in motion)
        checks.append(Check("contact", "the body never touches the garment during the motion (largest contact "
                            "force 0 N)", force, 0.0, "N", force > 0.0))
    return checks


def _intersection_checks(history: WearHistory) -> list[Check]:
    """"intersecting triangle pairs" over all records that counted them: bound 0 with self-contact on; without it
    information only (passed, whatever the count); none when no record counted."""
    counted = [s.intersecting_pairs for s in history.steps if s.intersecting_pairs is not None]
    if not counted:
        return []
    if getattr(history, "self_contact", False):
        return [bounded_check("intersecting triangle pairs", "largest number of intersecting triangle pairs of the "
                              "cloth (self-contact on)", max(counted), 0.0, "")]
    return [Check("intersecting triangle pairs", "largest number of intersecting triangle pairs of the cloth "
                  "(self-contact off: information, the bound not applied)", float(max(counted)), 0.0, "", True)]


def verdict(checks: list[Check]) -> dict:
    """summary.json's "verdict": "plausible" or "warnings", the failed checks' names and every check."""
    failed = [c.name for c in checks if not c.passed]
    return {"status": "warnings" if failed else "plausible", "failed": failed, "checks": [asdict(c) for c in checks]}
