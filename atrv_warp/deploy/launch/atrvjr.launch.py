"""``ros2 launch <this file> policy:=<exported .pt2> [namespace:=...] [rviz:=true]``: atrv-deploy on the atrvjr.

Its topics, frames and command type: ``config/atrvjr.yaml`` (atrv_warp.deploy.launching).
"""

from atrv_warp.deploy.launching import launch_description


def generate_launch_description():
    return launch_description("atrvjr")
