"""The deploy node's parameters (``python -m atrv_warp.deploy --help`` lists them); no ROS import."""

from __future__ import annotations

__all__ = ["PARAMETERS", "parameter_help", "unknown_parameters"]

PARAMETERS = (
    ("scan_topic", "scan", "sensor_msgs/LaserScan in (any beam count and field of view covering the policy's sectors)"),
    ("odom_topic", "odom", "nav_msgs/Odometry in (pose in odom_frame, twist in the base frame)"),
    ("imu_topic", "imu", "sensor_msgs/Imu in (orientation and angular velocity)"),
    ("goal_topic", "goal_pose", "geometry_msgs/PoseStamped in: the goal, in odom_frame (RViz's 2D Goal Pose)"),
    ("cmd_vel_topic", "cmd_vel", "geometry_msgs/Twist (or TwistStamped) out, at the policy's rate"),
    ("status_topic", "goal_status", ("std_msgs/String out: the goal status as JSON (state active | holding | reached "
                                     "| aborted, reason, goal, distance, steps, clipped_steps, compute_ms)")),
    ("odom_frame", "odom", "the odometry frame: /odom's header.frame_id, and the frame goals must be in"),
    ("base_frame", "base_link", "frame_id of a stamped /cmd_vel"),
    ("enable_stamped_cmd_vel", False, "publish geometry_msgs/TwistStamped instead of Twist (as Nav2's parameter)"),
    ("goal_tolerance", 1.0, ("the goal is reached within this distance on the odometry [m] (the nav tasks' radius); "
                             "0 = never: the next goal ends it")),
    ("max_linear", 0.0, "clamp |linear.x| to this [m/s]; 0 = the policy's trained limit"),
    ("max_angular", 0.0, "clamp |angular.z| to this [rad/s]; 0 = the policy's trained limit"),
    ("stale_timeout", 0.5, "stop the rover when a sensor's last message is older than this, in ROS time [s]"),
    ("time_limit", 60.0, "abort a goal not reached in this long, in ROS time [s]; 0 = no limit"),
    ("trace", "", ("write every control period here as a JSON line (time, state, sensor stamps, observation, action, "
                   "command): to compare the node's inputs with the simulator's step by step; '' = off")),
)
"""(name, default, description) of every parameter the node declares (plus ROS's own ``use_sim_time``)."""


def unknown_parameters(args: list[str] | None) -> list[str]:
    """Names given as ``-p name:=value`` that the node does not declare."""
    args = list(args or [])
    known = {name for name, _, _ in PARAMETERS} | {"use_sim_time"}
    names = [args[i + 1].split(":=")[0] for i, a in enumerate(args[:-1]) if a in ("-p", "--param")]
    return sorted(set(names) - known)


def parameter_help() -> str:
    """The node's parameters as ``name (default): description`` lines."""
    return "\n".join(f"    {name} ({default!r}): {text}" for name, default, text in PARAMETERS)
