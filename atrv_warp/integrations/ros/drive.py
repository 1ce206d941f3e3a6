"""A scripted drive over ROS 2, for calibration bags: :class:`ExcitationDriver` publishes
:class:`~atrv_warp.sim.sysid.excitation.Excitation`'s seeded random velocity commands on
``/cmd_vel`` (runs, arcs, turns in place, stops), steering back toward the start when the rover strays, and
:func:`record_drive_bag` runs it against the simulator node, which records the bag. Imported only where rclpy is installed (``pip install -e '.[ros]'``).
"""

from __future__ import annotations

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from atrv_warp.core.geometry import quat_to_yaw
from atrv_warp.sim.sysid.excitation import Excitation

__all__ = ["ExcitationDriver", "record_drive_bag"]


class ExcitationDriver(Node):
    """:class:`~atrv_warp.sim.sysid.excitation.Excitation`'s commands on ``/cmd_vel``, timed by
    ``/clock`` (sim time) and steering home from ``/ground_truth/odom``."""

    def __init__(self, seed: int = 0, radius: float = 8.0, max_linear: float = 1.2, max_angular: float = 1.2):
        super().__init__("atrv_excitation_driver")
        self.excitation = Excitation(seed, radius, max_linear, max_angular)
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(Clock, "/clock", self.on_clock, 10)
        self.create_subscription(Odometry, "/ground_truth/odom", self.on_pose, 10)
        self.pose = (0.0, 0.0, 0.0)

    def on_pose(self, msg: Odometry) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        self.pose = (p.x, p.y, float(quat_to_yaw((q.x, q.y, q.z, q.w))))

    def on_clock(self, msg: Clock) -> None:
        command = self.excitation.update(msg.clock.sec + 1e-9 * msg.clock.nanosec, self.pose)
        if command is not None:
            t = Twist()
            t.linear.x, t.angular.z = command
            self.pub.publish(t)


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
