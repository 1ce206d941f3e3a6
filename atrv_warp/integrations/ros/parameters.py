"""The simulator node's parameters and driving commands (``python -m atrv_warp.ros --help`` lists them)."""

from __future__ import annotations

from atrv_warp.sim.config import SENSOR_NOISE
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.modes import DriveMode

__all__ = ["COMMANDS", "DRIVER_PARAMETERS", "GOAL", "MAX_ROVERS", "PARAMETERS", "ROBOTS_OWN", "VELOCITY",
           "driver_config", "parameter_help"]

GOAL = "goal"
COMMANDS = tuple(m.value for m in DriveMode) + (GOAL,)

ROBOTS_OWN = -1.0
"""The default of a driver parameter that is the robot's (its file's ``[driver]`` values)."""

VELOCITY = "velocity"
"""The mode /cmd_vel switches to."""
MAX_ROVERS = 64

PARAMETERS = (
    ("real_time_factor", 1.0, "simulated seconds per wall second; 0 = as fast as possible"),
    ("publish_rate", 10.0, "rate of /pose, /odom, /ground_truth/odom, /joint_states, /imu and /scan [Hz of sim time]"),
    ("duration", 0.0, "stop after this much sim time [s]; 0 = until Ctrl-C"),
    ("mode", "coast", "initial driving mode: coast | forward | backward | rotate_left | rotate_right"),
    ("robot", "atrvjr", ("the robot: a shipped robot's name (atrvjr, jackal, husky) or a robot file's path; its URDF, "
                         "driver gains, frames and the task fitted to its limits")),
    ("variant", "realistic", "ATRV-Jr variant: realistic | reference"),
    ("task", "reach", ("world: reach (the flat arena) | nav (terrain and obstacles, drawn once at start) | nav_deploy "
                       "(nav's world; goal mode drives by /cmd_vel from the robot observation, the shipped nav_deploy "
                       "policy unless -p policy:=FILE)")),
    ("scan_beams", 181, "/scan beams over 180 deg (181: 1 deg, as a SICK LMS); 0 = no /scan"),
    ("scan_noise", SENSOR_NOISE.scan_range, "/scan range noise, standard deviation [m]"),
    ("scan_dropout", SENSOR_NOISE.scan_dropout, "/scan: probability that a beam returns nothing [-]"),
    ("x", 0.0, "start x of rover 0 [m]"), ("y", 0.0, "start y of rover 0 [m]"), ("yaw", 0.0, "start yaw [rad]"),
    ("spacing", 2.0, "rover k starts at y + k * spacing [m]"),
    ("num_rovers", 1, f"rovers simulated (1 … {MAX_ROVERS}); more than one puts each under /rover_<k>"),
    ("frame_id", "", "frame_id of /pose (default: the URDF's chassis link)"),
    ("odom_frame", "odom", "frame of /odom (REP 105)"), ("base_frame", "base_link", "child frame of /odom"),
    ("policy", "", ("policy file for goal mode (default: the shipped one); the world then runs the task it records, "
                    "as it trained (its limits and control period)")),
    ("bag", "", ("write an MCAP ROS 2 bag here: /cmd_vel, /joint_states, /odom, /ground_truth/odom, /pose, "
                 "/command, /goal, /goal_status (what atrv-calibrate reads), /tf, /tf_static and "
                 "/robot_description (what a 3D view draws the rover from); not /imu or /scan")),
    ("tf", True, ("publish live /tf and /tf_static (tf2_msgs: a ROS install's, or built from its definition "
                  "with gcc/g++ on first use, cached; without, one line says why)")),
    ("sim_config", "", "simulator-config TOML ([rover], [contact]; e.g. atrv-calibrate's output) applied to every rover"),
    ("wait_for_subscribers", 0, "wait for this many /pose subscribers before starting"),
    ("reach_radius", 1.0, "goal mode: reached within this distance [m]"),
    ("wheel_radius", 0.0, "the base driver's configured wheel radius [m]; 0 = the nominal rover's (not sim_config's)"),
    ("track_width", 0.0, "the base driver's configured wheel track [m]; 0 = the nominal rover's"),
    ("effective_track_factor", ROBOTS_OWN, "skid: effective track / wheel track; -1 = the robot's (its file's)"),
    ("wheel_kp", ROBOTS_OWN, "wheel-speed PI proportional gain [N·m per rad/s], run every substep; -1 = the robot's"),
    ("wheel_ki", ROBOTS_OWN, "wheel-speed PI integral gain [N·m per rad]; -1 = the robot's"),
    ("cmd_vel_timeout", DriverConfig.cmd_vel_timeout, "watchdog: stop when no /cmd_vel arrives for this long [s]"),
    ("odometry_accel_time", 0.0, ("the fused odometry's velocity blends the IMU's accelerometer into the encoders', "
                                  "a complementary filter of this time constant [s]; 0 = the encoders alone")),
    ("linear_max_velocity", 0.0, "diff_drive_controller's linear.x.max_velocity [m/s]; 0 = no limit"),
    ("linear_max_acceleration", 0.0, "linear.x.max_acceleration [m/s²]; 0 = the task's (nav_deploy: 1), else none"),
    ("angular_max_velocity", 0.0, "angular.z.max_velocity [rad/s]; 0 = no limit"),
    ("angular_max_acceleration", 0.0, "angular.z.max_acceleration [rad/s²]; 0 = the task's, else none"),
    ("cmd_vel_delay", 0.0, ("/cmd_vel reaches the driver this long after it arrives [s of sim time, whole steps]: a "
                            "command path's latency, which a bag's stamps do not show")),
    ("motor_lag", 0.0, "the motors' torque lag, a first-order time constant [s]; 0 = none (the driver's PI sees it)"),
    ("terrain", "", "the ground, a terrain preset (e.g. slope: a 10 deg incline uphill toward +x); '' = the task's"),
    ("imu_accel_noise", SENSOR_NOISE.accel, "IMU accelerometer noise, standard deviation [m/s²]"),
    ("imu_gyro_noise", SENSOR_NOISE.gyro, "IMU gyroscope noise, standard deviation [rad/s]"),
    ("wheel_speed_noise", SENSOR_NOISE.wheel_speed, "/joint_states velocity noise, standard deviation [rad/s]"),
    ("truth_noise", 0.0, "/ground_truth/odom position noise, standard deviation [m] (as motion capture or RTK GPS)"),
    ("truth_yaw_noise", 0.0, "/ground_truth/odom heading noise, standard deviation [rad]"),
    ("seed", 0, "seed of the sensor noise"),
    ("episode_seed", 2024, ("the evaluation set /reset_episode replays (python -m atrv_warp.evaluate --seed; 2024: "
                            "the standard set)")),
    ("lockstep", False, ("after each state publication, step only once a /cmd_vel has come (or lockstep_timeout "
                         "passed): a controller in another process acts on every step, at any real_time_factor; a "
                         "replayed episode (reset_episode) ends holding, without /clock, until the next one")),
    ("lockstep_timeout", 1.0, "lockstep: step anyway after this long without a /cmd_vel [s of wall time]"),
)
"""(name, default, description) of every parameter the node declares. The sensor noise defaults are
:data:`~atrv_warp.sim.config.SENSOR_NOISE`, the noise the randomization presets train with."""

DRIVER_PARAMETERS = {"wheel_radius": "wheel_radius", "track_width": "track_width",
                     "effective_track_factor": "effective_track_factor", "wheel_kp": "kp", "wheel_ki": "ki",
                     "cmd_vel_timeout": "cmd_vel_timeout", "odometry_accel_time": "odometry_accel_time",
                     "linear_max_velocity": "linear_max_velocity",
                     "linear_max_acceleration": "linear_max_acceleration",
                     "angular_max_velocity": "angular_max_velocity",
                     "angular_max_acceleration": "angular_max_acceleration"}
"""Node parameter -> :class:`~atrv_warp.sim.driver.DriverConfig` field."""


def driver_config(params: dict) -> DriverConfig:
    """The base's motor driver from the node's parameters (0 for a radius, track, limit or filter: unset; -1 for a gain
    or the track factor: the robot's); a bad value is a ``ValueError`` naming it."""
    optional = {"wheel_radius", "track_width", "linear_max_velocity", "linear_max_acceleration",
                "angular_max_velocity", "angular_max_acceleration", "odometry_accel_time"}
    values = {}
    for name, field in DRIVER_PARAMETERS.items():
        value = params[name]
        robots = field in ("kp", "ki", "effective_track_factor") and value == ROBOTS_OWN
        values[field] = None if (name in optional and value == 0) or robots else value
    try:
        return DriverConfig(**values)
    except ValueError as err:
        field = str(err).split()[0].removeprefix("DriverConfig.")
        node_name = next((n for n, f in DRIVER_PARAMETERS.items() if f == field), field)
        raise ValueError(f"parameter {node_name}: {str(err).split(' ', 1)[1]}") from None


def parameter_help() -> str:
    """The node's parameters as ``name (default): description`` lines."""
    return "\n".join(f"    {name} ({default!r}): {text}" for name, default, text in PARAMETERS)
