"""``ros2 launch <this file> robot:=<name or robot file> policy:=<exported follow_path .pt2> map:=<map YAML>
[localization:=static|amcl|none] [footprint:=...] [use_sim_time:=true]``: atrv-deploy as Nav2's controller, with
Nav2's map server, localisation, planner, local costmap, behaviours, behaviour tree and velocity smoother around it
(atrv_warp.deploy.nav2_stack).
"""

from atrv_warp.deploy.nav2_stack import nav2_launch_description


def generate_launch_description():
    return nav2_launch_description()
