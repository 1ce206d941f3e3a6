"""The launch description behind ``launch/rover.launch.py`` (``ros2 launch``; ROS 2's ``launch`` and ``launch_ros``
come with a ROS install and are imported only here, when the launch file runs).

It runs ``atrv-deploy`` on the robot ``robot:=`` names (a shipped robot's name or a robot file's path) with the
parameters its robot file's ``[deploy]`` table gives (its topics, frames and command type, relative to the robot's
namespace: :func:`robot_parameters`, written as a parameters file by :func:`params_file`), then ``params_file:=``'s
where given (a file of yours: ``trace``, the speed limits), and optionally RViz with a view made from those
parameters (:func:`rviz_config`: the scan, the odometry's path driven, the policy's command as the arc it drives in
the next second (``command_path``), the goal sent on ``goal_pose``, the frames; the "2D Goal Pose" tool sends goals).
Launch arguments: ``robot``, ``policy`` (the exported ``.pt2``, required), ``namespace`` (the robot's, e.g. a
Clearpath robot's serial ``j100_0123``), ``params_file``, ``use_sim_time``, ``rviz``.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

__all__ = ["LAUNCH", "LAUNCH_FILE", "TF_IN_NAMESPACE", "deploy_robots", "launch_description", "params_file", "robot_parameters",
           "rviz_config"]

LAUNCH = Path(__file__).resolve().parent / "launch"
"""The launch files' folder."""
LAUNCH_FILE = LAUNCH / "rover.launch.py"
"""The one launch file, for every robot (``robot:=NAME|PATH``)."""
TF_IN_NAMESPACE = "tf_in_namespace"
"""The ``[deploy]`` key beside the node's parameters: ``true`` where the robot's stack keeps ``/tf`` and
``/tf_static`` in its namespace (Clearpath's ROS 2 remaps ``/tf`` to ``tf``): the node's and RViz's follow."""


def deploy_robots() -> tuple[str, ...]:
    """The shipped robots whose files say how the node runs on them (a ``[deploy]`` table): the robots folder's."""
    from atrv_warp.core.robot import ROBOTS, load_robot

    return tuple(name for name in ROBOTS if load_robot(name).deploy)


def _robot(robot: str):
    """The robot ``robot`` names, with a ``[deploy]`` table. Raises ``ValueError`` naming what is missing."""
    from atrv_warp.core.robot import load_robot

    found = load_robot(robot)  # RobotFileError (a ValueError): an unknown name, listing the shipped robots
    if not found.deploy:
        raise ValueError(f"robot {robot!r} ({found.path}) has no [deploy] table: its file says nothing of its topics "
                         f"and frames; the shipped ones with one: {', '.join(deploy_robots())} "
                         "(docs/your-own-robot.md)")
    return found


def robot_parameters(robot: str) -> dict:
    """The deploy node's parameters on ``robot`` (a shipped robot's name or a robot file's path): its name and its
    file's ``[deploy]`` table, less ``tf_in_namespace`` (the launch's rule, not the node's), checked as the node checks
    them.

    Raises:
        ValueError: An unknown robot or a file without a ``[deploy]`` table (named); a value the node refuses.
    """
    from atrv_warp.deploy.parameters import ParameterError, check_parameters

    found = _robot(robot)
    given = {"robot": found.name, **{k: v for k, v in found.deploy.items() if k != TF_IN_NAMESPACE}}
    try:
        checked = check_parameters(given)
    except ParameterError as err:
        raise ValueError(f"{found.path}: [deploy]: {err}") from None
    if found.deploy.get(TF_IN_NAMESPACE, False) not in (True, False):  # a robot file error, named: a ValueError
        raise ValueError(f"{found.path}: [deploy]: {TF_IN_NAMESPACE} must be true or false")
    return {name: checked[name] for name in given}


def params_file(robot: str, folder: str | Path | None = None) -> Path:
    """:func:`robot_parameters` as a ROS 2 parameters file (for every node: ``/**``), written in ``folder`` (a new
    temporary one where not given); returns its path."""
    lines = ["/**:", "  ros__parameters:"]
    lines += [f"    {name}: {json.dumps(value)}" for name, value in robot_parameters(robot).items()]  # JSON is YAML
    out = Path(folder or tempfile.mkdtemp(prefix="atrv_deploy_params_")) / "parameters.yaml"
    out.write_text("\n".join(lines) + "\n")
    return out


def rviz_config(robot: str) -> str:
    """An RViz configuration (YAML) for ``robot``, its topics and frames those of :func:`robot_parameters` (the node's
    defaults where its file sets none), relative to RViz's namespace (the launch runs it in the robot's)."""
    from atrv_warp.deploy.parameters import check_parameters

    p = check_parameters(robot_parameters(robot))

    def topic(name: str, reliability: str = "Reliable") -> str:
        return (f"      Topic:\n        Value: {name}\n        Depth: 5\n        History Policy: Keep Last\n"
                f"        Reliability Policy: {reliability}\n        Durability Policy: Volatile\n")

    return (
        "Panels:\n  - Class: rviz_common/Displays\n    Name: Displays\n"
        "Visualization Manager:\n  Class: \"\"\n  Displays:\n"
        "    - Class: rviz_default_plugins/Grid\n      Enabled: true\n      Name: Grid\n"
        "    - Class: rviz_default_plugins/TF\n      Enabled: true\n      Name: Frames\n"
        "    - Class: rviz_default_plugins/LaserScan\n      Enabled: true\n      Name: Scan\n"
        + topic(p["scan_topic"], "Best Effort") +
        "      Size (m): 0.05\n      Style: Flat Squares\n"
        "    - Class: rviz_default_plugins/Odometry\n      Enabled: true\n      Name: Path driven\n"
        + topic(p["odom_topic"], "Best Effort") +
        "      Keep: 3000\n      Position Tolerance: 0.1\n      Angle Tolerance: 0.5\n"
        "    - Class: rviz_default_plugins/Path\n      Enabled: true\n      Name: Command\n"
        + topic("command_path") +
        "      Color: 255; 85; 0\n"
        "    - Class: rviz_default_plugins/Pose\n      Enabled: true\n      Name: Goal\n"
        + topic(p.get("goal_topic", "goal_pose")) +
        "      Shape: Axes\n"
        f"  Global Options:\n    Fixed Frame: {p['odom_frame']}\n"
        "  Tools:\n    - Class: rviz_default_plugins/Interact\n    - Class: rviz_default_plugins/MoveCamera\n"
        "    - Class: rviz_default_plugins/SetGoal\n"
        + topic(p.get("goal_topic", "goal_pose")) +
        "  Views:\n    Current:\n      Class: rviz_default_plugins/TopDownOrtho\n      Name: Current View\n"
        f"      Scale: 60\n      Target Frame: {p['base_frame']}\n"
    )


def launch_description():
    """``atrv-deploy`` on the robot ``robot:=`` names with its parameters, in the robot's namespace; RViz beside it if
    asked. The robot is read when the launch runs (an ``OpaqueFunction``), so that one file serves every robot."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    return LaunchDescription([
        DeclareLaunchArgument("robot", description="the robot: a shipped robot's name (atrvjr, husky, jackal) or a "
                                                   "robot file's path with a [deploy] table"),
        DeclareLaunchArgument("policy", description="the exported policy (.pt2) trained on that robot"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="the robot's namespace (a Clearpath robot's serial, e.g. j100_0123)"),
        DeclareLaunchArgument("params_file", default_value="",
                              description="a parameters file of yours, applied after the robot's (trace, limits)"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="follow /clock (a simulator)"),
        DeclareLaunchArgument("rviz", default_value="false", description="open RViz with the deploy view"),
        OpaqueFunction(function=_nodes),
    ])


def _nodes(context) -> list:
    """The node (and RViz) for the robot the launch's ``robot`` names, once the launch knows it."""
    from launch.actions import ExecuteProcess
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    robot = LaunchConfiguration("robot").perform(context)
    folder = Path(tempfile.mkdtemp(prefix="atrv_deploy_"))
    params = [str(params_file(robot, folder))]
    extra = LaunchConfiguration("params_file").perform(context)
    if extra:
        params.append(str(Path(extra).expanduser().resolve()))
    view = folder / "deploy.rviz"
    view.write_text(rviz_config(robot))
    namespace = LaunchConfiguration("namespace").perform(context).strip("/")
    sim_time, rviz = LaunchConfiguration("use_sim_time"), LaunchConfiguration("rviz")
    tf = ["-r", "/tf:=tf", "-r", "/tf_static:=tf_static"] if _robot(robot).deploy.get(TF_IN_NAMESPACE) else []
    files = [arg for path in params for arg in ("--params-file", path)]
    return [
        ExecuteProcess(cmd=[sys.executable, "-m", "atrv_warp.deploy", LaunchConfiguration("policy"), "--ros-args",
                            "-r", f"__ns:=/{namespace}", *tf, *files, "-p", ["use_sim_time:=", sim_time]],
                       output="screen", name="atrv_deploy", sigterm_timeout="5"),
        Node(package="rviz2", executable="rviz2", arguments=["-d", str(view)],
             namespace=namespace, parameters=[{"use_sim_time": sim_time}], condition=IfCondition(rviz),
             remappings=[("/tf", "tf"), ("/tf_static", "tf_static")] if tf else []),
    ]
