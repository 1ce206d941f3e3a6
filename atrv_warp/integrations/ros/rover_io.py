"""One simulated rover's ROS 2 side in the simulator node: its topics, its driving mode, and the messages it
publishes from the simulator's state (odometry, joint states, IMU, scan, /tf), each under ``/rover_<k>`` when the
node simulates more than one. :class:`~atrv_warp.integrations.ros.node.RoverSimNode` holds one per rover and steps
them.
"""

from __future__ import annotations

import collections
import itertools
import json
import math

import numpy as np
import torch
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Imu, JointState, LaserScan
from std_msgs.msg import Int32, String

from atrv_warp.core.geometry import wrap_angle, yaw_to_quat
from atrv_warp.integrations.ros.bag import joint_state_dict, odometry_dict, pose_dict, twist_dict
from atrv_warp.integrations.ros.base import imu_reading
from atrv_warp.integrations.ros.frames import planar_matrix, pose_matrix, transform_dict, turn_matrix
from atrv_warp.integrations.ros.parameters import COMMANDS, GOAL, VELOCITY
from atrv_warp.sim.modes import DRIVE_MODE_TORQUES, DriveMode

__all__ = ["RoverIO", "plan_message", "ros_time", "step_time_ns"]

# Diagonal covariances of the wheel odometry (x, y, z, roll, pitch, yaw); z and the tilts are not
# observed by wheel odometry, so they are marked as unknown with a large variance.
_ODOM_POSE_VAR = (0.01, 0.01, 1e6, 1e6, 1e6, 0.05)
_ODOM_TWIST_VAR = (0.01, 0.01, 1e6, 1e6, 1e6, 0.05)


def ros_time(ns: int) -> Time:
    """A time [ns] as a ``builtin_interfaces/Time`` (a message's stamp)."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def step_time_ns(sim_time: float, step_dt: float) -> int:
    """The simulation time [s], a whole number of steps of ``step_dt`` [s], in nanoseconds: that number of steps
    times the step's nanoseconds, exact. ``round(sim_time * 1e9)`` is not: ``sim_time`` sums ``step_dt`` in
    float64, and after 14,796 steps of 0.2 s it rounds to 1 ns short of the step, so a controller's timer due at the
    step (rclpy's, on ``/clock``) missed it: in lockstep the step waited out ``lockstep_timeout`` unanswered."""
    return round(sim_time / step_dt) * round(step_dt * 1e9)


def plan_message(points: list[list[float]], goal_yaw: float, frame: str, stamp: Time | None = None) -> Path:
    """A plan (x, y) [m], start to goal, as a ``nav_msgs/Path`` in ``frame``: each pose facing the next, the last the
    goal's heading ``goal_yaw`` [rad] (what Nav2's planners hand its controller); no points, no poses (no plan was
    found)."""
    msg = Path()
    msg.header.frame_id = frame
    if stamp is not None:
        msg.header.stamp = stamp
    yaws = [math.atan2(b[1] - a[1], b[0] - a[0]) for a, b in itertools.pairwise(points)] + [goal_yaw]
    for (x, y), yaw in zip(points, yaws[len(yaws) - len(points):], strict=True):
        pose = PoseStamped()
        pose.header = msg.header
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.z, pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        msg.poses.append(pose)
    return msg


class RoverIO:
    """One rover's topics and driving mode; its base's motor driver and wheel odometry run in the simulator
    (:attr:`atrv_warp.sim.RoverSim.driver`)."""

    def __init__(self, node: Node, index: int, prefix: str, qos: QoSProfile):
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
        self.plan_pub = node.create_publisher(Path, f"{prefix}/plan", qos) if node.env.planner is not None else None
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
                                  f"(nav_deploy, follow_path) and an episode index >= 0 "
                                  f"(here {len(self.node.rovers)} rover(s), "
                                  f"task action {task.action!r})")
            return
        self.pending_episode = msg.data

    def publish_episode(self, event: dict) -> None:
        self.episode_pub.publish(String(data=json.dumps(event)))

    def publish_plan(self, ns: int) -> None:
        """The replayed episode's plan as the environment has it now (its start, every replan), as Nav2's planner
        server publishes one on ``plan`` (:func:`plan_message`, in the world's frame, ``map``): what a ``FollowPath``
        client hands the controller."""
        env, k = self.node.env, self.index
        self.plan_pub.publish(plan_message(env.planner.points(k).tolist(), float(env.target_yaw[k]),
                                           self.node.world_frame, ros_time(ns)))

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
        msg.header.stamp = ros_time(ns)
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
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = ros_time(ns), self.tf_odom, self.tf_base
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
        truth.header.stamp, truth.header.frame_id, truth.child_frame_id = ros_time(ns), node.world_frame, self.tf_base
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
        """This rover's /tf, live (where tf2_msgs loads) and to the bag: world -> odom (unless ``map_to_odom`` is
        off) -> base_link (the odometry ``tf_odometry`` names, corrected to the true pose) and the turning wheels (:mod:`.frames`). A non-finite pose is never
        published: the rover's /tf is left out for the step, with one line logged."""
        node = self.node
        if node.bag is None and node.tf_pub is None:
            return
        fused = node.params["tf_odometry"] == "odometry/filtered"
        (x, y, yaw, _, _), wheels = self.odometry(fused=fused), node.wheel_positions(self.index)
        if not all(math.isfinite(v) for v in (*pose, x, y, yaw, *wheels)):
            if not self.tf_skipped:
                node.log.warning(f"{self.prefix or 'rover'}: non-finite pose, its /tf is not published until it "
                                 "is finite again")
            self.tf_skipped = True
            return
        self.tf_skipped = False
        world_base, odom_base = pose_matrix(pose[:3], pose[3:7]), planar_matrix(x, y, yaw)
        transforms = [transform_dict(node.world_frame, self.tf_odom, ns, world_base @ np.linalg.inv(odom_base))]
        transforms = transforms if node.params["map_to_odom"] else []  # else the stack's localisation's
        transforms.append(transform_dict(self.tf_odom, self.tf_base, ns, odom_base))
        transforms += [transform_dict(self.tf_chassis, self.tf_prefix + w.link, ns,
                                      np.asarray(w.origin, dtype=float) @ turn_matrix(w.axis, q))
                       for w, q in zip(node.sim.description.wheels, wheels)]
        node.record("/tf", "tf2_msgs/msg/TFMessage", {"transforms": transforms}, ns)
        if node.tf_pub is not None:
            node.tf_pub.publish(node.tf_message(transforms))

    def publish_joints(self, ns: int) -> None:
        node, k = self.node, self.index
        msg = JointState()
        msg.header.stamp = ros_time(ns)
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
        msg.header.stamp, msg.header.frame_id = ros_time(ns), self.tf_prefix + scanner.frame
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
        msg.header.stamp, msg.header.frame_id = ros_time(ns), self.tf_prefix + node.imu_frame
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
