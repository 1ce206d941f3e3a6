"""The command line of ``python -m atrv_warp.deploy POLICY.pt2 [--ros-args -p name:=value …]`` (``atrv-deploy``)."""

from __future__ import annotations

import argparse
import gc
import sys

from atrv_warp.deploy.parameters import parameter_help

__all__ = ["MISSING_ROS_MESSAGE", "build_parser", "main"]

MISSING_ROS_MESSAGE = (
    "ROS 2 Python packages are not installed (needed: rclpy, geometry_msgs, nav_msgs, sensor_msgs, std_msgs, "
    "rcl_interfaces): source the robot's ROS 2 installation (Humble or later), or pip install 'atrv-deploy[ros]'")

EPILOG = """\
Topics (relative: --ros-args -r __ns:=/rover_1 runs it for one rover of several):
  in:  scan (sensor_msgs/LaserScan), odom (nav_msgs/Odometry), imu (sensor_msgs/Imu),
       goal_pose (geometry_msgs/PoseStamped in the odometry frame or a frame /tf joins to it; a goal it
       cannot take stops the rover), /tf and /tf_static
  out: cmd_vel (geometry_msgs/Twist, or TwistStamped), goal_status (std_msgs/String, JSON),
       command_path (nav_msgs/Path: the command's next second in base_frame, for RViz)
  action: navigate_to_pose (nav2_msgs/action/NavigateToPose: RViz's "Nav2 Goal", Nav2's clients); a
       follow_path policy serves follow_path (nav2_msgs/action/FollowPath: Nav2's behaviour tree) instead,
       takes no goal_pose, and publishes on cmd_vel_nav (the velocity smoother's input)

One launch file for every robot, its parameters from the robot file's [deploy] table (robot:=NAME|PATH):
  python -m atrv_warp.deploy --launch-files jackal
and one that runs Nav2 around a follow_path policy (map:=, localization:=static|amcl|none):
  python -m atrv_warp.deploy --launch-files --nav2 jackal

Examples:
  python -m atrv_warp.export nav_deploy nav_deploy.pt2        # on the workstation
  atrv-deploy nav_deploy.pt2                                   # on the rover
  atrv-deploy nav_deploy.pt2 --ros-args -p use_sim_time:=true -p max_linear:=0.5
  ros2 launch $(python -m atrv_warp.deploy --launch-files jackal) robot:=jackal policy:=$PWD/jackal.pt2 \\
      namespace:=j100_0123
  ros2 topic pub --once -w 1 /goal_pose geometry_msgs/msg/PoseStamped \\
      "{header: {frame_id: odom}, pose: {position: {x: 4.0, y: 2.0}}}"

Parameters (--ros-args -p name:=value):
"""


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (its ROS parameters follow ``--ros-args``; ``--help`` lists them)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.deploy",
                                     description="Run an exported policy as a ROS 2 node: /scan, /odom, /imu and a "
                                                 "goal in, /cmd_vel out.",
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=EPILOG + parameter_help())
    parser.add_argument("policy", metavar="POLICY.pt2", help="an exported twist policy (python -m atrv_warp.export)")
    parser.add_argument("--launch-files", action="store_true",
                        help="check the robot named instead of POLICY.pt2 (a shipped robot's name or a robot file "
                             "whose [deploy] table gives its topics and frames), print the launch file (pass it the "
                             "same robot:=), and exit")
    parser.add_argument("--nav2", action="store_true",
                        help="with --launch-files: print the launch file that runs Nav2 around the node instead")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Load and check the policy (exit 2, one line, on a file or contract it cannot serve), then run the node until
    Ctrl-C or shutdown, which publishes a zero /cmd_vel first."""
    argv = sys.argv[1:] if argv is None else list(argv)
    ros_at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    parser = build_parser()
    args = parser.parse_args(argv[:ros_at])
    if args.launch_files:
        from atrv_warp.deploy.launching import LAUNCH_FILE, robot_parameters
        from atrv_warp.deploy.nav2_stack import NAV2_LAUNCH_FILE

        try:
            robot_parameters(args.policy)
        except ValueError as err:
            parser.error(" ".join(str(err).split()))
        print(NAV2_LAUNCH_FILE if args.nav2 else LAUNCH_FILE)
        return 0
    from atrv_warp.deploy.contract import PolicyRefused, load_deployable

    try:
        policy = load_deployable(args.policy)
    except PolicyRefused as err:
        print(f"{parser.prog}: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException
        from rclpy.signals import SignalHandlerOptions

        from atrv_warp.deploy.node import DeployNode, NodeConfigError
    except ImportError as err:
        print(f"{parser.prog}: error: {MISSING_ROS_MESSAGE} ({err.name} is missing)", file=sys.stderr)
        return 2
    import signal

    # Ctrl-C and SIGTERM end the spin here, with the context alive, so that the zero /cmd_vel still goes out. The
    # handler only asks the loop to stop: a KeyboardInterrupt raised inside rclpy's C++ take of a message surfaces as
    # a RuntimeError and would end the node with exit 1 after the stop
    try:
        rclpy.init(args=["atrv-deploy", *argv[ros_at:]], signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - rcl refuses malformed --ros-args with its own error types
        print(f"{parser.prog}: error: the ROS arguments {' '.join(argv[ros_at + 1:])!r} are refused by ROS: "
              f"{' '.join(str(err).split())[:300]}", file=sys.stderr)
        return 2
    stop_requested: list[int] = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda received, _frame: stop_requested.append(received))
    node = None
    try:
        node = DeployNode(policy, argv[ros_at:])
        # everything loaded so far (torch, rclpy, the policy) lives as long as the node: out of the collector's full
        # passes, which otherwise walk it all and, under a flood of messages, stalled a control period by ~0.1 s
        gc.freeze()
        while rclpy.ok() and not stop_requested:
            try:
                rclpy.spin_once(node, timeout_sec=0.1)  # returns often, so a signal is taken within 0.1 s
            except (KeyboardInterrupt, ExternalShutdownException):
                raise
            except Exception as err:  # noqa: BLE001 - the executor's own failure holds the rover; the node stays up
                node.on_executor_failure(err)
    except NodeConfigError:
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if rclpy.ok():
                node.stop("shutdown")
                node.log.info("stopped: zero /cmd_vel published")
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
