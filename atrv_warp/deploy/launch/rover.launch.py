"""``ros2 launch <this file> robot:=<name or robot file> policy:=<exported .pt2> [namespace:=...] [rviz:=true]``:
atrv-deploy on any robot whose file has a ``[deploy]`` table (its topics, frames and command type:
atrv_warp.deploy.launching).
"""

from atrv_warp.deploy.launching import launch_description


def generate_launch_description():
    return launch_description()
