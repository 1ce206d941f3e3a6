"""The rclpy node behind ``python -m atrv_warp.ros`` (imported only where rclpy is installed).

:class:`RoverSimNode` owns one simulated rover, its publishers, subscriptions and optional bag;
:meth:`RoverSimNode.spin_simulation` steps it in (scaled) real time and serves callbacks between
steps. Topics and parameters are listed in :mod:`atrv_warp.ros`.
"""

from __future__ import annotations

import math
import time

import rclpy
import torch
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from atrv_warp.integrations.ros import COMMANDS, GOAL, BagWriter, pose_dict
from atrv_warp.sim.simulator import DriveMode
from atrv_warp.task.env import ATRVjrEnv
from atrv_warp.task.spec import action_to_torque

__all__ = ["PARAMETERS", "NodeConfigError", "RoverSimNode"]

PARAMETERS = (
    ("real_time_factor", 1.0), ("publish_rate", 10.0), ("duration", 0.0), ("mode", "coast"),
    ("variant", "realistic"), ("x", 0.0), ("y", 0.0), ("yaw", 0.0), ("frame_id", ""), ("policy", ""),
    ("bag", ""), ("wait_for_subscribers", 0), ("reach_radius", 1.0))
"""(name, default) of every ROS parameter the node declares."""


class NodeConfigError(ValueError):
    """A parameter value the node cannot run with (already logged by the node)."""


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class RoverSimNode(Node):
    """One simulated ATRV-Jr as a ROS 2 node: ``/pose``, ``/clock``, ``/goal_status`` out;
    ``/command`` and ``/goal`` in.

    Construction declares the parameters; :meth:`setup` checks them (a bad one is logged and
    raises :class:`NodeConfigError`), then builds the simulator, publishers and subscriptions.
    """

    def __init__(self):
        super().__init__("atrv_sim")
        self.params = {name: self.declare_parameter(name, default).value for name, default in PARAMETERS}
        self.log = self.get_logger()
        self.bag: BagWriter | None = None
        self.sim = None

    def setup(self) -> None:
        self._check_parameters()
        self.env = ATRVjrEnv(1, variant=self.params["variant"])  # goal mode reads the policy's observation kernel
        self.sim = self.env.sim
        try:
            self.sim.reset(poses=[[self.params["x"], self.params["y"], self.params["yaw"]]])
        except ValueError as err:
            self._fail(f"parameters x, y, yaw: {err}")
        self.sim.set_mode(self.params["mode"])
        self.every = max(1, round(1.0 / (self.params["publish_rate"] * self.sim.sim_cfg.step_dt)))
        self.frame_id = self.params["frame_id"] or self.sim.description.chassis
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.pose_pub = self.create_publisher(PoseStamped, "/pose", qos)
        self.status_pub = self.create_publisher(String, "/goal_status", 10)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.create_subscription(String, "/command", self.on_command, qos)
        self.create_subscription(PoseStamped, "/goal", self.on_goal, qos)
        self.bag = BagWriter(self.params["bag"]) if self.params["bag"] else None
        self.mode = self.pending = self.params["mode"]
        self.goal: tuple[float, float] | None = None
        self.policy = None

    def _fail(self, message: str):
        self.log.error(message)
        raise NodeConfigError(message)

    def _check_parameters(self) -> None:
        p = self.params
        if p["mode"] not in COMMANDS or p["mode"] == GOAL:
            self._fail(f"parameter mode={p['mode']!r} is not a driving mode; use one of {list(COMMANDS[:-1])}")
        if p["real_time_factor"] < 0 or p["publish_rate"] <= 0:
            self._fail("real_time_factor must be >= 0 and publish_rate > 0")

    # ------------------------------------------------------------------ time and bag
    def stamp_ns(self) -> int:
        """Simulation time [ns]: the stamp of everything the node publishes."""
        return round(self.sim.sim_time * 1e9)

    def record(self, topic: str, type_name: str, message: dict, stamp_ns: int | None = None) -> None:
        if self.bag is not None:
            self.bag.write(topic, type_name, message, self.stamp_ns() if stamp_ns is None else stamp_ns)

    # ------------------------------------------------------------------ subscriptions
    def on_command(self, msg: String) -> None:
        text = msg.data.strip()
        self.record("/command", "std_msgs/msg/String", {"data": msg.data})
        if text not in COMMANDS:
            self.log.warning(f"ignored unknown command {msg.data!r}; known: {list(COMMANDS)}")
            return
        if text == GOAL and self.goal is None:
            self.log.warning("ignored 'goal': no goal received on /goal yet")
            return
        self.pending = text

    def on_goal(self, msg: PoseStamped) -> None:
        g = (msg.pose.position.x, msg.pose.position.y)
        if not all(math.isfinite(v) for v in g):
            self.log.warning(f"ignored non-finite goal {g}")
            return
        self.record("/goal", "geometry_msgs/msg/PoseStamped", pose_dict(msg))
        self.goal = g
        self.pending = GOAL
        self.log.info(f"goal ({g[0]:.2f}, {g[1]:.2f}) received: driving there")

    # ------------------------------------------------------------------ publishing
    def publish_pose(self) -> None:
        p = self.sim.root_pose[0].tolist()
        ns = self.stamp_ns()
        msg = PoseStamped()
        msg.header.stamp = _stamp(ns)
        msg.header.frame_id = self.frame_id
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p[0], p[1], p[2]
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = p[3], p[4], p[5], p[6]
        self.pose_pub.publish(msg)
        self.record("/pose", "geometry_msgs/msg/PoseStamped", pose_dict(msg), ns)

    def publish_status(self, text: str) -> None:
        self.status_pub.publish(String(data=text))
        self.record("/goal_status", "std_msgs/msg/String", {"data": text})

    # ------------------------------------------------------------------ driving
    def goal_action(self) -> tuple[torch.Tensor, float]:
        """Wheel torques the policy chooses toward the goal, and the distance to it [m]."""
        if self.policy is None:
            from tensordict import TensorDict

            from atrv_warp.rl.agents import load_policy

            self.policy = (load_policy(self.params["policy"] or None), TensorDict)
        policy, td_cls = self.policy
        obs = self.env.observe(torch.tensor([self.goal]))
        dist = float(self.env.target_distance[0])
        action = policy(td_cls(observation=obs, batch_size=[1]))["action"]
        return action_to_torque(action[0], self.env.task_cfg.action_scale), dist

    def step_once(self) -> float | None:
        """Apply a pending mode, drive (goal mode: the policy), step; returns the goal distance."""
        if self.pending != self.mode:
            self.mode = self.pending
            self.log.info(f"mode -> {self.mode}")
            if self.mode != GOAL:
                self.sim.set_mode(self.mode)
        dist = None
        if self.mode == GOAL:
            torques, dist = self.goal_action()
            if dist < self.params["reach_radius"]:
                self.publish_status("reached")
                self.log.info("goal reached")
                self.mode = self.pending = DriveMode.COAST.value
                self.sim.set_mode(DriveMode.COAST)
            else:
                self.sim.set_commands(torques)
        self.sim.step()
        self.clock_pub.publish(Clock(clock=_stamp(self.stamp_ns())))
        return dist

    def spin_simulation(self) -> None:
        """Step until ``duration`` of sim time (or shutdown), serving callbacks between steps."""
        p, sim = self.params, self.sim
        deadline = p["duration"] if p["duration"] > 0 else math.inf
        while p["wait_for_subscribers"] > 0 and rclpy.ok() \
                and self.pose_pub.get_subscription_count() < p["wait_for_subscribers"]:
            rclpy.spin_once(self, timeout_sec=0.05)
        self.log.info(f"simulating {sim} at real-time factor {p['real_time_factor']}, publishing /pose every "
                      f"{self.every * sim.sim_cfg.step_dt:.3f} s of sim time, mode {self.mode}")
        step, wall0 = 0, time.monotonic()
        self.publish_pose()
        while rclpy.ok() and sim.sim_time < deadline - 1e-9:
            rclpy.spin_once(self, timeout_sec=0.0)
            dist = self.step_once()
            step += 1
            if step % self.every == 0:
                self.publish_pose()
                if dist is not None and self.mode == GOAL:
                    self.publish_status(f"distance={dist:.3f}")
            if p["real_time_factor"] > 0:
                ahead = sim.sim_time / p["real_time_factor"] - (time.monotonic() - wall0)
                if ahead > 0:
                    rclpy.spin_once(self, timeout_sec=ahead)

    def close(self) -> None:
        """Close the bag and destroy the node."""
        if self.bag is not None:
            self.bag.close()
        if self.sim is not None:
            self.log.info(f"stopped at sim time {self.sim.sim_time:.2f} s")
        self.destroy_node()
