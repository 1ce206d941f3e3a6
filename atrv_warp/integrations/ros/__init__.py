"""ROS 2 bridge: the simulator node behind ``python -m atrv_warp.ros`` (topics and parameters there).

- this package: :func:`run`, which starts the node, and :data:`MISSING_ROS_MESSAGE`;
- :mod:`.parameters`: the node's parameters (in the deploy node's style, :mod:`atrv_warp.core.parameters`) and
  driving commands;
- :mod:`.node`: the rclpy node; :mod:`.rover_io`: one rover's topics and messages; :mod:`.base`: the base driver
  (velocity control, odometry, IMU);
- :mod:`.bag`: the MCAP bag writer; :mod:`.drive`: the calibration's scripted excitation driver;
- :mod:`.frames`: the frame tree the node publishes and records as /tf (tf2_msgs's type support, where no
  ROS install has it, from :mod:`atrv_warp.core.ros_interfaces`); :mod:`.markers`: the world as ``visualization_msgs/MarkerArray``.

rclpy is optional: this package imports without it (and without the simulator: importing
:mod:`.base` loads torch alone), :func:`run` says how to install it, and :mod:`.node` (the rclpy node)
is imported only when it is there.
"""

from __future__ import annotations

import signal
import sys

__all__ = ["MISSING_ROS_MESSAGE", "run"]

MISSING_ROS_MESSAGE = (
    "ROS 2 Python packages are not installed (needed: rclpy, geometry_msgs, std_msgs, rosgraph_msgs, "
    "visualization_msgs).\n"
    "Install the extra:  pip install -e '.[ros]'   (ros-rclpy[fastrtps], ros-geometry-msgs, ros-std-msgs, "
    "ros-visualization-msgs, mcap-ros2-support from PyPI), or source a ROS 2 installation."
)


def run(args: list[str] | None = None) -> int:
    """Run the node until ``duration`` of sim time, Ctrl-C or shutdown; 2 on a bad parameter."""
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException
        from rclpy.signals import SignalHandlerOptions

        from atrv_warp.integrations.ros.node import NodeConfigError, RoverSimNode
    except ImportError:
        print(MISSING_ROS_MESSAGE, file=sys.stderr)
        return 2
    # rclpy's own handlers would shut the context down under a running step, whose next publish then fails
    # (exit 1 on a plain Ctrl-C). Until the simulator is built, Ctrl-C raises KeyboardInterrupt as usual; from
    # then on Ctrl-C and SIGTERM only ask the step loop to stop, and the node closes with its context alive
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = RoverSimNode(args)
    stop_requested: list[int] = []
    previous = {}
    try:
        node.setup()
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, lambda received, _frame: stop_requested.append(received))
        node.spin_simulation(stop_requested=stop_requested)
    except NodeConfigError:
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.close()
        rclpy.try_shutdown()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return 0
