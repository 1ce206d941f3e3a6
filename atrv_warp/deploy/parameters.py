"""The deploy node's parameters (``python -m atrv_warp.deploy --help`` lists them) and their checks; no ROS import.

Every parameter is declared once in :data:`PARAMETERS` with its default, its kind (a topic, a frame, a file, a
switch or a number with its unit and least value) and what it does, in the style both nodes share
(:mod:`atrv_warp.core.parameters`). :func:`check_parameters` turns the values a node was given (``-p name:=value`` or
a ``--params-file``, as ROS parsed them: ``1`` is an integer there, ``abc`` a string) into the values it runs with,
and refuses a value it cannot run with in one line naming the parameter, what it needs and what it got.
"""

from __future__ import annotations

from atrv_warp.core import parameters as core_parameters
from atrv_warp.core.parameters import Parameter, ParameterError, params_files

__all__ = ["PARAMETERS", "PARAMETER_BY_NAME", "ZONE_MOTIONS", "Parameter", "ParameterError", "check_parameters",
           "parameter_help", "params_files", "unknown_parameters"]


ZONE_MOTIONS = ("any", "forward")
"""What ``zone_motion`` takes: the collision monitor's zones act on every command, or on those that drive forward
(:class:`atrv_warp.deploy.safety.CollisionMonitor`)."""

PARAMETERS = (
    Parameter("scan_topic", "scan", "sensor_msgs/LaserScan in (any beam count and field of view covering the policy's "
              "sectors)", "topic"),
    Parameter("odom_topic", "odom", "nav_msgs/Odometry in (pose in odom_frame, twist in the base frame)", "topic"),
    Parameter("imu_topic", "imu", "sensor_msgs/Imu in (orientation and angular velocity)", "topic"),
    Parameter("goal_topic", "goal_pose", "geometry_msgs/PoseStamped in: the goal, in odom_frame or any frame /tf joins "
              "to it, e.g. map (RViz's 2D Goal Pose); not read for a policy that follows a plan (Nav2's FollowPath on "
              "follow_path gives it its paths)", "topic"),
    Parameter("cmd_vel_topic", "cmd_vel", "geometry_msgs/Twist (or TwistStamped) out, at the policy's rate; a policy "
              "that follows a plan publishes on cmd_vel_nav (Nav2's velocity smoother's input) unless this is given",
              "topic"),
    Parameter("status_topic", "goal_status", "std_msgs/String out: the goal status as JSON (state active | holding | "
              "reached | aborted, reason, goal, distance, steps, clipped_steps, compute_ms)", "topic"),
    Parameter("odom_frame", "odom", "the odometry frame: /odom's header.frame_id, where the policy sees its goal (a "
              "goal in another frame is carried into it through /tf)", "frame"),
    Parameter("base_frame", "base_link", "frame_id of a stamped /cmd_vel", "frame"),
    Parameter("enable_stamped_cmd_vel", False, "publish geometry_msgs/TwistStamped instead of Twist (as Nav2's "
              "parameter)", "switch"),
    Parameter("goal_tolerance", -1.0, "the goal is reached within this distance on the odometry [m]; -1 = the radius "
              "the policy was trained to reach (its contract's reach_radius_m; 1.0 m for a file exported before it "
              "was kept); 0 = never: the next goal ends it", "number", "m", minus_one="the policy's"),
    Parameter("max_goal_distance", 0.0, "a goal farther than this from the rover is refused, and stops the rover [m]; "
              "0 = the farthest goal the policy observes (its goal_distance bound)", "number", "m"),
    Parameter("max_linear", 0.0, "clamp |linear.x| to this [m/s]; 0 = the policy's trained limit", "number", "m/s"),
    Parameter("max_angular", 0.0, "clamp |angular.z| to this [rad/s]; 0 = the policy's trained limit", "number",
              "rad/s"),
    Parameter("odom_jump_margin", 0.5, "odometry that moves farther between two messages than the trained speed "
              "allows plus this margin is a jump (an odometry reset): the goal is aborted [m]", "number", "m",
              positive=True),
    Parameter("stale_timeout", 0.5, "stop the rover when a sensor's last message is older than this, in ROS time [s]",
              "number", "s", positive=True),
    Parameter("time_limit", 60.0, "abort a goal not reached in this long, in ROS time [s]; 0 = no limit", "number",
              "s"),
    Parameter("collision_monitor", True, "slow and stop on the scan whatever the policy commands (stop_zone, "
              "slowdown_zone, as Nav2's collision monitor acts); false for a stack that runs Nav2's collision monitor",
              "switch"),
    Parameter("stop_zone", "", "the collision monitor's stop zone in the chassis frame, as Nav2 writes a polygon's "
              "points: \"[[x, y], [x, y], [x, y], ...]\" [m]; min_points scan returns inside it command zero; '' = "
              "none", "text"),
    Parameter("slowdown_zone", "", "its slow-down zone, likewise: min_points returns inside it scale the command by "
              "slowdown_ratio; '' = none", "text"),
    Parameter("slowdown_ratio", 0.5, "the slow-down zone's factor on the command (Nav2's default)", "number", "-",
              positive=True, high=1.0),
    Parameter("min_points", 4, "the least scan returns inside a zone that act (Nav2's default)", "integer", low=1),
    Parameter("zone_motion", "any", "the commands the zones act on: any (Nav2's polygons) | forward (only those that "
              "drive forward, as a Nav2 velocity polygon with the zones for forward motion: turning in place and "
              "backing away pass, so a wall ahead cannot hold the rover for good)", "choice", choices=ZONE_MOTIONS),
    Parameter("robot", "", "this robot: its name, as its robot file names it (atrvjr, jackal, husky, or yours), or "
              "its robot file's path (.toml): a policy trained on another robot is refused at start, naming both; '' "
              "= no check (the node logs the policy's robot either way)", "robot"),
    Parameter("allow_other_robot", False, "run a policy trained on another robot than robot:= on purpose (a study)",
              "switch"),
    Parameter("trace", "", "write every control period here as a JSON line (time, state, sensor stamps, observation, "
              "action, command): to compare the node's inputs with the simulator's step by step; an existing file is "
              "kept and a new name taken; '' = off", "file"),
)
"""Every parameter the node declares (plus ROS's own ``use_sim_time``)."""

PARAMETER_BY_NAME = {p.name: p for p in PARAMETERS}
"""Every :data:`PARAMETERS` entry by its name."""


def check_parameters(values: dict) -> dict:
    """The values the node was given (by name; a missing one takes its default), checked and as the node runs with
    them (:func:`atrv_warp.core.parameters.check_parameters` on :data:`PARAMETERS`).

    Raises:
        ParameterError: An unknown name, or a value of the wrong type or out of range (one line naming it).
    """
    return core_parameters.check_parameters(PARAMETERS, values)


def unknown_parameters(args: list[str] | None, params_files: dict[str, list[str]] | None = None) -> list[str]:
    """Names given as ``-p name:=value`` that the node does not declare, and those a ``--params-file`` sets for it
    (``params_files``: each file's parameter names for this node), each with where it came from."""
    return core_parameters.unknown_parameters(PARAMETER_BY_NAME, args, params_files)


def parameter_help() -> str:
    """The node's parameters as ``name (default): description`` lines."""
    return core_parameters.parameter_help(PARAMETERS)
