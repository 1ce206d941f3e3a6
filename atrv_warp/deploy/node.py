"""The rclpy node behind ``python -m atrv_warp.deploy`` (imported only where rclpy is installed).

:class:`DeployNode` subscribes to the robot's ``scan``, ``odom``, ``imu`` and ``goal_pose``, passes each message to
its :class:`~atrv_warp.deploy.controller.Controller`, and on a timer at the policy's rate (ROS time: with
``use_sim_time`` a simulator's ``/clock`` paces it) publishes the controller's ``cmd_vel`` and ``goal_status``.
Topic names are relative, so ``--ros-args -r __ns:=/rover_1`` runs it for one rover among several.
"""

from __future__ import annotations

import json

from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu, LaserScan
from std_msgs.msg import String

from atrv_warp.deploy.controller import Controller, Deployable, Settings, Tick
from atrv_warp.deploy.parameters import PARAMETERS, unknown_parameters

__all__ = ["DeployNode", "NodeConfigError"]


class NodeConfigError(ValueError):
    """A parameter the node cannot run with (already logged)."""


class DeployNode(Node):
    """An exported policy as a ROS 2 controller (parameters: :data:`atrv_warp.deploy.parameters.PARAMETERS`).

    Raises:
        NodeConfigError: An unknown parameter or a bad value, logged in one line naming it.
    """

    def __init__(self, policy: Deployable, args: list[str] | None = None):
        super().__init__("atrv_deploy")
        self.params = {name: self.declare_parameter(name, default, ParameterDescriptor(description=text)).value
                       for name, default, text in PARAMETERS}
        self.log = self.get_logger()
        p = self.params
        unknown = unknown_parameters(args)
        if unknown:
            self._fail(f"unknown parameter(s) {unknown}; known: {sorted(n for n, _, _ in PARAMETERS)}")
        try:
            settings = Settings(odom_frame=p["odom_frame"], goal_tolerance=p["goal_tolerance"],
                                max_linear=p["max_linear"], max_angular=p["max_angular"],
                                stale_timeout=p["stale_timeout"], time_limit=p["time_limit"])
        except ValueError as err:
            self._fail(str(err))
        self.policy = policy
        self.controller = Controller(policy, settings)
        self.stamped = bool(p["enable_stamped_cmd_vel"])
        self.cmd_pub = self.create_publisher(TwistStamped if self.stamped else Twist, p["cmd_vel_topic"], 10)
        self.status_pub = self.create_publisher(String, p["status_topic"], 10)
        sensors = qos_profile_sensor_data  # best effort: matches a reliable publisher and a sensor driver's
        self.create_subscription(Odometry, p["odom_topic"], self.on_odom, sensors)
        self.create_subscription(Imu, p["imu_topic"], self.on_imu, sensors)
        if "scan" in self.controller.sensors:
            self.create_subscription(LaserScan, p["scan_topic"], self.on_scan, sensors)
        self.create_subscription(PoseStamped, p["goal_topic"], self.on_goal,
                                 QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.trace = open(p["trace"], "w", encoding="utf-8") if p["trace"] else None  # noqa: SIM115 - closed in stop
        self.timer = self.create_timer(policy.period, self.on_tick)
        clamp = ""
        if settings.max_linear or settings.max_angular:
            clamp = (f"; speed clamp {self.controller.limits[0]:g} m/s, {self.controller.limits[1]:g} rad/s "
                     f"(trained at {policy.scale[0]:g}, {policy.scale[1]:g}): a clamp below the trained limits "
                     "changes how the policy drives")
        self.log.info(f"{policy.describe()}; cmd_vel as {'TwistStamped' if self.stamped else 'Twist'} on "
                      f"{self.cmd_pub.topic_name}, goals in {settings.odom_frame!r} on "
                      f"{self.resolve_topic_name(p['goal_topic'])}{clamp}")

    def _fail(self, message: str):
        self.log.error(message)
        raise NodeConfigError(message)

    def now(self) -> float:
        """ROS time [s] (simulation time under ``use_sim_time``)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _say(self, line: str | None, level: str = "warning") -> None:
        if line:
            getattr(self.log, level)(line)

    def on_odom(self, msg: Odometry) -> None:
        self._say(self.controller.on_odom(msg, self.now()))

    def on_imu(self, msg: Imu) -> None:
        self._say(self.controller.on_imu(msg, self.now()))

    def on_scan(self, msg: LaserScan) -> None:
        self._say(self.controller.on_scan(msg, self.now()))

    def on_goal(self, msg: PoseStamped) -> None:
        line = self.controller.on_goal(msg, self.now())
        self._say(line, "info" if line.startswith("goal (") else "warning")

    def on_tick(self) -> None:
        now = self.now()
        tick = self.controller.tick(now)
        self.publish(tick)
        if self.trace is not None:
            self.trace.write(json.dumps(self.controller.trace(now, tick)) + "\n")
            self.trace.flush()

    def publish(self, tick: Tick) -> None:
        """Publish a tick's command and status, and log its lines."""
        for line in tick.log:
            self.log.info(line)
        if tick.command is not None:
            twist = Twist()
            twist.linear.x, twist.angular.z = tick.command
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
        if self.trace is not None:
            self.trace.close()
            self.trace = None
