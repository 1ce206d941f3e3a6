"""A scripted drive over ROS 2, for calibration bags: :class:`ExcitationDriver` publishes seeded random
velocity commands on ``/cmd_vel`` (runs, arcs, turns in place, stops), steering back toward the start
when the rover strays, and :func:`record_drive_bag` runs it against the simulator node, which records the
bag. Imported only where rclpy is installed (``pip install -e '.[ros]'``).
"""

from __future__ import annotations

import math

import numpy as np
import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from atrv_warp.core.geometry import quat_to_yaw, wrap_angle

__all__ = ["ExcitationDriver", "record_drive_bag"]


class ExcitationDriver(Node):
    """Random velocity commands, each held 0.8-2.5 s of sim time and re-sent at 10 Hz (the base's watchdog
    wants them), drawn from ``seed``; beyond ``radius`` [m] from the start it drives back.

    Half the changes are steps, which saturate the motors (the motor's strength, and the friction where the tyres
    slide); the other half are ramps at 0.5-2 m/s² (and as many rad/s² per m/s of the limits' ratio), as a
    joystick or a base's acceleration limit gives: a driver that tracks its wheel speeds tightly then needs the
    torque that the rover's mass takes, which the wheel efforts record."""

    def __init__(self, seed: int = 0, radius: float = 8.0, max_linear: float = 1.2, max_angular: float = 1.2):
        super().__init__("atrv_excitation_driver")
        self.rng = np.random.default_rng(seed)
        self.radius, self.max_linear, self.max_angular = radius, max_linear, max_angular
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(Clock, "/clock", self.on_clock, 10)
        self.create_subscription(Odometry, "/ground_truth/odom", self.on_pose, 10)
        self.pose = (0.0, 0.0, 0.0)
        self.command = (0.0, 0.0)
        self.target = (0.0, 0.0)
        self.rate = math.inf
        """The ramp's rate toward ``target`` [m/s²] (``inf``: a step)."""
        self.last = 0.0
        self.next_change = 0.0
        self.next_send = 0.0

    def on_pose(self, msg: Odometry) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        self.pose = (p.x, p.y, float(quat_to_yaw((q.x, q.y, q.z, q.w))))

    def draw(self) -> tuple[float, float]:
        x, y, yaw = self.pose
        if math.hypot(x, y) > self.radius:  # head home: turn toward the start while rolling
            error = float(wrap_angle(math.atan2(-y, -x) - yaw))
            return (0.3 if abs(error) > 1.0 else 0.8), max(-1.0, min(1.0, 1.5 * error))
        kind = self.rng.random()
        if kind < 0.12:
            return 0.0, 0.0
        if kind < 0.32:
            return 0.0, float(self.rng.choice([-1, 1]) * self.rng.uniform(0.4, self.max_angular))
        return (float(self.rng.uniform(-0.5 * self.max_linear, self.max_linear)),
                float(self.rng.uniform(-self.max_angular, self.max_angular)))

    def on_clock(self, msg: Clock) -> None:
        now = msg.clock.sec + 1e-9 * msg.clock.nanosec
        if now >= self.next_change:
            self.target = self.draw()
            self.rate = math.inf if self.rng.random() < 0.5 else float(self.rng.uniform(0.5, 2.0))
            self.next_change = now + float(self.rng.uniform(0.8, 2.5))
            self.next_send = now
        dt, self.last = max(now - self.last, 0.0), now
        if math.isinf(self.rate):
            self.command = self.target
        else:
            step = (self.rate * dt, self.rate * dt * self.max_angular / self.max_linear)
            self.command = tuple(c + max(-d, min(d, t - c)) for c, t, d in zip(self.command, self.target, step))
        if now >= self.next_send - 1e-9:
            t = Twist()
            t.linear.x, t.angular.z = self.command
            self.pub.publish(t)
            self.next_send = now + 0.1


def record_drive_bag(path: str, minutes: float = 5.0, *, seed: int = 0, parameters: dict | None = None) -> str:
    """Drive one simulated rover with :class:`ExcitationDriver` for ``minutes`` of sim time, as fast as the
    machine allows, and record the simulator node's MCAP bag at ``path``. ``parameters``: more node
    parameters (``sim_config``, ``truth_noise``, ``wheel_speed_noise`` …). Returns ``path``."""
    from atrv_warp.integrations.ros.node import NodeConfigError, RoverSimNode

    values = {"bag": str(path), "duration": 60.0 * minutes, "real_time_factor": 0.0, "publish_rate": 20.0,
              "scan_beams": 0, "seed": seed, **(parameters or {})}
    args = ["--ros-args"] + [a for k, v in values.items() for a in ("-p", f"{k}:={v}")]
    rclpy.init(args=args)
    sim = RoverSimNode(args)
    driver = ExcitationDriver(seed)
    executor = SingleThreadedExecutor()
    try:
        sim.setup()
        executor.add_node(sim)
        executor.add_node(driver)
        sim.spin_simulation(executor)
    except NodeConfigError as err:
        raise ValueError(str(err)) from None
    finally:
        executor.shutdown()
        driver.destroy_node()
        sim.close()
        rclpy.try_shutdown()
    return str(path)
