"""The Nav2 stack launched around ``atrv-deploy`` (``deploy/launch/nav2.launch.py``, :mod:`atrv_warp.deploy.nav2_stack`):
every parameter it writes is one Nav2 documents for that node, the lifecycle manager brings up Nav2's nodes and not
ours, the velocity smoother passes what the policy trained with, and our node's own parameters are its own. Nothing
here runs Nav2 (no ROS install on the machines that test it): the names are checked against Nav2's."""

from __future__ import annotations

import json

import pytest
import yaml

from atrv_warp.deploy.nav2_stack import (
    LIFECYCLE_NODES,
    NAV2_LAUNCH_FILE,
    nav2_parameters,
    nav2_params_text,
)
from atrv_warp.deploy.parameters import PARAMETER_BY_NAME

# Nav2's names, node by node, as Kilted's nav2_bringup sets them
# (ros-navigation/navigation2@66d37649f0294d6add45662d2405d472b616d022:nav2_bringup/params/nav2_params.yaml), plus those
# its nodes declare that the file leaves at their defaults: map_server's yaml_filename (map_server.cpp), the costmaps'
# footprint (costmap_2d_ros.cpp), the lifecycle manager's autostart and node_names (lifecycle_manager.cpp),
# enable_stamped_cmd_vel (nav2_util/twist_publisher.hpp), all at the Kilted branch; use_sim_time is ROS's own.
NAV2 = {
    "map_server": {"yaml_filename", "topic_name", "frame_id", "service_introspection_mode"},
    "amcl": {"alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "base_frame_id", "beam_skip_distance",
             "beam_skip_error_threshold", "beam_skip_threshold", "do_beamskip", "global_frame_id", "lambda_short",
             "laser_likelihood_max_dist", "laser_max_range", "laser_min_range", "laser_model_type", "max_beams",
             "max_particles", "min_particles", "odom_frame_id", "pf_err", "pf_z", "recovery_alpha_fast",
             "recovery_alpha_slow", "resample_interval", "robot_model_type", "save_pose_rate", "scan_topic",
             "service_introspection_mode", "sigma_hit", "tf_broadcast", "transform_tolerance", "update_min_a",
             "update_min_d", "z_hit", "z_max", "z_rand", "z_short"},
    "bt_navigator": {"bt_loop_duration", "default_server_timeout", "error_code_name_prefixes", "filter_duration",
                     "global_frame", "navigate_through_poses.enable_groot_monitoring",
                     "navigate_through_poses.groot_server_port", "navigate_through_poses.plugin",
                     "navigate_to_pose.enable_groot_monitoring", "navigate_to_pose.groot_server_port",
                     "navigate_to_pose.plugin", "navigators", "odom_topic", "robot_base_frame",
                     "service_introspection_mode", "wait_for_service_timeout"},
    "planner_server": {"GridBased.allow_unknown", "GridBased.plugin", "GridBased.tolerance", "GridBased.use_astar",
                       "costmap_update_timeout", "expected_planner_frequency", "planner_plugins",
                       "service_introspection_mode"},
    "behavior_server": {"assisted_teleop.plugin", "backup.acceleration_limit", "backup.deceleration_limit",
                        "backup.minimum_speed", "backup.plugin", "behavior_plugins", "cycle_frequency",
                        "drive_on_heading.acceleration_limit", "drive_on_heading.deceleration_limit",
                        "drive_on_heading.minimum_speed", "drive_on_heading.plugin", "global_costmap_topic",
                        "global_footprint_topic", "global_frame", "local_costmap_topic", "local_footprint_topic",
                        "local_frame", "max_rotational_vel", "min_rotational_vel", "robot_base_frame",
                        "rotational_acc_lim", "simulate_ahead_time", "spin.plugin", "transform_tolerance",
                        "wait.plugin", "enable_stamped_cmd_vel"},
    "velocity_smoother": {"deadband_velocity", "feedback", "max_accel", "max_decel", "max_velocity", "min_velocity",
                          "odom_duration", "odom_topic", "scale_velocities", "smoothing_frequency",
                          "velocity_timeout", "enable_stamped_cmd_vel"},
    "lifecycle_manager": {"autostart", "node_names", "bond_timeout", "service_timeout",
                          "attempt_respawn_reconnection", "bond_respawn_max_duration"},
}
COSTMAP = {"always_send_full_costmap", "filters", "global_frame", "height", "plugins", "publish_frequency",
           "resolution", "robot_base_frame", "robot_radius", "rolling_window", "service_introspection_mode",
           "track_unknown_space", "update_frequency", "width", "footprint"}
"""A costmap's own names (both costmaps' in the file)."""
LAYERS = {
    "nav2_costmap_2d::ObstacleLayer": {"enabled", "observation_sources", "plugin", "scan.clearing", "scan.data_type",
                                       "scan.marking", "scan.max_obstacle_height", "scan.obstacle_max_range",
                                       "scan.obstacle_min_range", "scan.raytrace_max_range",
                                       "scan.raytrace_min_range", "scan.topic"},
    "nav2_costmap_2d::InflationLayer": {"cost_scaling_factor", "inflation_radius", "plugin"},
    "nav2_costmap_2d::StaticLayer": {"map_subscribe_transient_local", "plugin"},
}
"""Each layer plugin's names, as the file sets them for a layer of that plugin (whatever the layer is called)."""


def flat(values: dict, prefix: str = "") -> set[str]:
    out = set()
    for key, value in values.items():
        out |= flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}"}
    return out


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    from atrv_warp.rl.export import export_policy

    return str(export_policy("follow_path_jackal", tmp_path_factory.mktemp("nav2") / "path.pt2"))


@pytest.mark.parametrize("localization", ["static", "amcl", "none"])
def test_every_parameter_is_one_nav2_documents_and_the_smoother_passes_the_trained_limits(policy, localization):
    params = nav2_parameters("jackal", policy, map_yaml="/maps/office.yaml", localization=localization,
                             use_sim_time=True)
    for node, values in params.items():
        if node in ("global_costmap", "local_costmap"):
            costmap = values[node]
            layers = {name: costmap[name] for name in costmap["plugins"]}
            own = flat({k: v for k, v in costmap.items() if k not in layers}) - {"use_sim_time"}
            assert own <= COSTMAP, (node, own - COSTMAP)
            for name, layer in layers.items():
                assert flat(layer) <= LAYERS[layer["plugin"]], (node, name, flat(layer) - LAYERS[layer["plugin"]])
        else:
            names = flat(values) - {"use_sim_time"}
            assert names <= NAV2[node], (node, names - NAV2[node])
    assert ("amcl" in params) == (localization == "amcl")
    managed = params["lifecycle_manager"]["node_names"]
    assert "atrv_deploy" not in managed and set(LIFECYCLE_NODES) <= set(managed)
    assert set(managed) - {"local_costmap/local_costmap"} <= set(params)  # each managed node has its parameters
    smoother = params["velocity_smoother"]
    from atrv_warp.core.contract import read_exported

    scale = read_exported(policy)[1]["action"]["scale"]
    assert smoother["max_velocity"] == [scale[0], 0.0, scale[1]] and smoother["min_velocity"][0] == -scale[0]
    footprint = json.loads(params["local_costmap"]["local_costmap"]["footprint"])
    assert len(footprint) == 4 and max(x for x, _ in footprint) > 0.2  # the Jackal's outline, about 0.5 m long
    parsed = yaml.safe_load(nav2_params_text(params))  # the file the launch writes reads back as the parameters
    assert parsed["local_costmap"]["local_costmap"]["ros__parameters"] == params["local_costmap"]["local_costmap"]
    assert parsed["velocity_smoother"]["ros__parameters"] == smoother


def test_the_launch_runs_our_node_as_the_controller_and_names_its_parameters_as_ours():
    text = NAV2_LAUNCH_FILE.read_text()
    assert "def generate_launch_description():" in text and "nav2_launch_description" in text
    source = (NAV2_LAUNCH_FILE.parents[1] / "nav2_stack.py").read_text()
    for name in ("cmd_vel_topic", "use_sim_time"):  # what the launch sets on our node with -p
        assert f'"{name}:=' in source or f'"-p", f"{name}:=' in source
        assert name == "use_sim_time" or name in PARAMETER_BY_NAME
    assert "controller_server" not in source.split('"""', 2)[2]  # the policy is the controller
    with pytest.raises(ValueError, match="localization must be one of"):
        nav2_parameters("jackal", "x.pt2", map_yaml="m.yaml", localization="gps")


def test_a_file_without_its_footprint_needs_one_given(tmp_path):
    from test_deploy import task_contract, write_policy

    old = str(write_policy(tmp_path / "old.pt2", task_contract("follow_path")))  # no robot entry: no footprint
    with pytest.raises(ValueError, match=r"records no footprint .* give the launch footprint:="):
        nav2_parameters("jackal", old, map_yaml="m.yaml")
    given = "[[0.3, 0.2], [0.3, -0.2], [-0.3, -0.2], [-0.3, 0.2]]"
    params = nav2_parameters("jackal", old, map_yaml="m.yaml", footprint=given)
    assert params["global_costmap"]["global_costmap"]["footprint"] == given
