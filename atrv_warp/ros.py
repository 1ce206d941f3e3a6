"""ROS 2 bridge: a real rclpy node that simulates one ATRV-Jr, publishes ``/pose`` and obeys ``/command``.

Run::

    python -m atrv_warp.ros                                   # real time, pose at 10 Hz
    python -m atrv_warp.ros --ros-args -p real_time_factor:=0.0 -p duration:=5.0 -p mode:=forward
    ros2 topic pub --once /command std_msgs/msg/String "{data: rotate_left}"

Topics:
    ``/pose`` (geometry_msgs/msg/PoseStamped, out): chassis pose; stamp = simulation time,
    frame_id = the chassis body name (parameter ``frame_id`` overrides it).
    ``/command`` (std_msgs/msg/String, in): coast | forward | backward | rotate_left |
    rotate_right (applied at the next step) | goal (drive to the last ``/goal``); anything else is
    logged and ignored.
    ``/goal`` (geometry_msgs/msg/PoseStamped, in): a target; switches to ``goal`` mode, in which a
    trained policy (the shipped one by default) drives the rover there.
    ``/goal_status`` (std_msgs/msg/String, out): ``distance=<m>`` at the pose rate, then ``reached``.
    ``/clock`` (rosgraph_msgs/msg/Clock, out): simulation time, for nodes with ``use_sim_time``.

Parameters (``--ros-args -p name:=value``): ``real_time_factor`` (1.0; 0 = as fast as
possible), ``publish_rate`` [Hz] (10.0), ``duration`` [s of sim time] (0 = until Ctrl-C),
``mode`` (initial driving mode, coast), ``variant`` (realistic), ``x``, ``y``, ``yaw`` (start),
``frame_id``, ``policy`` (policy file for goal mode; empty = shipped), ``bag`` (write an MCAP
ROS 2 bag of /pose, /command, /goal, /goal_status; empty = off), ``wait_for_subscribers`` (wait
until this many /pose subscribers are matched before starting; 0).

The simulator does not depend on ROS: this module is a thin layer over
:meth:`atrv_warp.sim.RoverSim.set_mode`.
"""

from __future__ import annotations

import sys

from .integrations.ros import run

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    if any(a in ("-h", "--help") for a in argv[1:]) and "--ros-args" not in argv:
        print(__doc__)
        return 0
    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
