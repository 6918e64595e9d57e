"""Speed-versus-accuracy benchmark (fabricfem.benchmarks.speed_accuracy), quick mode: t_end = 0.3 s, two levels
per method, reference = implicit membrane (16, 0.005 s).

Independent reference used besides the self-convergence: at t = 0.3 s the free corner has not yet been
reached by the swing (damped free fall of a point: z = -(g / c)(t - (1 - e^{-ct}) / c) = -0.334 m, against a
side of 1 m), the sheet around it is still nearly horizontal, and the in-plane tension pulls it only
horizontally; so its vertical displacement is the damped free fall of a point mass, c = eta / rho.
"""
import math

import numpy as np
import pytest
from csv_checks import assert_positive_table
from mpi4py import MPI

from fabricfem.benchmarks.speed_accuracy import (
    AIR_DRAG,
    AREAL_DENSITY,
    CSV_COLUMNS,
    DRAPE_CSV_COLUMNS,
    DRAPE_METHODS,
    GRAVITY,
    METHODS,
    QUICK,
    DrapePlan,
    DrapeRow,
    SpeedRow,
    cheapest_meeting,
    same_branch,
    speed_accuracy,
    tablecloth_benchmark,
)


def damped_free_fall(t: float) -> float:
    """z(t) of a point released from rest under gravity with drag force -c m v, c = eta / rho [m]."""
    c = AIR_DRAG / AREAL_DENSITY
    return -GRAVITY / c * (t - (1.0 - math.exp(-c * t)) / c)


@pytest.mark.mpi
def test_quick_speed_accuracy(tmp_path):
    out = speed_accuracy(tmp_path, quick=True, verbose=False, problems=("corner-pinned",))
    rows, reference = out["rows"], out["reference"]
    assert {r.method for r in rows} == set(METHODS)
    for r in rows:
        for name in ("dt", "wall_s", "wall_vs_baseline", "error"):
            value = getattr(r, name)
            assert math.isfinite(value) and value > 0, (r.method, r.resolution, name, value)
        # Vertical corner displacement vs the damped free fall (module doc). 2%: the sheet's slope at the corner
        # is below ~0.1 rad at t = 0.3 s (the corner is 0.33 m below a pin line 1 m away, and the sheet's
        # horizontal pull on the corner is 0.1 m of displacement, ~25% of the vertical one, so the tension's
        # vertical share ~ slope x tension is a few % at most of the weight acting); a
        # discretization of the fall itself (velocity Verlet, Newmark) is second order in dt, 1e-4 here.
        assert r.u[2] == pytest.approx(damped_free_fall(QUICK.t_end), rel=0.02), (r.method, r.resolution, r.u)
    # implicit: errors decrease with refinement (mesh and step halved together). No tolerance: the
    # discretization error of the trapezoidal rule (O(dt^2)) and of the Q2 membrane (>= O(h^2)) should drop
    # about 4x per level, and the reference (n = 16, dt = 0.005 s) is one level finer than the finest measured
    # run, so its own error is ~1/4 of that run's: a strict decrease is the weakest claim the rates imply.
    implicit = sorted((r for r in rows if r.method == "implicit"), key=lambda r: r.ndofs)
    assert len(implicit) == 2 and implicit[1].error < implicit[0].error, [(r.resolution, r.error) for r in implicit]
    # the reference levels agree to the finest measured level's error (the coarser reference level IS that run)
    finest = implicit[-1]
    assert reference.level_difference == pytest.approx(finest.error, rel=1e-12)
    baseline = min((r for r in rows if r.method == "particles"), key=lambda r: r.ndofs)
    assert baseline.wall_vs_baseline == 1.0
    assert len(out["conclusions"]) == 2
    if MPI.COMM_WORLD.rank == 0:
        assert_positive_table(tmp_path / "speed_accuracy.csv", CSV_COLUMNS, len(rows),
                              ("dt", "ndofs", "wall_s", "error"))
        assert (tmp_path / "speed_accuracy.png").stat().st_size > 0
        assert (tmp_path / "speed_accuracy_reference.csv").stat().st_size > 0


def _row(method: str, wall: float, error: float) -> SpeedRow:
    return SpeedRow("p", method, "r", 1.0, 1, 1, wall, None, error, np.zeros(3))


def test_cheapest_meeting():
    rows = [_row("a", 1.0, 0.2), _row("a", 4.0, 0.05), _row("b", 2.0, 0.08), _row("b", 9.0, 0.005)]
    c = cheapest_meeting(rows, 0.10)
    assert (c.method, c.wall_s, c.runner_up, c.ratio) == ("b", 2.0, "a", 2.0)
    c = cheapest_meeting(rows, 0.01)
    assert (c.method, c.runner_up, c.ratio) == ("b", None, math.inf)
    assert cheapest_meeting(rows, 0.001).method is None
    with pytest.raises(ValueError, match="target"):
        cheapest_meeting(rows, -1.0)


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match="methods"):
        speed_accuracy(tmp_path, methods=("fem",), verbose=False)
    with pytest.raises(ValueError, match="n "):
        speed_accuracy(tmp_path, plan=QUICK.__class__(**{**QUICK.__dict__, "particles": (1,)}), verbose=False)
    with pytest.raises(ValueError, match="t_end"):
        speed_accuracy(tmp_path, plan=QUICK.__class__(**{**QUICK.__dict__, "t_end": -0.1}), verbose=False)


@pytest.mark.mpi
def test_quick_tablecloth(tmp_path):
    """Tablecloth part, quick plan (particles 10 x 10, shell quarter 5 x 5, reference shell quarter 10 x 10).

    Independent check of every solved position: a nearly inextensible cloth cannot place its corner / midside
    farther from the centre (held at the table centre by the mirror planes) than its material distance,
    measured along the shortest path over the table (fabricfem.verify.drape.shortest_path_over_table, itself
    checked against closed forms in tests/test_tablecloth.py). Allowed mean strain 1%: the shell strains
    ~q L / (E h) = 1e-4 under its weight; the particle grid's diagonal is carried by the shear springs
    (G h instead of E h along the diagonal, and the grid can trellis), so more than 1e-4 but far below 1%."""
    from fabricfem.verify.drape import CLOTH_L, shortest_path_over_table
    out = tablecloth_benchmark(tmp_path, quick=True, verbose=False)
    rows, reference = out["rows"], out["reference"]
    assert {r.method for r in rows} == set(DRAPE_METHODS)
    for r in rows + [reference]:
        for name in ("wall_s", "ndofs", "iterations"):
            assert math.isfinite(getattr(r, name)) and getattr(r, name) > 0, (r.resolution, name)
        corner = shortest_path_over_table(r.corner / CLOTH_L) / math.sqrt(0.5) - 1.0
        midside = shortest_path_over_table(r.midside / CLOTH_L) / 0.5 - 1.0
        assert corner <= 0.01 and midside <= 0.01, (r.method, r.resolution, corner, midside)
    for r in rows:
        assert math.isfinite(r.error) and r.error >= 0 and r.wall_vs_baseline > 0
    assert min(r.wall_vs_baseline for r in rows if r.method == "particles static") == 1.0
    if MPI.COMM_WORLD.rank == 0:
        assert_positive_table(tmp_path / "speed_accuracy_tablecloth.csv", DRAPE_CSV_COLUMNS, len(rows) + 1,
                              ("ndofs", "wall_s"))
        assert (tmp_path / "speed_accuracy_tablecloth.png").stat().st_size > 0


def _drape_row(folds: int, asymmetry: float) -> DrapeRow:
    return DrapeRow("t", "m", "r", 10, 1, 1, 1.0, None, None, np.zeros(3), np.zeros(3), folds, asymmetry)


def test_same_branch():
    ref = _drape_row(4, 0.0)
    assert same_branch(_drape_row(4, 0.001), ref)
    assert not same_branch(_drape_row(4, 0.05), ref)   # left the diagonal
    assert not same_branch(_drape_row(6, 0.0), ref)    # other fold count


def test_tablecloth_bad_plan(tmp_path):
    with pytest.raises(ValueError, match="plan.particles"):
        tablecloth_benchmark(tmp_path, plan=DrapePlan(particles=(15,), shell=(5,), reference=10, repeats=1),
                             verbose=False)
    with pytest.raises(ValueError, match="plan.shell"):
        tablecloth_benchmark(tmp_path, plan=DrapePlan(particles=(10,), shell=(4,), reference=10, repeats=1),
                             verbose=False)
    with pytest.raises(ValueError, match="problems"):
        speed_accuracy(tmp_path, problems=("sphere",), verbose=False)
