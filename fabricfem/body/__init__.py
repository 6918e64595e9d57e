"""The wearer: rigid ellipsoidal body segments posed from joint and marker positions [Man2006, ch. 5].

Modules: `ellipsoid` (implicit surface eq. 3.61, gap, exact closest point, surface velocity), `pose`
(segment frames from J1, J2, M, sec. 5.1; `Body`), `motion` (kinematics sources, motion-capture
readers, joint-torque convention), `arm` (the default arm of the sleeve study, sec. 5.3).
"""
from fabricfem.body.arm import DEFAULT_ARM, ArmDimensions, default_arm, elbow_flexion
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.motion import (
                                   ElbowFlexion,
                                   JointTrajectory,
                                   KinematicsSource,
                                   LegKinematics,
                                   joint_torque,
                                   read_marker_csv,
                                   read_trc,
                                   stepping_over,
                                   walking,
)
from fabricfem.body.pose import Body, Segment, segment_frame

__all__ = ["ArmDimensions", "Body", "DEFAULT_ARM", "ElbowFlexion", "Ellipsoid", "JointTrajectory",
           "KinematicsSource", "LegKinematics", "Segment", "default_arm", "elbow_flexion", "joint_torque",
           "read_marker_csv", "read_trc", "segment_frame", "stepping_over", "walking"]
