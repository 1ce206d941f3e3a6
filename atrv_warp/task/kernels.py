"""Drive-to-target task kernels: reset sampling, observations, rewards and terminations.

One thread per world. Figures are the reference task's (``TaskConfig``): targets and starts
uniform in ±12 m, reach within 1 m (+4), wall/flip (-4), otherwise progress reward, 200-step
truncation. The observation layout, its bounds, the end reasons and the reward terms come from
:mod:`atrv_warp.task.spec`; each reward term is its own ``@wp.func`` and is written out per step.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.contact import FLAG_OBSTACLE
from atrv_warp.sim.kernels.obstacles import (
    OBSTACLE_BOX,
    OBSTACLE_CYLINDER,
    OBSTACLE_NONE,
    ObstacleSet,
    bounding_radius,
)
from atrv_warp.sim.kernels.terrain import TerrainGrid
from atrv_warp.task.spec import OBS_DIM, OBS_INDEX, OBSERVATION, REWARD_TERMS, ROBOT_OBSERVATION, EndReason

# Why an episode ended (``end_reason``), from task_spec.EndReason.
END_NONE = wp.constant(int(EndReason.RUNNING))
END_SUCCESS = wp.constant(int(EndReason.SUCCESS))
END_WALL = wp.constant(int(EndReason.WALL))
END_FLIP = wp.constant(int(EndReason.FLIP))
END_TIMEOUT = wp.constant(int(EndReason.TIMEOUT))
END_NONFINITE = wp.constant(int(EndReason.NONFINITE))
END_OBSTACLE = wp.constant(int(EndReason.OBSTACLE))

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

# Reward-term columns of ``reward_terms``, from task_spec.REWARD_TERMS.
TERM_PROGRESS = wp.constant(REWARD_TERMS.index("progress"))
TERM_HEADING = wp.constant(REWARD_TERMS.index("heading"))
TERM_STEP_PENALTY = wp.constant(REWARD_TERMS.index("step_penalty"))
TERM_SUCCESS = wp.constant(REWARD_TERMS.index("success"))
TERM_FAILURE = wp.constant(REWARD_TERMS.index("failure"))
TERM_CLEARANCE = wp.constant(REWARD_TERMS.index("clearance"))
NUM_TERMS = wp.constant(len(REWARD_TERMS))


@wp.struct
class TaskParams:
    spawn_bound: float  # targets and starts uniform in [-bound, bound]^2 [m]
    reach_radius: float  # success distance [m]
    flip_roll: float  # |roll| above this ends the episode [rad]
    max_steps: int  # truncation
    success_reward: float
    failure_reward: float  # (negative) on wall or flip
    heading_weight: float  # weight of heading progress
    step_penalty: float  # subtracted every step
    clearance_weight: float  # cost per metre an obstacle reaches inside clearance_radius [1/m]
    clearance_radius: float  # [m] from the chassis origin
    robot_observation: int  # 1: the observation's leading fields are ROBOT_OBSERVATION's, 0: OBSERVATION's
    step_dt: float  # [s]


@wp.struct
class RoverState:
    """The simulator state the task reads, one struct so that a launch cannot reorder it
    (built once from :attr:`atrv_warp.sim.RoverSim.buffers`)."""

    body_q: wp.array(dtype=wp.transform)
    bodies_per_world: int
    chassis_body: int
    lin_vel: wp.array(dtype=wp.vec3)
    ang_vel: wp.array(dtype=wp.vec3)
    rpy: wp.array(dtype=wp.vec3)
    contact_flags: wp.array(dtype=wp.int32)
    nonfinite: wp.array(dtype=wp.int32)
    odometry: wp.array(dtype=wp.vec3)  # the base's fused odometry x [m], y [m], yaw [rad] (odometry frame; encoders
    # and gyro, the driver's ``fused``)
    odom_twist: wp.array(dtype=wp.vec2)  # the encoders' linear [m/s], angular [rad/s]


@wp.struct
class StepOutputs:
    """What one step writes per world (all length N; ``obs`` and ``reward_terms`` have columns)."""

    obs: wp.array2d(dtype=float)
    reward: wp.array(dtype=float)
    reward_terms: wp.array2d(dtype=float)
    terminated: wp.array(dtype=bool)
    truncated: wp.array(dtype=bool)
    end_reason: wp.array(dtype=wp.int32)
    distance: wp.array(dtype=float)


@wp.struct
class TaskBuffers:
    """Per-world task state (all length N)."""

    target: wp.array(dtype=wp.vec2)
    prev_distance: wp.array(dtype=float)
    prev_heading_error: wp.array(dtype=float)  # |heading error| at the previous step [rad]
    step_count: wp.array(dtype=wp.int32)
    episode: wp.array(dtype=wp.int32)  # episodes started in this world since seeding
    stream: wp.array(dtype=wp.int32)  # the reset stream this world draws from: its index, unless replaying another's
    goal_odom: wp.array(dtype=wp.vec2)  # the target in the odometry frame (the episode's start pose) [m]
    odom_drift: wp.array(dtype=wp.vec3)  # the odometry noise's random walk (x [m], y [m], yaw [rad]) this episode
    odom_scale: wp.array(dtype=float)  # the wheel odometry's distance per distance driven this episode [-] (1: exact)
    odom_slip_gain: wp.array(dtype=float)  # the odometry's extra distance per metre the encoders slip, this episode [-]


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


@wp.kernel
def sample_episodes(
    seed: int,
    params: TaskParams,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    poses: wp.array(dtype=wp.vec3),
):
    """Draw target, start position and yaw for masked worlds from a per-(world, episode) stream."""
    world = wp.tid()
    if not mask[world]:
        return
    h = wp.rand_init(seed, task.stream[world])
    state = wp.rand_init(wp.int32(h), task.episode[world])
    b = params.spawn_bound
    task.target[world] = wp.vec2(wp.randf(state, -b, b), wp.randf(state, -b, b))
    poses[world] = wp.vec3(wp.randf(state, -b, b), wp.randf(state, -b, b), wp.randf(state, -wp.pi, wp.pi))
    task.episode[world] = task.episode[world] + 1
    task.step_count[world] = 0


@wp.func
def write_observation(
    obs: wp.array2d(dtype=float),
    world: int,
    params: TaskParams,
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
def write_task_observation(
    obs: wp.array2d(dtype=float),
    world: int,
    params: TaskParams,
    task: TaskBuffers,
    rover: RoverState,
    pose: wp.transform,
    head_err: float,
):
    """The observation's leading fields: the robot's (``params.robot_observation``) or the arena's."""
    r = rover.rpy[world]
    if params.robot_observation != 0:
        scale = task.odom_scale[world]
        twist = rover.odom_twist[world]
        write_robot_observation(obs, world, task.goal_odom[world],
                                scaled_odometry(rover.odometry[world], scale) + task.odom_drift[world],
                                wp.vec2(scale * twist[0], twist[1]), r, body_yaw_rate(pose, rover.ang_vel[world]))
    else:
        write_observation(obs, world, params, task.target[world], pose, rover.lin_vel[world], r[0],
                          rover.ang_vel[world][2], head_err)


@wp.func
def write_neutral_observation(obs: wp.array2d(dtype=float), world: int, params: TaskParams, task: TaskBuffers):
    """A blown-up world's finite, neutral leading fields: at rest, the goal straight ahead (where it was last
    seen: the arena's target, or the robot's last distance)."""
    dim = OBS_DIM
    if params.robot_observation != 0:
        dim = ROBOT_DIM
    for i in range(dim):
        obs[world, i] = 0.0
    if params.robot_observation != 0:
        obs[world, ROBOT_GOAL_DISTANCE] = wp.clamp(task.prev_distance[world], -GOAL_DISTANCE_BOUND,
                                                   GOAL_DISTANCE_BOUND)
        obs[world, ROBOT_COS_BEARING] = 1.0
    else:
        target = task.target[world]
        obs[world, OBS_TARGET_X] = target[0]
        obs[world, OBS_TARGET_Y] = target[1]
        obs[world, OBS_COS_HEADING] = 1.0


@wp.kernel
def locate_goals(mask: wp.array(dtype=bool), starts: wp.array(dtype=wp.vec3), task: TaskBuffers):
    """The masked worlds' targets in their odometry frame, whose origin is the episode's start pose (x [m],
    y [m], yaw [rad]): ``R(-yaw) (target - start)`` [m]."""
    world = wp.tid()
    if not mask[world]:
        return
    s = starts[world]
    d = task.target[world] - wp.vec2(s[0], s[1])
    c = wp.cos(s[2])
    n = wp.sin(s[2])
    task.goal_odom[world] = wp.vec2(c * d[0] + n * d[1], -n * d[0] + c * d[1])


@wp.func
def twist_command(actions: wp.array2d(dtype=float), world: int, limits: wp.vec2) -> wp.vec2:
    """The twist (linear [m/s], angular [rad/s]) of a world's action: clipped to [-1, 1], times ``limits``
    (max_linear, max_angular); ``atrv_warp.task.spec.action_to_twist`` is its torch twin."""
    return wp.vec2(wp.clamp(actions[world, 0], -1.0, 1.0) * limits[0], wp.clamp(actions[world, 1], -1.0, 1.0) * limits[1])


@wp.kernel
def command_twist(actions: wp.array2d(dtype=float), limits: wp.vec2, twist: wp.array(dtype=wp.vec2),
                  age: wp.array(dtype=float)):
    """Every world's /cmd_vel for this step (:func:`twist_command`) into the driver's ``twist``, with its command
    ``age`` [s] restarted."""
    world = wp.tid()
    twist[world] = twist_command(actions, world, limits)
    age[world] = 0.0


@wp.kernel
def observe_reset(
    params: TaskParams,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    rover: RoverState,
    out: StepOutputs,
):
    """Observation (``out.obs``, ``out.distance``) of freshly reset worlds; primes the progress terms."""
    world = wp.tid()
    if not mask[world]:
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    r = rover.rpy[world]
    target = task.target[world]
    err = heading_error(pose, target, r[2])
    d = planar_distance(pose, target)
    task.prev_distance[world] = d
    task.prev_heading_error[world] = wp.abs(err)
    out.distance[world] = d
    write_task_observation(out.obs, world, params, task, rover, pose, err)


@wp.func
def progress_term(prev_distance: float, distance: float) -> float:
    """Distance gained toward the target this step [m]."""
    return prev_distance - distance


@wp.func
def heading_term(weight: float, prev_abs_error: float, abs_error: float) -> float:
    """``weight`` x the reduction of |heading error| this step."""
    return weight * (prev_abs_error - abs_error)


@wp.func
def step_penalty_term(step_penalty: float) -> float:
    """The cost of a non-terminal step."""
    return -step_penalty


@wp.func
def clearance_term(params: TaskParams, obstacles: ObstacleSet, world: int, pose: wp.transform) -> float:
    """``-clearance_weight`` x how far the nearest obstacle's bounding circle reaches inside ``clearance_radius``
    of the chassis origin [m]."""
    if params.clearance_weight == 0.0:
        return 0.0
    p = wp.transform_get_translation(pose)
    inside = float(0.0)  # a variable the loop changes (Warp)
    for o in range(obstacles.count):
        kind = obstacles.kind[world, o]
        if kind != OBSTACLE_NONE:
            q = obstacles.pose[world, o]
            gap = wp.length(wp.vec2(q[0] - p[0], q[1] - p[1])) - bounding_radius(kind, obstacles.size[world, o])
            inside = wp.max(inside, params.clearance_radius - gap)
    return -params.clearance_weight * inside


@wp.func
def clear_terms(terms: wp.array2d(dtype=float), world: int):
    for i in range(NUM_TERMS):
        terms[world, i] = 0.0


@wp.kernel
def compute_step_outcome(
    params: TaskParams,
    task: TaskBuffers,
    rover: RoverState,
    obstacles: ObstacleSet,
    out: StepOutputs,
):
    """Observation, reward (and its terms, which sum to it) and termination of every world after
    one step. The checks come in a fixed order: success, flip, obstacle, other contact, else a
    running step."""
    world = wp.tid()
    steps = task.step_count[world] + 1
    task.step_count[world] = steps
    target = task.target[world]
    if rover.nonfinite[world] != 0:
        # Contain a blown-up world: a finite, neutral observation and reward, then a reset.
        write_neutral_observation(out.obs, world, params, task)
        clear_terms(out.reward_terms, world)
        out.reward[world] = 0.0
        out.terminated[world] = True
        out.truncated[world] = False
        out.end_reason[world] = END_NONFINITE
        out.distance[world] = task.prev_distance[world]
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    r = rover.rpy[world]
    err = heading_error(pose, target, r[2])
    d = planar_distance(pose, target)
    gain = task.odom_slip_gain[world]
    if params.robot_observation != 0 and gain != 0.0:
        # the encoders' slip this step (their forward speed less the chassis's), amplified into the odometry's drift
        # along its heading (RandomizationConfig.odometry_slip_gain)
        v_true = wp.quat_rotate_inv(wp.transform_get_rotation(pose), rover.lin_vel[world])[0]
        slip = gain * (rover.odom_twist[world][0] - v_true) * params.step_dt
        yaw = rover.odometry[world][2] + task.odom_drift[world][2]
        task.odom_drift[world] = task.odom_drift[world] + wp.vec3(slip * wp.cos(yaw), slip * wp.sin(yaw), 0.0)
    write_task_observation(out.obs, world, params, task, rover, pose, err)
    reason = END_NONE
    clear_terms(out.reward_terms, world)
    if d < params.reach_radius:
        reason = END_SUCCESS
        out.reward_terms[world, TERM_SUCCESS] = params.success_reward
    elif wp.abs(r[0]) > params.flip_roll:
        # before the contact check: a flipping chassis usually also touches the ground
        reason = END_FLIP
        out.reward_terms[world, TERM_FAILURE] = params.failure_reward
    elif (rover.contact_flags[world] & FLAG_OBSTACLE) != 0:
        reason = END_OBSTACLE
        out.reward_terms[world, TERM_FAILURE] = params.failure_reward
    elif rover.contact_flags[world] != 0:
        # wall, or the chassis on the ground: any contact beyond the wheels' ground contacts
        reason = END_WALL
        out.reward_terms[world, TERM_FAILURE] = params.failure_reward
    else:
        out.reward_terms[world, TERM_PROGRESS] = progress_term(task.prev_distance[world], d)
        out.reward_terms[world, TERM_HEADING] = heading_term(params.heading_weight, task.prev_heading_error[world],
                                                         wp.abs(err))
        out.reward_terms[world, TERM_STEP_PENALTY] = step_penalty_term(params.step_penalty)
        out.reward_terms[world, TERM_CLEARANCE] = clearance_term(params, obstacles, world, pose)
    rew = wp.float32(0.0)
    for i in range(NUM_TERMS):  # in REWARD_TERMS order: progress + heading - penalty as before
        rew += out.reward_terms[world, i]
    task.prev_distance[world] = d
    task.prev_heading_error[world] = wp.abs(err)
    term = reason != END_NONE
    trunc = (not term) and steps >= params.max_steps
    if trunc:
        reason = END_TIMEOUT
    out.reward[world] = rew
    out.terminated[world] = term
    out.truncated[world] = trunc
    out.end_reason[world] = reason
    out.distance[world] = d


@wp.struct
class SceneParams:
    """How the navigation sampler lays out an episode (see :class:`atrv_warp.task.config.TaskConfig`)."""

    distance_min: float  # start-to-target distance range [m]
    distance_max: float
    obstacles: int  # obstacles per episode (<= the simulator's slots)
    on_path: int  # of which across the start-target line
    path_offset: float  # [m]
    size_min: float  # cylinder radius / box half side range [m]
    size_max: float
    clearance: float  # from start and target [m]
    tiles: int  # terrain tiles to draw from (1 on the flat arena)


@wp.func
def obstacle_clear(q: wp.vec2, r: float, start: wp.vec2, target: wp.vec2, clearance: float) -> bool:
    return wp.length(q - start) > r + clearance and wp.length(q - target) > r + clearance


@wp.kernel
def sample_nav_episodes(
    seed: int,
    params: TaskParams,
    scene: SceneParams,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    poses: wp.array(dtype=wp.vec3),
    obstacles: ObstacleSet,
    terrain: TerrainGrid,
):
    """Draw a masked world's episode: start and yaw, a target at a set distance, a terrain tile and
    an obstacle layout that keeps clear of both ends, from a per-(world, episode) stream."""
    world = wp.tid()
    if not mask[world]:
        return
    h = wp.rand_init(seed, task.stream[world])
    state = wp.rand_init(wp.int32(h), task.episode[world])
    b = params.spawn_bound
    start = wp.vec2(wp.randf(state, -b, b), wp.randf(state, -b, b))
    poses[world] = wp.vec3(start[0], start[1], wp.randf(state, -wp.pi, wp.pi))
    target = start
    for _ in range(32):  # a direction whose target lies inside the bound (the last try is clamped)
        a = wp.randf(state, -wp.pi, wp.pi)
        d = wp.randf(state, scene.distance_min, scene.distance_max)
        target = start + d * wp.vec2(wp.cos(a), wp.sin(a))
        if wp.abs(target[0]) <= b and wp.abs(target[1]) <= b:
            break
    target = wp.vec2(wp.clamp(target[0], -b, b), wp.clamp(target[1], -b, b))
    task.target[world] = target
    terrain.tile[world] = wp.int32(wp.min(int(wp.randf(state) * float(scene.tiles)), scene.tiles - 1))
    line = target - start
    length = wp.max(wp.length(line), 1.0e-6)
    along = line / length
    across = wp.vec2(-along[1], along[0])
    half = b + 2.0
    for o in range(obstacles.count):
        obstacles.kind[world, o] = 0
        if o >= scene.obstacles:
            continue
        for _ in range(8):  # retry a layout that would crowd the start or the target
            kind = OBSTACLE_CYLINDER
            if wp.randf(state) < 0.5:
                kind = OBSTACLE_BOX
            size = wp.vec2(wp.randf(state, scene.size_min, scene.size_max), 0.0)
            if kind == OBSTACLE_BOX:
                size = wp.vec2(size[0], wp.randf(state, scene.size_min, scene.size_max))
            q = wp.vec2(wp.randf(state, -half, half), wp.randf(state, -half, half))
            if o < scene.on_path:
                q = start + wp.randf(state, 0.35, 0.65) * line + wp.randf(state, -1.0, 1.0) * scene.path_offset * across
            yaw = wp.randf(state, -wp.pi, wp.pi)
            if obstacle_clear(q, bounding_radius(kind, size), start, target, scene.clearance):
                obstacles.kind[world, o] = kind
                obstacles.pose[world, o] = wp.vec3(q[0], q[1], yaw)
                obstacles.size[world, o] = size
                break
    task.episode[world] = task.episode[world] + 1
    task.step_count[world] = 0


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
