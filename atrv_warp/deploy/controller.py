"""The deploy node's logic, without ROS: decide each command from the robot's latest messages.

:class:`Controller` holds the latest ``/odom``, ``/imu``, ``/scan`` and goal (read by :mod:`atrv_warp.deploy.messages`),
and :meth:`Controller.tick` decides, once per control period, what the rover does with the exported policy
(:mod:`atrv_warp.deploy.contract`): drive by the policy, hold still (a stale, non-finite or unusable sensor; it
resumes when they are valid again), or end the goal (reached, time limit). A policy that follows a plan takes
``FollowPath`` paths instead of goals (:meth:`Controller.on_path`, :mod:`atrv_warp.deploy.follow`).
:mod:`atrv_warp.deploy.node` is the rclpy shell.

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from atrv_warp.core.geometry import quat_to_yaw
from atrv_warp.core.tf import TransformBuffer, frame_id

# The names this module held before its split (issue 69) import from here as they did, until 0.3.0; their homes are
# atrv_warp.deploy.contract and atrv_warp.deploy.messages (EXPORT_FORMAT, RATE_RANGE_HZ, PolicyRefused, load_deployable and
# scan_geometry are imported for that alone).
from atrv_warp.deploy.contract import EXPORT_FORMAT, RATE_RANGE_HZ, Deployable, PolicyRefused, load_deployable  # noqa: F401
from atrv_warp.deploy.follow import TRANSFORM_TOLERANCE, FollowedPath, PathRefused, read_path
from atrv_warp.deploy.messages import (
    read_imu,
    read_odometry,
    read_scan,
    scan_geometry,  # noqa: F401
)
from atrv_warp.deploy.parameters import PARAMETER_BY_NAME
from atrv_warp.deploy.safety import CollisionMonitor, parse_zone

__all__ = ["MOUNT_LIMIT_M", "STATES", "TIME_LIMIT", "Controller", "Settings", "Tick"]

TIME_LIMIT = "time limit"
"""How an aborted status's ``reason`` starts when the goal ran out of ``time_limit`` (the node's ``NavigateToPose``
result reports it as Nav2's ``TIMEOUT``)."""
MOUNT_LIMIT_M = 1.0
"""How far from the trained mount [m] a scanner's ``/tf`` mount may be: past it the transform is taken to be wrong
(every shipped robot is under 1 m long: a scanner moved farther is off the robot) and the scan refused."""
STATES = ("active", "holding", "reached", "aborted")
"""The goal status's ``state``: driving by the policy; held still for a ``reason`` (resumes by itself); the goal
reached (within ``goal_tolerance``); given up for a ``reason`` (time limit, shutdown, a new goal). A path's abort
``reason`` starts with Nav2's ``FollowPath`` result code name and a colon (``FAILED_TO_MAKE_PROGRESS: ...``) where
Nav2 has one."""

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
    collision_monitor: bool = True
    """Slow and stop on the scan whatever the policy commands (:mod:`atrv_warp.deploy.safety`)."""
    stop_zone: str = ""
    """The stop zone, Nav2's ``points`` text (``""``: none)."""
    slowdown_zone: str = ""
    """The slow-down zone, likewise."""
    slowdown_ratio: float = 0.5
    min_points: int = 4
    zone_motion: str = "any"
    """The commands the zones act on (``any`` | ``forward``)."""

    def __post_init__(self):
        for f in dataclasses.fields(self):  # each field is the node parameter of its name, checked as the node does
            PARAMETER_BY_NAME[f.name].check(getattr(self, f.name))
        for name in ("stop_zone", "slowdown_zone"):
            parse_zone(name, getattr(self, name))


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
        self.route: FollowedPath | None = None
        """The active ``FollowPath`` path (a policy that follows a plan), or None."""
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
        self.monitor = CollisionMonitor()
        """The collision monitor (:mod:`atrv_warp.deploy.safety`; no zones where ``collision_monitor`` is off)."""
        st = self.settings
        if st.collision_monitor:
            mount = (policy.contract.get("scan") or {}).get("mount")
            try:
                at = (float(mount["x"]), float(mount["y"]), float(mount["yaw"]))
            except (KeyError, TypeError, ValueError):
                at = (0.0, 0.0, 0.0)  # no mount recorded: the scanner at the chassis origin
            self.monitor = CollisionMonitor(parse_zone("stop_zone", st.stop_zone),
                                            parse_zone("slowdown_zone", st.slowdown_zone), st.slowdown_ratio,
                                            st.min_points, at if all(map(math.isfinite, at)) else (0.0, 0.0, 0.0),
                                            forward_only=st.zone_motion == "forward")
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

    @property
    def active(self) -> bool:
        """Whether a goal or a path is being driven (or held)."""
        return self.goal_given is not None or self.route is not None

    def _cancel(self, reason: str) -> str:
        """End the active goal for ``reason`` at the next period (zero command, aborted status); the line to log."""
        if not self.active:
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
            mount, source = self.scan_mount(frame_id(getattr(getattr(msg, "header", None), "frame_id", "") or ""))
        except ValueError as err:
            return self._store("scan", None, now, str(err), msg)
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
        the scan is read as it is: no mount recorded, no transform, or the trained mount).

        Raises:
            ValueError: ``/tf`` puts the scanner farther than :data:`MOUNT_LIMIT_M` from the trained mount (or not
                finitely anywhere): the scan is refused and the rover held until the transform is plausible.
        """
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
        found = self.frames.transform_pose2d((0.0, 0.0, 0.0), parent, frame) if frame and parent else None
        if found is None:
            return None, f"read as mounted where the policy's was (no /tf from {parent!r} to {frame!r})"
        origin, yaw = found[:2], found[2] - tyaw
        c, s = math.cos(tyaw), math.sin(tyaw)
        dx, dy = origin[0] - tx, origin[1] - ty
        mount = (c * dx + s * dy, -s * dx + c * dy, math.remainder(yaw, 2 * math.pi))
        if math.hypot(mount[0], mount[1]) < 1e-3 and abs(mount[2]) < 1e-3:
            return None, f"mounted where the policy's was (from /tf: {frame!r} in {parent!r})"
        if not (all(map(math.isfinite, mount)) and math.hypot(mount[0], mount[1]) <= MOUNT_LIMIT_M):
            raise ValueError(f"scan refused: /tf puts its scanner ({frame!r}) {math.hypot(mount[0], mount[1]):.2f} m "
                             f"from where the policy's was, more than {MOUNT_LIMIT_M:g} m (MOUNT_LIMIT_M): a wrong "
                             "transform would read a wall ahead as open ground")
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
        at = f"goal ({_coordinate(p.x)}, {_coordinate(p.y)}) in {frame}"
        if self._locate() is None:
            return f"{at}: waiting for the transform from {frame!r} to {odom!r} on /tf, holding still"
        if not all(map(math.isfinite, self.goal)):
            return self._cancel(f"goal refused: {at} is not finite in {odom!r} through /tf's transforms")
        there = f" = ({_coordinate(self.goal[0])}, {_coordinate(self.goal[1])}) in {odom}" if frame != odom else ""
        return f"{at}{there}: driving"

    def on_path(self, msg, now: float, *, preempt: bool = False) -> tuple[str | None, str]:
        """A ``FollowPath`` goal's ``nav_msgs/Path``: (None, the line to log) where it is taken, else (Nav2's result
        code name, why): then the active path ends too (the rover stops at the next period; Nav2's controller does
        not drive on an old path after refusing a new one). ``preempt``: the path replaces the active goal's (the
        behaviour tree's replan), which drives on without stopping: its progress checker and the last actions are
        kept, its goal checker starts again."""
        if self.policy.path_settings is None:
            raise ValueError("this policy drives to a goal, not along a path (a follow_path policy follows one)")
        try:
            frame, xy, goal_yaw = read_path(msg, tf=self.tf, odom_frame=self.settings.odom_frame)
        except PathRefused as err:
            reason = f"{err.code}: {err}"
            if self.active:
                self.pending = self._end("aborted", reason, log=False)
            return err.code, reason
        if preempt and self.route is not None:
            self.route.replace(frame, xy, goal_yaw)
        else:
            self.route = FollowedPath(self.policy.path_settings, frame, xy, goal_yaw, now)
            self.goal_time, self.steps, self.clipped_steps = now, 0, 0
            self.history.zero_()
        self.goal_given, self.hold_reason, self.pending = None, None, None
        end = self.route.end
        return None, (f"path ({len(xy)} poses in {frame}, to ({_coordinate(end[0])}, {_coordinate(end[1])}))"
                      f"{': replanned' if preempt else ''}: following")

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

    def on_tf(self, msg, now: float, *, static: bool = False) -> None:
        """A ``tf2_msgs/TFMessage`` from ``/tf`` or (``static``) ``/tf_static``: its transforms replace the ones they
        follow; an active goal in another frame moves with them from the next period. The work is bounded
        (:class:`~atrv_warp.core.tf.TransformBuffer`: frames capped, ``/tf`` frames unheard for a while dropped), so a
        flood of frames cannot stretch the control period."""
        self.frames.add(msg, now, static=static)

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
        elif self.active and source == "goal":
            self.pending = self._end("aborted", reason, log=False)
        self.hold_reason = f"fault: {source}"
        return Tick((0.0, 0.0), self.status("holding", reason) if self.active else None)

    # ---------------------------------------------------------------- the control period
    def status(self, state: str, reason: str = "") -> dict:
        """The goal status: ``state`` (:data:`STATES`), ``reason``, ``goal`` [m], ``distance`` to it on the
        odometry [m], ``steps`` driven by the policy, ``clipped_steps`` (steps a speed clamp clipped),
        ``compute_ms`` (the last step's observation and policy [ms])."""
        odom = self.sensors["odom"].value
        if self.route is not None:  # a path: its end in its own frame, the distance along the plan
            goal, distance = self.route.end, self.route.remaining
        else:
            goal = self.goal if self.goal and all(map(math.isfinite, self.goal)) else None  # standard JSON: no NaN
            distance = math.hypot(goal[0] - odom[0][0], goal[1] - odom[0][1]) if odom and goal else None
        return {"state": state, "reason": reason, "goal": list(goal) if goal else None,
                "distance": None if distance is None or not math.isfinite(distance) else round(distance, 4),
                "steps": self.steps, "clipped_steps": self.clipped_steps,
                "compute_ms": None if not math.isfinite(self.compute_ms) else round(self.compute_ms, 4)}

    def tick(self, now: float) -> Tick:
        """Decide this control period's command at ROS time ``now`` [s]."""
        if self.last_time is not None and now < self.last_time:  # time went back (a simulator restarted)
            for s in self.sensors.values():
                s.value = s.received = s.problem = None
        self.last_time = now
        if self.pending is not None:
            tick, self.pending = self.pending, None
            return tick
        if self.route is not None:
            return self._tick_path(now)
        if self.goal_given is None:
            return Tick(None, None)
        limit = self.settings.time_limit
        if limit and now - self.goal_time > limit:
            return self._end("aborted", f"{TIME_LIMIT}: not reached in {limit:g} s")
        if self._locate() is None:
            frame, odom = self.goal_given[0], self.settings.odom_frame
            return self._hold(f"no transform from {frame!r} to {odom!r} on /tf", "no transform")
        if not all(map(math.isfinite, self.goal)):
            return self._end("aborted", f"the goal is not finite in {self.settings.odom_frame!r} through /tf's "
                                        f"transforms from {self.goal_given[0]!r}")
        hold = self._sensors_hold(now)
        if hold is not None:
            return hold
        status = self.status("active")
        if status["distance"] > self.max_goal_distance:
            return self._end("aborted", f"the goal is {status['distance']:.1f} m away, farther than "
                                        f"max_goal_distance {self.max_goal_distance:g} m")
        if self.goal_tolerance and status["distance"] < self.goal_tolerance:
            return self._end("reached", f"within {self.goal_tolerance:g} m")
        return self._drive()

    def _tick_path(self, now: float) -> Tick:
        """A period on a path: held while a sensor is unusable or ``/tf`` does not join the odometry to the path's
        frame yet; aborted where it has not for :data:`~atrv_warp.deploy.follow.TRANSFORM_TOLERANCE` (``TF_ERROR``) or
        the progress checker fails (``FAILED_TO_MAKE_PROGRESS``); reached where the goal
        checker says so; else the policy drives on the plan as it reads from the robot's pose."""
        route, odom = self.route, self.settings.odom_frame
        hold = self._sensors_hold(now)
        if hold is not None:
            if route.held_too_long(now):
                s = route.settings
                return self._end("aborted", f"FAILED_TO_MAKE_PROGRESS: held still for more than "
                                            f"{s.movement_time_allowance:g} s ({hold.status['reason']})")
            return hold
        pose = self._pose_in(route.frame)
        if route.transform_lost(pose is not None, now):
            return self._end("aborted", f"TF_ERROR: no transform from {odom!r} to the path's frame {route.frame!r} "
                                        f"on /tf within {TRANSFORM_TOLERANCE:g} s")
        if pose is None:
            return self._hold(f"waiting for the transform from {odom!r} to the path's frame {route.frame!r} on /tf",
                              "no transform")
        route.follow(pose)
        if route.goal_reached(pose):
            s = route.settings
            return self._end("reached", f"within {s.xy_goal_tolerance:g} m and {s.yaw_goal_tolerance:g} rad of the "
                                        "path's end")
        if route.stalled(pose, now):
            s = route.settings
            return self._end("aborted", f"FAILED_TO_MAKE_PROGRESS: moved less than {s.required_movement_radius:g} m "
                                        f"in {s.movement_time_allowance:g} s")
        return self._drive()

    def _pose_in(self, frame: str) -> tuple[float, float, float] | None:
        """The odometry's pose (x, y, yaw) carried into ``frame`` through the latest transforms (None: no transform,
        or not finite)."""
        position = self.sensors["odom"].value[0]
        x, y, yaw = position[0], position[1], float(quat_to_yaw(torch.tensor(position[3:7], dtype=torch.float64)))
        if frame == self.settings.odom_frame:
            return x, y, yaw
        pose = self.frames.transform_pose2d((x, y, yaw), frame, self.settings.odom_frame)
        return pose if pose is not None and all(map(math.isfinite, pose)) else None

    def _sensors_hold(self, now: float) -> Tick | None:
        """A hold while a sensor the policy needs is missing, stale or unusable, else None."""
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
        return None

    def _drive(self) -> Tick:
        """A period the policy drives: its action, scaled, clamped and remembered (a hold where it fails)."""
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
        scan = self.sensors["scan"].value if "scan" in self.sensors else None
        safe, said = self.monitor.apply((clipped[0], clipped[1]), scan)
        self._remember(safe)
        log = ("resumed: driving by the policy",) if self.hold_reason else ()
        log += (said,) if said else ()
        self.hold_reason = None
        return Tick(safe, self.status("active"), log)

    def stop(self, reason: str) -> Tick:
        """End the goal now (e.g. ``"shutdown"``): zero command and an aborted status, or nothing without a goal."""
        if not self.active:
            return Tick((0.0, 0.0), None)
        return self._end("aborted", reason)

    def observation(self) -> torch.Tensor:
        """The policy's input (D,) from the latest messages, the goal and the commands sent (the contract's fields,
        in order: ``policy.observation.names``).

        Raises:
            ValueError: No goal, a sensor with no usable message yet, or an input the builder refuses (named).
        """
        path = self.route.fields if self.route is not None else None
        if self.goal is None and path is None:
            raise ValueError("no goal")
        missing = [s.topic for s in self.sensors.values() if s.value is None]
        if missing:
            raise ValueError(f"no usable message on {', '.join(missing)}")
        (pose, twist), (q, omega) = self.sensors["odom"].value, self.sensors["imu"].value
        scan = self.sensors["scan"].value if "scan" in self.sensors else None
        return self.policy.observation(odom_pose=pose, odom_twist=twist, imu_orientation=q, imu_angular_velocity=omega,
                                       goal=list(self.goal) if path is None else None, scan=scan, path=path,
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
        self.goal, self.goal_given, self.route, self.hold_reason = None, None, None, None
        line = f"goal {state}: {reason} ({status['steps']} steps, {status['clipped_steps']} clipped)"
        return Tick((0.0, 0.0), status, (line,) if log else ())


def _coordinate(value: float) -> str:
    """A coordinate for a log line: to the centimetre, or in three figures where it is huge (a goal at 1e308)."""
    return f"{value:.2f}" if abs(value) < 1e9 else f"{value:.3g}"
