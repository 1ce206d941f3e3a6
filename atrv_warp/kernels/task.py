"""Drive-to-target task kernels: reset sampling, observations, rewards and terminations.

One thread per world. Figures are the reference task's (``TaskConfig``): targets and starts
uniform in ±12 m, reach within 1 m (+4), wall/flip (-4), otherwise progress reward, 200-step
truncation.
"""

from __future__ import annotations

import warp as wp

# Why an episode ended (``end_reason``).
END_NONE = wp.constant(0)
END_SUCCESS = wp.constant(1)
END_WALL = wp.constant(2)
END_FLIP = wp.constant(3)
END_TIMEOUT = wp.constant(4)
END_NONFINITE = wp.constant(5)

OBS_DIM = 10


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
    target_bound: float  # observation clip for target x, y [m]
    position_bound: float  # ... rover x, y [m]
    velocity_bound: float  # ... vx, vy [m/s]
    roll_bound: float  # ... roll [rad]
    yaw_rate_bound: float  # ... yaw rate [rad/s]


@wp.struct
class TaskBuffers:
    """Per-world task state (all length N)."""

    target: wp.array(dtype=wp.vec2)
    prev_distance: wp.array(dtype=float)
    prev_heading_error: wp.array(dtype=float)  # |heading error| at the previous step [rad]
    step_count: wp.array(dtype=wp.int32)
    episode: wp.array(dtype=wp.int32)  # episodes started in this world since seeding


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
    h = wp.rand_init(seed, world)
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
    obs[world, 0] = wp.clamp(target[0], -params.target_bound, params.target_bound)
    obs[world, 1] = wp.clamp(target[1], -params.target_bound, params.target_bound)
    obs[world, 2] = wp.clamp(p[0], -params.position_bound, params.position_bound)
    obs[world, 3] = wp.clamp(p[1], -params.position_bound, params.position_bound)
    obs[world, 4] = wp.clamp(lin_vel[0], -params.velocity_bound, params.velocity_bound)
    obs[world, 5] = wp.clamp(lin_vel[1], -params.velocity_bound, params.velocity_bound)
    obs[world, 6] = wp.clamp(roll, -params.roll_bound, params.roll_bound)
    obs[world, 7] = wp.clamp(yaw_rate, -params.yaw_rate_bound, params.yaw_rate_bound)
    obs[world, 8] = wp.sin(head_err)
    obs[world, 9] = wp.cos(head_err)


@wp.kernel
def observe_reset(
    params: TaskParams,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    body_q: wp.array(dtype=wp.transform),
    bodies_per_world: int,
    chassis_body: int,
    lin_vel: wp.array(dtype=wp.vec3),
    ang_vel: wp.array(dtype=wp.vec3),
    rpy: wp.array(dtype=wp.vec3),
    obs: wp.array2d(dtype=float),
    distance: wp.array(dtype=float),
):
    """Observation of freshly reset worlds; primes the progress terms."""
    world = wp.tid()
    if not mask[world]:
        return
    pose = body_q[world * bodies_per_world + chassis_body]
    r = rpy[world]
    target = task.target[world]
    err = heading_error(pose, target, r[2])
    d = planar_distance(pose, target)
    task.prev_distance[world] = d
    task.prev_heading_error[world] = wp.abs(err)
    distance[world] = d
    write_observation(obs, world, params, target, pose, lin_vel[world], r[0], ang_vel[world][2], err)


@wp.kernel
def compute_step_outcome(
    params: TaskParams,
    task: TaskBuffers,
    body_q: wp.array(dtype=wp.transform),
    bodies_per_world: int,
    chassis_body: int,
    lin_vel: wp.array(dtype=wp.vec3),
    ang_vel: wp.array(dtype=wp.vec3),
    rpy: wp.array(dtype=wp.vec3),
    contact_flags: wp.array(dtype=wp.int32),
    nonfinite: wp.array(dtype=wp.int32),
    obs: wp.array2d(dtype=float),
    reward: wp.array(dtype=float),
    terminated: wp.array(dtype=bool),
    truncated: wp.array(dtype=bool),
    end_reason: wp.array(dtype=wp.int32),
    distance: wp.array(dtype=float),
):
    """Observation, reward and termination of every world after one step."""
    world = wp.tid()
    steps = task.step_count[world] + 1
    task.step_count[world] = steps
    target = task.target[world]
    if nonfinite[world] != 0:
        # Contain a blown-up world: a finite, neutral observation and reward, then a reset.
        for i in range(OBS_DIM):
            obs[world, i] = 0.0
        obs[world, 0] = target[0]
        obs[world, 1] = target[1]
        obs[world, 9] = 1.0
        reward[world] = 0.0
        terminated[world] = True
        truncated[world] = False
        end_reason[world] = END_NONFINITE
        distance[world] = task.prev_distance[world]
        return
    pose = body_q[world * bodies_per_world + chassis_body]
    r = rpy[world]
    err = heading_error(pose, target, r[2])
    d = planar_distance(pose, target)
    write_observation(obs, world, params, target, pose, lin_vel[world], r[0], ang_vel[world][2], err)
    reason = END_NONE
    rew = 0.0
    if d < params.reach_radius:
        reason = END_SUCCESS
        rew = params.success_reward
    elif wp.abs(r[0]) > params.flip_roll:
        # before the contact check: a flipping chassis usually also touches the ground
        reason = END_FLIP
        rew = params.failure_reward
    elif contact_flags[world] != 0:
        # wall, or the chassis on the ground: any contact beyond the wheels' ground contacts
        reason = END_WALL
        rew = params.failure_reward
    else:
        rew = (task.prev_distance[world] - d) + params.heading_weight * (
            task.prev_heading_error[world] - wp.abs(err)) - params.step_penalty
    task.prev_distance[world] = d
    task.prev_heading_error[world] = wp.abs(err)
    term = reason != END_NONE
    trunc = (not term) and steps >= params.max_steps
    if trunc:
        reason = END_TIMEOUT
    reward[world] = rew
    terminated[world] = term
    truncated[world] = trunc
    end_reason[world] = reason
    distance[world] = d
