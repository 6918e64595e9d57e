"""sleeve-trends: the trends of the thesis's sleeve study (sec. 5.3) checked on our study outputs.

Reads docs/figures/sleeve/<figure>.csv (the committed study outputs), else results/sleeve_study/<figure>.csv, when a study (`fabricfem study sleeve`) has been run;
otherwise runs the reduced quick study (mesh I, explicit flexion to 6 degrees) and says so in every quantity
("[reduced]"). The thesis's statements are the references (they are trends, not numbers):

* torque at the final angle higher for mu = 0.5 than for mu = 0.1 (sec. 5.3.1-5.3.2);
* the looser sleeve (R = 0.07 m) gives less torque than R = 0.06 m above 20 degrees (sec. 5.3.3);
* doubling the thickness multiplies the torque by 1.6 to 2.4 ("roughly double", membrane-dominated,
  sec. 5.3.4; the band is the task's reading of "roughly");
* fabrics II and III give at least ten times fabric I's torque ("roughly proportional to the stiffness",
  E ratios 292 and 6000, sec. 5.3.5). The study runs them with dynamic similarity (fabricfem.wear.sleeve), under
  which torque / E would be the same for all three fabrics without gravity (all moduli scale with E,
  G = E / 200; case sleeve-similarity); with the sleeve's weight fabric I's torque is
  partly the weight the forearm carries, which does not scale with E, so the ratios fall below the E ratios;
* the mu = 0.5 mesh series changes by less than 10% between the two finest meshes.

A curve that stopped early (quasi-static Newton failure) is compared at the largest angle both curves
reached, and the quantity names that angle; the model is not tuned to make a trend hold.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fabricfem.studies.sleeve import read_figures, run_study
from fabricfem.verify import CaseResult, Timer, case, reproduction, result
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.run import run_sleeve

STUDY_DIRS = (Path("docs/figures/sleeve"), Path("results/sleeve_study"))   # committed study first, then a local one
def _common(a, b) -> float:
    return float(min(a[0][-1], b[0][-1]))


def _at(curve, angle: float) -> float:
    return float(np.interp(angle, curve[0], curve[1]))


def _check(name: str, quantity: str, value: float, reference: float, passed: bool, wall: float) -> CaseResult:
    rel = abs(value - reference) / abs(reference) if reference else abs(value)
    return CaseResult(name, quantity, float(value), float(reference), float(rel), float("nan"), bool(passed), 0, wall)


def trends(figures, tag: str, wall: float) -> list[CaseResult]:
    out = []
    n = "sleeve-trends"
    fr = figures["friction"]
    a = _common(fr["mu = 0.1"], fr["mu = 0.5"])
    lo, hi = _at(fr["mu = 0.1"], a), _at(fr["mu = 0.5"], a)
    out.append(_check(n, f"{tag} T(mu=0.5)/T(mu=0.1) at {a:.1f} deg > 1", hi / lo if lo else np.inf, 1.0,
                      hi > lo, wall))
    fit = figures["fit"]
    a = _common(fit["R = 0.06 m"], fit["R = 0.07 m"])
    angles = fit["R = 0.06 m"][0]
    above = angles[(angles > 20.0) & (angles <= a)]
    if len(above):
        ratios = [_at(fit["R = 0.07 m"], x) / _at(fit["R = 0.06 m"], x) for x in above]
        out.append(_check(n, f"{tag} max T(R=0.07)/T(R=0.06) over 20-{a:.1f} deg < 1", max(ratios), 1.0,
                          max(ratios) < 1.0, wall))
    else:
        t6, t7 = _at(fit["R = 0.06 m"], a), _at(fit["R = 0.07 m"], a)
        out.append(_check(n, f"{tag} T(R=0.07)/T(R=0.06) at {a:.1f} deg (20 deg not reached: NOT the thesis "
                          f"check) < 1", t7 / t6 if t6 else np.inf, 1.0, False, wall))
    th = figures["thickness"]
    a = _common(th["t = 1 mm"], th["t = 2 mm"])
    r = _at(th["t = 2 mm"], a) / _at(th["t = 1 mm"], a)
    out.append(_check(n, f"{tag} T(t=2mm)/T(t=1mm) at {a:.1f} deg in [1.6, 2.4]", r, 2.0, 1.6 <= r <= 2.4, wall))
    fb = figures["fabrics"]
    for k in ("II", "III"):
        if f"fabric {k}" not in fb:
            out.append(_check(n, f"{tag} T(fabric {k})/T(fabric I) >= 10: fabric {k} not in the study (not checked)",
                              np.nan, 10.0, False, wall))
            continue
        a = _common(fb["fabric I"], fb[f"fabric {k}"])
        r = _at(fb[f"fabric {k}"], a) / _at(fb["fabric I"], a)
        out.append(_check(n, f"{tag} T(fabric {k})/T(fabric I) at {a:.1f} deg >= 10", r, 10.0, r >= 10.0, wall))
    ms = figures.get("mesh_mu0.5", {})
    labels = list(ms)
    if len(labels) >= 2:
        c1, c2 = ms[labels[-2]], ms[labels[-1]]
        a = _common(c1, c2)
        t1, t2 = _at(c1, a), _at(c2, a)
        change = abs(t2 - t1) / abs(t2) if t2 else np.inf
        out.append(_check(n, f"{tag} |T({labels[-1]}) - T({labels[-2]})| / T at {a:.1f} deg < 10%", change, 0.0,
                          change < 0.1, wall))
    else:
        out.append(_check(n, f"{tag} mesh series mu=0.5: only one mesh in the reduced study (not checked)",
                          np.nan, 0.0, False, wall))
    return out


@reproduction("sleeve-trends", deviation=(
    "evaluated on 57-degree explicit data with gravity on the blended arm in docs/figures/sleeve (regenerated "
    "2026-11-27): parameter figures on mesh III, mesh series I-IV at mu = 0.1 and 0.5: T(mu=0.5)/T(mu=0.1) at 57 "
    "deg = 1.30 passes (0.0388 vs 0.0297 N m); T(fabric II, III)/T(fabric I) = 220 and 4578 pass; max "
    "T(R=0.07)/T(R=0.06) over 20-57 deg = 1.22 fails (the looser sleeve hangs with more of its weight on the "
    "forearm, and R = 0.06 m has 4.3 mm clearance on our ANSUR II arm, not a tight fit); T(t=2mm)/T(t=1mm) at 57 "
    "deg = 3.48 fails (about a quarter of the torque is bending of the sagging, wrinkling sleeve, which scales with "
    "t^3; on the union of ellipsoids neither was a rate effect, 1.37-1.54 and 3.3-3.5 at 22.5 deg/s, nor a mesh "
    "effect, 1.41 and 3.1 on mesh IV); |T(mesh IV) - T(mesh III)| / T at 57 deg, mu = 0.5, = 15.7 % fails (8.2 % on "
    "the union): the thesis's meshes III and IV are not converged on the blended arm (16.7 % and 6.1 % RMS from "
    "80x104 at mu = 0.1, docs/studies/sleeve.md) and one record at 57 degrees moves with slip events. The thesis's "
    "'roughly double' is what a membrane-locked (fully integrated) tube gives: 2.2-2.3 on meshes II-III, fading "
    "with refinement; see verify scordelis-lo, docs/figures/sleeve/fit_sensitivity.md"))
def sleeve_trends() -> list[CaseResult]:
    """Sleeve-study trends of [Man2006, sec. 5.3] (friction, fit, thickness, fabrics, mesh) on study outputs."""
    with Timer() as timer:
        found = [d for d in STUDY_DIRS if (d / "friction.csv").exists()]
        if found:
            readme = found[0] / "README.txt"
            first = readme.read_text().splitlines()[0] if readme.exists() else "study"
            figures, tag = read_figures(found[0]), "[full study]" if first == "full study" else f"[{first}]"
        else:
            with tempfile.TemporaryDirectory() as tmp:
                run_study(tmp, quick=True, comm=MPI.COMM_SELF)
                figures = read_figures(Path(tmp))
            tag = "[reduced]"
    return trends(figures, tag, timer.elapsed)


# ------------------------------------------------------------------------------------------------------------
# dynamic similarity of the explicit flexion (fabricfem.wear.sleeve.SleeveConfig.flexion_speed)
# ------------------------------------------------------------------------------------------------------------
SIMILARITY_ANGLE = 10.0      # deg: contact starts near 5 deg on mesh I


@case("sleeve-similarity")
def sleeve_similarity() -> list[CaseResult]:
    """Dynamic similarity of the explicit sleeve flexion (mesh I, mu = 0.1, G = E / 200, to 10 degrees, gravity off).

    1. Exact scaling (derived in SleeveConfig.flexion_speed): fabric I (1.2 MPa, 436 kg/m^3) at 45 deg/s and a
       fabric with E x 6.25 (c x 2.5, not a power of two, so the arithmetic is not a bitwise rescaling) at the
       similar speed 112.5 deg/s with damping 25 1/s give the same torque / E. Tolerance 1e-6 relative: the two
       runs are the same discrete equations up to rounding (dt, record time and damping all scale with
       c_ref / c), and round-off reaches the torque through the contact decisions by no more than in the
       1-vs-2-rank test of tests/test_sleeve.py (1e-6).
    2. Independent reference, the quasi-static torque (Newton equilibrium per degree, solver "quasistatic";
       rate independent and exactly proportional to E, so fabric I's T_qs / E serves): the E x 6.25 fabric
       WITHOUT similarity at 22.5 deg/s (5 times slower in units of its wave speed than the similar run, the
       same as fabric I at 9 deg/s) must lie within 5 % of it (the mass-damping drag at 45 deg/s is about 20 %
       of the torque, fabricfem.wear.sleeve docstring; a fifth of the dimensionless speed gives 4 %), and its
       distance from it must be smaller than the similar run's (the flexion slowed approaches quasi-static).
    The similar run carries fabric I's own distance from quasi-static equilibrium (reported in the quantity).
    """
    name = "sleeve-similarity"
    with Timer() as timer:
        # gravity off: the weight rho t g does not scale with E, so the similarity is exact only without it
        # (the study's fabrics runs have gravity on: there torque / E differs between the fabrics by the
        # weight's share, which is physics, not a scaling error)
        base = SleeveConfig.of(n_around=10, n_along=13, final_angle=SIMILARITY_ANGLE, E=1.2e6, G=1.2e6 / 200,
                            density=436.0, gravity=False)
        stiff = base.with_(E=7.5e6, G=7.5e6 / 200)
        a = SIMILARITY_ANGLE

        def torque_over_E(cfg: SleeveConfig) -> tuple[float, int]:
            h = run_sleeve(cfg, MPI.COMM_SELF)
            return h.torque_at(a) / cfg.material.E, h.ndofs

        t_ref, ndofs = torque_over_E(base.with_(dynamic_similarity=True))
        t_similar, _ = torque_over_E(stiff.with_(dynamic_similarity=True))
        t_slow, _ = torque_over_E(stiff.with_(angular_velocity=22.5))
        t_qs, _ = torque_over_E(base.with_(solver="quasistatic", method=None, angle_steps=int(round(a))))
    wall = timer.elapsed
    out = [result(name, f"T/E at {a:g} deg: E x 6.25 at 112.5 deg/s (similar) vs fabric I at 45 deg/s [m^3]",
                  t_similar, t_ref, 1e-6, ndofs, wall)]
    excess_similar, excess_slow = abs(t_similar / t_qs - 1.0), abs(t_slow / t_qs - 1.0)
    out.append(CaseResult(name, f"|T/T_qs - 1| at {a:g} deg: E x 6.25 at 22.5 deg/s without similarity "
                          f"({excess_slow:.3g}) < similar run ({excess_similar:.3g})", excess_slow, excess_similar,
                          float("nan"), float("nan"), bool(excess_slow < excess_similar), ndofs, wall))
    out.append(result(name, f"T/E at {a:g} deg, E x 6.25 at 22.5 deg/s without similarity vs quasi-static [m^3]",
                      t_slow, t_qs, 0.05, ndofs, wall))
    return out
