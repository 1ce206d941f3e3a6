"""Observation kernels: the observation's leading fields (the arena's, :data:`~atrv_warp.task.spec.OBSERVATION`, or
the robot's, :data:`~atrv_warp.task.spec.ROBOT_OBSERVATION`), then the scan's sectors and the last actions after them.

One thread per world. Indices and clip bounds come from :mod:`atrv_warp.task.spec`; ``robot`` (1: the robot
observation) is the task's observation kind, resolved once by the environment (0: the arena's; 2: the path
observation, whose fields :func:`~atrv_warp.task.kernels.paths.follow_paths` writes; -1: a kind of a task's own, whose
fields :func:`~atrv_warp.task.kernels.tables.field_kernel` writes).
"""

from __future__ import annotations

import warp as wp

from atrv_warp.task.kernels.state import RoverState, StepOutputs, TaskBuffers
from atrv_warp.task.spec import OBS_DIM, OBS_INDEX, OBSERVATION, ROBOT_OBSERVATION

__all__ = ["ScanReading", "beam_reading", "body_yaw_rate", "clear_actions", "heading_error", "observe_reset",
           "observe_step", "planar_distance", "record_actions", "scaled_odometry", "wrap_angle",
           "write_action_observation", "write_goal_observation", "write_scan_observation"]

# Observation indices and clip bounds, from task_spec.OBSERVATION.
OBS_TARGET_X = wp.constant(OBS_INDEX["target_x"])
OBS_TARGET_Y = wp.constant(OBS_INDEX["target_y"])
OBS_ROVER_X = wp.constant(OBS_INDEX["rover_x"])
OBS_ROVER_Y = wp.constant(OBS_INDEX["rover_y"])
OBS_ROVER_VX = wp.constant(OBS_INDEX["rover_vx"])
OBS_ROVER_VY = wp.constant(OBS_INDEX["rover_vy"])
OBS_ROLL = wp.constant(OBS_INDEX["roll"])
OBS_YAW_RATE = wp.constant(OBS_INDEX["yaw_rate"])
OBS_SIN_HEADING = wp.constant(OBS_INDEX["sin_heading_error"])
OBS_COS_HEADING = wp.constant(OBS_INDEX["cos_heading_error"])
_BOUND = {f.name: f.bound for f in OBSERVATION}
TARGET_BOUND = wp.constant(_BOUND["target_x"])
POSITION_BOUND = wp.constant(_BOUND["rover_x"])
VELOCITY_BOUND = wp.constant(_BOUND["rover_vx"])
ROLL_BOUND = wp.constant(_BOUND["roll"])
YAW_RATE_BOUND = wp.constant(_BOUND["yaw_rate"])
assert _BOUND["target_x"] == _BOUND["target_y"] and _BOUND["rover_x"] == _BOUND["rover_y"]
assert _BOUND["rover_vx"] == _BOUND["rover_vy"]

# The robot observation's indices and clip bounds, from task_spec.ROBOT_OBSERVATION.
_ROBOT_INDEX = {f.name: i for i, f in enumerate(ROBOT_OBSERVATION)}
_ROBOT_BOUND = {f.name: f.bound for f in ROBOT_OBSERVATION}
ROBOT_DIM = wp.constant(len(ROBOT_OBSERVATION))
ROBOT_GOAL_DISTANCE = wp.constant(_ROBOT_INDEX["goal_distance"])
ROBOT_SIN_BEARING = wp.constant(_ROBOT_INDEX["sin_goal_bearing"])
ROBOT_COS_BEARING = wp.constant(_ROBOT_INDEX["cos_goal_bearing"])
ROBOT_ODOM_LINEAR = wp.constant(_ROBOT_INDEX["odom_linear"])
ROBOT_ODOM_ANGULAR = wp.constant(_ROBOT_INDEX["odom_angular"])
ROBOT_ROLL = wp.constant(_ROBOT_INDEX["imu_roll"])
ROBOT_PITCH = wp.constant(_ROBOT_INDEX["imu_pitch"])
ROBOT_YAW_RATE = wp.constant(_ROBOT_INDEX["imu_yaw_rate"])
GOAL_DISTANCE_BOUND = wp.constant(_ROBOT_BOUND["goal_distance"])
ODOM_LINEAR_BOUND = wp.constant(_ROBOT_BOUND["odom_linear"])
ODOM_ANGULAR_BOUND = wp.constant(_ROBOT_BOUND["odom_angular"])
IMU_ROLL_BOUND = wp.constant(_ROBOT_BOUND["imu_roll"])
IMU_PITCH_BOUND = wp.constant(_ROBOT_BOUND["imu_pitch"])
IMU_YAW_RATE_BOUND = wp.constant(_ROBOT_BOUND["imu_yaw_rate"])


@wp.func
def wrap_angle(a: float) -> float:
    return wp.atan2(wp.sin(a), wp.cos(a))


@wp.func
def heading_error(pose: wp.transform, target: wp.vec2, yaw: float) -> float:
    """Angle from the rover heading to the target direction, in [-pi, pi] [rad]."""
    p = wp.transform_get_translation(pose)
    return wrap_angle(wp.atan2(target[1] - p[1], target[0] - p[0]) - yaw)


@wp.func
def planar_distance(pose: wp.transform, target: wp.vec2) -> float:
    p = wp.transform_get_translation(pose)
    return wp.length(wp.vec2(target[0] - p[0], target[1] - p[1]))


@wp.func
def write_arena_observation(
    obs: wp.array2d(dtype=float),
    world: int,
    target: wp.vec2,
    pose: wp.transform,
    lin_vel: wp.vec3,
    roll: float,
    yaw_rate: float,
    head_err: float,
):
    p = wp.transform_get_translation(pose)
    obs[world, OBS_TARGET_X] = wp.clamp(target[0], -TARGET_BOUND, TARGET_BOUND)
    obs[world, OBS_TARGET_Y] = wp.clamp(target[1], -TARGET_BOUND, TARGET_BOUND)
    obs[world, OBS_ROVER_X] = wp.clamp(p[0], -POSITION_BOUND, POSITION_BOUND)
    obs[world, OBS_ROVER_Y] = wp.clamp(p[1], -POSITION_BOUND, POSITION_BOUND)
    obs[world, OBS_ROVER_VX] = wp.clamp(lin_vel[0], -VELOCITY_BOUND, VELOCITY_BOUND)
    obs[world, OBS_ROVER_VY] = wp.clamp(lin_vel[1], -VELOCITY_BOUND, VELOCITY_BOUND)
    obs[world, OBS_ROLL] = wp.clamp(roll, -ROLL_BOUND, ROLL_BOUND)
    obs[world, OBS_YAW_RATE] = wp.clamp(yaw_rate, -YAW_RATE_BOUND, YAW_RATE_BOUND)
    obs[world, OBS_SIN_HEADING] = wp.sin(head_err)
    obs[world, OBS_COS_HEADING] = wp.cos(head_err)


@wp.func
def body_yaw_rate(pose: wp.transform, ang_vel: wp.vec3) -> float:
    """Angular velocity about the chassis z [rad/s]: the world-frame ``ang_vel`` rotated into the chassis frame,
    which is the IMU's (the URDF's cbimu_frame is aligned with the chassis; tests/test_robot_task.py checks)."""
    return wp.quat_rotate_inv(wp.transform_get_rotation(pose), ang_vel)[2]


@wp.func
def write_goal_observation(obs: wp.array2d(dtype=float), world: int, goal: wp.vec2, odometry: wp.vec3):
    """The goal's distance [m] and bearing (sine, cosine) from the base at ``odometry`` (x, y, yaw in the
    odometry frame), for a ``goal`` in the odometry frame."""
    dx = goal[0] - odometry[0]
    dy = goal[1] - odometry[1]
    bearing = wrap_angle(wp.atan2(dy, dx) - odometry[2])
    obs[world, ROBOT_GOAL_DISTANCE] = wp.clamp(wp.length(wp.vec2(dx, dy)), -GOAL_DISTANCE_BOUND, GOAL_DISTANCE_BOUND)
    obs[world, ROBOT_SIN_BEARING] = wp.sin(bearing)
    obs[world, ROBOT_COS_BEARING] = wp.cos(bearing)


@wp.func
def scaled_odometry(odometry: wp.vec3, scale: float) -> wp.vec3:
    """The pose a base's odometry reports when its encoders read ``scale`` times the distance driven: the position
    from the odometry frame's origin (the episode's start) scaled, the gyro's heading kept."""
    return wp.vec3(scale * odometry[0], scale * odometry[1], odometry[2])


@wp.func
def write_robot_observation(
    obs: wp.array2d(dtype=float),
    world: int,
    goal: wp.vec2,
    odometry: wp.vec3,
    odom_twist: wp.vec2,
    rpy: wp.vec3,
    yaw_rate: float,
):
    """:data:`ROBOT_OBSERVATION`'s fields, each clipped to its bound: the goal from wheel odometry, the encoders'
    twist, the IMU's roll, pitch [rad] and yaw rate [rad/s]."""
    write_goal_observation(obs, world, goal, odometry)
    obs[world, ROBOT_ODOM_LINEAR] = wp.clamp(odom_twist[0], -ODOM_LINEAR_BOUND, ODOM_LINEAR_BOUND)
    obs[world, ROBOT_ODOM_ANGULAR] = wp.clamp(odom_twist[1], -ODOM_ANGULAR_BOUND, ODOM_ANGULAR_BOUND)
    obs[world, ROBOT_ROLL] = wp.clamp(rpy[0], -IMU_ROLL_BOUND, IMU_ROLL_BOUND)
    obs[world, ROBOT_PITCH] = wp.clamp(rpy[1], -IMU_PITCH_BOUND, IMU_PITCH_BOUND)
    obs[world, ROBOT_YAW_RATE] = wp.clamp(yaw_rate, -IMU_YAW_RATE_BOUND, IMU_YAW_RATE_BOUND)


@wp.func
def write_leading_fields(obs: wp.array2d(dtype=float), world: int, robot: int, task: TaskBuffers, rover: RoverState,
                         pose: wp.transform, head_err: float):
    """The observation's leading fields: the robot's (``robot`` 1) or the arena's."""
    r = rover.rpy[world]
    if robot != 0:
        scale = task.odom_scale[world]
        twist = rover.odom_twist[world]
        write_robot_observation(obs, world, task.goal_odom[world],
                                scaled_odometry(rover.odometry[world], scale) + task.odom_drift[world],
                                wp.vec2(scale * twist[0], twist[1]), r, body_yaw_rate(pose, rover.ang_vel[world]))
    else:
        write_arena_observation(obs, world, task.target[world], pose, rover.lin_vel[world], r[0],
                                rover.ang_vel[world][2], head_err)


@wp.func
def write_neutral_observation(obs: wp.array2d(dtype=float), world: int, robot: int, task: TaskBuffers):
    """A blown-up world's finite, neutral leading fields: at rest, the goal straight ahead (where it was last
    seen: the arena's target, or the robot's last distance)."""
    dim = OBS_DIM
    if robot != 0:
        dim = ROBOT_DIM
    for i in range(dim):
        obs[world, i] = 0.0
    if robot != 0:
        obs[world, ROBOT_GOAL_DISTANCE] = wp.clamp(task.prev_distance[world], -GOAL_DISTANCE_BOUND,
                                                   GOAL_DISTANCE_BOUND)
        obs[world, ROBOT_COS_BEARING] = 1.0
    else:
        target = task.target[world]
        obs[world, OBS_TARGET_X] = target[0]
        obs[world, OBS_TARGET_Y] = target[1]
        obs[world, OBS_COS_HEADING] = 1.0


@wp.kernel
def observe_reset(robot: int, mask: wp.array(dtype=bool), task: TaskBuffers, rover: RoverState, out: StepOutputs):
    """Observation (``out.obs``, ``out.distance``) of freshly reset worlds; primes the progress terms."""
    world = wp.tid()
    if not mask[world]:
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    target = task.target[world]
    err = heading_error(pose, target, rover.rpy[world][2])
    d = planar_distance(pose, target)
    task.prev_distance[world] = d
    task.prev_heading_error[world] = wp.abs(err)
    out.distance[world] = d
    if robot == 0 or robot == 1:  # else the path kernel (2) or a task's own field kernels (-1) write them
        write_leading_fields(out.obs, world, robot, task, rover, pose, err)


@wp.kernel
def observe_step(robot: int, task: TaskBuffers, rover: RoverState, out: StepOutputs):
    """Every world's leading fields after a step (a blown-up world's neutral ones); none for the path observation
    (``robot`` 2) or a task's own kind (-1), whose kernels write them."""
    world = wp.tid()
    if robot < 0 or robot > 1:
        return
    if rover.nonfinite[world] != 0:
        write_neutral_observation(out.obs, world, robot, task)
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    err = heading_error(pose, task.target[world], rover.rpy[world][2])
    write_leading_fields(out.obs, world, robot, task, rover, pose, err)


@wp.struct
class ScanReading:
    """How the observation reads a scan: the sectors' beams and REP 117's range rule (``atrv_warp.core.scan``)."""

    first: wp.array(dtype=wp.int32)  # (S,) each sector's first beam
    end: wp.array(dtype=wp.int32)  # (S,) one past its last beam
    clip: float  # [m]
    range_min: float  # [m]
    range_max: float  # [m]


@wp.func
def beam_reading(r: float, reading: ScanReading) -> float:
    """One beam as the observation reads it (REP 117): beyond range_max clear (1), below range_min blocked (0),
    else min(r, clip) / clip; NaN (an invalid beam) reads 2, which no sector keeps."""
    if wp.isnan(r):
        return 2.0
    if r > reading.range_max:
        return 1.0
    if r < reading.range_min:
        return 0.0
    return wp.min(r, reading.clip) / reading.clip


@wp.kernel
def write_scan_observation(
    ranges: wp.array2d(dtype=float),
    nonfinite: wp.array(dtype=wp.int32),
    first_column: int,
    reading: ScanReading,
    obs: wp.array2d(dtype=float),
):
    """Observed scan (dim = (N, sectors)): each sector's nearest valid return (:func:`beam_reading`), blocked (0)
    without a valid beam; a non-finite world observes an empty scan (1). ``atrv_warp.core.scan.sector_readings``
    is its torch twin."""
    world, sector = wp.tid()
    r = float(2.0)
    for i in range(reading.first[sector], reading.end[sector]):
        r = wp.min(r, beam_reading(ranges[world, i], reading))
    if r > 1.0:
        r = 0.0
    if nonfinite[world] != 0:
        r = 1.0
    obs[world, first_column + sector] = r


@wp.kernel
def record_actions(actions: wp.array2d(dtype=float), history: wp.array2d(dtype=wp.vec2)):
    """Push each world's action, clipped to [-1, 1], onto the front of its history (newest first; dim = N)."""
    world = wp.tid()
    n = history.shape[1]
    for j in range(n - 1):
        k = n - 1 - j
        history[world, k] = history[world, k - 1]
    history[world, 0] = wp.vec2(wp.clamp(actions[world, 0], -1.0, 1.0), wp.clamp(actions[world, 1], -1.0, 1.0))


@wp.kernel
def clear_actions(mask: wp.array(dtype=bool), history: wp.array2d(dtype=wp.vec2)):
    """Forget the masked worlds' actions (a new episode has chosen none yet; dim = (N, history))."""
    world, k = wp.tid()
    if mask[world]:
        history[world, k] = wp.vec2(0.0, 0.0)


@wp.kernel
def write_action_observation(history: wp.array2d(dtype=wp.vec2), first_column: int, obs: wp.array2d(dtype=float)):
    """Observed last actions (dim = (N, history)): step k's [left, right] at ``first_column + 2 k``."""
    world, k = wp.tid()
    a = history[world, k]
    obs[world, first_column + 2 * k] = a[0]
    obs[world, first_column + 2 * k + 1] = a[1]
