"""The speed benchmarks' bookkeeping (fabricfem.benchmarks.wear_speed, fabricfem.benchmarks.commits): the accuracy
measure against closed forms and the refusals of bad input before any run."""
import numpy as np
import pytest

from fabricfem.benchmarks.commits import compare_commits
from fabricfem.benchmarks.wear_speed import torque_rms_error, wear_bench


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


def test_bad_benchmark_input_is_refused_naming_it(tmp_path):
    with pytest.raises(ValueError, match="meshes"):
        wear_bench(tmp_path, meshes=("V",))
    with pytest.raises(ValueError, match="variants"):
        wear_bench(tmp_path, variants=("mass x3",))
    with pytest.raises(ValueError, match="repeats"):
        wear_bench(tmp_path, repeats=0)
    with pytest.raises(ValueError, match="scene"):
        compare_commits(tmp_path / "missing.toml", "HEAD")
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nname = "s"\n')
    with pytest.raises(ValueError, match="set"):
        compare_commits(scene, "HEAD", settings=("motion.strides",))
    with pytest.raises(ValueError, match="not a commit"):
        compare_commits(scene, "no-such-commit-xyz")
