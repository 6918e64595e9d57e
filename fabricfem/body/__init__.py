"""The wearer: rigid ellipsoidal body segments posed from joint and marker positions [Man2006, ch. 5].

Modules: `ellipsoid` (implicit surface eq. 3.61, gap, exact closest point, surface velocity), `pose`
(segment frames from J1, J2, M, sec. 5.1; `Body`), `schedule` (segments switched off and on in time),
`motion` (kinematics sources, joint-torque convention), `conventions` (units and axes of motion files),
`mocap` (C3D, TRC, CSV readers and writers, marker mapping and its plain-data form), `bvh` (BVH parse,
forward kinematics, write), `placement` (a motion moved into a garment, the garment-body distance bound),
`arm` (the default arm of the sleeve study, sec. 5.3), `lower_body` (the eight-segment lower body, standing
and two-leg gait), `crossing` (four strides, one over an obstacle, sec. 5.4).
"""
from fabricfem.body.arm import DEFAULT_ARM, ArmDimensions, default_arm, elbow_flexion
from fabricfem.body.bvh import BvhSkeleton, forward_kinematics, parse_bvh, read_bvh, write_bvh
from fabricfem.body.crossing import ObstacleWalk, obstacle_walk
from fabricfem.body.ellipsoid import Ellipsoid
from fabricfem.body.lower_body import (
                                       DEFAULT_LOWER_BODY,
                                       LowerBodyDimensions,
                                       LowerBodyGait,
                                       lower_body,
                                       standing,
                                       winter_walking,
)
from fabricfem.body.mocap import (
                                  Mean,
                                  Offset,
                                  load_motion,
                                  map_points,
                                  read_c3d,
                                  read_marker_csv,
                                  read_trc,
                                  segment_points,
                                  write_c3d,
                                  write_trc,
)
from fabricfem.body.motion import (
                                   ElbowFlexion,
                                   JointTrajectory,
                                   KinematicsSource,
                                   LegKinematics,
                                   joint_torque,
                                   stepping_over,
                                   walking,
)
from fabricfem.body.pose import Body, Segment, segment_frame
from fabricfem.body.schedule import SegmentSchedule

__all__ = [
                                       "DEFAULT_ARM",
                                       "DEFAULT_LOWER_BODY",
                                       "ArmDimensions",
                                       "Body",
                                       "BvhSkeleton",
                                       "ElbowFlexion",
                                       "Ellipsoid",
                                       "JointTrajectory",
                                       "KinematicsSource",
                                       "LegKinematics",
                                       "LowerBodyDimensions",
                                       "LowerBodyGait",
                                       "Mean",
                                       "ObstacleWalk",
                                       "Offset",
                                       "Segment",
                                       "SegmentSchedule",
                                       "default_arm",
                                       "elbow_flexion",
                                       "forward_kinematics",
                                       "joint_torque",
                                       "load_motion",
                                       "lower_body",
                                       "map_points",
                                       "obstacle_walk",
                                       "parse_bvh",
                                       "read_bvh",
                                       "read_c3d",
                                       "read_marker_csv",
                                       "read_trc",
                                       "segment_frame",
                                       "segment_points",
                                       "standing",
                                       "stepping_over",
                                       "walking",
                                       "winter_walking",
                                       "write_bvh",
                                       "write_c3d",
                                       "write_trc",
]
