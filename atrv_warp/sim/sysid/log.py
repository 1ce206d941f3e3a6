"""A drive recorded on a rover, read from a ROS 2 bag in MCAP format (``ros2 bag record -s mcap``, or the
simulator node's ``bag`` parameter): the commands, the wheel encoders and a reference pose, as arrays.

Topics (names are options; the defaults are the simulator node's):

- ``/cmd_vel`` (``geometry_msgs/Twist``, or ``TwistStamped``): the velocity commands the base received;
- ``/joint_states`` (``sensor_msgs/JointState``): the four wheel joints' velocities [rad/s], and their
  efforts [N·m] where the driver reports them;
- a reference pose: ``/ground_truth/odom`` (``nav_msgs/Odometry``), or any ``Odometry`` or
  ``geometry_msgs/PoseStamped`` topic, e.g. motion capture or RTK GPS.

Times are the messages' header stamps, and the bag's log time for a message without a header (a Twist).
Every problem is a :class:`BagError` whose one line names the file.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from atrv_warp.core.geometry import quat_to_rpy, quat_to_yaw

__all__ = ["POSE_TYPES", "BagError", "DriveLog", "Topics", "read_drive_log"]

POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
"""Message types a reference-pose topic may have."""
_CMD_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
_JOINT_TYPES = ("sensor_msgs/msg/JointState",)


class BagError(ValueError):
    """A bag that cannot be calibrated from; the message is one line naming the file and the problem."""


@dataclass(frozen=True)
class Topics:
    """Topic names of a drive log (the simulator node's by default)."""

    cmd_vel: str = "/cmd_vel"
    joint_states: str = "/joint_states"
    pose: str = "/ground_truth/odom"


@dataclass
class DriveLog:
    """One rover's recorded drive, times in seconds from the first message read.

    Attributes:
        path: The bag.
        pose_time, pose: (P,) times and (P, 3) x [m], y [m], yaw [rad] (unwrapped) of the reference pose.
        body_velocity: (P, 3) forward and leftward speed [m/s] and yaw rate [rad/s]: the Odometry's twist,
            or finite differences of the poses for a PoseStamped topic.
        joint_time, wheel_speed: (J,) times and (J, 2) mean forward wheel speed of the left and right side [rad/s].
        effort: (J, 2) mean forward wheel effort per side [N·m], or ``None`` if the driver reports none.
        cmd_time, cmd: (C,) times and (C, 2) commanded linear [m/s] and angular [rad/s] velocity; empty if the
            bag has no command topic.
        topics: Every topic in the bag and its message type.
        twist: Whether the pose topic carried the velocity (Odometry); if not, ``body_velocity`` is from
            finite differences, which a fit takes again from smoothed poses.
        tilt: (P, 2) the chassis' roll and pitch [rad] from the reference pose's orientation (zero where it
            gives the heading alone).
        tilt_rate: (P, 2) the chassis' angular velocity about its own x and y [rad/s] (the Odometry's twist), or
            ``None`` for a PoseStamped topic.
        wheel_joints, wheel_each: The wheel joints in the order of ``wheels``, and (J, W) each one's forward
            speed [rad/s].
    """

    path: str
    pose_time: np.ndarray
    pose: np.ndarray
    body_velocity: np.ndarray
    joint_time: np.ndarray
    wheel_speed: np.ndarray
    effort: np.ndarray | None
    cmd_time: np.ndarray
    cmd: np.ndarray
    topics: dict[str, str] = field(default_factory=dict)
    twist: bool = True
    tilt: np.ndarray | None = None
    tilt_rate: np.ndarray | None = None
    wheel_joints: tuple[str, ...] = ()
    wheel_each: np.ndarray | None = None

    @property
    def duration(self) -> float:
        """Seconds covered by both the poses and the wheel encoders."""
        return max(0.0, min(self.pose_time[-1], self.joint_time[-1]) - max(self.pose_time[0], self.joint_time[0]))


def _stamp(decoded, log_time_ns: int) -> int:
    header = getattr(decoded, "header", None)
    if header is None:
        return log_time_ns
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def read_drive_log(path, wheels: dict[str, tuple[int, float]], topics: Topics = Topics()) -> DriveLog:
    """Read ``path`` into a :class:`DriveLog`.

    Args:
        path: An MCAP bag.
        wheels: Each wheel joint's name -> (side: 0 left, 1 right; sign: +1 if positive joint velocity drives
            forward), from the rover's URDF (:func:`atrv_warp.sim.urdf.load_rover`).
        topics: The topic names.

    Raises:
        BagError: not an MCAP file or truncated; a needed topic is missing (the message lists the bag's
            topics); a topic's message type does not match; timestamps go backwards; a wheel joint is missing.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = Path(path)
    if path.is_dir():  # a rosbag2 folder (metadata.yaml and its .mcap files)
        files = sorted(path.glob("*.mcap"))
        if len(files) != 1:
            raise BagError(f"{path}: a bag folder with {len(files)} .mcap files; give one of them"
                           + (f" ({', '.join(f.name for f in files)})" if files else ""))
        path = files[0]
    if not path.is_file():
        raise BagError(f"{path}: no such file")
    needed = {topics.pose: POSE_TYPES, topics.joint_states: _JOINT_TYPES, topics.cmd_vel: _CMD_TYPES}
    rows: dict[str, list] = {topics.pose: [], topics.joint_states: [], topics.cmd_vel: []}
    last: dict[str, int] = {}
    seen: dict[str, str] = {}
    with path.open("rb") as fh:
        if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes; record with "
                           "`ros2 bag record -s mcap`)")
        fh.seek(0)
        try:
            reader = make_reader(fh, validate_crcs=True, decoder_factories=[DecoderFactory()])  # a damaged chunk is named
            summary = reader.get_summary()
            if summary is not None:
                seen = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()
                        if c.schema_id in summary.schemas}
                _check_topics(path, seen, needed, topics)
            for schema, channel, message, decoded in reader.iter_decoded_messages(topics=list(rows), log_time_order=False):
                seen.setdefault(channel.topic, schema.name if schema else "?")
                if schema is None or schema.name not in needed[channel.topic]:
                    raise BagError(f"{path}: topic {channel.topic} has message type {schema.name if schema else '?'}, "
                                   f"expected {' or '.join(needed[channel.topic])}")
                t = _stamp(decoded, message.log_time)
                if t < last.get(channel.topic, t):
                    raise BagError(f"{path}: timestamps go backwards on {channel.topic}: "
                                   f"{t / 1e9:.3f} s after {last[channel.topic] / 1e9:.3f} s")
                last[channel.topic] = t
                rows[channel.topic].append((t, decoded))
        except BagError:
            raise
        except (McapError, EOFError, OSError, ValueError, KeyError, IndexError, struct.error) as err:
            what = "not an MCAP file" if "magic" in f"{type(err).__name__} {err}".lower() else "truncated or corrupt"
            raise BagError(f"{path}: {what} near byte {fh.tell():,} ({type(err).__name__}: {err})") from None
        except Exception as err:  # noqa: BLE001 - a damaged chunk fails in its decompressor (zstandard, lz4), any type
            raise BagError(f"{path}: corrupt near byte {fh.tell():,}: a chunk does not decompress "
                           f"({type(err).__name__}: {' '.join(str(err).split())[:160]})") from None
    if summary is None:  # a bag without a summary section (cut short while recording): check what was read
        _check_topics(path, seen, needed, topics)
    return _arrays(path, rows, wheels, topics, seen)


MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The eight bytes every MCAP file starts with."""


def _check_topics(path: Path, seen: dict[str, str], needed: dict, topics: Topics) -> None:
    have = ", ".join(f"{t} ({seen[t]})" for t in sorted(seen)) or "none"
    for topic in (topics.pose, topics.joint_states):
        if topic not in seen:
            raise BagError(f"{path}: no topic {topic} (this bag has: {have})")
    for topic, types in needed.items():
        if topic in seen and seen[topic] not in types:
            raise BagError(f"{path}: topic {topic} has message type {seen[topic]}, expected {' or '.join(types)}")


def _arrays(path: Path, rows: dict, wheels: dict[str, tuple[int, float]], topics: Topics,
            seen: dict[str, str]) -> DriveLog:
    poses, joints, cmds = rows[topics.pose], rows[topics.joint_states], rows[topics.cmd_vel]
    if len(poses) < 2 or len(joints) < 2:
        raise BagError(f"{path}: too few messages to fit ({len(poses)} on {topics.pose}, {len(joints)} on "
                       f"{topics.joint_states})")
    t0 = min(r[0][0] for r in (poses, joints, cmds) if r)
    pose_time = np.array([(t - t0) * 1e-9 for t, _ in poses])
    pose, twist = [], []
    for _, m in poses:
        p = m.pose.pose if hasattr(m.pose, "pose") else m.pose
        o = p.orientation
        pose.append((p.position.x, p.position.y, o.x, o.y, o.z, o.w))
        if hasattr(m, "twist"):
            tw = m.twist.twist
            twist.append((tw.linear.x, tw.linear.y, tw.angular.z, tw.angular.x, tw.angular.y))
    pose = np.array(pose, dtype=np.float64)
    rpy = quat_to_rpy(torch.from_numpy(pose[:, 2:])).numpy()
    pose = np.concatenate([pose[:, :2], quat_to_yaw(torch.from_numpy(pose[:, 2:])).numpy()[:, None]], 1)
    pose[:, 2] = np.unwrap(pose[:, 2])
    tilt_rate = None
    if twist:
        body_velocity = np.array(twist, dtype=np.float64)
        body_velocity, tilt_rate = body_velocity[:, :3], body_velocity[:, 3:]
    else:  # PoseStamped: the velocity from the poses, turned into the chassis frame
        vx, vy = np.gradient(pose[:, 0], pose_time), np.gradient(pose[:, 1], pose_time)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        body_velocity = np.stack([c * vx + s * vy, -s * vx + c * vy, np.gradient(pose[:, 2], pose_time)], -1)
    names = list(joints[0][1].name)
    missing = sorted(set(wheels) - set(names))
    if missing:
        raise BagError(f"{path}: {topics.joint_states} lacks wheel joint(s) {missing} (it has {names})")
    index = [names.index(j) for j in wheels]
    side = np.array([wheels[j][0] for j in wheels])
    sign = np.array([wheels[j][1] for j in wheels], dtype=np.float64)
    weight = np.stack([(side == s) / max(1, int((side == s).sum())) for s in (0, 1)], -1) * sign[:, None]  # (W, 2)
    velocity, effort = [], []
    for _, m in joints:
        if list(m.name) != names or len(m.velocity) != len(names):
            raise BagError(f"{path}: {topics.joint_states} changes its joints or lacks velocities mid-bag")
        velocity.append([m.velocity[i] for i in index])
        effort.append([m.effort[i] for i in index] if len(m.effort) == len(names) else None)
    has_effort = all(e is not None for e in effort)
    cmd = [((m.twist if hasattr(m, "twist") else m).linear.x, (m.twist if hasattr(m, "twist") else m).angular.z)
           for _, m in cmds]
    arrays = DriveLog(
        path=str(path), pose_time=pose_time, pose=pose, body_velocity=body_velocity,
        joint_time=np.array([(t - t0) * 1e-9 for t, _ in joints]),
        wheel_speed=np.array(velocity, dtype=np.float64) @ weight,
        effort=np.array(effort, dtype=np.float64) @ weight if has_effort else None,
        cmd_time=np.array([(t - t0) * 1e-9 for t, _ in cmds]),
        cmd=np.array(cmd, dtype=np.float64).reshape(-1, 2), topics=dict(sorted(seen.items())), twist=bool(twist),
        tilt=rpy[:, :2], tilt_rate=tilt_rate, wheel_joints=tuple(wheels),
        wheel_each=np.array(velocity, dtype=np.float64) * sign[None, :])
    for name in ("pose", "body_velocity", "wheel_speed", "cmd", "tilt_rate"):  # the tilt and each wheel: as these
        if getattr(arrays, name) is not None and not np.isfinite(getattr(arrays, name)).all():
            raise BagError(f"{path}: non-finite values in the {name.replace('_', ' ')}")
    return arrays
