"""A robot's ROS 2 messages read for the deploy node, by their fields alone (``msg.pose.pose.position.x``,
``msg.ranges``), so that the tests and a robot without this package's simulator use the same code: each reader
returns plain values or raises a ``ValueError`` naming what is wrong with the message.

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from atrv_warp.core.observation import RobotObservation, Scan

__all__ = ["read_imu", "read_odometry", "read_scan", "scan_geometry"]


def read_odometry(msg) -> tuple[list[float], list[float]]:
    """A ``nav_msgs/Odometry``'s pose (x, y, z, qx, qy, qz, qw) and twist (linear x, y, z, angular x, y, z).

    Raises:
        ValueError: A non-finite value or a zero orientation quaternion (named).
    """
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    t = msg.twist.twist
    pose = [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
    twist = [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z]
    if not all(math.isfinite(v) for v in pose + twist):
        raise ValueError(f"non-finite odometry (pose {_short(pose)}, twist {_short(twist)})")
    if math.hypot(*pose[3:]) < 1e-6:
        raise ValueError("odometry orientation is a zero quaternion")
    return pose, twist


def read_imu(msg) -> tuple[list[float], list[float]]:
    """A ``sensor_msgs/Imu``'s orientation (x, y, z, w) and angular velocity (x, y, z) [rad/s].

    Raises:
        ValueError: A non-finite value or a zero orientation quaternion (named).
    """
    q, w = msg.orientation, msg.angular_velocity
    orientation, omega = [q.x, q.y, q.z, q.w], [w.x, w.y, w.z]
    if not all(math.isfinite(v) for v in orientation + omega):
        raise ValueError(f"non-finite IMU (orientation {_short(orientation)}, angular velocity {_short(omega)})")
    if math.hypot(*orientation) < 1e-6:
        raise ValueError("IMU orientation is a zero quaternion (an IMU without orientation cannot serve the policy)")
    return orientation, omega


def scan_geometry(msg) -> str:
    """A ``LaserScan``'s geometry in words: beams, angles [rad] and field of view [deg]."""
    beams = len(msg.ranges)
    last = msg.angle_min + msg.angle_increment * max(beams - 1, 0)
    return (f"{beams} beams from {msg.angle_min:.3f} to {last:.3f} rad "
            f"({math.degrees(last - msg.angle_min):.0f} deg)")


def read_scan(msg, observation: RobotObservation) -> Scan:
    """A ``sensor_msgs/LaserScan`` as the observation builder reads it (REP 117: ``+inf`` no return, ``-inf`` too
    close, ``NaN`` invalid).

    Raises:
        ValueError: A geometry the policy's sectors cannot use (no beams, a non-finite or non-positive
            ``angle_increment``, a field of view that does not reach every sector: both geometries named), or no
            valid beam.
    """
    geometry = [msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max]
    if not msg.ranges or not all(math.isfinite(v) for v in geometry) or not msg.angle_increment > 0:
        raise ValueError(f"unusable scan geometry: {len(msg.ranges)} beams, angle_min {msg.angle_min}, "
                         f"angle_increment {msg.angle_increment} (need > 0: counter-clockwise beams), range "
                         f"[{msg.range_min}, {msg.range_max}] m")
    if not 0 <= msg.range_min < msg.range_max:
        raise ValueError(f"impossible scan: range_min {msg.range_min} m, range_max {msg.range_max} m (need 0 <= "
                         "range_min < range_max)")
    sectors = observation.sectors
    last = msg.angle_min + msg.angle_increment * (len(msg.ranges) - 1)
    if sectors is not None and not sectors.covered_by(msg.angle_min, last):
        raise ValueError(f"scan refused: its field of view ({scan_geometry(msg)}) does not cover the policy's "
                         f"{sectors.count} sectors from {sectors.edges[0]:.3f} to {sectors.edges[-1]:.3f} rad "
                         f"({math.degrees(sectors.edges[-1] - sectors.edges[0]):.0f} deg)")
    ranges = torch.as_tensor(list(msg.ranges), dtype=torch.float64)
    if bool(torch.isnan(ranges).all()):
        raise ValueError(f"scan with no valid beam (all {len(msg.ranges)} ranges NaN)")
    return Scan(ranges, float(msg.angle_min), float(msg.angle_increment), float(msg.range_min), float(msg.range_max))


def _short(values: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.3g}" for v in values) + "]"
