"""The compiled explicit contact step (fabricfem.contact.compiled) against the numpy one it replaces
(fabricfem.contact.explicit.project_with_segment and ExplicitBodyContact.correct).

The compiled loops do the numpy functions' arithmetic in the same order without contracted multiply-adds, so the
projections, segments, forces and torques agree to the last bit except through q = f + 1, which numpy forms by a
matrix product (BLAS rounding) and which only preselects points for the ray casts. The bounds: 1e-15 m on
projected points (one rounding of a 0.1 m coordinate is 1.4e-17 m), exact equality of segments and moved flags
away from the surface; the sleeve's torque histories to 1e-12 relative (measured: identical).
"""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fabricfem.body.blend_kernel import implicit_values
from fabricfem.body.blended import blend, stacked
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.contact import compiled
from fabricfem.contact.explicit import numpy_contact, project_compiled, project_onto_skin
from fabricfem.contact.projection import resolve_widths, skin_gap
from fabricfem.wear.config import SleeveConfig
from fabricfem.wear.run import run_sleeve


def rotation(angle: float) -> np.ndarray:
    """Rotation by `angle` [rad] about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def elbow(angle: float = 2.4) -> list[Ellipsoid]:
    """An upper arm and a forearm flexed by `angle` [rad] about the elbow at the origin (their lens in the inner
    elbow traps points: at 2.4 rad 111 of the points below stay inside after the projection passes), and a third
    segment apart."""
    forearm = 0.15 * np.array([np.cos(angle), np.sin(angle), 0.0])
    return [Ellipsoid(np.array([-0.15, 0.0, 0.0]), rotation(0.0), np.array([0.15, 0.04, 0.04])),
            Ellipsoid(forearm, rotation(angle), np.array([0.15, 0.04, 0.04])),
            Ellipsoid(np.array([0.4, 0.0, 0.0]), rotation(0.3), np.array([0.1, 0.03, 0.03]))]


def test_projection_matches_numpy_including_the_crease():
    """Random points in and around the segments, many in the inner elbow where the blend of two segments applies:
    the compiled projection marks the same crease points and moves the same points as project_onto_skin; away
    from the crease to the same positions (1e-15 m) and segments; in the crease to the blended skin's closest point
    within 1e-8 m (both closest-point iterations stop at a tangential residual of 1e-9 m)."""
    rng = np.random.default_rng(3)
    ellipsoids = elbow()
    x = np.vstack([rng.uniform([-0.1, -0.05, -0.03], [0.05, 0.1, 0.03], size=(4000, 3)),      # the inner elbow
                   rng.uniform([0.25, -0.05, -0.04], [0.55, 0.05, 0.04], size=(1000, 3))])   # around the third
    expected = project_onto_skin(x, ellipsoids)
    zeros = np.zeros(1)
    rows = np.zeros((len(x), 3), dtype=np.int64)
    widths = resolve_widths(None, len(ellipsoids))            # every two segments blend over BLEND_WIDTH
    trial, skin = project_compiled(x, rows, zeros, zeros, zeros, 1e-4, compiled.stacked(ellipsoids), widths,
                                   MPI.COMM_SELF)
    crease = expected.crease
    assert np.array_equal(trial, x)
    assert expected.moved.sum() > 1500 and (crease & expected.moved).sum() > 500   # many points inside, in the blend
    assert np.array_equal(skin.crease, crease) and np.array_equal(skin.moved, expected.moved)
    assert np.abs(skin.position[~crease] - expected.position[~crease]).max() <= 1e-15
    assert np.array_equal(skin.segment[~crease], expected.segment[~crease])
    inside = crease & expected.moved
    assert np.abs(skin.position[inside] - expected.position[inside]).max() <= 1e-8
    assert np.abs(skin.normal[inside] - expected.normal[inside]).max() <= 1e-6
    assert np.abs(skin.weights[inside] - expected.weights[inside]).max() <= 1e-6


def test_implicit_values_give_the_sign_of_the_gap():
    """The compiled phi (`implicit_values`, which `max_penetration` uses to skip the points outside) equals the
    numpy blend's phi to 1e-14 m (the same Newton iteration per segment, [Eberly2013]; its stopping differs by
    round-off) and has the sign of skin_gap's gap at every point of the inner elbow and around it, so that the
    penetration of the points with phi < 0 is the penetration of all."""
    rng = np.random.default_rng(5)
    ellipsoids = elbow()
    x = np.vstack([rng.uniform([-0.1, -0.05, -0.03], [0.05, 0.1, 0.03], size=(3000, 3)),
                   rng.uniform([-0.3, -0.1, -0.1], [0.6, 0.2, 0.1], size=(2000, 3))])
    widths = resolve_widths(None, len(ellipsoids))
    phi = implicit_values(x, *stacked(ellipsoids), widths)
    expected, _, _ = blend(x, *stacked(ellipsoids), widths)
    gap, *_ = skin_gap(x, ellipsoids, widths)
    assert np.abs(phi - expected).max() <= 1e-14
    assert (phi < 0).sum() > 1000 and np.array_equal(phi < 0.0, gap < 0.0)


def test_too_many_segments_rejected():
    one = elbow()[0]
    with pytest.raises(ValueError, match="segments"):
        compiled.stacked([one] * (compiled.MAX_SEGMENTS + 1))


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_sleeve_history_matches_numpy(friction):
    """The sleeve on mesh I through the settling and 8 degrees of flexion (sticking and slipping nodes, nodes that
    touch down and lift off): the compiled and the numpy contact give the same torque history (1e-12 relative)
    and the same final contact state."""
    config = SleeveConfig().with_(n_around=10, n_along=13, final_angle=8.0, friction=friction)
    runs = {}
    for name in ("compiled", "numpy"):
        if name == "numpy":
            with numpy_contact():
                runs[name] = run_sleeve(config)
        else:
            runs[name] = run_sleeve(config)
    # every record: the settling's and the motion's (the start state and 1..8 degrees)
    torques = {name: h.torque("elbow") for name, h in runs.items()}
    assert len(torques["compiled"]) == len(torques["numpy"])
    assert all(len(h.motion_curve("elbow")[0]) == 9 for h in runs.values())
    peak = np.abs(torques["numpy"]).max()
    assert np.abs(torques["compiled"] - torques["numpy"]).max() <= 1e-12 * peak
