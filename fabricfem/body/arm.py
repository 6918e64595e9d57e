"""The default arm of the sleeve study [Man2006, sec. 5.3]: upper arm and forearm ellipsoids.

Source: 2012 Anthropometric Survey of U.S. Army Personnel (ANSUR II), C. C. Gordon et al., Natick
technical report NATICK/TR-15/007, 2014, adult male sample. Values used:

    measured (ANSUR II male medians, as specified for this project; not re-read from the report here)
        acromion-radiale length (upper arm)      0.335 m
        radiale-stylion length (forearm)         0.267 m
        biceps circumference, flexed             0.350 m   (rounded)
        forearm circumference, flexed            0.300 m   (rounded)
    derived (this module)
        cross-section radius r = C / (2 pi) of a circle of the same girth:
            upper arm 0.0557 m, forearm 0.0477 m  (both below the sleeve radius R = 0.06 m of the thesis,
            so the sleeve of sec. 5.3 fits over the arm with 4.3 mm and 12.3 mm clearance)
        long semi-axis r1 = f L with f = long_axis_factor, default f = 1/2: the ellipsoid tips reach the
            joint centres (x^c = (J1 + J2) / 2 as in [Man2006, sec. 5.1]), so the upper-arm and forearm tips
            meet AT the elbow centre and the arm has zero girth there

Long semi-axis (`ArmDimensions.long_axis_factor`): the thesis (sec. 5.1) fixes the centre x^c = (J1 + J2) / 2
and the axis directions of a segment ellipsoid, not the length of its long semi-axis. With f > 1/2 the
ellipsoids overlap across the joint (common in ellipsoid body models), and the cross-section radius of a
segment of radius r at its joint, at distance L / 2 from its centre, is (ellipse x^2 / r1^2 + y^2 / r^2 = 1)

        r_joint = r sqrt(1 - (L / 2 / r1)^2) = r sqrt(1 - 1 / (2 f)^2)

so the elbow girth radius of the arm (largest of the two segments there, `elbow_radius`) is 0 for f = 1/2,
0.0308 m for f = 0.6 and 0.0390 m for f = 0.7 (ANSUR radii; the upper arm is the thicker one). f < 1/2 is
refused (the segments would leave a gap at the joint); f > 1 is refused (a tip more than L / 2 past its
joint is no longer a model of the arm).

Flexed girths (muscle contracted) overestimate the relaxed arm slightly; the circle-equivalent radius
ignores the flattening of the real cross-section.

Frame of the default arm (matching `fabricfem.meshes.tube`, whose axis is +x from x = 0): shoulder at
the origin, elbow at x = 0.335 m, wrist at x = 0.602 m; flexion about +z moves the forearm towards +y.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from fabricfem.body.motion import ElbowFlexion, KinematicsSource
from fabricfem.body.pose import Body, Segment


@dataclass(frozen=True)
class ArmDimensions:
    """Arm segment lengths and girths [m] (defaults: ANSUR II adult male, see module docstring)."""

    upper_arm_length: float = 0.335
    forearm_length: float = 0.267
    upper_arm_girth: float = 0.350
    forearm_girth: float = 0.300
    long_axis_factor: float = 0.5     # long semi-axis r1 = factor x segment length [-], 0.5 <= factor <= 1

    def __post_init__(self):
        for name in ("upper_arm_length", "forearm_length", "upper_arm_girth", "forearm_girth"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be a positive length [m], got {v!r}")
        f = self.long_axis_factor
        if not (isinstance(f, (int, float)) and math.isfinite(f) and 0.5 <= f <= 1.0):
            raise ValueError(f"long_axis_factor must lie in [0.5, 1] (long semi-axis / segment length; below 0.5 "
                             f"the segments leave a gap at the joint), got {f!r}")

    @property
    def upper_arm_radius(self) -> float:
        """Circle-equivalent radius C / (2 pi) [m] (derived)."""
        return self.upper_arm_girth / (2.0 * math.pi)

    @property
    def forearm_radius(self) -> float:
        """Circle-equivalent radius C / (2 pi) [m] (derived)."""
        return self.forearm_girth / (2.0 * math.pi)

    @property
    def upper_arm_long_semi_axis(self) -> float:
        """r1 = long_axis_factor x upper_arm_length [m]."""
        return self.long_axis_factor * self.upper_arm_length

    @property
    def forearm_long_semi_axis(self) -> float:
        """r1 = long_axis_factor x forearm_length [m]."""
        return self.long_axis_factor * self.forearm_length

    @property
    def joint_radius_factor(self) -> float:
        """sqrt(1 - (L / 2 / r1)^2) = sqrt(1 - 1 / (2 f)^2) [-]: a segment's cross-section radius at its
        joints over its largest radius (ellipse at distance L / 2 from the centre, module docstring)."""
        return math.sqrt(max(0.0, 1.0 - (0.5 / self.long_axis_factor) ** 2))

    @property
    def elbow_radius(self) -> float:
        """Girth radius of the arm at the elbow centre [m]: the larger cross-section radius of the two
        segments there, r sqrt(1 - (L / 2 / r1)^2) (0 for long_axis_factor = 0.5)."""
        return max(self.upper_arm_radius, self.forearm_radius) * self.joint_radius_factor

    def segments(self) -> tuple[Segment, Segment]:
        """The two segments: radii (f L, r, r), f = long_axis_factor (f = 0.5: (L / 2, r, r))."""
        r_u, r_f = self.upper_arm_radius, self.forearm_radius
        return (Segment("upper_arm", "shoulder", "elbow", "upper_arm_marker",
                        (self.upper_arm_long_semi_axis, r_u, r_u)),
                Segment("forearm", "elbow", "wrist", "forearm_marker",
                        (self.forearm_long_semi_axis, r_f, r_f)))


DEFAULT_ARM = ArmDimensions()


def elbow_flexion(dimensions: ArmDimensions = DEFAULT_ARM, angular_velocity: float = math.radians(45.0),
                  final_angle: float = math.radians(57.0), **kwargs) -> ElbowFlexion:
    """Elbow flexion of the default arm (along +x, flexing about +z), see `ElbowFlexion`."""
    elbow = (dimensions.upper_arm_length, 0.0, 0.0)
    wrist = (dimensions.upper_arm_length + dimensions.forearm_length, 0.0, 0.0)
    return ElbowFlexion(shoulder=(0.0, 0.0, 0.0), elbow=elbow, wrist=wrist, angular_velocity=angular_velocity,
                        final_angle=final_angle, **kwargs)


def default_arm(kinematics: KinematicsSource | None = None, dimensions: ArmDimensions = DEFAULT_ARM) -> Body:
    """Upper arm + forearm body; kinematics default: 57 degree elbow flexion at 45 deg/s."""
    return Body(dimensions.segments(), kinematics if kinematics is not None else elbow_flexion(dimensions))
