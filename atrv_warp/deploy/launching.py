"""The launch description behind each robot's ``launch/<robot>.launch.py`` (``ros2 launch``; ROS 2's ``launch`` and
``launch_ros`` come with a ROS install and are imported only here, when a launch file runs).

It runs ``atrv-deploy`` with the robot's parameters file (``config/<robot>.yaml``: its topics, frames and command
type, relative to the robot's namespace) and optionally RViz with a view made from that file (:func:`rviz_config`:
the scan, the odometry's path driven, the policy's command as the arc it drives in the next second
(``command_path``), the goal sent on ``goal_pose``, the frames; the "2D Goal Pose" tool sends goals). Launch arguments:
``policy`` (the exported ``.pt2``, required), ``namespace`` (the robot's, e.g. a Clearpath robot's serial
``j100_0123``), ``use_sim_time``, ``rviz``.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["CONFIG", "LAUNCH", "NAMESPACED_TF", "ROBOTS", "launch_description", "params_file", "robot_parameters",
           "rviz_config"]

CONFIG = Path(__file__).resolve().parent / "config"
"""The parameters files and the RViz configuration."""
LAUNCH = Path(__file__).resolve().parent / "launch"
"""One launch file per shipped robot."""
ROBOTS = ("atrvjr", "husky", "jackal")
"""The robots a launch file ships for."""
NAMESPACED_TF = ("husky", "jackal")
"""Robots whose stack keeps ``tf`` and ``tf_static`` in the robot's namespace (Clearpath's ROS 2 remaps ``/tf`` to
``tf``): the node's and RViz's ``/tf`` are remapped to them."""


def params_file(robot: str) -> Path:
    """The parameters file of ``robot`` (one of :data:`ROBOTS`). Raises ``ValueError`` naming the known ones."""
    if robot not in ROBOTS:
        raise ValueError(f"no launch configuration for robot {robot!r}; shipped: {', '.join(ROBOTS)}")
    return CONFIG / f"{robot}.yaml"


def robot_parameters(robot: str) -> dict:
    """The parameters in ``robot``'s parameters file, as Python values (read as rclpy reads a ``--params-file``)."""
    from rclpy.parameter import parameter_dict_from_yaml_file, parameter_value_to_python

    found = parameter_dict_from_yaml_file(str(params_file(robot)), use_wildcard=True)
    return {name: parameter_value_to_python(p.value) for name, p in found.items()}


def rviz_config(robot: str) -> str:
    """An RViz configuration (YAML) for ``robot``, its topics and frames read from its parameters file, relative to
    RViz's namespace (the launch runs it in the robot's)."""
    p = robot_parameters(robot)

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


def launch_description(robot: str):
    """``atrv-deploy`` for ``robot`` with its parameters file, in the robot's namespace; RViz beside it if asked."""
    import tempfile

    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, ExecuteProcess
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration, PythonExpression
    from launch_ros.actions import Node

    params = params_file(robot)
    view = Path(tempfile.mkdtemp(prefix="atrv_deploy_rviz_")) / f"{robot}.rviz"
    view.write_text(rviz_config(robot))
    policy, namespace = LaunchConfiguration("policy"), LaunchConfiguration("namespace")
    sim_time, rviz = LaunchConfiguration("use_sim_time"), LaunchConfiguration("rviz")
    ns = PythonExpression(["'/' + '", namespace, "'.strip('/')"])
    tf = ["-r", "/tf:=tf", "-r", "/tf_static:=tf_static"] if robot in NAMESPACED_TF else []
    return LaunchDescription([
        DeclareLaunchArgument("policy", description=f"the exported policy (.pt2) trained on {robot}"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="the robot's namespace (a Clearpath robot's serial, e.g. j100_0123)"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="follow /clock (a simulator)"),
        DeclareLaunchArgument("rviz", default_value="false", description="open RViz with the deploy view"),
        ExecuteProcess(cmd=[sys.executable, "-m", "atrv_warp.deploy", policy, "--ros-args", "-r",
                            ["__ns:=", ns], *tf, "--params-file", str(params), "-p", ["use_sim_time:=", sim_time]],
                       output="screen", name="atrv_deploy", sigterm_timeout="5"),
        Node(package="rviz2", executable="rviz2", arguments=["-d", str(view)],
             namespace=namespace, parameters=[{"use_sim_time": sim_time}], condition=IfCondition(rviz),
             remappings=[("/tf", "tf"), ("/tf_static", "tf_static")] if tf else []),
    ])
