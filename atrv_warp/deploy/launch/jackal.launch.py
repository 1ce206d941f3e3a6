"""``ros2 launch <this file> policy:=<exported .pt2> [namespace:=...] [rviz:=true]``: atrv-deploy on the jackal.

Its topics, frames and command type: ``config/jackal.yaml`` (atrv_warp.deploy.launching).
"""

from atrv_warp.deploy.launching import launch_description


def generate_launch_description():
    return launch_description("jackal")
