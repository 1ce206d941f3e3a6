"""The rover's frame tree as ``tf2_msgs/TFMessage`` dicts, for the node's /tf and bags (no rclpy, no
tf2_msgs); the quaternion maths is the light core's (:mod:`atrv_warp.core.geometry`).

REP 105, with the simulator as the localisation::

    world -> odom -> base_link -> <chassis> -> <wheels>      (/tf, every state publication)
                                    <chassis> -> <fixed frames: lrf_frame, cbimu_frame, ...>  (/tf_static)

``odom -> base_link`` is the wheel odometry (/odom); ``world -> odom`` is the correction that puts
``base_link`` at the simulator's true pose (/ground_truth/odom without its optional noise), as a
localisation node would publish it; ``base_link -> <chassis>`` is the identity (the URDF's root link
is the base), static; each wheel turns about its joint axis by its joint position. With several rovers
every frame but ``world`` is prefixed ``rover_<k>/``. In a map, ``world`` is ``map`` (:data:`MAP_FRAME`).
"""

from __future__ import annotations

import math

import numpy as np

from atrv_warp.core.geometry import matrix_to_quat, quat_to_matrix, yaw_to_quat

__all__ = ["MAP_FRAME", "WORLD_FRAME", "planar_matrix", "pose_matrix", "transform_dict", "turn_matrix"]

WORLD_FRAME = "world"
"""The fixed frame of /ground_truth/odom, the markers and the top of the tree."""
MAP_FRAME = "map"
"""The top of the tree in place of ``world`` where the node drives in a map (parameter ``map``): Nav2's global frame,
the frame of /map, whose ``map -> odom`` is what AMCL would publish."""


def pose_matrix(xyz, quat_xyzw) -> np.ndarray:
    """4x4 transform of a position [m] and a unit quaternion (x, y, z, w), normalised first (a float32 pose's
    is unit to 1e-7 only; its matrix would then not be a rotation, and the quaternion read back off by 1e-3)."""
    q = np.asarray([float(v) for v in quat_xyzw])
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix((q / np.linalg.norm(q)).tolist()).numpy()
    m[:3, 3] = [float(v) for v in xyz]
    return m


def planar_matrix(x: float, y: float, yaw: float) -> np.ndarray:
    """4x4 transform of a planar pose: (x, y) [m] and a heading [rad] about z."""
    return pose_matrix((x, y, 0.0), yaw_to_quat(float(yaw)).tolist())


def turn_matrix(axis, angle: float) -> np.ndarray:
    """4x4 rotation by ``angle`` [rad] about the unit ``axis`` (a revolute joint at ``angle``)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    s = math.sin(0.5 * angle)
    return pose_matrix((0.0, 0.0, 0.0), (a[0] * s, a[1] * s, a[2] * s, math.cos(0.5 * angle)))


def transform_dict(parent: str, child: str, stamp_ns: int, m: np.ndarray) -> dict:
    """A ``geometry_msgs/TransformStamped`` as the nested dict :class:`~.bag.BagWriter` writes: ``child``'s
    pose ``m`` (4x4) in ``parent``."""
    x, y, z, w = matrix_to_quat(np.asarray(m, dtype=float)[:3, :3]).tolist()
    t = m[:3, 3]
    return {"header": {"stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
                       "frame_id": parent},
            "child_frame_id": child,
            "transform": {"translation": {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])},
                          "rotation": {"x": x, "y": y, "z": z, "w": w}}}
