"""ROS 2 base driver for simulated rovers (any robot file): ``python -m atrv_warp.ros [--ros-args -p name:=value …]``.

Run::

    python -m atrv_warp.ros                                   # one rover, real time
    python -m atrv_warp.ros --ros-args -p num_rovers:=2       # /rover_0/…, /rover_1/…
    python -m atrv_warp.ros --ros-args -p task:=nav           # terrain and obstacles, seen on /scan
    ros2 topic pub -r 10 /cmd_vel geometry_msgs/msg/Twist "{linear: {x: 0.5}, angular: {z: 0.2}}"
    ros2 topic pub --once /command std_msgs/msg/String "{data: rotate_left}"

Topics (per rover; under ``/rover_<k>`` when ``num_rovers`` > 1):
    ``cmd_vel`` (geometry_msgs/Twist, in): linear.x [m/s] and angular.z [rad/s], through skid-steer
    kinematics (effective track = ``effective_track_factor`` x wheel track) to wheel-speed
    targets, held by a PI controller within the motor limit. A watchdog stops the rover when no
    command arrives for ``cmd_vel_timeout`` s of sim time. Non-finite values are logged, ignored.
    ``command`` (std_msgs/String, in): coast | forward | backward | rotate_left | rotate_right
    (the reference's fixed-torque modes) | goal; the newest command source wins.
    ``goal`` (geometry_msgs/PoseStamped, in): drive there with the trained policy (shipped one
    by default); ``goal_status`` (std_msgs/String, out): ``distance=<m>``, then ``reached``.
    ``odom`` (nav_msgs/Odometry, out): wheel odometry (frame ``odom``, child ``base_link``), skid
    error included, with pose and twist covariances; the odom frame starts at the start pose.
    ``odometry/filtered`` (nav_msgs/Odometry, out): the encoders' distance along the gyro's heading (what
    ``robot_localization`` gives; the robot observation's odometry), same frames as ``odom``.
    ``reset_episode`` (std_msgs/Int32, in): replay evaluation episode k of ``episode_seed`` (its world,
    start and goal; one rover, a twist task: nav_deploy, follow_path), stepping the task's environment with the last
    ``cmd_vel`` until it ends; ``episode`` (std_msgs/String, out, JSON): ``{"event": "start", "episode",
    "seed", "start", "goal", "goal_yaw"}`` (world = odometry frame at the start), then ``{"event": "end",
    "episode", "end_reason", "steps", "unanswered"}`` (``lockstep``: the steps taken on
    ``lockstep_timeout``, without a new ``cmd_vel``) (benchmarks/transfer/deploy_closed_loop.py). A reset advances ``/clock`` by
    one step; in ``lockstep`` the episode's last state goes out without ``/clock`` and the simulator holds until
    the next ``reset_episode`` (send a controller its next goal meanwhile: it acts first on the reset state).
    ``plan`` (nav_msgs/Path, out; a path task in a map): the replayed episode's plan in ``map``, at its start and each
    replan, as Nav2's planner server publishes one (for a ``FollowPath`` client).
    ``ground_truth/odom`` (nav_msgs/Odometry, out): the simulator's pose (frame ``world``) and
    body-frame twist.
    ``joint_states`` (sensor_msgs/JointState, out): wheel joint positions [rad] and velocities.
    ``imu`` (sensor_msgs/Imu, out, frame: the robot file's IMU link, the ATRV-Jr's ``cbimu_frame``): orientation, angular velocity and
    specific force (+9.81 m/s² up at rest) from the simulated motion, with Gaussian noise.
    ``scan`` (sensor_msgs/LaserScan, out, frame: its laser link, the ATRV-Jr's ``lrf_frame``): the laser scanner, ``scan_beams``
    beams over 180 deg (-90 to +90 deg, counter-clockwise), 0.1 … 20 m, ``scan_noise`` Gaussian
    noise; a beam without a return reads +inf (REP 117).
    ``pose`` (geometry_msgs/PoseStamped, out): the reference's chassis pose topic.
Shared: ``/clock`` (rosgraph_msgs/Clock, every step, after its state topics: use ``use_sim_time``) and
``/robot_description`` (std_msgs/String, the URDF, transient local).
State topics come at ``publish_rate`` Hz of sim time; stamps are sim time (plus a step per episode reset). ``/tf``
(``world`` -> ``odom`` -> ``base_link`` -> the chassis -> the wheels, REP 105 with the simulator as the localisation) and
``/tf_static`` (the URDF's fixed frames), unless ``-p tf:=false``: tf2_msgs is not on the package index, so a ROS
install's is used, or its type support is built from its definition on first use (gcc/g++) and cached.

Parameters: see :data:`atrv_warp.integrations.ros.parameters.PARAMETERS` (each declared with its
description: ``ros2 param describe /atrv_sim <name>``). An unknown parameter, or a bad value,
is refused at start-up with a message naming it.
"""

from __future__ import annotations

import sys

from atrv_warp.integrations.ros import run
from atrv_warp.integrations.ros.parameters import parameter_help

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    if any(a in ("-h", "--help") for a in argv[1:]) and "--ros-args" not in argv:
        print(__doc__)
        print(f"Parameters (--ros-args -p name:=value):\n{parameter_help()}")
        return 0
    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
