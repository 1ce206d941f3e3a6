"""The simulator node's parameters and driving commands (``python -m atrv_warp.ros --help`` lists them)."""

from __future__ import annotations

import math

from atrv_warp.core import parameters as core_parameters
from atrv_warp.core.parameters import Parameter
from atrv_warp.sim.config import SENSOR_NOISE, VARIANTS
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.modes import DriveMode

__all__ = ["COMMANDS", "DRIVER_PARAMETERS", "GOAL", "MAX_ROVERS", "PARAMETERS", "PARAMETER_BY_NAME", "ROBOTS_OWN",
           "VELOCITY", "driver_config", "parameter_help", "publish_every", "unknown_parameters"]

GOAL = "goal"
COMMANDS = tuple(m.value for m in DriveMode) + (GOAL,)

ROBOTS_OWN = -1.0
"""The default of a driver parameter that is the robot's (its file's ``[driver]`` values)."""

VELOCITY = "velocity"
"""The mode /cmd_vel switches to."""
MAX_ROVERS = 64

PARAMETERS = (
    Parameter("real_time_factor", 1.0, "simulated seconds per wall second; 0 = as fast as possible", "number"),
    Parameter("publish_rate", 10.0, "rate of /pose, /odom, /ground_truth/odom, /joint_states, /imu and /scan [Hz of "
              "sim time]: every step or every few (the nearest; the log says the rate it runs at)", "number", "Hz",
              positive=True),
    Parameter("duration", 0.0, "stop after this much sim time [s]; 0 = until Ctrl-C", "number", "s"),
    Parameter("mode", "coast", "initial driving mode: coast | forward | backward | rotate_left | rotate_right",
              "choice", choices=tuple(m.value for m in DriveMode)),
    Parameter("robot", "atrvjr", "the robot: a shipped robot's name (atrvjr, jackal, husky) or a robot file's path; "
              "its URDF, driver gains, frames and the task fitted to its limits", "text"),
    Parameter("variant", "realistic", "ATRV-Jr variant: realistic | reference", "choice", choices=tuple(VARIANTS)),
    Parameter("task", "reach", "world: reach (the flat arena) | nav (terrain and obstacles, drawn once at start) | "
              "nav_deploy (nav's world; goal mode drives by /cmd_vel from the robot observation, the shipped "
              "nav_deploy policy unless -p policy:=FILE)", "text"),
    Parameter("scan_beams", 181, "/scan beams over 180 deg (181: 1 deg, as a SICK LMS); 0 = no /scan", "integer"),
    Parameter("scan_noise", SENSOR_NOISE.scan_range, "/scan range noise, standard deviation [m]", "number", "m"),
    Parameter("scan_dropout", SENSOR_NOISE.scan_dropout, "/scan: probability that a beam returns nothing [-]", "number",
              high=1.0),
    Parameter("x", 0.0, "start x of rover 0 [m]", "number", "m", low=-math.inf),
    Parameter("y", 0.0, "start y of rover 0 [m]", "number", "m", low=-math.inf),
    Parameter("yaw", 0.0, "start yaw [rad]", "number", "rad", low=-math.inf),
    Parameter("spacing", 2.0, "rover k starts at y + k * spacing [m]", "number", "m", low=-math.inf),
    Parameter("num_rovers", 1, f"rovers simulated (1 … {MAX_ROVERS}); more than one puts each under /rover_<k>",
              "integer", low=1, high=MAX_ROVERS),
    Parameter("frame_id", "", "frame_id of /pose (default: the URDF's chassis link)", "text"),
    Parameter("odom_frame", "odom", "frame of /odom (REP 105)", "frame"),
    Parameter("base_frame", "base_link", "child frame of /odom", "frame"),
    Parameter("policy", "", "policy file for goal mode (default: the shipped one); the world then runs the task it "
              "records, as it trained (its limits and control period)", "text"),
    Parameter("allow_other_robot", False, "goal mode: drive with a policy trained on another robot than robot:= on "
              "purpose (a study); without it, that is refused naming both", "switch"),
    Parameter("bag", "", "write an MCAP ROS 2 bag here: /cmd_vel, /joint_states, /odom, /ground_truth/odom, /pose, "
              "/command, /goal, /goal_status (what atrv-calibrate reads), /tf, /tf_static and /robot_description "
              "(what a 3D view draws the rover from); not /imu or /scan", "file"),
    Parameter("tf", True, "publish live /tf and /tf_static (tf2_msgs: a ROS install's, or built from its definition "
              "with gcc/g++ on first use, cached; without, one line says why)", "switch"),
    Parameter("tf_odometry", "odom", "the odometry /tf's odom -> base_link follows: odom (the wheels', as "
              "diff_drive_controller publishes it) | odometry/filtered (the fused one's, as robot_localization "
              "publishes it where it runs); world or map -> odom puts base_link at the true pose either way", "choice",
              choices=("odom", "odometry/filtered")),
    Parameter("sim_config", "", "simulator-config TOML ([rover], [contact]; e.g. atrv-calibrate's output) applied to "
              "every rover", "text"),
    Parameter("wait_for_subscribers", 0, "wait for this many /pose subscribers before starting", "integer"),
    Parameter("reach_radius", 1.0, "goal mode: reached within this distance [m]", "number", "m", positive=True),
    Parameter("wheel_radius", 0.0, "the base driver's configured wheel radius [m]; 0 = the nominal rover's (not "
              "sim_config's)", "number", "m"),
    Parameter("track_width", 0.0, "the base driver's configured wheel track [m]; 0 = the nominal rover's", "number",
              "m"),
    Parameter("effective_track_factor", ROBOTS_OWN, "skid: effective track / wheel track; -1 = the robot's (its "
              "file's)", "number", positive=True, minus_one="the robot's"),
    Parameter("wheel_kp", ROBOTS_OWN, "wheel-speed PI proportional gain [N·m per rad/s], run every substep; -1 = the "
              "robot's", "number", "N·m s/rad", minus_one="the robot's"),
    Parameter("wheel_ki", ROBOTS_OWN, "wheel-speed PI integral gain [N·m per rad]; -1 = the robot's", "number",
              "N·m/rad", minus_one="the robot's"),
    Parameter("cmd_vel_timeout", DriverConfig.cmd_vel_timeout, "watchdog: stop when no /cmd_vel arrives for this long "
              "[s]", "number", "s", positive=True),
    Parameter("odometry_accel_time", 0.0, "the fused odometry's velocity blends the IMU's accelerometer into the "
              "encoders', a complementary filter of this time constant [s]; 0 = the encoders alone", "number", "s"),
    Parameter("linear_max_velocity", 0.0, "diff_drive_controller's linear.x.max_velocity [m/s]; 0 = no limit",
              "number", "m/s"),
    Parameter("linear_max_acceleration", 0.0, "linear.x.max_acceleration [m/s²]; 0 = the task's (nav_deploy: 1), else "
              "none", "number", "m/s²"),
    Parameter("angular_max_velocity", 0.0, "angular.z.max_velocity [rad/s]; 0 = no limit", "number", "rad/s"),
    Parameter("angular_max_acceleration", 0.0, "angular.z.max_acceleration [rad/s²]; 0 = the task's, else none",
              "number", "rad/s²"),
    Parameter("cmd_vel_delay", 0.0, "/cmd_vel reaches the driver this long after it arrives [s of sim time, whole "
              "steps]: a command path's latency, which a bag's stamps do not show", "number", "s"),
    Parameter("motor_lag", 0.0, "the motors' torque lag, a first-order time constant [s]; 0 = none (the driver's PI "
              "sees it)", "number", "s"),
    Parameter("terrain", "", "the ground, a terrain preset (e.g. slope: a 10 deg incline uphill toward +x); '' = the "
              "task's", "text"),
    Parameter("map", "", "a Nav2 map_server map (YAML) to drive in, or a procedural place (building:1@7, yard:1): "
              "its walls for /scan and collision, served on /map (frame map, transient local) with map -> odom on "
              "/tf; the rovers start at their first episodes' starts in its free space", "text"),
    Parameter("publish_map", True, "with map: serve it on /map; off for a stack whose map_server serves it", "switch"),
    Parameter("map_to_odom", True, "publish world (map) -> odom on /tf, the true pose's correction of the odometry; "
              "off for a stack whose localisation (amcl) publishes it", "switch"),
    Parameter("imu_accel_noise", SENSOR_NOISE.accel, "IMU accelerometer noise, standard deviation [m/s²]", "number",
              "m/s²"),
    Parameter("imu_gyro_noise", SENSOR_NOISE.gyro, "IMU gyroscope noise, standard deviation [rad/s]", "number",
              "rad/s"),
    Parameter("wheel_speed_noise", SENSOR_NOISE.wheel_speed, "/joint_states velocity noise, standard deviation "
              "[rad/s]", "number", "rad/s"),
    Parameter("truth_noise", 0.0, "/ground_truth/odom position noise, standard deviation [m] (as motion capture or RTK "
              "GPS)", "number", "m"),
    Parameter("truth_yaw_noise", 0.0, "/ground_truth/odom heading noise, standard deviation [rad]", "number", "rad"),
    Parameter("seed", 0, "seed of the sensor noise", "integer"),
    Parameter("episode_seed", 2024, "the evaluation set /reset_episode replays (python -m atrv_warp.evaluate --seed; "
              "2024: the standard set)", "integer"),
    Parameter("lockstep", False, "after each state publication, step only once a /cmd_vel has come (or "
              "lockstep_timeout passed): a controller in another process acts on every step, at any "
              "real_time_factor; a replayed episode (reset_episode) ends holding, without /clock, until the next one",
              "switch"),
    Parameter("lockstep_timeout", 1.0, "lockstep: step anyway after this long without a /cmd_vel [s of wall time]",
              "number", "s", positive=True),
)
"""Every parameter the node declares, in the style both nodes share (:mod:`atrv_warp.core.parameters`): each type
and range checked before the node builds anything. The sensor noise defaults are
:data:`~atrv_warp.sim.config.SENSOR_NOISE`, the noise the randomization presets train with."""

PARAMETER_BY_NAME = {p.name: p for p in PARAMETERS}
"""Every :data:`PARAMETERS` entry by its name."""

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


def unknown_parameters(args: list[str] | None, params_files: dict[str, list[str]] | None = None) -> list[str]:
    """Names given as ``-p name:=value`` that the node does not declare, and those a ``--params-file`` sets for it
    (``params_files``: each file's parameter names for this node), each with where it came from."""
    return core_parameters.unknown_parameters(PARAMETER_BY_NAME, args, params_files)


def parameter_help() -> str:
    """The node's parameters as ``name (default): description`` lines."""
    return core_parameters.parameter_help(PARAMETERS)


def publish_every(publish_rate: float, step_dt: float) -> tuple[int, str | None]:
    """(steps between state publications, a line saying the rate they come at where it is not ``publish_rate`` [Hz]
    within 1 %, else ``None``) for a simulator stepping every ``step_dt`` [s]: the nearest whole number of steps."""
    every = max(1, round(1.0 / (publish_rate * step_dt)))
    rate = 1.0 / (every * step_dt)
    if abs(rate - publish_rate) <= 0.01 * publish_rate:
        return every, None
    most = " (the simulator's step rate, the most there is)" if every == 1 and publish_rate > rate else ""
    return every, (f"publish_rate {publish_rate:g} Hz: state topics every {every} step(s) of {step_dt:.3g} s, "
                   f"{rate:.3g} Hz{most}")
