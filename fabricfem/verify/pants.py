"""Verification of the pants study's monitors [Man2006, sec. 5.4]: the right-knee torque counts only the segments
at and below the right knee."""
from __future__ import annotations

import numpy as np

from fabricfem.body.lower_body import lower_body
from fabricfem.contact.torque import TorqueMonitor
from fabricfem.verify import Timer, case, result

KNEE_AXIS = (0.0, 1.0, 0.0)      # knee flexion of the lower body (x forward, y left, z up): the shank swings back
BELOW_KNEE = ("shank_r", "foot_r")


@case("pants-torque-segments")
def pants_torque_segments() -> list:
    """The knee-torque monitor of the pants (TorqueMonitor about knee_r along +y over shank_r and foot_r, the
    thesis's "segments at the knee level and below"), on the standing lower body, with hand-computed moments:
    (1) one nodal force f = (0, 0, -2) N on the cloth at a point 0.1 m in front of the right knee on the shank:
    the body takes -f, tau = a . (r x -f) with r = (0.1, 0, -0.05): a . (r x (0, 0, 2)) = -(0.1 * 2) = -0.2 N m
    about +y (1e-12, round-off); (2) the same force on a node touching the right thigh adds nothing (0, exactly);
    (3) no contact force: zero torque (exactly)."""
    with Timer() as timer:
        body = lower_body()
        names = list(body.segments)
        knee = body.kinematics.positions(0.0)["knee_r"]
        monitor = TorqueMonitor.build(names, "knee_r", KNEE_AXIS, BELOW_KNEE)
        point = knee + np.array([0.1, 0.0, -0.05])
        force_on_cloth = np.array([[0.0, 0.0, -2.0]])
        shank = names.index("shank_r")
        thigh = names.index("thigh_r")
        tau_shank = monitor.value(point[None, :], force_on_cloth, np.array([shank]), lambda: knee, None)
        tau_both = monitor.value(np.array([point, knee + [0.1, 0.0, 0.2]]), np.repeat(force_on_cloth, 2, axis=0),
                                 np.array([shank, thigh]), lambda: knee, None)
        tau_none = monitor.value(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64), lambda: knee, None)
    r = point - knee
    hand = float(np.dot(KNEE_AXIS, np.cross(r, -force_on_cloth[0])))
    return [result("pants-torque-segments", "knee_r torque of a force on the shank [N m] vs r x f by hand",
                   tau_shank, hand, 1e-12, 0, timer.elapsed),
            result("pants-torque-segments", "change when the same force also acts on the thigh [N m]",
                   tau_both - tau_shank, 0.0, 0.0, 0, timer.elapsed, scale=1.0),
            result("pants-torque-segments", "torque without contact forces [N m]", tau_none, 0.0, 0.0, 0,
                   timer.elapsed, scale=1.0)]
