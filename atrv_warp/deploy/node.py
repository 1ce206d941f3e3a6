"""The rclpy node behind ``python -m atrv_warp.deploy`` (imported only where rclpy is installed).

:class:`DeployNode` subscribes to the robot's ``scan``, ``odom``, ``imu`` and ``goal_pose``, passes each message to
its :class:`~atrv_warp.deploy.controller.Controller`, and on a timer at the policy's rate (ROS time: with
``use_sim_time`` a simulator's ``/clock`` paces it) publishes the controller's ``cmd_vel`` and ``goal_status``.
Topic names are relative, so ``--ros-args -r __ns:=/rover_1`` runs it for one rover among several. Goals come on
``goal_pose`` (RViz's "2D Goal Pose"; volatile, as RViz publishes: a goal is not replayed to a restarted node) and
through Nav2's
``NavigateToPose`` action on ``navigate_to_pose`` (RViz's "Nav2 Goal", a behaviour tree, a waypoint follower), in
the odometry frame or any frame ``/tf`` joins to it. A policy that follows a plan (``follow_path``) serves Nav2's
``FollowPath`` on ``follow_path`` instead, as Nav2's controller server does (the behaviour tree sends it the planner's
path about once a second), and publishes on ``cmd_vel_nav``, the velocity smoother's input.

No input ends the node: every callback runs inside a guard (:meth:`DeployNode.guarded`), so that a failure is one
log line and a zero command, never an exception out of the executor, as Nav2's controller server publishes zero,
aborts the goal and stays up. rclpy ties a logging call site to one severity, so each severity has its own.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math

from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry, Path
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.expand_topic_name import expand_topic_name
from rclpy.node import Node
from rclpy.parameter import parameter_dict_from_yaml_file
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.validate_topic_name import validate_topic_name
from sensor_msgs.msg import Imu, LaserScan
from std_msgs.msg import String

from atrv_warp.core.files import OutputPathError, fresh_path
from atrv_warp.core.parameters import given_parameters, params_file_names
from atrv_warp.deploy.contract import Deployable
from atrv_warp.deploy.controller import TIME_LIMIT, Controller, Settings, Tick
from atrv_warp.deploy.parameters import (
    PARAMETERS,
    ParameterError,
    check_parameters,
    unknown_parameters,
)

__all__ = ["ACTION_REQUEST_DEPTH", "COMMAND_PATH_SECONDS", "FOLLOW_PATH_TOPIC", "RESULT_CODES", "DeployNode",
           "NodeConfigError"]

RELIABLE = ReliabilityPolicy.RELIABLE


COMMAND_PATH_SECONDS = 1.0
"""The ``command_path`` topic shows where this period's command would take the rover in this long [s]."""
FOLLOW_PATH_TOPIC = "cmd_vel_nav"
"""Where a plan-following policy's node publishes unless ``cmd_vel_topic`` is given: the velocity smoother's input,
where Nav2's own launch remaps its controller server's ``cmd_vel``."""
ACTION_REQUEST_DEPTH = 100
"""How many goal, cancel and result requests each action server queues: a client's burst (a cancel storm, a result
asked for each of many goals at once) beyond the services' default 10 would be lost in the transport, never answered."""
RESULT_CODES = {TIME_LIMIT: 9003}
"""Nav2's ``NavigateToPose`` result ``error_code`` for an abort whose reason starts with a key (``TIMEOUT``); any other
abort is ``UNKNOWN`` (9000). Humble's result carries no code."""


def _tf_message() -> tuple[type | None, str]:
    """``tf2_msgs/msg/TFMessage``: a ROS 2 install's, else built from its definition where the rosidl generators are
    installed (:mod:`atrv_warp.core.ros_interfaces`); or None and why."""
    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

    return load_interface(TF2_MSGS, "msg", "TFMessage")


class NodeConfigError(ValueError):
    """A parameter the node cannot run with (already logged)."""


class DeployNode(Node):
    """An exported policy as a ROS 2 controller (parameters: :data:`atrv_warp.deploy.parameters.PARAMETERS`).

    Raises:
        NodeConfigError: An unknown parameter (given with ``-p`` or in a ``--params-file``) or a bad value, logged in
            one line naming it.
    """

    def __init__(self, policy: Deployable, args: list[str] | None = None, **node_kwargs):
        super().__init__("atrv_deploy", **node_kwargs)
        self.log = self.get_logger()
        self.trace = None
        self._said: str | None = None
        """The last failure line logged (a failure repeated every period is said once)."""
        dynamic = ParameterDescriptor(dynamic_typing=True)  # any type in; check_parameters names a wrong one
        given = {p.name: self.declare_parameter(p.name, p.default, dynamic).value for p in PARAMETERS}
        try:
            files = self._params_file_names(args)
            unknown = unknown_parameters(args, files)
            if unknown:
                raise ParameterError(f"unknown parameter(s) {', '.join(unknown)}; known: "
                                     f"{', '.join(p.name for p in PARAMETERS)}")
            self.params = p = check_parameters(given)
            for name in (q.name for q in PARAMETERS if q.kind == "topic"):
                self._check_topic(name, p[name])
            settings = Settings(**{f.name: p[f.name] for f in dataclasses.fields(Settings)})
        except ParameterError as err:
            self._fail(str(err))
        trained_on = policy.robot or "atrvjr"
        if p["robot"] and p["robot"] != trained_on:
            line = (f"the policy was trained on {trained_on}, but this robot is {p['robot']} (robot:=): its limits, "
                    "period and footprint are another robot's")
            if not p["allow_other_robot"]:
                self._fail(f"{line}; deploy one trained on {p['robot']}, or set allow_other_robot:=true on purpose")
            self.log.warning(f"{line} (allow_other_robot:=true)")
        self.log.info(policy.describe_robot())
        self.policy = policy
        tf_message, tf_from = _tf_message()
        self.controller = Controller(policy, settings, tf=tf_message is not None)
        m = self.controller.monitor
        self.log.info("collision monitor: " + (
            f"stop zone of {len(m.stop_zone)} points, slow-down zone of {len(m.slowdown_zone)} points (x "
            f"{m.slowdown_ratio:g}), acting on {m.min_points} scan returns" if m.active else
            "off (collision_monitor:=false)" if not settings.collision_monitor else
            "no zones (stop_zone, slowdown_zone): the policy's commands pass as they are"))
        self.stamped = p["enable_stamped_cmd_vel"]
        self.follows_path = policy.path_settings is not None
        if self.follows_path and "cmd_vel_topic" not in given_parameters(args, files):
            p["cmd_vel_topic"] = FOLLOW_PATH_TOPIC
        self.cmd_pub = self.create_publisher(TwistStamped if self.stamped else Twist, p["cmd_vel_topic"], 10)
        self.status_pub = self.create_publisher(String, p["status_topic"], 10)
        self.command_path_pub = self.create_publisher(Path, "command_path", 10)
        """The command as the arc it drives in the next :data:`COMMAND_PATH_SECONDS`, in ``base_frame`` (RViz's view)."""
        sensors = qos_profile_sensor_data  # best effort: matches a reliable publisher and a sensor driver's
        guard = self.guarded
        self.create_subscription(Odometry, p["odom_topic"], guard("odom", self.controller.on_odom), sensors)
        self.create_subscription(Imu, p["imu_topic"], guard("imu", self.controller.on_imu), sensors)
        if "scan" in self.controller.sensors:
            self.create_subscription(LaserScan, p["scan_topic"], guard("scan", self.controller.on_scan), sensors)
        self.action = None
        """The ``NavigateToPose`` or ``FollowPath`` goal being driven: (goal handle, future its execution awaits), or
        None."""
        self._preempt = False
        """Whether the FollowPath goal about to execute replaces an active one (its path is handed over)."""
        if self.follows_path:  # Nav2's controller: paths come by FollowPath only
            self._start_follow_path_server()
        else:
            goal = guard("goal", self.on_goal_topic)
            self.create_subscription(PoseStamped, p["goal_topic"], goal, QoSProfile(depth=10, reliability=RELIABLE))
            self._start_action_server()
        if tf_message is not None:  # goals in any frame: the tree from /tf and /tf_static, as tf2_ros's listener reads it
            self.create_subscription(tf_message, "/tf", guard("tf", self.controller.on_tf), QoSProfile(depth=100))
            static = functools.partial(self.controller.on_tf, static=True)  # kept: never stale
            self.create_subscription(tf_message, "/tf_static", guard("tf", static),
                                     QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        else:
            self.log.warning(f"no /tf ({tf_from}; tf2_msgs comes with a ROS 2 install): this node takes goals in "
                             f"{settings.odom_frame!r} only")
        if p["trace"]:
            try:
                path, line = fresh_path(p["trace"])
            except OutputPathError as err:
                self._fail(f"parameter trace: {err}")
            if line:
                self.log.warning(line)
            self.trace = path.open("w", encoding="utf-8")
        self.timer = self.create_timer(policy.period, self.on_tick)
        clamp = ""
        if settings.max_linear or settings.max_angular:
            clamp = (f"; speed clamp {self.controller.limits[0]:g} m/s, {self.controller.limits[1]:g} rad/s "
                     f"(trained at {policy.scale[0]:g}, {policy.scale[1]:g}): a clamp below the trained limits "
                     "changes how the policy drives")
        tolerance = self.controller.goal_tolerance
        reached = (f"reached within {tolerance:g} m" + (" (trained)" if settings.goal_tolerance < 0 else "")
                   if tolerance else "never judged reached (goal_tolerance:=0)")
        if self.follows_path:
            s = policy.path_settings
            goals = (f"paths by FollowPath, ended by Nav2's goal checker ({s.xy_goal_tolerance:g} m, "
                     f"{s.yaw_goal_tolerance:g} rad, stateful) and progress checker ({s.required_movement_radius:g} m "
                     f"in {s.movement_time_allowance:g} s)")
        else:
            goals = (f"goals in {settings.odom_frame!r} on {self.resolve_topic_name(p['goal_topic'])}"
                     f"{' (or any frame /tf joins to it)' if tf_message is not None else ''}, {reached}")
        self.log.info(f"{policy.describe()}; cmd_vel as {'TwistStamped' if self.stamped else 'Twist'} on "
                      f"{self.cmd_pub.topic_name}, {goals}{clamp}")

    # ---------------------------------------------------------------- parameters
    def _params_file_names(self, args: list[str] | None) -> dict[str, list[str]]:
        """Each ``--params-file``'s parameter names for this node (its name, namespace or ``/**``)."""
        return params_file_names(args, self.get_fully_qualified_name(), parameter_dict_from_yaml_file)

    def _check_topic(self, name: str, topic: str) -> None:
        try:
            validate_topic_name(expand_topic_name(topic, self.get_name(), self.get_namespace()))
        except Exception as err:  # noqa: BLE001 - rclpy's name checks raise several kinds; each is a bad name
            raise ParameterError(f"parameter {name} must be a ROS topic name, got {topic!r}: "
                                 f"{' '.join(str(err).split())[:160]}") from None

    def _fail(self, message: str):
        self.log.error(message)
        raise NodeConfigError(message)

    # ---------------------------------------------------------------- callbacks
    def now(self) -> float:
        """ROS time [s] (simulation time under ``use_sim_time``)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def guarded(self, source: str, handle):
        """A subscription callback: ``handle(msg, now)``'s line logged (``info`` for a goal taken, else ``warning``);
        any exception it raises becomes one ``error`` line, the controller's :meth:`~Controller.fault` (the
        ``source`` sensor unusable until its next good message) and a zero command."""

        def callback(msg) -> None:
            now = self.now()
            try:
                line = handle(msg, now)
            except Exception as err:  # noqa: BLE001 - no message may end the node
                self._failed(source, err, now)
                return
            if line and line.startswith("goal ("):
                self.log.info(line)
            elif line:
                self.log.warning(line)

        return callback

    def on_goal_topic(self, msg, now: float) -> str | None:
        """A goal on ``goal_topic``: taken (it replaces a ``NavigateToPose`` goal, which is aborted) or refused."""
        line = self.controller.on_goal(msg, now)
        if line.startswith("goal ("):
            self._resolve("aborted", f"replaced by a goal on {self.resolve_topic_name(self.params['goal_topic'])}")
        return line

    # ---------------------------------------------------------------- NavigateToPose
    def _start_action_server(self) -> None:
        """Nav2's ``NavigateToPose`` on ``navigate_to_pose`` (relative: in the node's namespace), where ``nav2_msgs``
        loads (a ROS install's, or built from the distribution's definition); otherwise one line says why."""
        from atrv_warp.deploy.nav2 import load_navigate_to_pose

        action, where = load_navigate_to_pose()
        self.navigate_to_pose = action
        if action is None:
            self.log.warning(f"no NavigateToPose action: {where}; goals come on the goal topic only")
            return
        self._serve(action, "navigate_to_pose", self._execute, self._on_action_goal, self._on_action_accepted, where)

    def _serve(self, action, name: str, execute, goal_callback, accepted_callback, where: str) -> None:
        """An action server of ``action`` on ``name`` (relative: in the node's namespace); every cancel accepted; its
        goal, cancel and result requests queued :data:`ACTION_REQUEST_DEPTH` deep."""
        from rclpy.action import ActionServer

        queue = QoSProfile(depth=ACTION_REQUEST_DEPTH, reliability=RELIABLE)
        self.action_server = ActionServer(self, action, name, execute, goal_callback=goal_callback,
                                          handle_accepted_callback=accepted_callback,
                                          cancel_callback=lambda _handle: self._cancel_response(),
                                          goal_service_qos_profile=queue, result_service_qos_profile=queue,
                                          cancel_service_qos_profile=queue)
        self.log.info(f"{action.__name__} on {self.get_namespace().rstrip('/')}/{name} ({where})")

    @staticmethod
    def _cancel_response():
        from rclpy.action import CancelResponse

        return CancelResponse.ACCEPT

    def _on_action_goal(self, request):
        """Accept a goal the controller can take; reject another with one line, the active goal driving on (Nav2)."""
        from rclpy.action import GoalResponse

        try:
            problem = self.controller.goal_problem(request.pose)
        except Exception as err:  # noqa: BLE001 - a goal the checks cannot read is rejected, never the node's end
            problem = f"{type(err).__name__}: {err}"
        if problem is None:
            return GoalResponse.ACCEPT
        self.log.warning(f"NavigateToPose goal rejected: {problem}" +
                         ("; the active goal goes on" if self.controller.goal_given else ""))
        return GoalResponse.REJECT

    def _on_action_accepted(self, handle) -> None:
        """A new goal replaces the one being driven (aborted, as Nav2's navigator preempts), then runs."""
        self._resolve("aborted", "replaced by a new NavigateToPose goal")
        handle.execute()

    async def _execute(self, handle):
        """Drive to the goal until it ends; its result says reached, aborted (why) or cancelled."""
        from rclpy.task import Future

        future, now = Future(), self.now()
        self.action = (handle, future)
        try:
            line = self.controller.on_goal(handle.request.pose, now)
        except Exception as err:  # noqa: BLE001 - a goal that cannot be read ends itself, never the node
            self._failed("goal", err, now)
            line = f"goal refused: {type(err).__name__}: {err}"
        self.log.info(f"NavigateToPose {line}")
        if not line.startswith("goal ("):
            self._resolve("aborted", line)
        state, reason = await future
        result = self.navigate_to_pose.Result()
        if hasattr(result, "error_msg"):  # Jazzy and later; Humble's result is empty
            result.error_msg = "" if state == "reached" else reason
            result.error_code = 0 if state in ("reached", "cancelled") else next(
                (code for key, code in RESULT_CODES.items() if reason.startswith(key)), 9000)
        self._settle(handle, state, reason)
        return result

    def _settle(self, handle, state: str, reason: str) -> None:
        """End an action goal as its ``state`` says: succeeded where reached, cancelled where its client asked,
        else aborted; one line."""
        if state == "reached":
            handle.succeed()
        elif state == "cancelled" and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        name = type(handle.request).__name__.removesuffix("_Goal")
        self.log.info(f"{name} goal {state}" + (f": {reason}" if reason else ""))

    # ---------------------------------------------------------------- FollowPath
    def _start_follow_path_server(self) -> None:
        """Nav2's ``FollowPath`` on ``follow_path`` (relative: in the node's namespace), as its controller server
        serves it; without ``nav2_msgs`` (neither installed nor buildable) the node cannot take a path: one error line,
        and it holds the rover still."""
        from atrv_warp.deploy.nav2 import load_follow_path

        action, where = load_follow_path()
        self.follow_path = action
        if action is None:
            self.log.error(f"no FollowPath action: {where}; this policy follows Nav2's plans and takes no goal "
                           "otherwise: the rover holds still")
            return
        self._serve(action, "follow_path", self._execute_path, self._accept_path, self._on_path_accepted, where)

    @staticmethod
    def _accept_path(_request):
        """Every goal is accepted, as Nav2's controller server accepts them (a bad path is aborted in execution)."""
        from rclpy.action import GoalResponse

        return GoalResponse.ACCEPT

    def _on_path_accepted(self, handle) -> None:
        """A new goal while one is active takes over its path without stopping; the replaced goal ends aborted with
        an empty result (Nav2's preemption). One whose cancel was asked for and not yet carried out ends cancelled,
        and the new goal starts afresh (its checkers and last actions new), as after the stop it asked for."""
        cancelled = self.action is not None and self.action[0].is_cancel_requested
        self._preempt = self.action is not None and not cancelled and self.controller.route is not None
        if cancelled:
            self._resolve("cancelled", "cancelled by the client")
        else:
            self._resolve("replaced", "replaced by a new FollowPath goal")
        handle.execute()

    async def _execute_path(self, handle):
        """Follow the path until it ends; the result carries Nav2's code where the distribution's definition has
        one."""
        from rclpy.task import Future

        future, now = Future(), self.now()
        self.action = (handle, future)
        preempt, self._preempt = self._preempt, False
        try:
            code, line = self.controller.on_path(handle.request.path, now, preempt=preempt)
        except Exception as err:  # noqa: BLE001 - a path that cannot be read ends its goal, never the node
            self._failed("goal", err, now)
            code, line = "UNKNOWN", f"UNKNOWN: {type(err).__name__}: {err}"
        self.log.info(f"FollowPath {line}")
        if code is not None:
            self._resolve("aborted", line)
        state, reason = await future
        result = self.follow_path.Result()
        if hasattr(result, "error_code"):  # Jazzy and later; Humble's result is empty
            from atrv_warp.deploy.nav2 import FOLLOW_PATH_CODES

            failed = state == "aborted"
            result.error_code = FOLLOW_PATH_CODES.get(reason.split(":", 1)[0], 100) if failed else 0
            result.error_msg = reason if failed else ""
        self._settle(handle, state, reason)
        return result

    def _resolve(self, state: str, reason: str) -> None:
        """End the ``NavigateToPose`` or ``FollowPath`` goal being driven, if any, with ``state`` and ``reason``."""
        if self.action is None:
            return
        _handle, future = self.action
        self.action = None
        if not future.done():
            future.set_result((state, reason))

    def _feedback(self, status: dict, now: float) -> None:
        handle, _ = self.action
        if self.follows_path:  # FollowPath's feedback: the distance along the path to its end, and the speed
            feedback = self.follow_path.Feedback()
            odom = self.controller.sensors["odom"].value
            feedback.distance_to_goal = float(status["distance"] or 0.0)
            feedback.speed = float(math.hypot(*odom[1][:2])) if odom is not None else 0.0
            handle.publish_feedback(feedback)
            return
        feedback = self.navigate_to_pose.Feedback()
        odom = self.controller.sensors["odom"].value
        if odom is not None:
            pose = feedback.current_pose
            pose.header.frame_id = self.controller.settings.odom_frame
            pose.header.stamp = self.get_clock().now().to_msg()
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = odom[0][:3]
            (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
             pose.pose.orientation.w) = odom[0][3:]
        feedback.navigation_time = Duration(seconds=max(now - self.controller.goal_time, 0.0)).to_msg()
        distance = status["distance"]
        if distance is not None:
            feedback.distance_remaining = float(distance)
            feedback.estimated_time_remaining = Duration(seconds=distance / self.policy.scale[0]).to_msg()
        handle.publish_feedback(feedback)

    def _follow_action(self, tick: Tick, now: float) -> Tick:
        """The ``NavigateToPose`` goal against this period's decision: a cancel requested stops the rover (this
        period's command becomes zero); an end resolves the goal; otherwise feedback."""
        if self.action is None:
            return tick
        handle, _ = self.action
        if handle.is_cancel_requested:
            tick = self.controller.stop("cancelled")
            self._resolve("cancelled", "cancelled by the client")
            return tick
        if tick.status is None:
            return tick
        if tick.status["state"] in ("reached", "aborted"):
            self._resolve(tick.status["state"], tick.status["reason"])
        else:
            self._feedback(tick.status, now)
        return tick

    # ---------------------------------------------------------------- the control period
    def on_tick(self) -> None:
        """The control period: the controller's decision published (and traced); a failure holds the rover."""
        now = self.now()
        try:
            tick = self._follow_action(self.controller.tick(now), now)
            self.publish(tick)
        except Exception as err:  # noqa: BLE001 - no decision may end the node
            self._failed("tick", err, now)
            return
        if tick.status is not None and tick.status["state"] == "active":
            self._said = None  # driving again: a later failure is news
        if self.trace is not None:
            try:
                self.trace.write(json.dumps(self.controller.trace(now, tick)) + "\n")
                self.trace.flush()
            except (OSError, ValueError, TypeError) as err:
                self.log.error(f"trace stopped: {err}")  # the rover drives on; only the record ends
                self._close_trace()

    def on_executor_failure(self, err: Exception) -> None:
        """What the spin loop calls when rclpy itself raised (outside every guarded callback): one line and a hold."""
        self._failed("executor", err, self.now())

    def _failed(self, source: str, err: Exception, now: float) -> None:
        """One error line (once while it repeats), and a zero command with the controller holding."""
        line = f"{source} callback failed ({type(err).__name__}: {' '.join(str(err).split())[:200]}): holding still"
        if line != self._said:
            self.log.error(line)
            self._said = line
        try:
            self.publish(self.controller.fault(source, line, now))
        except Exception as again:  # noqa: BLE001 - a publisher that fails too: say so once, stay up
            self.log.error(f"could not publish the zero command ({type(again).__name__}: {again})")

    def publish(self, tick: Tick) -> None:
        """Publish a tick's command and status, and log its lines."""
        for line in tick.log:
            self.log.info(line)
        if tick.command is not None:
            twist = Twist()
            twist.linear.x, twist.angular.z = (float(v) if math.isfinite(v) else 0.0 for v in tick.command)
            self._publish_command_path(twist.linear.x, twist.angular.z)
            if self.stamped:
                msg = TwistStamped()
                msg.header.stamp = self.get_clock().now().to_msg()
                msg.header.frame_id = self.params["base_frame"]
                msg.twist = twist
                self.cmd_pub.publish(msg)
            else:
                self.cmd_pub.publish(twist)
        if tick.status is not None:
            self.status_pub.publish(String(data=json.dumps(tick.status)))

    def _publish_command_path(self, v: float, w: float) -> None:
        """The arc (v [m/s], w [rad/s]) drives in :data:`COMMAND_PATH_SECONDS` from the base, as a ``nav_msgs/Path``."""
        msg = Path()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.params["base_frame"]
        x = y = yaw = 0.0
        dt = COMMAND_PATH_SECONDS / 10
        for k in range(11):
            pose = PoseStamped()
            pose.header = msg.header
            pose.pose.position.x, pose.pose.position.y = x, y
            pose.pose.orientation.z, pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
            msg.poses.append(pose)
            if k < 10:
                x, y, yaw = x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw), yaw + w * dt
        self.command_path_pub.publish(msg)

    def stop(self, reason: str) -> None:
        """Publish a zero command (and the goal's aborted status), and wait up to 0.5 s for subscribers to have it."""
        self.publish(self.controller.stop(reason))
        if self.action is not None:  # its client hears why: let the executor send the result
            import rclpy

            self._resolve("aborted", reason)
            for _ in range(5):
                rclpy.spin_once(self, timeout_sec=0.02)
        self.cmd_pub.wait_for_all_acked(Duration(seconds=0.5))
        self._close_trace()

    def _close_trace(self) -> None:
        if self.trace is not None:
            try:
                self.trace.close()
            except OSError:
                pass
            self.trace = None
