"""The rclpy node behind ``python -m atrv_warp.ros`` (imported only where rclpy is installed).

:class:`RoverSimNode` simulates ``num_rovers`` rovers in one simulator, each with its own topics
(under ``/rover_<k>`` when there is more than one), and steps them on an rclpy timer in (scaled)
real time; the executor serves the subscriptions between steps. Topics and parameters are listed in :mod:`atrv_warp.cli.ros`.
"""

from __future__ import annotations

import collections
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rclpy
import torch
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState, LaserScan
from std_msgs.msg import Int32, String
from visualization_msgs.msg import MarkerArray

from atrv_warp.core.files import OutputPathError, check_output_path, fresh_path
from atrv_warp.core.geometry import quat_to_matrix, wrap_angle, yaw_to_quat
from atrv_warp.integrations.ros.bag import BagWriter, joint_state_dict, odometry_dict, pose_dict, twist_dict
from atrv_warp.integrations.ros.base import imu_reading
from atrv_warp.integrations.ros.frames import WORLD_FRAME, planar_matrix, pose_matrix, transform_dict, turn_matrix
from atrv_warp.integrations.ros.markers import scene_of, world_markers
from atrv_warp.integrations.ros.parameters import COMMANDS, GOAL, MAX_ROVERS, PARAMETERS, VELOCITY, driver_config
from atrv_warp.sim.modes import DRIVE_MODE_TORQUES, DriveMode
from atrv_warp.task.spec import END_REASONS, action_to_torque, action_to_twist

__all__ = ["NodeConfigError", "RoverIO", "RoverSimNode", "unknown_parameters"]

# Diagonal covariances of the wheel odometry (x, y, z, roll, pitch, yaw); z and the tilts are not
# observed by wheel odometry, so they are marked as unknown with a large variance.
_ODOM_POSE_VAR = (0.01, 0.01, 1e6, 1e6, 1e6, 0.05)
_ODOM_TWIST_VAR = (0.01, 0.01, 1e6, 1e6, 1e6, 0.05)


class NodeConfigError(ValueError):
    """A parameter value the node cannot run with (already logged by the node)."""


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _transform_msg(t: dict) -> TransformStamped:
    """A :func:`~.frames.transform_dict` as a ``geometry_msgs/TransformStamped``."""
    msg = TransformStamped()
    msg.header.stamp = Time(**t["header"]["stamp"])
    msg.header.frame_id, msg.child_frame_id = t["header"]["frame_id"], t["child_frame_id"]
    tr, rot = msg.transform.translation, msg.transform.rotation
    tr.x, tr.y, tr.z = (t["transform"]["translation"][k] for k in "xyz")
    rot.x, rot.y, rot.z, rot.w = (t["transform"]["rotation"][k] for k in "xyzw")
    return msg


def unknown_parameters(args: list[str] | None) -> list[str]:
    """Names given as ``-p name:=value`` after ``--ros-args`` that the node does not declare."""
    args = list(args or [])
    known = {name for name, _, _ in PARAMETERS} | {"use_sim_time"}
    names = [args[i + 1].split(":=")[0] for i, a in enumerate(args[:-1]) if a in ("-p", "--param")]
    return sorted(set(names) - known)


class RoverIO:
    """One rover's topics and driving mode; its base's motor driver and wheel odometry run in the simulator
    (:attr:`atrv_warp.sim.RoverSim.driver`)."""

    def __init__(self, node: RoverSimNode, index: int, prefix: str, qos: QoSProfile):
        self.node, self.index, self.prefix = node, index, prefix
        self.mode = self.pending = node.params["mode"]
        self.goal: tuple[float, float] | None = None
        self.distance: float | None = None
        """Distance to the goal at the last goal-mode step [m]."""
        self.start = (0.0, 0.0, 0.0)
        """The pose the odometry frame was put at [m, m, rad] (the world's start pose: odom = world until it drifts)."""
        self.stopped = False
        """The driver's timeout has stopped this rover (logged once)."""
        self.prev_vel = torch.zeros(3)
        self.episode: int | None = None
        """The evaluation episode this rover replays (``reset_episode``), until it ends."""
        self.unanswered = 0
        """``lockstep``: the replayed episode's steps taken on ``lockstep_timeout``, without a new /cmd_vel."""
        self.pending_episode: int | None = None
        self.delayed: collections.deque[tuple[int, float, float]] = collections.deque()
        """``cmd_vel_delay``: the /cmd_vel commands on their way to the driver, each with the step it arrives at."""
        tf_prefix = f"rover_{index}/" if prefix else ""  # its /tf frame names (frames.py)
        self.tf_odom, self.tf_base = tf_prefix + node.odom_frame, tf_prefix + node.base_frame
        self.tf_chassis = tf_prefix + node.sim.description.chassis
        self.tf_prefix = tf_prefix
        self.tf_skipped = False
        """The last state publication's /tf was left out (a non-finite pose); logged once until it is finite."""
        self.pose_pub = node.create_publisher(PoseStamped, f"{prefix}/pose", qos)
        self.status_pub = node.create_publisher(String, f"{prefix}/goal_status", 10)
        self.odom_pub = node.create_publisher(Odometry, f"{prefix}/odom", 10)
        self.fused_pub = node.create_publisher(Odometry, f"{prefix}/odometry/filtered", 10)
        self.episode_pub = node.create_publisher(String, f"{prefix}/episode", qos)
        self.truth_pub = node.create_publisher(Odometry, f"{prefix}/ground_truth/odom", 10)
        self.joint_pub = node.create_publisher(JointState, f"{prefix}/joint_states", 10)
        self.imu_pub = node.create_publisher(Imu, f"{prefix}/imu", 10)
        self.scan_pub = node.create_publisher(LaserScan, f"{prefix}/scan", 10) if node.scanner is not None else None
        node.create_subscription(String, f"{prefix}/command", self.on_command, qos)
        node.create_subscription(PoseStamped, f"{prefix}/goal", self.on_goal, qos)
        node.create_subscription(Twist, f"{prefix}/cmd_vel", self.on_cmd_vel, qos)
        node.create_subscription(Int32, f"{prefix}/reset_episode", self.on_reset_episode, qos)

    # ------------------------------------------------------------------ subscriptions
    def on_command(self, msg: String) -> None:
        text = msg.data.strip()
        self.node.record(f"{self.prefix}/command", "std_msgs/msg/String", {"data": msg.data})
        if text not in COMMANDS:
            self.node.log.warning(f"ignored unknown command {msg.data!r} on {self.prefix}/command; "
                                  f"known: {list(COMMANDS)}")
            return
        if text == GOAL and self.goal is None:
            self.node.log.warning("ignored 'goal': no goal received on /goal yet")
            return
        self.pending = text

    def on_goal(self, msg: PoseStamped) -> None:
        g = (msg.pose.position.x, msg.pose.position.y)
        if not all(math.isfinite(v) for v in g):
            self.node.log.warning(f"ignored non-finite goal {g}")
            return
        refusal = self.node.goal_policy_refusal()
        if refusal:
            self.node.log.warning(f"ignored goal {g}: {refusal}")
            return
        self.node.record(f"{self.prefix}/goal", "geometry_msgs/msg/PoseStamped", pose_dict(msg))
        self.goal = g
        self.pending = GOAL
        self.node.publish_markers()  # the goal disc
        self.node.log.info(f"goal ({g[0]:.2f}, {g[1]:.2f}) received: driving there")

    def on_cmd_vel(self, msg: Twist) -> None:
        v, w = msg.linear.x, msg.angular.z
        if not (math.isfinite(v) and math.isfinite(w)):
            self.node.log.warning(f"ignored non-finite {self.prefix}/cmd_vel (linear.x={v}, angular.z={w})")
            return
        self.node.record(f"{self.prefix}/cmd_vel", "geometry_msgs/msg/Twist", twist_dict(msg))
        if self.node.delay_steps:  # a command path's latency: the driver takes it that many steps later
            self.delayed.append((self.node.steps + self.node.delay_steps, v, w))
        else:
            self.node.sim.set_twist([v, w], worlds=[self.index])  # the base's driver takes it (and restarts its timeout)
        self.node.commanded = True  # lockstep: the next step may go
        self.stopped = False
        self.pending = VELOCITY  # the next step logs the switch; the driver has the command already

    def on_reset_episode(self, msg: Int32) -> None:
        """Replay evaluation episode ``msg.data`` at the next step (:meth:`RoverSimNode.start_episode`)."""
        task = self.node.env.task_cfg
        if task.action != "twist" or len(self.node.rovers) > 1 or msg.data < 0:
            self.node.log.warning(f"ignored reset_episode {msg.data}: episodes replay with one rover, a twist task "
                                  f"(nav_deploy) and an episode index >= 0 (here {len(self.node.rovers)} rover(s), "
                                  f"task action {task.action!r})")
            return
        self.pending_episode = msg.data

    def publish_episode(self, event: dict) -> None:
        self.episode_pub.publish(String(data=json.dumps(event)))

    # ------------------------------------------------------------------ driving
    def drive(self, goal_action) -> None:
        """Set this rover's input for the next step: its torque mode's torques, the policy's action toward its goal,
        or nothing in velocity mode (the driver holds the last ``/cmd_vel``, and stops the rover after its timeout)."""
        node, k = self.node, self.index
        if self.pending != self.mode:
            self.mode = self.pending
            node.log.info(f"{self.prefix or 'rover'}: mode -> {self.mode}")
        if self.mode == VELOCITY:
            if bool(node.sim.driver.timed_out[k]) and not self.stopped:
                self.stopped = True
                node.log.warning(f"{self.prefix}/cmd_vel silent for {node.sim.driver_cfg.cmd_vel_timeout:g} s: "
                                 "stopping")
            return
        if self.mode == GOAL:
            dist = goal_action(k)
            self.distance = dist
            if dist < node.params["reach_radius"]:
                self.publish_status("reached")
                node.log.info("goal reached")
                self.mode = self.pending = DriveMode.COAST.value
                node.sim.set_commands([0.0, 0.0], worlds=[k])
            return
        node.sim.set_commands(DRIVE_MODE_TORQUES[DriveMode(self.mode)], worlds=[k])

    def odometry(self, fused: bool = False) -> tuple[float, float, float, float, float]:
        """The base's wheel odometry in the node's odometry frame (the start pose composed with the driver's):
        x [m], y [m], yaw [rad], linear [m/s], angular [rad/s]; ``fused``: the driver's fused odometry (encoders and
        gyro, and the accelerometer with ``odometry_accel_time``; ``odometry/filtered``, what the robot observation is
        trained on) instead of the wheels' alone."""
        d = self.node.sim.driver
        x, y, yaw = (d.fused if fused else d.odometry)[self.index].double().tolist()
        x0, y0, yaw0 = self.start
        c, s = math.cos(yaw0), math.sin(yaw0)
        linear, angular = d.odom_twist[self.index].double().tolist()
        return x0 + c * x - s * y, y0 + s * x + c * y, float(wrap_angle(torch.tensor(yaw0 + yaw))), linear, angular

    # ------------------------------------------------------------------ publishing
    def publish_status(self, text: str) -> None:
        self.status_pub.publish(String(data=text))
        self.node.record(f"{self.prefix}/goal_status", "std_msgs/msg/String", {"data": text})

    def publish_state(self, ns: int, frame_pose: torch.Tensor, accel: torch.Tensor) -> None:
        node, sim, k = self.node, self.node.sim, self.index
        p = sim.root_pose[k].tolist()
        msg = PoseStamped()
        msg.header.stamp = _stamp(ns)
        msg.header.frame_id = node.frame_id
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p[0], p[1], p[2]
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = p[3], p[4], p[5], p[6]
        self.pose_pub.publish(msg)
        node.record(f"{self.prefix}/pose", "geometry_msgs/msg/PoseStamped", pose_dict(msg), ns)
        self.publish_odometry(ns, p)
        self.publish_frames(ns, p)
        self.publish_joints(ns)
        self.publish_imu(ns, frame_pose, accel)
        if self.scan_pub is not None:
            self.publish_scan(ns)
        if self.mode == GOAL and self.distance is not None:
            self.publish_status(f"distance={self.distance:.3f}")

    def publish_odometry(self, ns: int, pose: list[float]) -> None:
        node, sim, k = self.node, self.node.sim, self.index
        x, y, yaw, linear, angular = self.odometry()
        msg = Odometry()
        # the frames /tf names (rover_<k>/odom -> rover_<k>/base_link with several rovers): one naming rule
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = _stamp(ns), self.tf_odom, self.tf_base
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = yaw_to_quat(yaw).tolist()
        msg.pose.covariance = [v if i == j else 0.0 for i in range(6) for j, v in enumerate(_ODOM_POSE_VAR)]
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = linear, angular
        msg.twist.covariance = [v if i == j else 0.0 for i in range(6) for j, v in enumerate(_ODOM_TWIST_VAR)]
        self.odom_pub.publish(msg)
        node.record(f"{self.prefix}/odom", "nav_msgs/msg/Odometry", odometry_dict(msg), ns)
        fx, fy, fyaw = self.odometry(fused=True)[:3]  # the encoders' distance along the gyro's heading
        msg.pose.pose.position.x, msg.pose.pose.position.y = fx, fy
        o.x, o.y, o.z, o.w = yaw_to_quat(fyaw).tolist()
        self.fused_pub.publish(msg)
        truth = Odometry()
        truth.header.stamp, truth.header.frame_id, truth.child_frame_id = _stamp(ns), WORLD_FRAME, self.tf_base
        t = truth.pose.pose
        t.position.x, t.position.y, t.position.z = pose[0], pose[1], pose[2]
        t.orientation.x, t.orientation.y, t.orientation.z, t.orientation.w = pose[3], pose[4], pose[5], pose[6]
        if node.params["truth_noise"] > 0 or node.params["truth_yaw_noise"] > 0:  # a motion-capture or RTK fix
            e = torch.randn(3, generator=node.noise, dtype=torch.float64).tolist()
            t.position.x += node.params["truth_noise"] * e[0]
            t.position.y += node.params["truth_noise"] * e[1]
            dq = yaw_to_quat(node.params["truth_yaw_noise"] * e[2]).tolist()  # q <- rotation about world z, times q
            x, y, z, w = pose[3], pose[4], pose[5], pose[6]
            t.orientation.x = dq[3] * x - dq[2] * y
            t.orientation.y = dq[3] * y + dq[2] * x
            t.orientation.z = dq[3] * z + dq[2] * w
            t.orientation.w = dq[3] * w - dq[2] * z
        rot = node.chassis_rotation(k)
        v_body = rot.T @ sim.lin_vel[k].to(torch.float64)
        w_body = rot.T @ sim.ang_vel[k].to(torch.float64)
        tw = truth.twist.twist
        tw.linear.x, tw.linear.y, tw.linear.z = v_body.tolist()
        tw.angular.x, tw.angular.y, tw.angular.z = w_body.tolist()
        self.truth_pub.publish(truth)
        node.record(f"{self.prefix}/ground_truth/odom", "nav_msgs/msg/Odometry", odometry_dict(truth), ns)

    def static_frames(self, ns: int) -> list[dict]:
        """This rover's /tf_static: ``base_link`` on the chassis link (when named apart), and the chassis's
        fixed frames (sensors) from the URDF."""
        desc = self.node.sim.description
        out = [] if self.tf_base == self.tf_chassis else [transform_dict(self.tf_base, self.tf_chassis, ns, np.eye(4))]
        return out + [transform_dict(self.tf_chassis, self.tf_prefix + f.name, ns, np.asarray(f.transform, dtype=float))
                      for f in desc.frames]

    def publish_frames(self, ns: int, pose: list[float]) -> None:
        """This rover's /tf, live (where tf2_msgs loads) and to the bag: world -> odom -> base_link (odometry,
        corrected to the true pose) and the turning wheels (:mod:`.frames`). A non-finite pose is never
        published: the rover's /tf is left out for the step, with one line logged."""
        node = self.node
        if node.bag is None and node.tf_pub is None:
            return
        (x, y, yaw, _, _), wheels = self.odometry(), node.wheel_positions(self.index)
        if not all(math.isfinite(v) for v in (*pose, x, y, yaw, *wheels)):
            if not self.tf_skipped:
                node.log.warning(f"{self.prefix or 'rover'}: non-finite pose, its /tf is not published until it "
                                 "is finite again")
            self.tf_skipped = True
            return
        self.tf_skipped = False
        world_base, odom_base = pose_matrix(pose[:3], pose[3:7]), planar_matrix(x, y, yaw)
        transforms = [transform_dict(WORLD_FRAME, self.tf_odom, ns, world_base @ np.linalg.inv(odom_base)),
                      transform_dict(self.tf_odom, self.tf_base, ns, odom_base)]
        transforms += [transform_dict(self.tf_chassis, self.tf_prefix + w.link, ns,
                                      np.asarray(w.origin, dtype=float) @ turn_matrix(w.axis, q))
                       for w, q in zip(node.sim.description.wheels, wheels)]
        node.record("/tf", "tf2_msgs/msg/TFMessage", {"transforms": transforms}, ns)
        if node.tf_pub is not None:
            node.tf_pub.publish(node.tf_message(transforms))

    def publish_joints(self, ns: int) -> None:
        node, k = self.node, self.index
        msg = JointState()
        msg.header.stamp = _stamp(ns)
        msg.name = node.joint_names
        msg.position = node.wheel_positions(k)
        noise = node.params["wheel_speed_noise"]
        velocity = torch.tensor(node.wheel_velocities(k), dtype=torch.float64)
        if noise > 0:
            velocity += noise * torch.randn(len(velocity), generator=node.noise, dtype=torch.float64)
        msg.velocity = velocity.tolist()
        # effort: the torque each motor applied at the end of the step [N·m] (torque scale and the taper near
        # its no-load speed included; a real drive reports it from its current), in each joint's sense
        torque = node.sim.wheel_torque[k].tolist()
        msg.effort = [node.wheel_sign[j] * torque[j] for j in range(len(torque))]
        self.joint_pub.publish(msg)
        node.record(f"{self.prefix}/joint_states", "sensor_msgs/msg/JointState", joint_state_dict(msg), ns)

    def publish_scan(self, ns: int) -> None:
        """The last scan as ``sensor_msgs/LaserScan`` in the scanner's frame; no return is +inf (REP 117)."""
        scanner = self.node.scanner
        cfg = scanner.cfg
        msg = LaserScan()
        msg.header.stamp, msg.header.frame_id = _stamp(ns), self.tf_prefix + scanner.frame
        msg.angle_min, msg.angle_max = float(cfg.angles[0]), float(cfg.angles[-1])
        msg.angle_increment = float(cfg.angles[1] - cfg.angles[0]) if cfg.beams > 1 else 0.0
        msg.time_increment = 0.0  # every beam of a scan is cast at the same simulated instant
        msg.scan_time = self.node.every * self.node.sim.sim_cfg.step_dt
        msg.range_min, msg.range_max = cfg.min_range, cfg.max_range
        ranges = scanner.ranges[self.index].tolist()
        msg.ranges = [r if r < cfg.max_range else math.inf for r in ranges]
        self.scan_pub.publish(msg)

    def publish_imu(self, ns: int, frame_pose: torch.Tensor, accel: torch.Tensor) -> None:
        node, k = self.node, self.index
        r = imu_reading(frame_pose, node.sim.ang_vel[k], accel, node.sim.sim_cfg.gravity,
                        (node.params["imu_accel_noise"], node.params["imu_gyro_noise"]), node.noise)
        msg = Imu()
        msg.header.stamp, msg.header.frame_id = _stamp(ns), self.tf_prefix + node.imu_frame
        q = msg.orientation
        q.x, q.y, q.z, q.w = r["orientation"]
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = r["angular_velocity"]
        a = msg.linear_acceleration
        a.x, a.y, a.z = r["linear_acceleration"]
        gyro, acc = node.params["imu_gyro_noise"] ** 2, node.params["imu_accel_noise"] ** 2
        msg.angular_velocity_covariance = [gyro, 0.0, 0.0, 0.0, gyro, 0.0, 0.0, 0.0, gyro]
        msg.linear_acceleration_covariance = [acc, 0.0, 0.0, 0.0, acc, 0.0, 0.0, 0.0, acc]
        msg.orientation_covariance = [1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6]
        self.imu_pub.publish(msg)


class RoverSimNode(Node):
    """Simulated rovers of one robot as a ROS 2 base driver.

    Construction declares the parameters (with descriptions); :meth:`setup` checks them (a bad
    or unknown one is logged and raises :class:`NodeConfigError`), then builds the simulator
    and every rover's topics.
    """

    def __init__(self, args: list[str] | None = None):
        super().__init__("atrv_sim")
        self.params = {name: self.declare_parameter(name, default, ParameterDescriptor(description=text)).value
                       for name, default, text in PARAMETERS}
        self.log = self.get_logger()
        self.args = args
        self.bag: BagWriter | None = None
        self.tf_pub = None
        """Live /tf's publisher, where tf2_msgs loads (parameter ``tf``)."""
        self.sim = None
        self.scanner = None
        self.rovers: list[RoverIO] = []
        self.policy = None  # goal mode's (policy, TensorDict): a -p policy file once checked, else loaded on first use
        self.goal_refusal: str | None = None
        """Why goal mode cannot drive this robot (:meth:`goal_policy_refusal`), once decided."""
        self._goal_decided = False
        self.commanded = False
        """A /cmd_vel came since the last state publication (``lockstep``)."""
        self.published_at = 0.0
        self.holding = False
        """``lockstep``: a replayed episode has ended; nothing steps until the next ``reset_episode``."""
        self.reset_ns = 0
        """ROS time the episode resets added to the simulation time [ns]: one period each."""
        self.steps = 0
        """Simulator steps taken (:meth:`on_step_timer`; ``cmd_vel_delay`` counts in them)."""
        self.delay_steps = 0
        """``cmd_vel_delay`` in whole steps."""
        self.stop_requested: Sequence = ()
        """Non-empty once the process has been asked to stop (:meth:`spin_simulation`'s ``stop_requested``)."""

    def setup(self) -> None:
        self._check_parameters()
        p = self.params
        k = p["num_rovers"]
        task = p["task"]
        if p["policy"]:  # the world runs the task the policy records (as it trained), not today's fit of its name
            from atrv_warp.policy import policy_record
            from atrv_warp.storage import FileFormatError

            try:
                task = policy_record(p["policy"]).task
            except (FileNotFoundError, FileFormatError, ValueError) as err:
                self._fail(f"parameter policy: {err}")
            if task.name != p["task"]:
                self._fail(f"parameter policy: {p['policy']} was trained on task {task.name!r}, not task={p['task']!r}")
        from atrv_warp.task.env import RoverEnv  # the simulator (Newton), once the parameters are good

        # goal mode reads the policy's observation kernel
        try:
            self.env = RoverEnv(k, robot=p["robot"], variant=p["variant"], task=task, seed=int(p["seed"]),
                                 sim_config=p["sim_config"] or None, driver=self.driver,
                                 **({"terrain": p["terrain"]} if p["terrain"] else {}))
        except ValueError as err:
            self._fail(f"parameter sim_config: {err}" if p["sim_config"] else str(err))
        if p["sim_config"]:
            self.log.info(f"simulator config {p['sim_config']}: {self.env.sim.rover_cfg.torque_scale:g}x motor torque, "
                          f"{self.env.sim.rover_cfg.payload_mass:g} kg payload, friction "
                          f"{self.env.sim.contact_cfg.friction:g}, wheel radius {self.env.sim.rover_cfg.wheel_radius:g} m")
        self.sim = self.env.sim
        starts = [[p["x"], p["y"] + i * p["spacing"], p["yaw"]] for i in range(k)]
        if p["task"] != "reach":  # terrain tiles and obstacle layouts come with the task's first episodes
            self.env.reset()
            starts = self.sim.root_pose[:, :2].tolist()
            starts = [[x, y, float(yaw)] for (x, y), yaw in zip(starts, self.sim.rpy[:, 2].tolist())]
            self.log.info("task nav: rovers start at their first episodes' starts "
                          + ", ".join(f"({x:.1f}, {y:.1f})" for x, y, _ in starts))
        try:
            self.sim.reset(poses=starts)
        except ValueError as err:
            self._fail(f"parameters x, y, yaw, spacing: {err}")
        self.sim.driver.lag.fill_(p["motor_lag"])
        self.delay_steps = round(p["cmd_vel_delay"] / self.sim.sim_cfg.step_dt)
        if p["motor_lag"] or self.delay_steps or p["terrain"]:
            self.log.info(f"effects: /cmd_vel delayed {self.delay_steps} step(s), motor lag {p['motor_lag']:g} s, "
                          f"terrain {p['terrain'] or self.env.task_cfg.terrain}")
        if p["scan_beams"] > 0:
            from atrv_warp.sim.scanner import LaserScanner, ScannerConfig

            scan = ScannerConfig(beams=p["scan_beams"], noise_std=p["scan_noise"], dropout=p["scan_dropout"])
            self.scanner = LaserScanner(self.sim, scan, seed=int(p["seed"]))
        desc = self.sim.description
        self.every = max(1, round(1.0 / (p["publish_rate"] * self.sim.sim_cfg.step_dt)))
        self.frame_id = p["frame_id"] or desc.chassis
        self.odom_frame, self.base_frame, self.imu_frame = (p["odom_frame"], p["base_frame"],
                                                           self.sim.rover_cfg.robot_spec.imu_frame)
        self.joint_names = [w.joint for w in desc.wheels]
        self.side = torch.tensor([w.side for w in desc.wheels])
        self.wheel_sign = [float(w.drive_sign) for w in desc.wheels]
        self.noise = torch.Generator().manual_seed(int(p["seed"]))
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        urdf = Path(desc.path).read_text()
        self.create_publisher(String, "/robot_description", latched).publish(String(data=urdf))
        self.marker_pub = self.create_publisher(MarkerArray, "/visualization_marker_array", latched)
        self.rovers = [RoverIO(self, i, f"/rover_{i}" if k > 1 else "", qos) for i in range(k)]
        for rover, start in zip(self.rovers, starts):  # the odom frame starts at the start pose
            rover.start = tuple(float(v) for v in start)
        self.publish_markers()
        self.tf_pub = self.tf_message = None
        if p["tf"]:
            self._start_tf(latched)
        self.bag = None
        if p["bag"]:
            try:
                path, line = fresh_path(p["bag"])  # an existing bag is kept: the next free name is taken
            except OutputPathError as err:
                self._fail(f"parameter bag: {err}")
            if line:
                self.log.warning(line)
            self.bag = BagWriter(path)
        if self.bag is not None:  # what a 3D panel needs to draw the rover from the bag alone
            self.record("/robot_description", "std_msgs/msg/String", {"data": urdf})
            self.record("/tf_static", "tf2_msgs/msg/TFMessage",
                        {"transforms": [t for r in self.rovers for t in r.static_frames(self.stamp_ns())]})

    def _fail(self, message: str):
        self.log.error(message)
        raise NodeConfigError(message)

    def _check_parameters(self) -> None:
        p = self.params
        unknown = unknown_parameters(self.args)
        if unknown:
            self._fail(f"unknown parameter(s) {unknown}; known: {sorted(n for n, _, _ in PARAMETERS)}")
        if p["mode"] not in COMMANDS or p["mode"] == GOAL:
            self._fail(f"parameter mode={p['mode']!r} is not a driving mode; use one of {list(COMMANDS[:-1])}")
        if p["real_time_factor"] < 0 or p["publish_rate"] <= 0:
            self._fail("real_time_factor must be >= 0 and publish_rate > 0")
        if not 1 <= p["num_rovers"] <= MAX_ROVERS:
            self._fail(f"num_rovers must be in 1 … {MAX_ROVERS}, got {p['num_rovers']}")
        from atrv_warp.core.robot import RobotFileError, load_robot

        try:
            load_robot(p["robot"])
        except RobotFileError as err:
            self._fail(f"parameter robot: {err}")
        try:
            self.driver = driver_config(p)
        except ValueError as err:
            self._fail(str(err))
        from atrv_warp.task.registry import TASK_VARIANTS

        if p["task"] not in TASK_VARIANTS:
            self._fail(f"task={p['task']!r} is not a task; use one of {sorted(TASK_VARIANTS)}")
        if p["scan_beams"] < 0 or p["scan_noise"] < 0:
            self._fail("scan_beams and scan_noise must be >= 0")
        negative = [n for n in ("wheel_speed_noise", "truth_noise", "truth_yaw_noise", "imu_accel_noise",
                                "imu_gyro_noise") if not p[n] >= 0]
        if negative:
            self._fail(f"noise parameter(s) {negative} must be >= 0 (standard deviations)")
        bad = [n for n in ("cmd_vel_delay", "motor_lag") if not (math.isfinite(p[n]) and p[n] >= 0)]
        if bad:
            self._fail(f"parameter(s) {bad} must be finite and >= 0 [s]")
        if p["terrain"]:
            from atrv_warp.sim.terrain import TERRAIN_PRESETS

            if p["terrain"] not in TERRAIN_PRESETS:
                self._fail(f"terrain={p['terrain']!r} is not a terrain; use one of {sorted(TERRAIN_PRESETS)}")
        if not 0.0 <= p["scan_dropout"] <= 1.0:
            self._fail(f"scan_dropout is a probability in [0, 1], got {p['scan_dropout']}")
        if p["bag"]:  # before the simulator is built: a bag it cannot write fails in one line, not after the compile
            try:
                check_output_path(p["bag"], "bag")
            except OutputPathError as err:
                self._fail(f"parameter bag: {err}")
        if p["policy"]:  # goal mode's policy: a file the task can run, checked before any rover starts
            from tensordict import TensorDict

            from atrv_warp.policy import load_policy
            from atrv_warp.storage import FileFormatError

            try:
                self.policy = (load_policy(p["policy"], task=p["task"]), TensorDict)
                self._check_policy_robot(p["policy"])
            except (FileNotFoundError, FileFormatError, ValueError) as err:
                self._fail(f"parameter policy: {err}")

    def goal_policy_refusal(self) -> str | None:
        """Why goal mode cannot drive this robot (the task's shipped policy was trained on another robot, and no
        ``-p policy:=`` gives one of its own), or ``None``; decided once."""
        if self.policy is not None or self.params["policy"]:
            return None
        if not self._goal_decided:
            from atrv_warp.policy import PolicyRobotMismatch, shipped_policy_for

            try:
                self._check_policy_robot(shipped_policy_for(self.params["task"], self.params["robot"]))
            except PolicyRobotMismatch as err:
                self.goal_refusal = f"{err} (give one trained on it: -p policy:=FILE)"
            self._goal_decided = True
        return self.goal_refusal

    def _check_policy_robot(self, policy) -> None:
        """A goal policy trained on another robot than the node's is refused, naming both."""
        from atrv_warp.core.robot import load_robot
        from atrv_warp.policy import check_policy_robot, policy_record

        check_policy_robot(policy_record(policy), load_robot(self.params["robot"]), source=policy)

    def _start_tf(self, latched: QoSProfile) -> None:
        """Live /tf and /tf_static, where tf2_msgs loads (a ROS install's, or built from its definition on
        first use: :mod:`atrv_warp.core.ros_interfaces`); otherwise one line says why and the node goes on without."""
        from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

        cls, where = load_interface(TF2_MSGS, "msg", "TFMessage")
        if cls is None:
            self.log.warning(f"no live /tf: {where}")
            return
        self.log.info(f"/tf and /tf_static from {where}")
        self.tf_message = lambda transforms: cls(transforms=[_transform_msg(t) for t in transforms])
        self.tf_pub = self.create_publisher(cls, "/tf", 100)
        ns = self.stamp_ns()
        self.create_publisher(cls, "/tf_static", latched).publish(
            self.tf_message([t for r in self.rovers for t in r.static_frames(ns)]))

    def publish_markers(self) -> None:
        """The latched /visualization_marker_array (world frame): walls, each rover's obstacles, goal and
        terrain (:mod:`.markers`); a rover whose world holds a non-finite pose is left out, with one line."""
        several = len(self.rovers) > 1
        scenes = [scene_of(self.sim, r.index, ns=f"rover_{r.index}/" if several else "", goal=r.goal,
                           goal_radius=self.params["reach_radius"]) for r in self.rovers]
        msg, skipped = world_markers(self.sim.arena_cfg, scenes, WORLD_FRAME, _stamp(self.stamp_ns()))
        for name in skipped:
            self.log.warning(f"markers of {name} not published: its world holds a non-finite pose")
        self.marker_pub.publish(msg)

    # ------------------------------------------------------------------ simulator reads
    def stamp_ns(self) -> int:
        """ROS time [ns], the stamp of everything the node publishes and its ``/clock``: the simulation time, plus one
        step per ``reset_episode`` (a reset takes a control period, so a controller timed on the clock acts on the
        reset state)."""
        return round(self.sim.sim_time * 1e9) + self.reset_ns

    def record(self, topic: str, type_name: str, message: dict, stamp_ns: int | None = None) -> None:
        if self.bag is not None:
            self.bag.write(topic, type_name, message, self.stamp_ns() if stamp_ns is None else stamp_ns)

    def side_speeds(self) -> torch.Tensor:
        """(K, 2) mean left and right forward wheel speeds [rad/s]."""
        ws = self.sim.wheel_speed
        return torch.stack([ws[:, self.side == 0].mean(-1), ws[:, self.side == 1].mean(-1)], -1)

    def _wheel_view(self, array, index) -> list[float]:
        return array.view(self.sim.num_worlds, -1)[:, index].tolist()

    def wheel_positions(self, k: int) -> list[float]:
        import warp as wp

        b = self.sim.buffers
        return self._wheel_view(wp.to_torch(b.joint_q), wp.to_torch(b.layout.wheel_coord).long())[k]

    def wheel_velocities(self, k: int) -> list[float]:
        import warp as wp

        b = self.sim.buffers
        return self._wheel_view(wp.to_torch(b.joint_qd), wp.to_torch(b.layout.wheel_dof).long())[k]

    def chassis_rotation(self, k: int) -> torch.Tensor:
        """Rover ``k``'s chassis rotation matrix (world from body), float64."""
        return quat_to_matrix(self.sim.root_pose[k, 3:7].to(torch.float64))

    # ------------------------------------------------------------------ driving
    def goal_action(self, k: int) -> float:
        """Drive rover ``k`` by the policy toward its goal (its torques, or its ``/cmd_vel`` through the driver, as
        the task's action says) for the next step; returns the distance to the goal [m]."""
        if self.policy is None:
            from tensordict import TensorDict

            from atrv_warp.policy import load_policy, shipped_policy_for

            task = self.params["task"]  # the robot's shipped policy for the task (nav_deploy_husky), else the task's
            name = shipped_policy_for(task, self.params["robot"])
            self.policy = (load_policy(name, task=task), TensorDict)
            self._check_policy_robot(name)
        policy, td_cls = self.policy
        targets = self.sim.root_pose[:, :2].clone()  # rovers not in goal mode: their own position
        for rover in self.rovers:
            if rover.goal is not None:
                targets[rover.index] = torch.tensor(rover.goal)
        obs = self.env.observe(targets)
        action = policy(td_cls(observation=obs, batch_size=[self.sim.num_worlds]))["action"][k]
        task = self.env.task_cfg
        if task.action == "twist":
            self.sim.set_twist(action_to_twist(action, task.max_linear, task.max_angular), worlds=[k])
        else:
            self.sim.set_commands(action_to_torque(action, task.action_scale), worlds=[k])
        return float(self.env.target_distance[k])

    def step_once(self) -> bool:
        """Every rover's input for its mode and one simulator step; True when a replayed episode ended in it."""
        for rover in self.rovers:
            while rover.delayed and rover.delayed[0][0] <= self.steps:  # delayed /cmd_vel due at this step
                _, v, w = rover.delayed.popleft()
                self.sim.set_twist([v, w], worlds=[rover.index])
            rover.drive(self.goal_action)
        # what every rover commanded, as the policy's actions: a task that observes its last actions sees them
        task = self.env.task_cfg
        if task.action == "twist":
            self.env.record_actions(self.sim.driver.twist / torch.tensor([task.max_linear, task.max_angular]))
        else:
            self.env.record_actions(self.sim.commands / task.action_scale)
        for rover in self.rovers:
            rover.prev_vel = self.sim.lin_vel[rover.index].clone()
        if any(r.episode is not None for r in self.rovers):
            return self.step_episode()
        self.sim.step()
        return False

    def start_episode(self, rover: RoverIO) -> None:
        """Put ``rover`` in evaluation episode ``rover.pending_episode`` of ``episode_seed`` (the world, start and
        goal ``python -m atrv_warp.evaluate`` gives that episode: :meth:`RoverEnv.reset_to_episodes`), its odometry
        frame at the new start, still; publish ``episode`` ``{"event": "start", "episode", "seed", "start": [x, y,
        yaw], "goal": [x, y]}`` (world frame = the odometry frame at the start) and the state."""
        k, seed = rover.pending_episode, int(self.params["episode_seed"])
        rover.pending_episode = None
        self.reset_ns += round(self.sim.sim_cfg.step_dt * 1e9)
        self.env.reset_to_episodes([rover.index], [k], seed=seed)
        self.sim.set_twist([0.0, 0.0], worlds=[rover.index])
        rover.delayed.clear()  # a delayed /cmd_vel of the last episode is not this one's
        self.sim.driver.lag[rover.index] = self.params["motor_lag"]  # the episode's reset drew the env's lag
        # the odometry frame where the environment puts it (the start as drawn, not the settled chassis's pose: on a
        # slope their yaws differ by a fraction of a degree), so the goal is seen as evaluate's policy sees it
        rover.start = tuple(float(v) for v in self.env.episode_start[rover.index].tolist())
        rover.goal = tuple(self.env.target[rover.index].tolist())
        rover.episode, rover.mode, rover.pending, rover.unanswered = k, VELOCITY, VELOCITY, 0
        rover.publish_episode({"event": "start", "episode": k, "seed": seed, "start": list(rover.start),
                               "goal": list(rover.goal)})
        self.publish_markers()

    def step_episode(self) -> bool:
        """One environment step of the replayed episode, the rover's last /cmd_vel as its action (so the episode
        ends as ``evaluate``'s do: reached, wall, flip, obstacle, timeout); at its end ``episode`` ``{"event": "end",
        "episode", "end_reason", "steps"}`` and the rover stops. True when the episode ended."""
        from tensordict import TensorDict

        task = self.env.task_cfg
        action = (self.sim.driver.twist / torch.tensor([task.max_linear, task.max_angular])).clamp(-1.0, 1.0)
        out = self.env.step(TensorDict(action=action, batch_size=[self.sim.num_worlds]))["next"]
        ended = False
        for rover in self.rovers:  # every rover whose episode ended in this step says so, not only the first
            if rover.episode is not None and bool(out["done"][rover.index]):
                reason = END_REASONS[int(out["end_reason"][rover.index])]
                rover.publish_episode({"event": "end", "episode": rover.episode, "end_reason": reason,
                                       "steps": int(self.env.step_count[rover.index]),
                                       "unanswered": rover.unanswered})
                self.log.info(f"episode {rover.episode}: {reason}")
                rover.episode = None
                self.sim.set_twist([0.0, 0.0], worlds=[rover.index])
                ended = True
        return ended

    def publish_state(self) -> None:
        self.commanded, self.published_at = False, time.monotonic()
        ns = self.stamp_ns()
        if self.scanner is not None:
            self.scanner.scan()
        frames = self.sim.frame_pose(self.imu_frame)
        dt = self.sim.sim_cfg.step_dt
        for rover in self.rovers:
            accel = (self.sim.lin_vel[rover.index] - rover.prev_vel) / dt
            rover.publish_state(ns, frames[rover.index], accel)

    def spin_simulation(self, executor=None, stop_requested: Sequence = ()) -> None:
        """Step on a timer (period ``step_dt / real_time_factor``; 0 = as fast as possible) until
        ``duration`` of sim time, shutdown, or ``stop_requested`` is non-empty (checked before each step: a
        signal handler's list); the executor serves the subscriptions between steps (``executor``: one that
        also serves other nodes of this process, e.g. a scripted driver)."""
        p, sim = self.params, self.sim
        self.stop_requested = stop_requested
        first = self.rovers[0].pose_pub
        while (p["wait_for_subscribers"] > 0 and rclpy.ok() and not stop_requested
               and first.get_subscription_count() < p["wait_for_subscribers"]):
            rclpy.spin_once(self, timeout_sec=0.05)
        if stop_requested:
            return
        self.log.info(f"simulating {sim} ({len(self.rovers)} rover(s)) at real-time factor {p['real_time_factor']}, "
                      f"publishing every {self.every * sim.sim_cfg.step_dt:.3f} s of sim time, mode {p['mode']}")
        self.deadline = p["duration"] if p["duration"] > 0 else math.inf
        self.steps = 0
        self.finished = Future()
        self.publish_state()
        period = sim.sim_cfg.step_dt / p["real_time_factor"] if p["real_time_factor"] > 0 else 0.0
        self.step_timer = self.create_timer(period, self.on_step_timer)
        if executor is None:
            rclpy.spin_until_future_complete(self, self.finished)
        else:
            executor.spin_until_future_complete(self.finished)

    def on_step_timer(self) -> None:
        """One simulator step; state topics every ``publish_rate``, then ``/clock`` (so that a node timed on the
        clock reads this step's sensors); finish at the deadline. ``reset_episode`` requests start first, and
        ``lockstep`` holds the step until a ``/cmd_vel`` has come.

        In ``lockstep``, a replayed episode pairs each step with the controller's answer to the state before it, as
        ``evaluate`` pairs each action with its observation: the reset state comes one period of ``/clock`` after
        the last, so the controller acts on it (its command is the episode's first action); the episode's last
        state goes out without ``/clock`` (nothing is left to act on), and nothing steps until the next
        ``reset_episode``, so a controller given its next goal meanwhile acts first on that episode's reset state."""
        if self.stop_requested:
            self.finish()
            return
        for rover in self.rovers:
            if rover.pending_episode is not None:
                self.start_episode(rover)
                self.holding = False
                self.publish_state()
                self.clock_pub.publish(Clock(clock=_stamp(self.stamp_ns())))
                return
        if self.holding:
            return
        if (self.params["lockstep"] and not self.commanded
                and time.monotonic() - self.published_at < self.params["lockstep_timeout"]):
            return
        if self.sim.sim_time < self.deadline - 1e-9:
            if self.params["lockstep"] and not self.commanded:
                for rover in self.rovers:
                    rover.unanswered += rover.episode is not None
            ended = self.step_once()
            self.steps += 1
            if self.steps % self.every == 0:
                self.publish_state()
            self.holding = ended and self.params["lockstep"]
            if not self.holding:
                self.clock_pub.publish(Clock(clock=_stamp(self.stamp_ns())))
        if self.sim.sim_time >= self.deadline - 1e-9:
            self.finish()

    def finish(self) -> None:
        """End :meth:`spin_simulation`: no more steps."""
        if not self.finished.done():
            self.step_timer.cancel()
            self.finished.set_result(True)

    def close(self) -> None:
        """Close the bag and destroy the node."""
        if self.bag is not None:
            self.bag.close()
        if self.sim is not None:
            self.log.info(f"stopped at sim time {self.sim.sim_time:.2f} s")
        self.destroy_node()
