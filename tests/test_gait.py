"""The obstacle walk (fabricfem.body.crossing): refusals, angle ranges, continuity, pace, vectorisation."""
import numpy as np
import pytest

from fabricfem.body.crossing import obstacle_walk


@pytest.fixture(scope="module")
def walk():
    return obstacle_walk()


@pytest.mark.parametrize("key, value, match", [
    ("obstacle_height", 0.8, "obstacle_height"), ("clearance", 0.4, "obstacle_height"),
    ("cycle_time", 0.0, "cycle_time"), ("cycle_time", -1.0, "cycle_time"), ("strides", 2, "strides"),
    ("speed", 0.0, "speed"), ("crossing_speed", -0.1, "crossing_speed"), ("lead", "both", "lead"),
    ("obstacle_depth", 0.5, "obstacle_depth")])
def test_refusals_name_the_key(key, value, match):
    with pytest.raises(ValueError, match=match):
        obstacle_walk(**{key: value})


def test_angle_ranges(walk):
    t = np.linspace(*walk.time_range, 3001)
    lead, trail = walk.angles(t, "r"), walk.angles(t, "l")
    assert 90.0 <= lead[:, 0].max() <= 100.0 and 115.0 <= lead[:, 1].max() <= 125.0
    assert trail[:, 1].max() <= 130.0 and trail[:, 0].max() <= 60.0 + 1e-4
    for a in (lead, trail):
        assert -50.0 <= a[:, 2].min() and a[:, 2].max() <= 30.0 and a[:, 1].min() > -1.0
    assert np.allclose(walk.knee_angle_r(t), lead[:, 1])


def test_joint_velocities_are_bounded(walk):
    """C^1 bumps: no jumps; rates below 600 deg/s (the bumps' 1000 deg per stride phase at the crossing pace
    is 425 deg/s; Winter's walking up to 370 deg/s)."""
    t = np.linspace(*walk.time_range, 20001)
    for s in "lr":
        rate = np.abs(np.diff(walk.angles(t, s), axis=0)) / np.diff(t)[:, None]
        assert rate.max() < 600.0


def test_pace_and_rise(walk):
    t0, t1 = walk.crossing_window
    inside = np.linspace(t0, t1, 50)
    assert np.allclose(walk.pelvis_speed(inside), 0.6, atol=1e-12)
    assert np.isclose(t1 - t0, walk.stride_length / 0.6)
    assert np.allclose(walk.pelvis_speed(np.array([0.0, walk.time_range[1]])), 1.43)
    t = np.linspace(*walk.time_range, 5001)
    x = walk.points(t)["hip_l"][:, 0]
    assert np.all(np.diff(x) > 0.0) and np.isclose(x[-1] - x[0], 4 * walk.stride_length)
    rise = walk.pelvis_rise(t)
    assert rise.min() == 0.0 and np.isclose(rise.max(), walk.rise) and 0.0 < walk.rise <= 0.3
    assert np.all(rise[(t < t0) | (t > t1)] < 1e-30)


def test_vectorised_equals_per_time(walk):
    t = np.linspace(*walk.time_range, 37)
    many = walk.points(t)
    for i, ti in enumerate(t):
        one = walk.positions(float(ti))
        assert all(np.array_equal(one[n], many[n][i]) for n in walk.names)


def test_left_lead_mirrors_the_roles():
    left = obstacle_walk(lead="left", strides=3)
    t = np.linspace(*left.time_range, 2001)
    assert 115.0 <= left.angles(t, "l")[:, 1].max() <= 125.0 and left.angles(t, "r")[:, 1].max() > 125.0
