"""The rclpy node behind ``python -m atrv_warp.deploy`` (imported only where rclpy is installed).

:class:`DeployNode` subscribes to the robot's ``scan``, ``odom``, ``imu`` and ``goal_pose``, passes each message to
its :class:`~atrv_warp.deploy.controller.Controller`, and on a timer at the policy's rate (ROS time: with
``use_sim_time`` a simulator's ``/clock`` paces it) publishes the controller's ``cmd_vel`` and ``goal_status``.
Topic names are relative, so ``--ros-args -r __ns:=/rover_1`` runs it for one rover among several.

No input ends the node: every callback runs inside a guard (:meth:`DeployNode.guarded`), so that a failure is one
log line and a zero command, never an exception out of the executor, as Nav2's controller server publishes zero,
aborts the goal and stays up. rclpy ties a logging call site to one severity, so each severity has its own.
"""

from __future__ import annotations

import dataclasses
import json
import math

from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
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
from atrv_warp.deploy.controller import Controller, Deployable, Settings, Tick
from atrv_warp.deploy.parameters import (
    PARAMETERS,
    ParameterError,
    check_parameters,
    params_files,
    unknown_parameters,
)

__all__ = ["DeployNode", "NodeConfigError"]


def _tf_message() -> type | None:
    """``tf2_msgs/msg/TFMessage`` where a ROS 2 install provides it (no package index does), else None."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


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
            unknown = unknown_parameters(args, self._params_file_names(args))
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
        tf_message = _tf_message()
        self.controller = Controller(policy, settings, tf=tf_message is not None)
        self.stamped = p["enable_stamped_cmd_vel"]
        self.cmd_pub = self.create_publisher(TwistStamped if self.stamped else Twist, p["cmd_vel_topic"], 10)
        self.status_pub = self.create_publisher(String, p["status_topic"], 10)
        sensors = qos_profile_sensor_data  # best effort: matches a reliable publisher and a sensor driver's
        guard = self.guarded
        self.create_subscription(Odometry, p["odom_topic"], guard("odom", self.controller.on_odom), sensors)
        self.create_subscription(Imu, p["imu_topic"], guard("imu", self.controller.on_imu), sensors)
        if "scan" in self.controller.sensors:
            self.create_subscription(LaserScan, p["scan_topic"], guard("scan", self.controller.on_scan), sensors)
        self.create_subscription(PoseStamped, p["goal_topic"], guard("goal", self.controller.on_goal),
                                 QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        if tf_message is not None:  # goals in any frame: the tree from /tf and /tf_static, as tf2_ros's listener reads it
            self.create_subscription(tf_message, "/tf", guard("tf", self.controller.on_tf), QoSProfile(depth=100))
            self.create_subscription(tf_message, "/tf_static", guard("tf", self.controller.on_tf),
                                     QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        else:
            self.log.warning("tf2_msgs is not installed (it comes with a ROS 2 install): this node reads no /tf, so "
                             f"it takes goals in {settings.odom_frame!r} only")
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
        self.log.info(f"{policy.describe()}; cmd_vel as {'TwistStamped' if self.stamped else 'Twist'} on "
                      f"{self.cmd_pub.topic_name}, goals in {settings.odom_frame!r} on "
                      f"{self.resolve_topic_name(p['goal_topic'])}"
                      f"{' (or any frame /tf joins to it)' if tf_message is not None else ''}, {reached}{clamp}")

    # ---------------------------------------------------------------- parameters
    def _params_file_names(self, args: list[str] | None) -> dict[str, list[str]]:
        """Each ``--params-file``'s parameter names for this node (its name, namespace or ``/**``)."""
        found = {}
        for file in params_files(args):
            try:
                found[file] = list(parameter_dict_from_yaml_file(file, use_wildcard=True,
                                                                 target_nodes=[self.get_fully_qualified_name()]))
            except RuntimeError as err:
                if "does not contain any valid parameters" not in str(err):
                    raise ParameterError(f"--params-file {file}: {err}") from None
                found[file] = []  # a file for other nodes
            except (OSError, ValueError, AttributeError, TypeError) as err:  # unreadable, or YAML of another shape
                raise ParameterError(f"--params-file {file}: not a ROS parameter file ({err})") from None
        return found

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

    def on_tick(self) -> None:
        """The control period: the controller's decision published (and traced); a failure holds the rover."""
        now = self.now()
        try:
            tick = self.controller.tick(now)
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

    def stop(self, reason: str) -> None:
        """Publish a zero command (and the goal's aborted status), and wait up to 0.5 s for subscribers to have it."""
        self.publish(self.controller.stop(reason))
        self.cmd_pub.wait_for_all_acked(Duration(seconds=0.5))
        self._close_trace()

    def _close_trace(self) -> None:
        if self.trace is not None:
            try:
                self.trace.close()
            except OSError:
                pass
            self.trace = None
