"""A Nav2 stack around ``atrv-deploy`` as its controller: ``launch/nav2.launch.py`` and the parameters it writes.

``ros2 launch $(python -m atrv_warp.deploy --launch-files --nav2 jackal) robot:=jackal policy:=$PWD/path.pt2
map:=$PWD/office.yaml`` starts ``atrv-deploy`` first (a ``follow_path`` policy: it serves ``FollowPath`` and publishes
on ``cmd_vel_nav``), then Nav2's ``map_server``, ``amcl`` (``localization:=amcl``; ``static``: a fixed ``map -> odom``;
``none``: yours or a simulator's), ``planner_server`` with its global costmap, a local costmap of its own
(``nav2_costmap_2d``, named ``local_costmap`` in ``local_costmap`` as the controller server would host it: the behaviour
tree clears it by ``local_costmap/clear_entirely_local_costmap`` and the behaviour server reads its ``costmap_raw`` and
footprint), ``behavior_server``, ``bt_navigator`` (its default tree: plan, follow, recover) and ``velocity_smoother``
(``cmd_vel_nav`` in, the robot's command topic out), all brought up by ``lifecycle_manager``, whose ``node_names`` list
Nav2's nodes, not ours (``atrv-deploy`` is no lifecycle node). No Nav2 controller server runs: the policy is the
controller.

:func:`nav2_parameters` writes the parameters: Nav2's own names as Kilted's ``nav2_bringup`` sets them
(:data:`SOURCE`), with the robot's frames and topics (its robot file's ``[deploy]`` table), its footprint (the one the
policy trained with, from the exported file; ``footprint:=`` for an older file), and the velocity smoother's limits at
the speeds and accelerations the policy trained with (read from the exported file's contract: a smoother below them
changes how it drives). ``tests/test_nav2_stack.py`` checks every name against Nav2's. This module imports no ROS;
the launch description's ``launch`` and ``launch_ros`` come with a ROS install. Not run against Nav2 here (no ROS
install on the machines that test it): the docs say so.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from atrv_warp.deploy.launching import LAUNCH, TF_IN_NAMESPACE, robot_parameters

__all__ = ["LIFECYCLE_NODES", "LOCALIZATION", "NAV2_LAUNCH_FILE", "SOURCE", "nav2_launch_description",
           "nav2_parameters", "nav2_params_text", "robot_footprint"]

NAV2_LAUNCH_FILE = LAUNCH / "nav2.launch.py"
SOURCE = "ros-navigation/navigation2@66d37649f0294d6add45662d2405d472b616d022:nav2_bringup/params/nav2_params.yaml"
"""Where the parameters' names and the values not the robot's come from (Kilted's ``nav2_bringup``)."""
LOCALIZATION = ("amcl", "static", "none")
"""``localization:=``: Nav2's AMCL on the map and the scan; a fixed identity ``map -> odom``; none (the simulator
node with a map publishes ``map -> odom`` itself, as does a localisation of yours)."""
LIFECYCLE_NODES = ("map_server", "planner_server", "local_costmap/local_costmap", "behavior_server", "bt_navigator",
                   "velocity_smoother")
"""The nodes ``lifecycle_manager`` brings up (``amcl`` after ``map_server`` with ``localization:=amcl``)."""


def robot_footprint(contract: dict) -> str:
    """The outline of the robot the policy trained on, about its chassis origin, as Nav2 writes a footprint
    (``"[[x, y], ...]"`` [m]): the exported file's ``robot.footprint_m``.

    Raises:
        ValueError: A file exported before the contract kept it: give ``footprint:=`` to the launch.
    """
    points = (contract.get("robot") or {}).get("footprint_m")
    if not (isinstance(points, list) and len(points) >= 3):
        raise ValueError("the policy's file records no footprint (exported before the contract kept one): give the "
                         "launch footprint:=\"[[x, y], ...]\" (Nav2's form, metres about the base frame)")
    return json.dumps(points)


def _contract_limits(contract: dict) -> tuple[float, float, float, float]:
    """(linear [m/s], angular [rad/s], linear acceleration [m/s²], angular acceleration [rad/s²]) the policy trained
    with: its action's scale and its base's limits (the robot's where the task set none)."""
    action = contract.get("action") or {}
    linear, angular = (float(v) for v in action["scale"])
    base = action.get("base_limits") or {}
    limits = (contract.get("robot") or {}).get("limits") or {}
    accel = float((base.get("linear_max_acceleration") or {}).get("value") or limits.get("linear_acceleration") or 2.5)
    alpha = float((base.get("angular_max_acceleration") or {}).get("value") or limits.get("angular_acceleration")
                  or 3.2)
    return linear, angular, accel, alpha


def nav2_parameters(robot: str, policy: str, *, map_yaml: str, footprint: str = "", localization: str = "static",
                    use_sim_time: bool = False) -> dict:
    """Every Nav2 node's parameters, by node (``{"planner_server": {...}, "global_costmap": {"global_costmap":
    {...}}, ...}`` as a ROS 2 parameters file nests them; :data:`SOURCE`'s names), for ``robot`` driven by the
    exported ``policy`` in the map ``map_yaml``.

    Raises:
        ValueError: An unknown ``localization``, a robot without a ``[deploy]`` table, or no footprint to be had.
    """
    if localization not in LOCALIZATION:
        raise ValueError(f"localization must be one of {list(LOCALIZATION)}, got {localization!r}")
    from atrv_warp.deploy.parameters import check_parameters

    p = check_parameters(robot_parameters(robot))  # the robot file's [deploy] values, the node's defaults elsewhere
    from atrv_warp.core.contract import read_exported

    _, contract = read_exported(policy)
    footprint = footprint or robot_footprint(contract)
    linear, angular, accel, alpha = _contract_limits(contract)
    base, odom = p["base_frame"], p["odom_frame"]
    common = {"use_sim_time": use_sim_time}
    scan = {"topic": p["scan_topic"], "data_type": "LaserScan", "marking": True, "clearing": True,
            "obstacle_max_range": 2.5, "obstacle_min_range": 0.0, "raytrace_max_range": 3.0,
            "raytrace_min_range": 0.0, "max_obstacle_height": 2.0}
    inflation = {"plugin": "nav2_costmap_2d::InflationLayer", "cost_scaling_factor": 3.0, "inflation_radius": 0.7}
    obstacles = {"plugin": "nav2_costmap_2d::ObstacleLayer", "enabled": True, "observation_sources": "scan",
                 "scan": scan}
    params = {
        "map_server": common | {"yaml_filename": map_yaml},
        "planner_server": common | {"expected_planner_frequency": 20.0, "planner_plugins": ["GridBased"],
                                    "GridBased": {"plugin": "nav2_navfn_planner::NavfnPlanner", "tolerance": 0.5,
                                                  "use_astar": False, "allow_unknown": True}},
        "global_costmap": {"global_costmap": common | {
            "update_frequency": 1.0, "publish_frequency": 1.0, "global_frame": "map", "robot_base_frame": base,
            "footprint": footprint, "resolution": 0.05, "track_unknown_space": True,
            "plugins": ["static_layer", "obstacle_layer", "inflation_layer"],
            "static_layer": {"plugin": "nav2_costmap_2d::StaticLayer", "map_subscribe_transient_local": True},
            "obstacle_layer": obstacles, "inflation_layer": inflation, "always_send_full_costmap": True}},
        "local_costmap": {"local_costmap": common | {
            "update_frequency": 5.0, "publish_frequency": 2.0, "global_frame": odom, "robot_base_frame": base,
            "rolling_window": True, "width": 3, "height": 3, "resolution": 0.05, "footprint": footprint,
            "plugins": ["obstacle_layer", "inflation_layer"], "obstacle_layer": obstacles,
            "inflation_layer": inflation, "always_send_full_costmap": True}},
        "behavior_server": common | {
            "local_costmap_topic": "local_costmap/costmap_raw", "global_costmap_topic": "global_costmap/costmap_raw",
            "local_footprint_topic": "local_costmap/published_footprint",
            "global_footprint_topic": "global_costmap/published_footprint", "cycle_frequency": 10.0,
            "behavior_plugins": ["spin", "backup", "wait"], "spin": {"plugin": "nav2_behaviors::Spin"},
            "backup": {"plugin": "nav2_behaviors::BackUp"}, "wait": {"plugin": "nav2_behaviors::Wait"},
            "local_frame": odom, "global_frame": "map", "robot_base_frame": base, "transform_tolerance": 0.1,
            "simulate_ahead_time": 2.0, "max_rotational_vel": min(1.0, angular), "min_rotational_vel": 0.4,
            "rotational_acc_lim": min(3.2, alpha), "enable_stamped_cmd_vel": p["enable_stamped_cmd_vel"]},
        "bt_navigator": common | {
            "global_frame": "map", "robot_base_frame": base, "odom_topic": p["odom_topic"], "bt_loop_duration": 10,
            "default_server_timeout": 20, "navigators": ["navigate_to_pose"],
            "navigate_to_pose": {"plugin": "nav2_bt_navigator::NavigateToPoseNavigator"}},
        "velocity_smoother": common | {
            "smoothing_frequency": 20.0, "scale_velocities": False, "feedback": "OPEN_LOOP",
            "max_velocity": [linear, 0.0, angular], "min_velocity": [-linear, 0.0, -angular],
            "max_accel": [accel, 0.0, alpha], "max_decel": [-accel, 0.0, -alpha], "odom_topic": p["odom_topic"],
            "odom_duration": 0.1, "deadband_velocity": [0.0, 0.0, 0.0], "velocity_timeout": 1.0,
            "enable_stamped_cmd_vel": p["enable_stamped_cmd_vel"]},
        "lifecycle_manager": common | {"autostart": True, "node_names": list(_lifecycle_nodes(localization))},
    }
    if localization == "amcl":
        params["amcl"] = common | {"base_frame_id": base, "odom_frame_id": odom, "global_frame_id": "map",
                                   "scan_topic": p["scan_topic"], "robot_model_type":
                                   "nav2_amcl::DifferentialMotionModel", "tf_broadcast": True}
    return params


def _lifecycle_nodes(localization: str) -> tuple[str, ...]:
    return LIFECYCLE_NODES[:1] + (("amcl",) if localization == "amcl" else ()) + LIFECYCLE_NODES[1:]


def nav2_params_text(params: dict) -> str:
    """A ROS 2 parameters file of ``params`` (each node's under ``ros__parameters``; JSON values are YAML)."""
    lines = []

    def node(name: str, values: dict, depth: int) -> None:
        lines.append(f"{'  ' * depth}{name}:")
        lines.append(f"{'  ' * depth}  ros__parameters:")
        emit(values, depth + 2)

    def emit(values: dict, depth: int) -> None:
        for key, value in values.items():
            if isinstance(value, dict):
                lines.append(f"{'  ' * depth}{key}:")
                emit(value, depth + 1)
            else:
                lines.append(f"{'  ' * depth}{key}: {json.dumps(value)}")

    for name, values in params.items():
        if name in ("global_costmap", "local_costmap"):  # the costmap node in its own namespace
            lines.append(f"{name}:")
            node(name, values[name], 1)
        else:
            node(name, values, 0)
    return "\n".join(lines) + "\n"


def nav2_launch_description():
    """The launch description of ``launch/nav2.launch.py`` (arguments read when it runs: an ``OpaqueFunction``)."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    return LaunchDescription([
        DeclareLaunchArgument("robot", description="the robot: a shipped robot's name or a robot file's path with a "
                                                   "[deploy] table"),
        DeclareLaunchArgument("policy", description="the exported follow_path policy (.pt2) trained on that robot"),
        DeclareLaunchArgument("map", description="the Nav2 map (map_server's YAML)"),
        DeclareLaunchArgument("localization", default_value="static", description=" | ".join(LOCALIZATION)),
        DeclareLaunchArgument("footprint", default_value="", description="Nav2's footprint \"[[x, y], ...]\" [m]; "
                                                                         "'' = from the robot's URDF"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="follow /clock (a simulator)"),
        OpaqueFunction(function=_nav2_nodes),
    ])


def _nav2_nodes(context) -> list:
    from launch.actions import ExecuteProcess
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    from atrv_warp.core.robot import load_robot
    from atrv_warp.deploy.launching import params_file
    from atrv_warp.deploy.parameters import check_parameters

    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context)

    robot, policy, localization = arg("robot"), str(Path(arg("policy")).expanduser().resolve()), arg("localization")
    sim_time = arg("use_sim_time").lower() == "true"
    params = nav2_parameters(robot, policy, map_yaml=str(Path(arg("map")).expanduser().resolve()),
                             footprint=arg("footprint"), localization=localization, use_sim_time=sim_time)
    folder = Path(tempfile.mkdtemp(prefix="atrv_nav2_"))
    nav2_file = folder / "nav2_params.yaml"
    nav2_file.write_text(nav2_params_text(params))
    deploy = check_parameters(robot_parameters(robot))
    tf = [("/tf", "tf"), ("/tf_static", "tf_static")] if load_robot(robot).deploy.get(TF_IN_NAMESPACE) else []
    robot_cmd = deploy["cmd_vel_topic"]

    def nav2(package: str, executable: str, name: str, remap=(), namespace: str = "") -> Node:
        return Node(package=package, executable=executable, name=name, namespace=namespace, output="screen",
                    parameters=[str(nav2_file)], remappings=[*tf, *remap])

    nodes = [  # ours first: Nav2's behaviour tree waits for its follow_path server
        ExecuteProcess(cmd=[sys.executable, "-m", "atrv_warp.deploy", policy, "--ros-args", *[
            a for r in tf for a in ("-r", f"{r[0]}:={r[1]}")], "--params-file", str(params_file(robot, folder)),
            "-p", "cmd_vel_topic:=cmd_vel_nav", "-p", f"use_sim_time:={str(sim_time).lower()}"],
            output="screen", name="atrv_deploy", sigterm_timeout="5"),
        nav2("nav2_map_server", "map_server", "map_server"),
        nav2("nav2_planner", "planner_server", "planner_server"),
        nav2("nav2_costmap_2d", "nav2_costmap_2d", "local_costmap", namespace="local_costmap"),
        nav2("nav2_behaviors", "behavior_server", "behavior_server", remap=[("cmd_vel", "cmd_vel_nav")]),
        nav2("nav2_bt_navigator", "bt_navigator", "bt_navigator"),
        nav2("nav2_velocity_smoother", "velocity_smoother", "velocity_smoother",
             remap=[("cmd_vel", "cmd_vel_nav"), ("cmd_vel_smoothed", robot_cmd)]),
        nav2("nav2_lifecycle_manager", "lifecycle_manager", "lifecycle_manager"),
    ]
    if localization == "amcl":
        nodes.append(nav2("nav2_amcl", "amcl", "amcl"))
    elif localization == "static":
        nodes.append(Node(package="tf2_ros", executable="static_transform_publisher", output="screen",
                          arguments=["--frame-id", "map", "--child-frame-id", deploy["odom_frame"]],
                          remappings=tf))
    return nodes
