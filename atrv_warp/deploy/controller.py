"""The deploy node's logic, without ROS: load an exported policy, read a robot's messages, decide each command.

:func:`load_deployable` opens a ``.pt2`` (``python -m atrv_warp.export``) and refuses, in one line, a file or a
contract the node cannot serve: a missing or garbage file, no contract, another contract format, a ``torque``
policy (it commands wheel torques, not ``/cmd_vel``) or an ``arena`` observation (it observes what only the
simulator knows). :class:`Controller` holds the latest ``/odom``, ``/imu``, ``/scan`` and goal, and
:meth:`Controller.tick` decides, once per control period, what the rover does: drive by the policy, hold still
(a stale, non-finite or unusable sensor; it resumes when they are valid again), or end the goal (reached, time
limit). Messages are read by their fields alone (``msg.pose.pose.position.x``, ``msg.ranges``), so the tests and
a robot without this package's simulator use the same code; :mod:`atrv_warp.deploy.node` is the rclpy shell.

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from atrv_warp.core.files import ExportedFileError, load_exported_program
from atrv_warp.core.observation import RobotObservation, Scan
from atrv_warp.core.tf import TransformBuffer, frame_id
from atrv_warp.deploy.parameters import PARAMETER_BY_NAME

__all__ = ["EXPORT_FORMAT", "RATE_RANGE_HZ", "STATES", "TIME_LIMIT", "Controller", "Deployable", "PolicyRefused", "Settings", "Tick",
           "load_deployable", "read_imu", "read_odometry", "read_scan", "scan_geometry"]

EXPORT_FORMAT = "atrv_warp.exported_policy/3"
"""The contract format this node reads (``atrv_warp.rl.export.EXPORT_FORMAT``; ``tests/test_deploy.py`` holds the
two equal without importing the exporter here)."""

TIME_LIMIT = "time limit"
"""How an aborted status's ``reason`` starts when the goal ran out of ``time_limit`` (the node's ``NavigateToPose``
result reports it as Nav2's ``TIMEOUT``)."""
STATES = ("active", "holding", "reached", "aborted")
"""The goal status's ``state``: driving by the policy; held still for a ``reason`` (resumes by itself); the goal
reached (within ``goal_tolerance``); given up for a ``reason`` (time limit, shutdown, a new goal)."""


class PolicyRefused(ValueError):
    """A policy file or contract the node cannot serve; the message is one line naming the file and the problem."""


@dataclass(frozen=True)
class Deployable:
    """An exported policy the node can run: a ``twist`` action from the ``robot`` observation."""

    path: str
    """The ``.pt2`` file."""
    module: torch.nn.Module
    """The exported program's module: observation (B, D) float32 -> action (B, 2) in [-1, 1]."""
    contract: dict
    """Its ``atrv_warp.json`` (:func:`atrv_warp.rl.export.contract`)."""
    observation: RobotObservation
    """Builds its input from the robot's messages (the contract's fields, sectors and action history)."""
    scale: tuple[float, float]
    """What an action of 1.0 commands: linear.x [m/s], angular.z [rad/s] (the trained limits)."""
    rate_hz: float
    """The control rate it was trained at [Hz] (1 / the simulator's ``step_dt``)."""

    @property
    def period(self) -> float:
        """The control period [s]."""
        return 1.0 / self.rate_hz

    @property
    def reach_radius(self) -> float | None:
        """The distance from the goal within which the policy's task counted it reached [m] (its contract's
        ``reach_radius_m``; ``None`` for a file exported before it was kept)."""
        radius = self.contract.get("reach_radius_m")
        ok = isinstance(radius, int | float) and not isinstance(radius, bool) and math.isfinite(radius) and radius > 0
        return float(radius) if ok else None

    @property
    def robot(self) -> str | None:
        """The robot it was trained on (its contract's ``robot.name``; ``None`` for a policy exported before robots had
        files, which trained on the ATRV-Jr)."""
        robot = self.contract.get("robot")
        name = robot.get("name") if isinstance(robot, dict) else None
        return name if isinstance(name, str) and name else None

    def describe_robot(self) -> str:
        """One line: the robot it was trained on, and that robot's published limits."""
        robot = self.contract.get("robot")
        if not isinstance(robot, dict):
            return "trained on the ATRV-Jr (exported before policies recorded their robot)"
        lim = robot.get("limits") if isinstance(robot.get("limits"), dict) else {}  # a file's contract: any shape
        parts = [f"{lim[k]:g} {u}" for k, u in (("linear_velocity", "m/s"), ("angular_velocity", "rad/s"),
                                                ("linear_acceleration", "m/s²"), ("angular_acceleration", "rad/s²"))
                 if isinstance(lim.get(k), (int, float))]
        return f"trained on {self.robot} ({robot.get('title')!s}), whose limits are {', '.join(parts) or 'not recorded'}"

    def describe(self) -> str:
        """One line: what the policy observes and commands, at what rate."""
        s = self.observation.sectors
        scan = f", {s.count} scan sectors over [{s.edges[0]:.3f}, {s.edges[-1]:.3f}] rad" if s else ""
        return (f"{self.path}: task {self.contract.get('task', '?')}, robot observation "
                f"({len(self.observation.fields)},){scan}, twist action x ({self.scale[0]:g} m/s, {self.scale[1]:g} "
                f"rad/s) at {self.rate_hz:g} Hz{self.base_limits()}")

    def base_limits(self) -> str:
        """The limits its training's base applied to /cmd_vel (the contract's ``base_limits``), for the robot's
        ``diff_drive_controller`` to apply too: ``""`` where none, else e.g. ``"; trained on a base with
        linear.x.max_acceleration 1 m/s²"``."""
        limits = (self.contract.get("action") or {}).get("base_limits") or {}
        names = {"linear_max_acceleration": "linear.x.max_acceleration",
                 "angular_max_acceleration": "angular.z.max_acceleration"}
        cells = [f"{names.get(k, k)} {v['value']:g} {v['unit']}" for k, v in limits.items()]
        return f"; trained on a base with {', '.join(cells)}" if cells else ""


RATE_RANGE_HZ = (1.0, 200.0)
"""The control rates [Hz] the node serves: a contract outside them is refused (a robot's base takes commands at
tens of Hz; 10⁻⁶ Hz would never command, 10⁹ Hz would flood the bus)."""


def load_deployable(path: str | Path) -> Deployable:
    """Open an exported policy and check that the node can serve its contract.

    The file is checked before torch loads it (:func:`atrv_warp.core.files.load_exported_program`: nothing in it
    can run code), and the program is run once on a zero observation of the contract's width.

    Raises:
        PolicyRefused: One line naming the file and the problem: missing, not a ``torch.export`` archive, refused
            by the check, no or another contract format, a ``torque`` action, an ``arena`` observation (its fields
            named), a contract the observation builder cannot read, a rate outside :data:`RATE_RANGE_HZ`, or a
            program that does not take the contract's observation to a (1, 2) action.
    """
    path = str(path)
    if not Path(path).is_file():
        raise PolicyRefused(f"{path}: no such policy file (export one: python -m atrv_warp.export POLICY OUT.pt2)")
    try:
        program, extra = load_exported_program(path)
    except ExportedFileError as err:
        raise PolicyRefused(str(err)) from None
    try:
        contract = json.loads(extra.get("atrv_warp.json", ""))
    except json.JSONDecodeError:
        raise PolicyRefused(f"{path}: no atrv_warp.json contract in the file (export it with "
                            "python -m atrv_warp.export)") from None
    if not isinstance(contract, dict) or contract.get("format") != EXPORT_FORMAT:
        got = contract.get("format") if isinstance(contract, dict) else None
        raise PolicyRefused(f"{path}: contract format {got!r}, this node reads {EXPORT_FORMAT!r}: export the policy "
                            "again (python -m atrv_warp.export POLICY OUT.pt2)")
    action = contract.get("action") or {}
    if action.get("kind") != "twist":
        raise PolicyRefused(f"{path}: a {action.get('kind')!r} policy ({', '.join(map(str, action.get('names', [])))} "
                            f"[{', '.join(map(str, action.get('units', [])))}]); the node commands /cmd_vel and serves "
                            "'twist' policies only (task nav_deploy)")
    kind = contract.get("observation_kind", "arena")
    if kind != "robot":
        names = [f.get("name") if isinstance(f, dict) else f for f in contract.get("observation", [])]
        raise PolicyRefused(f"{path}: the policy observes the {kind!r} observation ({', '.join(map(str, names[:8]))}"
                            f"{', …' if len(names) > 8 else ''}), which a robot does not publish; the node serves "
                            "'robot' observations (task nav_deploy)")
    try:
        observation = RobotObservation.from_contract(contract)
        scale = tuple(float(v) for v in action["scale"])
        rate = float(contract["rate_hz"])
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise PolicyRefused(f"{path}: a contract the node cannot read ({type(err).__name__}: {err})") from None
    if len(scale) != 2 or not all(math.isfinite(v) and v > 0 for v in scale):
        raise PolicyRefused(f"{path}: action scale {list(scale)} must be two finite numbers > 0")
    low, high = RATE_RANGE_HZ
    if not (math.isfinite(rate) and low <= rate <= high):
        raise PolicyRefused(f"{path}: control rate {rate:g} Hz is outside the {low:g}-{high:g} Hz the node serves")
    step_dt = contract.get("step_dt")
    if step_dt is not None and not (isinstance(step_dt, (int, float)) and math.isclose(rate * step_dt, 1.0,
                                                                                         rel_tol=1e-6)):
        raise PolicyRefused(f"{path}: rate_hz {rate:g} disagrees with step_dt {step_dt!r} s (the period, 1 / rate_hz)")
    module = program.module()
    width = len(observation.fields)
    try:
        with torch.no_grad():
            out = module(torch.zeros(1, width))
    except Exception as err:  # noqa: BLE001 - any failure here is a program that does not fit its contract
        raise PolicyRefused(f"{path}: the contract lists {width} observation fields, but the program refuses a "
                            f"(1, {width}) input ({type(err).__name__}: {' '.join(str(err).split())[:120]})") from None
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (1, 2) or not bool(torch.isfinite(out).all()):
        got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise PolicyRefused(f"{path}: the program maps a (1, {width}) observation to {got}, not a finite (1, 2) "
                            "action")
    return Deployable(path, module, contract, observation, scale, rate)


# ------------------------------------------------------------------ reading messages

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


# ------------------------------------------------------------------ deciding


@dataclass(frozen=True)
class Settings:
    """What the node's parameters set (``python -m atrv_warp.deploy --help`` lists them)."""

    odom_frame: str = "odom"
    """The odometry frame: ``/odom``'s ``header.frame_id``, and the frame goals must come in."""
    goal_tolerance: float = -1.0
    """The goal is reached within this distance of the odometry's position [m]; -1: the radius the policy was trained
    to reach (:attr:`Deployable.reach_radius`); 0: the node never ends a goal as reached (whoever sent it ends it
    with the next goal, as an evaluation's episodes end on the true position)."""
    max_linear: float = 0.0
    """Speed clamp on ``linear.x`` [m/s]; 0 = the policy's trained limit."""
    max_angular: float = 0.0
    """Speed clamp on ``angular.z`` [rad/s]; 0 = the policy's trained limit."""
    stale_timeout: float = 0.5
    """A sensor older than this (ROS time since its last message) stops the rover [s]."""
    time_limit: float = 60.0
    """A goal not reached in this long (ROS time) is aborted [s]; 0 = no limit."""
    max_goal_distance: float = 0.0
    """A goal farther than this from the rover is aborted at once, and stops the rover [m]; 0 = the farthest goal
    the policy observes (its contract's ``goal_distance`` bound)."""
    odom_jump_margin: float = 0.5
    """Odometry that moves farther between two messages than the trained speed allows in the time between them,
    plus this margin, has jumped (reset, or a broken estimate): the goal is aborted [m]."""

    def __post_init__(self):
        for f in dataclasses.fields(self):  # each field is the node parameter of its name, checked as the node does
            PARAMETER_BY_NAME[f.name].check(getattr(self, f.name))


@dataclass
class _Sensor:
    topic: str
    value: object = None
    received: float | None = None
    """ROS time [s] of the last message, valid or not."""
    problem: str | None = None
    """Why the last message cannot be used (None: it can)."""
    stamp: float | None = None
    """The last message's ``header.stamp`` [s] (None: it has no header)."""


@dataclass(frozen=True)
class Tick:
    """What one control period decided."""

    command: tuple[float, float] | None
    """(linear.x [m/s], angular.z [rad/s]) to publish on ``/cmd_vel`` (zeros to stop); None: publish nothing (no
    goal)."""
    status: dict | None
    """The goal status to publish (:meth:`Controller.status`), or None."""
    log: tuple[str, ...] = ()
    """Lines to log (each said once: at a change, not every period)."""


class Controller:
    """One rover's control loop: the latest messages in, one command per control period out.

    Feed it the messages as they come (:meth:`on_odom`, :meth:`on_imu`, :meth:`on_scan`, :meth:`on_goal`, each with
    the ROS time it arrived [s]; each returns a line to log or None) and call :meth:`tick` once per control period.
    A goal drives the rover until it is reached (``goal_tolerance``, on the odometry), the ``time_limit`` passes,
    :meth:`stop` is called or a new goal replaces it. A goal in another frame than the odometry's (``map``) is carried
    into it through the transforms :meth:`on_tf` is given (``tf``: the node reads ``/tf``), again every period, so it
    follows a localisation's correction; until the tree joins the two frames the rover holds still. While a sensor
    the policy needs is missing, older than ``stale_timeout``, non-finite, or a scan unusable (no valid beam, a field
    of view short of the policy's sectors, ``range_min > range_max``), the rover is held still with zero commands and
    resumes by itself when they are valid again. A goal that cannot be taken (in no frame, in another frame where no
    transforms come, non-finite, farther than ``max_goal_distance``)
    and odometry that jumps farther than the trained speed allows (``odom_jump_margin``) end the active goal: the
    next period publishes zero and the aborted status, and the rover waits for a new goal.
    """

    def __init__(self, policy: Deployable, settings: Settings | None = None, *, tf: bool = False):
        self.policy, self.settings = policy, settings or Settings()
        self.tf = tf
        """Whether transforms come (:meth:`on_tf`): goals in other frames than the odometry's are taken."""
        self.frames = TransformBuffer()
        """The latest transforms from ``/tf`` and ``/tf_static``."""
        self.mount_source: str | None = None
        """How the last scan's mounting was found (:meth:`scan_mount`)."""
        self.goal_given: tuple[str, float, float] | None = None
        """The active goal as it was sent: its frame and position [m]."""
        self.sensors = {"odom": _Sensor("/odom"), "imu": _Sensor("/imu")}
        if policy.observation.sectors is not None:
            self.sensors["scan"] = _Sensor("/scan")
        self.limits = (self.settings.max_linear or policy.scale[0], self.settings.max_angular or policy.scale[1])
        tolerance = self.settings.goal_tolerance
        self.goal_tolerance = (policy.reach_radius or 1.0) if tolerance < 0 else tolerance
        """The goal is reached within this distance [m] (0: never): the setting, or the policy's trained radius."""
        self.goal: tuple[float, float] | None = None
        """The active goal in the odometry frame [m] (None: no goal, or no transform into that frame yet)."""
        self.goal_time = 0.0
        self.steps = self.clipped_steps = 0
        self.compute_ms = float("nan")
        self.hold_reason: str | None = None
        k, c = policy.observation.action_history, len(policy.observation.action_columns)
        self.history = torch.zeros(k, c, dtype=torch.float64)
        self.last_time: float | None = None
        self._drove_at: float | None = None
        """ROS time [s] of the last step the policy drove."""
        self.last_observation: torch.Tensor | None = None
        """The policy's input (D,) at the last step it drove (float32)."""
        self.last_action: list[float] | None = None
        """The policy's action at the last step it drove, in [-1, 1] (before scaling and clamps)."""
        self.pending: Tick | None = None
        """An end decided between periods (a refused goal, an odometry jump), published by the next :meth:`tick`."""
        self.odom_fix: tuple[float, float, float] | None = None
        """The last valid odometry's (x [m], y [m], time [s]): what a jump is measured from."""
        bound = {f.name: f.high for f in policy.observation.fields}.get("goal_distance", math.inf)
        self.max_goal_distance = self.settings.max_goal_distance or bound
        """Farther goals are aborted [m] (``max_goal_distance``, or the policy's ``goal_distance`` bound)."""

    # ---------------------------------------------------------------- messages
    def on_odom(self, msg, now: float) -> str | None:
        """A ``nav_msgs/Odometry``; one line to log when it becomes unusable (or another frame than the goals')."""
        frame = msg.header.frame_id
        if frame != self.settings.odom_frame:
            return self._store("odom", None, now, f"/odom is in frame {frame!r}, not the odom_frame "
                               f"{self.settings.odom_frame!r}: set -p odom_frame:={frame or '<frame>'}")
        try:
            odometry = read_odometry(msg)
        except ValueError as err:
            return self._store("odom", None, now, str(err), msg)
        line = self._store("odom", odometry, now, None, msg)
        jump = self._jump(odometry[0], now, self.sensors["odom"].stamp)
        return self._cancel(jump) if jump else line

    def _jump(self, pose: Sequence[float], now: float, stamp: float | None) -> str | None:
        """Why the odometry's move since the last valid message is impossible for the rover, or None."""
        x, y, t = pose[0], pose[1], stamp if stamp else now
        fix, self.odom_fix = self.odom_fix, (x, y, t)
        if fix is None:
            return None
        dt = max(t - fix[2], 0.0)
        moved, allowed = math.hypot(x - fix[0], y - fix[1]), self.policy.scale[0] * dt + self.settings.odom_jump_margin
        if moved <= allowed:
            return None
        return (f"/odom jumped {moved:.2f} m in {dt:.2f} s (more than the trained {self.policy.scale[0]:g} m/s allows "
                f"+ odom_jump_margin {self.settings.odom_jump_margin:g} m): an odometry reset moves the goal's frame")

    def _cancel(self, reason: str) -> str:
        """End the active goal for ``reason`` at the next period (zero command, aborted status); the line to log."""
        if self.goal_given is None:
            return reason
        self.pending = self._end("aborted", reason, log=False)
        return f"{reason}; the goal is aborted and the rover stops"

    def on_imu(self, msg, now: float) -> str | None:
        """A ``sensor_msgs/Imu``; one line to log when it becomes unusable."""
        try:
            return self._store("imu", read_imu(msg), now, None, msg)
        except ValueError as err:
            return self._store("imu", None, now, str(err), msg)

    def on_scan(self, msg, now: float) -> str | None:
        """A ``sensor_msgs/LaserScan``; one line to log when it becomes unusable (a refused geometry names both)."""
        if "scan" not in self.sensors:
            return None
        try:
            scan = read_scan(msg, self.policy.observation)
        except ValueError as err:
            return self._store("scan", None, now, str(err), msg)
        mount, source = self.scan_mount(frame_id(getattr(getattr(msg, "header", None), "frame_id", "") or ""))
        if mount is not None:
            scan = dataclasses.replace(scan, mount=mount)
        line = self._store("scan", scan, now, None, msg)
        said, self.mount_source = self.mount_source, source
        if source != said and (mount is not None or said is not None):
            line = "; ".join(x for x in (line, f"/scan: {source}") if x)
        return line

    def scan_mount(self, frame: str) -> tuple[tuple[float, float, float] | None, str]:
        """Where the scanner of frame ``frame`` sits relative to the one the policy was trained with (the contract's
        ``scan.mount`` on the chassis), from ``/tf``: ((x [m], y [m], yaw [rad]), how it was found), or (None, why
        the scan is read as it is: no mount recorded, no transform, or the trained mount)."""
        trained = (self.policy.contract.get("scan") or {}).get("mount")
        if not isinstance(trained, dict):
            return None, "read as trained (the policy records no scanner mount)"
        try:
            parent, tx, ty, tyaw = (str(trained["parent"]), float(trained["x"]), float(trained["y"]),
                                    float(trained["yaw"]))
        except (KeyError, TypeError, ValueError):
            return None, f"read as trained (the policy's scan.mount is unreadable: {trained!r:.80})"
        if not all(map(math.isfinite, (tx, ty, tyaw))):
            return None, "read as trained (the policy's scan.mount is not finite)"
        origin = self.frames.transform_point((0.0, 0.0, 0.0), parent, frame) if frame and parent else None
        ahead = self.frames.transform_point((1.0, 0.0, 0.0), parent, frame) if origin is not None else None
        if ahead is None:
            return None, f"read as mounted where the policy's was (no /tf from {parent!r} to {frame!r})"
        yaw = math.atan2(ahead[1] - origin[1], ahead[0] - origin[0]) - tyaw
        c, s = math.cos(tyaw), math.sin(tyaw)
        dx, dy = origin[0] - tx, origin[1] - ty
        mount = (c * dx + s * dy, -s * dx + c * dy, math.remainder(yaw, 2 * math.pi))
        if math.hypot(mount[0], mount[1]) < 1e-3 and abs(mount[2]) < 1e-3:
            return None, f"mounted where the policy's was (from /tf: {frame!r} in {parent!r})"
        return mount, (f"its scanner ({frame!r}) is {mount[0]:+.3f} m, {mount[1]:+.3f} m and "
                       f"{math.degrees(mount[2]):+.1f} deg from where the policy's was (from /tf); its returns are "
                       "carried to the trained mount")

    def _store(self, name: str, value, now: float, problem: str | None, msg=None) -> str | None:
        s = self.sensors[name]
        changed = problem != s.problem
        s.value, s.received, s.problem = value, now, problem
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        s.stamp = None if stamp is None else stamp.sec + 1e-9 * stamp.nanosec
        if changed and problem is not None:
            return f"{s.topic}: {problem}; the rover holds still until it is valid"
        if changed:
            return f"{s.topic} valid again"
        return None

    def on_goal(self, msg, now: float) -> str:
        """A ``geometry_msgs/PoseStamped`` goal; returns the line to log (taken, or why it is refused). A refused goal
        ends the active one (the rover stops), as a new goal that is taken replaces it. A goal in another frame is
        taken where transforms come (``tf``), and carried into the odometry frame every period."""
        problem = self.goal_problem(msg)
        if problem:
            return self._cancel(f"goal refused: {problem}")
        frame, p, odom = frame_id(msg.header.frame_id), msg.pose.position, self.settings.odom_frame
        self.goal_given, self.goal_time = (frame, float(p.x), float(p.y)), now
        self.steps = self.clipped_steps = 0
        self.hold_reason, self.pending = None, None
        self.history.zero_()
        at = f"goal ({p.x:.2f}, {p.y:.2f}) in {frame}"
        if self._locate() is None:
            return f"{at}: waiting for the transform from {frame!r} to {odom!r} on /tf, holding still"
        there = f" = ({self.goal[0]:.2f}, {self.goal[1]:.2f}) in {odom}" if frame != odom else ""
        return f"{at}{there}: driving"

    def goal_problem(self, msg) -> str | None:
        """Why the ``geometry_msgs/PoseStamped`` goal ``msg`` cannot be taken (no frame, a frame no transforms join
        to, a non-finite position), or None; nothing changes (a ``NavigateToPose`` goal refused this way leaves the
        active one driving)."""
        frame, p, odom = frame_id(msg.header.frame_id), msg.pose.position, self.settings.odom_frame
        if not (math.isfinite(p.x) and math.isfinite(p.y)):
            return f"non-finite position ({p.x}, {p.y})"
        if not frame:
            return (f"it names no frame (header.frame_id is empty); send it in {odom!r} or a frame /tf joins to it "
                    "(map)")
        if frame != odom and not self.tf:
            return (f"it is in frame {frame!r} and this node reads no /tf (tf2_msgs is not installed: source the "
                    f"robot's ROS 2); send it in the odometry frame {odom!r}")
        return None

    def on_tf(self, msg, now: float) -> None:
        """A ``tf2_msgs/TFMessage`` from ``/tf`` or ``/tf_static``: its transforms replace the ones they follow; an
        active goal in another frame moves with them from the next period."""
        self.frames.add(msg)

    def _locate(self) -> tuple[float, float] | None:
        """The active goal in the odometry frame now (:attr:`goal`), through the latest transforms."""
        if self.goal_given is None:
            self.goal = None
            return None
        frame, x, y = self.goal_given
        point = self.frames.transform_point((x, y, 0.0), self.settings.odom_frame, frame)
        self.goal = None if point is None else (point[0], point[1])
        return self.goal

    def fault(self, source: str, reason: str, now: float) -> Tick:
        """A callback that failed (``source``: a sensor's name, ``goal`` or ``tick``): its sensor is unusable until
        its next good message, a goal that may have been half taken is ended, and the rover holds still now."""
        if source in self.sensors:
            self._store(source, None, now, reason)
        elif self.goal_given is not None and source == "goal":
            self.pending = self._end("aborted", reason, log=False)
        self.hold_reason = f"fault: {source}"
        return Tick((0.0, 0.0), self.status("holding", reason) if self.goal_given is not None else None)

    # ---------------------------------------------------------------- the control period
    def status(self, state: str, reason: str = "") -> dict:
        """The goal status: ``state`` (:data:`STATES`), ``reason``, ``goal`` [m], ``distance`` to it on the
        odometry [m], ``steps`` driven by the policy, ``clipped_steps`` (steps a speed clamp clipped),
        ``compute_ms`` (the last step's observation and policy [ms])."""
        odom = self.sensors["odom"].value
        distance = math.hypot(self.goal[0] - odom[0][0], self.goal[1] - odom[0][1]) if odom and self.goal else None
        return {"state": state, "reason": reason, "goal": list(self.goal) if self.goal else None,
                "distance": None if distance is None else round(distance, 4), "steps": self.steps,
                "clipped_steps": self.clipped_steps, "compute_ms": None if math.isnan(self.compute_ms)
                else round(self.compute_ms, 4)}

    def tick(self, now: float) -> Tick:
        """Decide this control period's command at ROS time ``now`` [s]."""
        if self.last_time is not None and now < self.last_time:  # time went back (a simulator restarted)
            for s in self.sensors.values():
                s.value = s.received = s.problem = None
        self.last_time = now
        if self.pending is not None:
            tick, self.pending = self.pending, None
            return tick
        if self.goal_given is None:
            return Tick(None, None)
        limit = self.settings.time_limit
        if limit and now - self.goal_time > limit:
            return self._end("aborted", f"{TIME_LIMIT}: not reached in {limit:g} s")
        if self._locate() is None:
            frame, odom = self.goal_given[0], self.settings.odom_frame
            return self._hold(f"no transform from {frame!r} to {odom!r} on /tf", "no transform")
        reasons, keys, quiet = [], [], True  # quiet: every reason was logged when its message came
        for s in self.sensors.values():
            if s.received is None:
                reasons.append(f"no {s.topic} yet")
                keys.append(reasons[-1])
                quiet = False
            elif now - s.received > self.settings.stale_timeout:
                reasons.append(f"{s.topic} stale ({now - s.received:.2f} s > {self.settings.stale_timeout:g} s)")
                keys.append(f"{s.topic} stale")
                quiet = False
            elif s.problem is not None:
                reasons.append(f"{s.topic}: {s.problem}")
                keys.append(reasons[-1])
        if reasons:
            return self._hold("; ".join(reasons), "; ".join(keys), quiet)
        status = self.status("active")
        if status["distance"] > self.max_goal_distance:
            return self._end("aborted", f"the goal is {status['distance']:.1f} m away, farther than "
                                        f"max_goal_distance {self.max_goal_distance:g} m")
        if self.goal_tolerance and status["distance"] < self.goal_tolerance:
            return self._end("reached", f"within {self.goal_tolerance:g} m")
        start = time.perf_counter()
        try:
            action = self._act()
        except ValueError as err:
            return self._hold(f"observation: {err}", "observation")
        except Exception as err:  # noqa: BLE001 - a policy that fails on some input holds the rover, never ends the node
            return self._hold(f"the policy failed ({type(err).__name__}: {' '.join(str(err).split())[:120]})",
                              "policy failed")
        self.compute_ms = 1e3 * (time.perf_counter() - start)
        if not all(math.isfinite(a) for a in action):
            return self._hold(f"the policy gave a non-finite action {action}", "non-finite action")
        command = [a * k for a, k in zip(action, self.policy.scale)]
        clipped = [max(-m, min(m, c)) for c, m in zip(command, self.limits)]
        self.steps += 1
        self.clipped_steps += clipped != command
        self._remember(clipped)
        log = ("resumed: driving by the policy",) if self.hold_reason else ()
        self.hold_reason = None
        return Tick((clipped[0], clipped[1]), self.status("active"), log)

    def stop(self, reason: str) -> Tick:
        """End the goal now (e.g. ``"shutdown"``): zero command and an aborted status, or nothing without a goal."""
        if self.goal_given is None:
            return Tick((0.0, 0.0), None)
        return self._end("aborted", reason)

    def observation(self) -> torch.Tensor:
        """The policy's input (D,) from the latest messages, the goal and the commands sent (the contract's fields,
        in order: ``policy.observation.names``).

        Raises:
            ValueError: No goal, a sensor with no usable message yet, or an input the builder refuses (named).
        """
        if self.goal is None:
            raise ValueError("no goal")
        missing = [s.topic for s in self.sensors.values() if s.value is None]
        if missing:
            raise ValueError(f"no usable message on {', '.join(missing)}")
        (pose, twist), (q, omega) = self.sensors["odom"].value, self.sensors["imu"].value
        scan = self.sensors["scan"].value if "scan" in self.sensors else None
        return self.policy.observation(odom_pose=pose, odom_twist=twist, imu_orientation=q, imu_angular_velocity=omega,
                                       goal=list(self.goal), scan=scan,
                                       last_actions=self.history if self.history.numel() else None)

    def trace(self, now: float, tick: Tick) -> dict:
        """One control period as a JSON-able record (the node's ``trace`` file; compare it step by step with the
        environment's observation and action): ROS ``time`` [s], the goal status's ``state``, ``goal`` and ``steps``, each sensor's last
        ``stamps`` [s] (its ``header.stamp``: how old the input was), the ``observation`` and ``action`` of a step
        the policy drove (else None) and the ``command`` published."""
        drove = self._drove_at == now and tick.status is not None and tick.status["state"] == "active"
        return {"time": now, "state": tick.status["state"] if tick.status else None,
                "goal": tick.status["goal"] if tick.status else None, "steps": tick.status["steps"] if tick.status else None,
                "stamps": {name: s.stamp for name, s in self.sensors.items()},
                "observation": self.last_observation.tolist() if drove else None,
                "action": self.last_action if drove else None,
                "command": list(tick.command) if tick.command is not None else None}

    def _act(self) -> list[float]:
        obs = self.observation()
        with torch.no_grad():
            action = [float(a) for a in self.policy.module(obs[None])[0]]
        self.last_observation, self.last_action, self._drove_at = obs, action, self.last_time
        return action

    def _remember(self, command: Sequence[float]) -> None:
        """The command sent, as the action the policy observes next (in [-1, 1], newest first)."""
        if self.history.numel():
            action = torch.tensor([c / k for c, k in zip(command, self.policy.scale)], dtype=torch.float64)
            self.history = torch.cat([action.clamp(-1.0, 1.0)[None], self.history[:-1]])

    def _hold(self, reason: str, key: str, quiet: bool = False) -> Tick:
        """Zero command, status ``holding``; one line when the reason (``key``: it without its figures) changes,
        unless ``quiet`` (the sensor's own line said it)."""
        log = () if key == self.hold_reason or quiet else (f"holding still: {reason}",)
        self.hold_reason = key
        self._remember((0.0, 0.0))
        return Tick((0.0, 0.0), self.status("holding", reason), log)

    def _end(self, state: str, reason: str, *, log: bool = True) -> Tick:
        status = self.status(state, reason)
        self.goal, self.goal_given, self.hold_reason = None, None, None
        line = f"goal {state}: {reason} ({status['steps']} steps, {status['clipped_steps']} clipped)"
        return Tick((0.0, 0.0), status, (line,) if log else ())
