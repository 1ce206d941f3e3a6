"""The deploy node's parameters (``python -m atrv_warp.deploy --help`` lists them) and their checks; no ROS import.

Every parameter is declared once in :data:`PARAMETERS` with its default, its kind (a topic, a frame, a file, a
switch or a number with its unit and least value) and what it does. :func:`check_parameters` turns the values a
node was given (``-p name:=value`` or a ``--params-file``, as ROS parsed them: ``1`` is an integer there, ``abc`` a
string) into the values it runs with, and refuses a value it cannot run with in one line naming the parameter, what
it needs and what it got.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PARAMETERS", "PARAMETER_BY_NAME", "Parameter", "ParameterError", "check_parameters", "parameter_help",
           "params_files",
           "unknown_parameters"]

KINDS = ("topic", "frame", "file", "name", "robot", "switch", "number")


class ParameterError(ValueError):
    """A parameter value the node cannot run with; the message is one line naming the parameter."""


@dataclass(frozen=True)
class Parameter:
    """One parameter of the deploy node."""

    name: str
    default: str | bool | float
    text: str
    """What it does (the ``--help`` line)."""
    kind: str
    """:data:`KINDS`: ``topic`` (a ROS topic name, relative or absolute), ``frame`` (a tf frame id), ``file`` (a path
    to write, ``''`` = off), ``name`` (a word, ``''`` = none), ``robot`` (a robot's name or its robot file's path,
    ``''`` = none: the node runs with the name), ``switch`` (``true`` | ``false``) or ``number``."""
    unit: str = ""
    """The unit of a number (``m/s``)."""
    positive: bool = False
    """A number must be > 0 (else >= 0)."""
    from_policy: bool = False
    """A number may also be -1: the value the policy was trained with, read from its contract."""

    def check(self, value):
        """``value`` as the node runs with it (an integer number as a float).

        Raises:
            ParameterError: A value of another type, or out of range (one line naming the parameter).
        """
        if self.kind == "switch":
            if not isinstance(value, bool):
                raise self._error("true or false", value)
            return value
        if self.kind == "number":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self._error(f"a number [{self.unit}]", value)
            number = float(value)
            if self.from_policy and number == -1:
                return number
            if not math.isfinite(number) or number < 0 or (self.positive and number == 0):
                policy = ", or -1 (the policy's)" if self.from_policy else ""
                raise self._error(f"a finite number {'>' if self.positive else '>='} 0 [{self.unit}]{policy}", value)
            return number
        if not isinstance(value, str):
            raise self._error("a string", value)
        if self.kind in ("topic", "frame") and not value:
            raise self._error(f"a {self.kind} name (it is empty)", value)
        if self.kind == "frame" and (value.strip() != value or " " in value or value.startswith("/")):
            raise self._error("a tf frame id without spaces or a leading '/' (e.g. odom)", value)
        if self.kind == "robot" and value and (value.endswith(".toml") or "/" in value):
            from atrv_warp.core.robot import RobotFileError, load_robot  # the light core: TOML and the standard library

            try:
                return load_robot(value).name  # a robot file, as the simulator node and every command take one
            except RobotFileError as err:
                raise self._error(f"a robot's name or a robot file that loads ({err})", value) from None
        if self.kind in ("name", "robot") and value and not value.replace("_", "").replace("-", "").isalnum():
            raise self._error("a name of letters, digits, '_' and '-'" + (", or a robot file's path (.toml)"
                                                                           if self.kind == "robot" else ""), value)
        return value

    def _error(self, needs: str, value) -> ParameterError:
        kind = "an integer" if isinstance(value, int) and not isinstance(value, bool) else type(value).__name__
        return ParameterError(f"parameter {self.name} must be {needs}, got {value!r} ({kind}): {self.text}")


PARAMETERS = (
    Parameter("scan_topic", "scan", "sensor_msgs/LaserScan in (any beam count and field of view covering the policy's "
              "sectors)", "topic"),
    Parameter("odom_topic", "odom", "nav_msgs/Odometry in (pose in odom_frame, twist in the base frame)", "topic"),
    Parameter("imu_topic", "imu", "sensor_msgs/Imu in (orientation and angular velocity)", "topic"),
    Parameter("goal_topic", "goal_pose", "geometry_msgs/PoseStamped in: the goal, in odom_frame or any frame /tf joins "
              "to it, e.g. map (RViz's 2D Goal Pose)", "topic"),
    Parameter("cmd_vel_topic", "cmd_vel", "geometry_msgs/Twist (or TwistStamped) out, at the policy's rate", "topic"),
    Parameter("status_topic", "goal_status", "std_msgs/String out: the goal status as JSON (state active | holding | "
              "reached | aborted, reason, goal, distance, steps, clipped_steps, compute_ms)", "topic"),
    Parameter("odom_frame", "odom", "the odometry frame: /odom's header.frame_id, where the policy sees its goal (a "
              "goal in another frame is carried into it through /tf)", "frame"),
    Parameter("base_frame", "base_link", "frame_id of a stamped /cmd_vel", "frame"),
    Parameter("enable_stamped_cmd_vel", False, "publish geometry_msgs/TwistStamped instead of Twist (as Nav2's "
              "parameter)", "switch"),
    Parameter("goal_tolerance", -1.0, "the goal is reached within this distance on the odometry [m]; -1 = the radius "
              "the policy was trained to reach (its contract's reach_radius_m; 1.0 m for a file exported before it "
              "was kept); 0 = never: the next goal ends it", "number", "m", from_policy=True),
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
    """The values a node was given (by name; a missing one takes its default), checked and as the node runs with
    them.

    Raises:
        ParameterError: An unknown name, or a value of the wrong type or out of range (one line naming it).
    """
    unknown = sorted(set(values) - set(PARAMETER_BY_NAME))
    if unknown:
        raise ParameterError(f"unknown parameter(s) {unknown}; known: {sorted(PARAMETER_BY_NAME)}")
    return {p.name: p.check(values.get(p.name, p.default)) for p in PARAMETERS}


def unknown_parameters(args: list[str] | None, params_files: dict[str, list[str]] | None = None) -> list[str]:
    """Names given as ``-p name:=value`` that the node does not declare, and those a ``--params-file`` sets for it
    (``params_files``: each file's parameter names for this node), each with where it came from."""
    args = list(args or [])
    known = set(PARAMETER_BY_NAME) | {"use_sim_time"}
    names = {args[i + 1].split(":=")[0] for i, a in enumerate(args[:-1]) if a in ("-p", "--param")}
    found = sorted(names - known)
    for file, file_names in (params_files or {}).items():
        found += [f"{name} (in {file})" for name in sorted(set(file_names) - known)]
    return found


def params_files(args: list[str] | None) -> list[str]:
    """The files named by ``--params-file FILE`` among a node's ROS arguments."""
    args = list(args or [])
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--params-file"]


def parameter_help() -> str:
    """The node's parameters as ``name (default): description`` lines."""
    return "\n".join(f"    {p.name} ({p.default!r}): {p.text}" for p in PARAMETERS)
