"""Stability-map benchmark (fabricfem.benchmarks.stability_map), quick version: one k/rho, the 8 x 8 mesh.

References: the linear stability limit of central differences / velocity Verlet, dt = 2 / omega_max with
omega_max the largest eigenfrequency of K vs the lumped mass (SLEPc / scipy eigsh, independent of the
time stepping), and the predicted steps of the methods' own estimates.
"""
import csv
import math

import pytest
from csv_checks import assert_positive_table
from mpi4py import MPI

from fabricfem.benchmarks import stability_map
from fabricfem.benchmarks.stability_map import CSV_COLUMNS

QUICK_STEPS = 100  # stability_map(quick=True) runs of 100 steps
REL_TOL = 0.01  # bisection resolution of the benchmark (default rel_tol)


def detection_overshoot(n_steps: int, seed_energy_ratio: float = 1e-32, bound: float = 10.0) -> float:
    """Largest relative excess eps of dt over the true limit that an n_steps run may still call stable.

    At omega dt = 2 (1 + eps) the unstable central-difference root has |lambda| ~ 1 + 2 sqrt(2 eps); the run
    is only stopped once the mode's energy (~ |lambda|^(2N)) has grown from its seed (round-off: 1e-16
    amplitude, 1e-32 energy, relative to the energy of the load) past `bound` x that energy, so
    eps ~ (ln(bound / seed) / (4 sqrt(2) N))^2 at worst: 1.8% for 100 steps, 0.45% for 200."""
    return (math.log(bound / seed_energy_ratio) / (4.0 * math.sqrt(2.0) * n_steps)) ** 2


@pytest.mark.mpi
def test_quick_stability_map(tmp_path):
    rows = stability_map(tmp_path, quick=True, verbose=False)
    assert {r.method for r in rows} == {"shell", "membrane", "particles"}
    assert all(r.k_over_rho == 1000.0 and r.n == 8 and r.n_steps == QUICK_STEPS for r in rows)
    for r in rows:
        for name in ("dt_predicted", "dt_measured", "dt_eigen", "step_wall_s", "wall_per_simulated_s",
                     "rss_hwm_MiB"):
            value = getattr(r, name)
            assert math.isfinite(value) and value > 0, (r.method, name, value)
        # Band 0.5 .. 5 for measured / predicted: both estimates bound omega_max from above (Gershgorin for
        # the particles, rigorously; eq. 2.87 with constants calibrated on single elements for the shell), so
        # the ratio is >= ~1 up to the bisection resolution; below 0.5 the predicted step would be unsafe by
        # a factor 2, above 5 the estimate would waste more than 5x the steps. A sanity band, not an accuracy
        # claim: the accuracy is checked against the eigenvalue limit below.
        assert 0.5 < r.ratio < 5.0, (r.method, r.ratio)
        # measured vs the linear limit 2 / omega_max: the bisection returns a stable step within REL_TOL
        # below an unstable one, so at least 1 / (1 + REL_TOL) of the limit (0.5% margin for the change of
        # omega_max with the sag during the run); a finite run can miss a growth just above the limit:
        # at most detection_overshoot(100) = 1.8%, plus REL_TOL, plus the same 0.5% margin.
        lower = 1.0 / (1.0 + REL_TOL) - 0.005
        upper = 1.0 + detection_overshoot(QUICK_STEPS) + REL_TOL + 0.005
        assert lower <= r.measured_over_eigen <= upper, (r.method, r.measured_over_eigen, lower, upper)
        # the predicted step must be safe: an upper bound of omega_max gives dt_predicted <= dt_eigen
        # (1e-6: the convergence tolerance of the SLEPc eigenvalue omega^2, rtol = 1e-6)
        assert r.dt_predicted <= r.dt_eigen * (1.0 + 1e-6), (r.method, r.dt_predicted, r.dt_eigen)
    shell = next(r for r in rows if r.method == "shell")
    # thickness shear limits the Naghdi shell (stability.py docstring): its step is below the membrane one
    assert shell.dt_predicted < shell.dt_membrane_estimate
    assert next(r for r in rows if r.method == "particles").cost_vs_particles == 1.0
    if MPI.COMM_WORLD.rank == 0:
        assert_positive_table(tmp_path / "stability_map.csv", CSV_COLUMNS, len(rows),
                              ("k_over_rho", "dt_predicted", "dt_measured", "ratio"))
        assert (tmp_path / "stability_map.png").stat().st_size > 0
        memory = list(csv.reader(open(tmp_path / "stability_map_memory.csv")))
        assert memory[0] == ["stage", "rss_hwm_MiB"] and float(memory[-1][1]) >= float(memory[1][1]) > 0


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match="k_over_rho"):
        stability_map(tmp_path, k_over_rho=(-50.0,), verbose=False)
    with pytest.raises(ValueError, match="n "):
        stability_map(tmp_path, meshes=(1,), verbose=False)
    with pytest.raises(ValueError, match="methods"):
        stability_map(tmp_path, methods=("fem",), verbose=False)
    with pytest.raises(ValueError, match="n_steps"):
        stability_map(tmp_path, n_steps=0, verbose=False)
