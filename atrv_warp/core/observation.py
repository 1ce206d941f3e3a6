"""The robot observation, built from what a robot publishes: the same vector the environment computes, in torch.

A policy trained on ``observation="robot"`` (the ``nav_deploy`` task) observes only what the rover's own stack
publishes. :class:`RobotObservation` turns those messages into the policy's input:

- wheel odometry (``nav_msgs/Odometry`` on ``/odom``): the pose in the odometry frame, as (x, y, yaw) or as
  position (x, y, z) + orientation quaternion (x, y, z, w), and the twist's ``linear.x`` and ``angular.z``;
- the IMU (``sensor_msgs/Imu``): its orientation quaternion (x, y, z, w) and angular velocity (x, y, z) in the
  IMU's frame;
- a ``sensor_msgs/LaserScan`` (:class:`Scan`): any beam count and field of view, reduced into the policy's
  sectors through :mod:`.scan` (REP 117);
- the goal (x, y) in the odometry frame (``/goal_pose`` transformed into ``odom``), or, for a policy that follows a
  plan (``observation_kind`` ``path``, the ``follow_path`` task), the plan's fields as
  :class:`~atrv_warp.core.path.PathTracker` reads them (``path_<k>_x``, ``path_<k>_y``, ``path_remaining``,
  ``sin_goal_yaw``, ``cos_goal_yaw``);
- the policy's last actions, newest first.

Nothing is declared here: the field order, each field's clip bounds, the scan's sector edges and clip, and the
action history's length come from an exported policy's contract (``atrv_warp.json`` in the ``.pt2``, written by
:func:`atrv_warp.rl.export.contract` from :mod:`atrv_warp.task.spec`), so a deploy node or a second engine's twin
builds the observation from the file alone. The maths is the environment's (``task/kernels/observe.py``):

- ``goal_distance`` = |goal - p| [m]; the bearing = wrap(atan2(goal - p) - yaw) [rad], observed as its sine and
  cosine (p, yaw: the odometry pose);
- ``odom_linear``, ``odom_angular``: the odometry twist [m/s, rad/s];
- ``imu_roll``, ``imu_pitch``: intrinsic Z-Y-X angles of the IMU's orientation (:func:`.geometry.quat_to_rpy`)
  [rad]; ``imu_yaw_rate``: the IMU's angular velocity about its z [rad/s];
- ``scan_<k>``: :func:`.scan.sector_readings`; ``last_action_<k>_<column>``: the action chosen k steps before;

each clipped to its field's [low, high]. Example, one robot::

    import json, torch
    from atrv_warp.core.files import load_exported_program
    from atrv_warp.core.observation import RobotObservation, Scan

    program, extra = load_exported_program("nav_deploy.pt2")    # checked: nothing in the file can run code
    policy = program.module()
    build = RobotObservation.from_contract(json.loads(extra["atrv_warp.json"]))
    obs = build(odom_pose=[x, y, yaw], odom_twist=[v, w], imu_orientation=q_xyzw, imu_angular_velocity=omega,
                goal=[gx, gy], scan=Scan(ranges, angle_min, angle_increment, range_min, range_max),
                last_actions=history)                # (D,), float32
    action = policy(obs[None])[0]                    # in [-1, 1]²
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from atrv_warp.core.geometry import quat_to_rpy, quat_to_yaw, wrap_angle
from atrv_warp.core.scan import ScanSectors, remount, sector_readings

__all__ = ["PATH_SIGNALS", "ROBOT_SIGNALS", "RobotObservation", "Scan"]

ROBOT_SIGNALS: tuple[str, ...] = ("goal_distance", "sin_goal_bearing", "cos_goal_bearing", "odom_linear",
                                  "odom_angular", "imu_roll", "imu_pitch", "imu_yaw_rate")
"""The leading fields :class:`RobotObservation` computes from a robot's messages (by name; their order, bounds,
units and frames are the contract's, from ``atrv_warp.task.spec.ROBOT_OBSERVATION``)."""
PATH_SIGNALS: tuple[str, ...] = ("path_remaining", "sin_goal_yaw", "cos_goal_yaw")
"""A plan-following policy's fields besides its points (``path_<k>_x``, ``path_<k>_y``), read from the ``path``
mapping :class:`~atrv_warp.core.path.PathTracker` gives (``atrv_warp.task.spec.PATH_OBSERVATION``)."""
_GOAL_SIGNALS = ("goal_distance", "sin_goal_bearing", "cos_goal_bearing")

_SCAN = re.compile(r"scan_(\d+)")
_LAST_ACTION = re.compile(r"last_action_(\d+)_(\w+)")
_PATH_POINT = re.compile(r"path_(\d+)_[xy]")


@dataclass(frozen=True)
class Scan:
    """One ``sensor_msgs/LaserScan``'s ranges and geometry (the scanner's frame, counter-clockwise from its +x)."""

    ranges: object
    """(..., B) ranges [m] (``+inf`` no return, ``-inf`` too close, ``NaN`` invalid: REP 117)."""
    angle_min: float
    """Angle of the first beam [rad]."""
    angle_increment: float
    """Angle between beams [rad] (> 0: beams ordered counter-clockwise)."""
    range_min: float
    """Shorter ranges read as too close (blocked) [m]."""
    range_max: float
    """Longer ranges read as no return (clear) [m]."""
    mount: tuple[float, float, float] | None = None
    """Where this scanner is in the frame of the scanner the policy was trained with: (x [m], y [m], yaw [rad]);
    ``None``: there (its returns are read as they are; else :func:`.scan.remount` carries them over)."""

    def angles(self) -> torch.Tensor:
        """(B,) float64 each beam's angle [rad]: ``angle_min + i * angle_increment``."""
        beams = torch.as_tensor(self.ranges).shape[-1]
        return self.angle_min + self.angle_increment * torch.arange(beams, dtype=torch.float64)


@dataclass(frozen=True)
class _Field:
    name: str
    low: float
    high: float


class RobotObservation:
    """Builds a robot-observation policy's input (B, D) from a robot's odometry, IMU, scan, goal and last actions.

    Construct it from an exported policy's contract (:meth:`from_contract`); ``atrv_warp.task.spec.policy_contract``
    gives the same plain values for a task without exporting. Calling it (:meth:`__call__`) takes one robot's
    messages (unbatched) or a batch of B robots' (a leading dimension on every input) and gives (D,) or (B, D)
    float32 in the contract's field order, each value clipped to its [low, high].
    """

    def __init__(self, fields: Sequence[Mapping], *, sectors: ScanSectors | None = None, action_columns:
                 Sequence[str] = ()):
        """
        Args:
            fields: The observation's fields in order, each a mapping with ``name``, ``low`` and ``high`` (the
                contract's ``observation`` entries).
            sectors: The scan's sectors (needed when a field is ``scan_<k>``).
            action_columns: The action's column names (``last_action_<k>_<column>`` fields).

        Raises:
            ValueError: A field this class cannot compute from a robot's messages (an arena field such as
                ``target_x``), a scan sector the sectors lack, or a last-action column the action lacks.
        """
        self.fields = tuple(_Field(str(f["name"]), float(f["low"]), float(f["high"])) for f in fields)
        self.sectors, self.action_columns = sectors, tuple(action_columns)
        self.action_history = 0
        """K: the last actions observed (``last_action_1_*`` … ``last_action_K_*``)."""
        for f in self.fields:
            if f.name in ROBOT_SIGNALS or f.name in PATH_SIGNALS or _PATH_POINT.fullmatch(f.name):
                continue
            if m := _SCAN.fullmatch(f.name):
                if sectors is None or int(m[1]) >= sectors.count:
                    raise ValueError(f"the policy observes {f.name!r}, but its contract declares "
                                     f"{sectors.count if sectors else 'no'} scan sectors")
            elif m := _LAST_ACTION.fullmatch(f.name):
                if m[2] not in self.action_columns or int(m[1]) < 1:
                    raise ValueError(f"the policy observes {f.name!r}, but its action's columns are "
                                     f"{list(self.action_columns)}")
                self.action_history = max(self.action_history, int(m[1]))
            else:
                raise ValueError(f"the policy observes {f.name!r}, which a robot does not publish: RobotObservation "
                                 f"builds the robot observation ({', '.join(ROBOT_SIGNALS)}, scan sectors, last "
                                 "actions) and the path one (the plan's points and fields); export a policy trained "
                                 "with observation='robot' or 'path' (e.g. task nav_deploy or follow_path)")
        self.follows_path = any(f.name in PATH_SIGNALS or _PATH_POINT.fullmatch(f.name) for f in self.fields)
        """Whether the policy observes a plan (``path=`` is then needed, ``goal=`` not)."""
        self.low = torch.tensor([f.low for f in self.fields], dtype=torch.float64)
        self.high = torch.tensor([f.high for f in self.fields], dtype=torch.float64)

    @classmethod
    def from_contract(cls, contract: Mapping) -> RobotObservation:
        """From an exported policy's contract (its ``atrv_warp.json``, or
        ``atrv_warp.task.spec.policy_contract(task)``): ``observation``, ``scan.sectors``, ``action.names``.

        Raises:
            ValueError: The contract's policy observes something a robot does not publish (``observation_kind``
                other than ``robot``), or the contract lacks what the builder reads.
        """
        kind = contract.get("observation_kind", "arena")  # format 2 contracts predate robot observations
        if kind not in ("robot", "path"):
            raise ValueError(f"the policy observes the {kind!r} observation; RobotObservation builds the 'robot' and "
                             "'path' ones (a policy trained with observation='robot' or 'path', e.g. task nav_deploy "
                             "or follow_path)")
        try:
            fields = contract["observation"]
            scan = contract.get("scan") or {}
            sectors = scan.get("sectors")
            columns = contract["action"]["names"]
        except (KeyError, TypeError, AttributeError) as err:
            raise ValueError(f"not an exported policy's contract: {err!r} missing") from None
        return cls(fields, sectors=ScanSectors(tuple(sectors["edges_rad"]), float(sectors["clip_m"]))
                   if sectors else None, action_columns=columns)

    @property
    def names(self) -> tuple[str, ...]:
        """The fields' names, in order."""
        return tuple(f.name for f in self.fields)

    def __call__(self, *, odom_pose, odom_twist, imu_orientation, imu_angular_velocity, goal=None,
                 scan: Scan | None = None, last_actions=None, path: Mapping | None = None) -> torch.Tensor:
        """The observation, (D,) for one robot or (B, D) for a batch (float32, each value clipped to its bounds).

        Args:
            odom_pose: (..., 3) x [m], y [m], yaw [rad] of the base in the odometry frame, or (..., 7) position
                (x, y, z) [m] and orientation quaternion (x, y, z, w) as ``nav_msgs/Odometry``'s ``pose.pose``.
            odom_twist: (..., 2) ``linear.x`` [m/s] and ``angular.z`` [rad/s] of the odometry's twist (base_link), or
                (..., 6) the whole twist (linear x, y, z; angular x, y, z).
            imu_orientation: (..., 4) the IMU's orientation quaternion (x, y, z, w) (normalised here).
            imu_angular_velocity: (..., 3) the IMU's angular velocity (x, y, z) [rad/s] in its own frame.
            goal: (..., 2) the goal's x, y [m] in the odometry frame (a policy that observes a goal).
            scan: The latest laser scan (needed when the policy observes scan sectors); its ranges (..., beams).
            last_actions: (..., K, C) or (..., K * C) the actions the policy chose 1 … K steps before, newest first,
                in the contract's column order (needed when it observes them; zeros after a reset).
            path: The plan's fields by name, as :class:`~atrv_warp.core.path.PathTracker` gives them for the
                robot's pose (a policy that follows a plan): each a number, or (...) for a batch.

        Raises:
            ValueError: An input of the wrong shape, a non-finite odometry, IMU, goal or action value, a zero
                quaternion, or a missing scan or action history; the message names the input.
        """
        pose = _vector("odom_pose", odom_pose, (3, 7))
        batch = pose.shape[:-1]
        twist = _vector("odom_twist", odom_twist, (2, 6), batch)
        q = _vector("imu_orientation", imu_orientation, (4,), batch)
        omega = _vector("imu_angular_velocity", imu_angular_velocity, (3,), batch)
        if pose.shape[-1] == 7:
            yaw = quat_to_yaw(_unit("odom_pose orientation", pose[..., 3:7]))
        else:
            yaw = pose[..., 2]
        rpy = quat_to_rpy(_unit("imu_orientation", q))
        values = {"odom_linear": twist[..., 0], "odom_angular": twist[..., -1], "imu_roll": rpy[..., 0],
                  "imu_pitch": rpy[..., 1], "imu_yaw_rate": omega[..., 2]}
        if any(f.name in _GOAL_SIGNALS for f in self.fields):
            if goal is None:
                raise ValueError("goal: the policy observes its goal; pass goal=(x, y) in the odometry frame")
            delta = _vector("goal", goal, (2,), batch) - pose[..., :2]
            bearing = wrap_angle(torch.atan2(delta[..., 1], delta[..., 0]) - yaw)
            values.update(goal_distance=delta.norm(dim=-1), sin_goal_bearing=bearing.sin(),
                          cos_goal_bearing=bearing.cos())
        if self.follows_path:
            values.update(self._path(path, batch))
        if any(_SCAN.fullmatch(f.name) for f in self.fields):
            values.update(self._scan(scan, batch))
        if self.action_history:
            values.update(self._last_actions(last_actions, batch))
        out = torch.stack([values[f.name] for f in self.fields], -1)
        return torch.minimum(torch.maximum(out, self.low), self.high).to(torch.float32)

    def _path(self, path: Mapping | None, batch: torch.Size) -> dict[str, torch.Tensor]:
        names = [f.name for f in self.fields if f.name in PATH_SIGNALS or _PATH_POINT.fullmatch(f.name)]
        if not isinstance(path, Mapping):
            raise ValueError(  # noqa: TRY004 - every bad input is a ValueError here
                "path: the policy follows a plan; pass path=PathTracker(...)(pose), its fields by name")
        missing = [n for n in names if n not in path]
        if missing:
            raise ValueError(f"path: the plan's fields lack {', '.join(missing[:4])}{', …' if len(missing) > 4 else ''}")
        values = {}
        for n in names:
            v = torch.as_tensor(path[n], dtype=torch.float64)
            if v.shape != batch or not bool(torch.isfinite(v).all()):
                raise ValueError(f"path.{n}: expected a finite value of shape {tuple(batch)}, got {v.tolist()}")
            values[n] = v
        return values

    def _scan(self, scan: Scan | None, batch: torch.Size) -> dict[str, torch.Tensor]:
        if scan is None:
            raise ValueError(f"scan: the policy observes {self.sectors.count} scan sectors; pass the latest LaserScan "
                             "as scan=Scan(ranges, angle_min, angle_increment, range_min, range_max)")
        ranges = torch.as_tensor(scan.ranges, dtype=torch.float64)
        if ranges.ndim < 1 or ranges.shape[:-1] != batch or ranges.shape[-1] < 1:
            raise ValueError(f"scan.ranges: expected shape {(*batch, 'beams')}, got {tuple(ranges.shape)}")
        geometry = {"angle_min": scan.angle_min, "angle_increment": scan.angle_increment,
                    "range_min": scan.range_min, "range_max": scan.range_max}
        for name, value in geometry.items():
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise ValueError(f"scan.{name}: expected a finite number, got {value!r}")
        if not scan.angle_increment > 0:
            raise ValueError(f"scan.angle_increment: expected > 0 (beams counter-clockwise), got {scan.angle_increment}")
        angles = scan.angles()
        if scan.mount is not None and any(scan.mount):
            ranges, angles = remount(ranges, angles, scan.mount, range_min=scan.range_min, range_max=scan.range_max)
        readings = sector_readings(ranges, angles, self.sectors, range_min=scan.range_min,
                                   range_max=scan.range_max).to(torch.float64)
        return {f"scan_{k}": readings[..., k] for k in range(self.sectors.count)}

    def _last_actions(self, last_actions, batch: torch.Size) -> dict[str, torch.Tensor]:
        k, c = self.action_history, len(self.action_columns)
        if last_actions is None:
            raise ValueError(f"last_actions: the policy observes its last {k} actions ({k}, {c}), newest first")
        a = torch.as_tensor(last_actions, dtype=torch.float64)
        if a.shape == (*batch, k * c):
            a = a.unflatten(-1, (k, c))
        if a.shape != (*batch, k, c):
            raise ValueError(f"last_actions: expected shape {(*batch, k, c)} (newest first) or {(*batch, k * c)}, "
                             f"got {tuple(a.shape)}")
        if not bool(torch.isfinite(a).all()):
            raise ValueError("last_actions: non-finite values")
        a = a.clamp(-1.0, 1.0)
        return {f"last_action_{i + 1}_{col}": a[..., i, j] for i in range(k) for j, col in enumerate(self.action_columns)}


def _vector(name: str, value, sizes: tuple[int, ...], batch: torch.Size | None = None) -> torch.Tensor:
    """``value`` as float64 (..., n) with n in ``sizes`` and the leading shape ``batch``; finite."""
    try:
        x = torch.as_tensor(value, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError) as err:
        raise ValueError(f"{name}: not a tensor of numbers ({err})") from None
    if x.ndim < 1 or x.shape[-1] not in sizes or (batch is not None and x.shape[:-1] != batch):
        lead = "..." if batch is None else ", ".join(map(str, batch))
        want = " or ".join(f"({lead + ', ' if lead else ''}{n})" for n in sizes)
        raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
    if not bool(torch.isfinite(x).all()):
        raise ValueError(f"{name}: non-finite values {x.flatten().tolist()[:8]}")
    return x


def _unit(name: str, q: torch.Tensor) -> torch.Tensor:
    norm = q.norm(dim=-1, keepdim=True)
    if not bool((norm > 1e-6).all()):
        raise ValueError(f"{name}: a zero quaternion is no orientation")
    return q / norm
