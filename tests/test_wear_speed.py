"""The speed benchmarks' bookkeeping (fabricfem.benchmarks.wear_speed, fabricfem.benchmarks.commits): the accuracy
measure against closed forms and the refusals of bad input before any run."""
import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from fabricfem import io as fio
from fabricfem.benchmarks.commits import compare_commits
from fabricfem.benchmarks.internal_force import internal_force_bench
from fabricfem.benchmarks.parallel_runs import parallel_bench
from fabricfem.benchmarks.wear_speed import csv_moment, mean_moment_error, pants_moment, wear_bench
from fabricfem.studies.sleeve import compare_figures
from fabricfem.wear.garment import WearStep
from fabricfem.wear.outputs import torque_rms_error


def test_torque_rms_error_of_an_offset_and_of_a_shifted_grid():
    """T = T_ref + c over 10-57 deg gives c / mean|T_ref| exactly; a curve sampled on another grid is interpolated
    linearly (a linear curve is reproduced: error 0 to round-off); records below 10 deg do not count."""
    angles = np.arange(0.0, 58.0)
    ref = 0.02 + 1e-4 * angles
    mask = angles >= 10.0
    assert torque_rms_error(angles, ref + 3e-4, angles, ref) == pytest.approx(3e-4 / np.mean(ref[mask]), rel=1e-12)
    other = np.linspace(0.0, 57.0, 23)
    assert torque_rms_error(other, 0.02 + 1e-4 * other, angles, ref) < 1e-14
    spoiled = ref.copy()
    spoiled[:10] += 1.0
    assert torque_rms_error(angles, spoiled, angles, ref) == 0.0


def test_pants_accuracy_measure_is_the_mean_knee_moment_magnitude():
    """The pants' measure: the magnitude sqrt(Mx^2 + My^2 + Mz^2) of the three knee monitors on the motion records
    only (3-4-12 gives 13 exactly), and |mean M - mean M_ref| / mean M_ref (a 10 % larger mean gives 0.1)."""
    def step(phase, t, m):
        return WearStep(phase, t, {"knee_r": m[0], "knee_r_x": m[1], "knee_r_z": m[2], "other": 100.0}, 0.0, "",
                        (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, {}, 0.0, 1, 0.0, 0.0, 0.0)

    class History:
        steps = [step("settle", 0.9, (5.0, 0.0, 0.0)), step("motion", 1.0, (3.0, 4.0, 12.0)),
                 step("motion", 1.1, (0.0, -6.0, 8.0))]
    times, moments = pants_moment(History())
    np.testing.assert_allclose(times, [1.0, 1.1])
    np.testing.assert_allclose(moments, [13.0, 10.0], rtol=1e-15)
    assert mean_moment_error(1.1 * moments, moments) == pytest.approx(0.1, rel=1e-12)


def test_bad_benchmark_input_is_refused_naming_it(tmp_path):
    with pytest.raises(ValueError, match="meshes"):
        wear_bench(tmp_path, meshes=("V",))
    with pytest.raises(ValueError, match="variants"):
        wear_bench(tmp_path, variants=("mass x3",))
    with pytest.raises(ValueError, match="repeats"):
        wear_bench(tmp_path, repeats=0)
    with pytest.raises(ValueError, match="duration"):
        wear_bench(tmp_path, meshes=("pants",), duration=0.0)
    with pytest.raises(ValueError, match="scene"):
        compare_commits(tmp_path / "missing.toml", "HEAD")
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nname = "s"\n')
    with pytest.raises(ValueError, match="set"):
        compare_commits(scene, "HEAD", settings=("motion.strides",))
    with pytest.raises(ValueError, match="not a commit"):
        compare_commits(scene, "no-such-commit-xyz")


def test_study_figures_compared_with_stored_ones(tmp_path):
    """compare_figures: a variant whose torque is the stored one plus 2e-4 N m gives 2e-4 / mean|T| (10 deg on);
    a variant missing from either side is skipped; a missing folder is refused naming the option."""
    header = ("variant", "angle_deg", "torque_Nm")
    angles = np.arange(0.0, 58.0)
    stored = 0.02 + 1e-4 * angles
    (tmp_path / "old").mkdir()
    fio.write_csv(tmp_path / "old" / "friction.csv", header,
                  [["mu = 0.1", a, t] for a, t in zip(angles, stored)] + [["only stored", 0.0, 1.0]])
    fio.write_csv(tmp_path / "new" / "friction.csv", header, [["mu = 0.1", a, t + 2e-4] for a, t in zip(angles, stored)])
    rows = compare_figures(tmp_path / "new", tmp_path / "old")
    assert [r[:2] for r in rows] == [["friction", "mu = 0.1"]]
    assert rows[0][2] == pytest.approx(2e-4 / np.mean(stored[angles >= 10.0]), rel=1e-12)
    assert (tmp_path / "new" / "comparison.csv").exists()
    with pytest.raises(ValueError, match="compare-with"):
        compare_figures(tmp_path / "new", tmp_path / "nowhere")


def test_internal_force_bench_rows_and_files(tmp_path):
    """`fabricfem bench kernel` on mesh I, two evaluations: a row per implementation and the floor, the three
    forces equal to round-off (the bound of tests/test_shell_reference.py), CSV and PNG written."""
    rows = internal_force_bench(tmp_path, meshes=("I",), evaluations=2, repeats=1)
    assert [r["implementation"] for r in rows] == ["per evaluation", "quadrature, FFCx", "hand kernel",
                                                  "assembly floor"]
    assert all(r["max_relative_difference"] < 1e-11 for r in rows[:3])
    assert all(r["ms_per_evaluation"] > 0 for r in rows)
    assert (tmp_path / "internal_force.csv").exists() and (tmp_path / "internal_force.png").exists()
    with pytest.raises(ValueError, match="meshes"):
        internal_force_bench(tmp_path, meshes=("V",))


def test_knee_moment_of_a_run_csv(tmp_path):
    """csv_moment reads the motion records of torque.csv and combines the right-knee monitors as pants_moment."""
    path = tmp_path / "torque.csv"
    path.write_text("time_s,phase,knee_r_torque_Nm,knee_r_x_torque_Nm,knee_l_torque_Nm\n"
                    "0.1,sew,5.0,5.0,1.0\n0.2,motion,3.0,4.0,9.0\n0.3,motion,0.0,-2.0,9.0\n")
    times, moments = csv_moment(path)
    np.testing.assert_allclose(times, [0.2, 0.3])
    np.testing.assert_allclose(moments, [5.0, 2.0], rtol=1e-15)
    path.write_text("time_s,phase,knee_r_torque_Nm\n0.1,sew,1.0\n")
    with pytest.raises(ValueError, match="motion"):
        csv_moment(path)


def test_parallel_bench_times_one_and_two_ranks_and_refuses_bad_input(tmp_path):
    """bench parallel on a 6 x 8 sleeve to 1 degree: a row per mesh with both medians, the speed-up as their ratio
    and the two torque histories equal to round-off (1e-8 of the largest: the same arithmetic summed in another
    order); parallel.csv has a row per run. Bad input names the option."""
    if shutil.which("mpirun") is None:
        pytest.skip("needs mpirun")
    sleeve = Path(__file__).resolve().parents[1] / "scenes" / "sleeve.toml"
    rows = parallel_bench(sleeve, ("6x8",), ("motion.final_angle=1.0", "motion.settle_time=0.02"), 1, tmp_path,
                          say=lambda *a: None)
    (row,) = rows
    assert row["dofs"] == 2 * 6 * 17 * 5 and row["speedup"] == pytest.approx(row["serial_s"] / row["two_ranks_s"])
    assert row["torque_difference"] <= 1e-8
    assert len(list(csv.DictReader(open(tmp_path / "parallel.csv")))) == 2
    assert (tmp_path / "parallel.png").exists()
    with pytest.raises(ValueError, match="meshes"):
        parallel_bench(sleeve, ("6by8",), repeats=1, out=tmp_path)
    with pytest.raises(ValueError, match="repeats"):
        parallel_bench(sleeve, ("6x8",), repeats=0, out=tmp_path)
