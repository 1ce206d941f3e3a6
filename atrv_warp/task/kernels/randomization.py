"""Domain-randomization kernels: per-world draws of the physics, the action latency buffer and motor lag, and
the observation noise (:mod:`atrv_warp.task.randomization` declares what they do).

One thread per world. Every draw comes from a stream of its own: (seed, world) hashed with a salt that sets
these streams apart from the episode sampler's, then the episode, then (``interval`` draws and noise) the
step, then the parameter. So a world's draws do not depend on which other parameters are randomized, on
the number of worlds, or on when other worlds reset.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.params import WorldPhysics
from atrv_warp.task.kernels.observe import (
    IMU_PITCH_BOUND,
    IMU_ROLL_BOUND,
    IMU_YAW_RATE_BOUND,
    OBS_ROLL,
    OBS_ROVER_VX,
    OBS_ROVER_VY,
    OBS_YAW_RATE,
    ODOM_ANGULAR_BOUND,
    ODOM_LINEAR_BOUND,
    ROBOT_ODOM_ANGULAR,
    ROBOT_ODOM_LINEAR,
    ROBOT_PITCH,
    ROBOT_ROLL,
    ROBOT_YAW_RATE,
    ROLL_BOUND,
    VELOCITY_BOUND,
    YAW_RATE_BOUND,
    scaled_odometry,
    write_goal_observation,
)
from atrv_warp.task.kernels.state import TaskBuffers
from atrv_warp.task.kernels.steps import twist_command
from atrv_warp.task.randomization import MAX_LATENCY, PHYSICS_DRAWS

__all__ = [
    "DRAW_COUNT",
    "HISTORY",
    "MODE_CODES",
    "PHASE_EPISODE",
    "PHASE_TICK",
    "ActionDelay",
    "DrawSpec",
    "ObservationNoise",
    "add_observation_noise",
    "add_robot_observation_noise",
    "delay_actions",
    "delay_twist",
    "draw_physics",
]

# Rows of DrawSpec: the physical parameters in PHYSICS_DRAWS order, then the latency and the motor lag.
DRAW_FRICTION = wp.constant(PHYSICS_DRAWS.index("friction"))
DRAW_PAYLOAD_MASS = wp.constant(PHYSICS_DRAWS.index("payload_mass"))
DRAW_PAYLOAD_OFFSET = wp.constant(PHYSICS_DRAWS.index("payload_offset"))
DRAW_TORQUE_SCALE = wp.constant(PHYSICS_DRAWS.index("torque_scale"))
DRAW_SPEED_LIMIT = wp.constant(PHYSICS_DRAWS.index("speed_limit"))
DRAW_WHEEL_RADIUS = wp.constant(PHYSICS_DRAWS.index("wheel_radius"))
DRAW_STIFFNESS = wp.constant(PHYSICS_DRAWS.index("stiffness"))
DRAW_LATENCY = wp.constant(len(PHYSICS_DRAWS))
DRAW_MOTOR_LAG = wp.constant(len(PHYSICS_DRAWS) + 1)
DRAW_ODOMETRY_SCALE = wp.constant(len(PHYSICS_DRAWS) + 2)
DRAW_ODOMETRY_SLIP_GAIN = wp.constant(len(PHYSICS_DRAWS) + 3)
DRAW_COUNT = len(PHYSICS_DRAWS) + 4

# DrawSpec.mode codes (RandomizationConfig's DRAW_MODES, and 0 for a parameter left alone)
MODE_OFF = wp.constant(0)
MODE_STARTUP = wp.constant(1)
MODE_RESET = wp.constant(2)
MODE_INTERVAL = wp.constant(3)
MODE_CODES = {"startup": 1, "reset": 2, "interval": 3}

PHASE_EPISODE = wp.constant(0)
"""draw_physics at an episode's start (a reset)"""
PHASE_TICK = wp.constant(1)
"""draw_physics after a step (the ``interval`` draws)"""

HISTORY = wp.constant(MAX_LATENCY + 1)
"""Slots of the action ring buffer."""

STREAM_SALT = wp.constant(0x2B7E1516)
"""Sets the randomization's streams apart from the episode sampler's (same seed, world and episode)."""


@wp.struct
class DrawSpec:
    """Each randomized quantity's range and mode, DRAW_COUNT rows."""

    low: wp.array(dtype=float)
    high: wp.array(dtype=float)
    log: wp.array(dtype=int)
    mode: wp.array(dtype=int)
    every: wp.array(dtype=int)


@wp.struct
class ActionDelay:
    """Each world's latency [steps], motor lag, ring buffer and lagged torques."""

    latency: wp.array(dtype=wp.int32)
    alpha: wp.array(dtype=float)  # 1 - exp(-step_dt / tau); 1 = no lag (torque actions: the lag per step)
    tau: wp.array(dtype=float)  # the drawn lag's time constant [s] (twist actions: the driver's lag per substep)
    history: wp.array2d(dtype=wp.vec2)  # (N, HISTORY) commanded torques [N·m]
    applied: wp.array(dtype=wp.vec2)  # the lag filter's state [N·m]


@wp.struct
class ObservationNoise:
    """Standard deviations of the observation noise (:class:`~atrv_warp.sim.config.SensorNoise`)."""

    velocity: float  # [m/s]
    gyro: float  # [rad/s]
    attitude: float  # [rad]
    odom_angular: float  # the wheel odometry's yaw rate [rad/s]: the velocity noise through the kinematics


@wp.func
def world_stream(seed: int, world: int, episode: int) -> wp.uint32:
    h = wp.rand_init(seed, world)
    return wp.rand_init(wp.int32(h) ^ STREAM_SALT, episode)


@wp.func
def due(spec: DrawSpec, p: int, phase: int, episode: int, steps: int) -> bool:
    """Whether quantity ``p`` is drawn now."""
    mode = spec.mode[p]
    if mode == MODE_OFF:
        return False
    if phase == PHASE_EPISODE:
        return mode != MODE_STARTUP or episode == 0
    return mode == MODE_INTERVAL and steps > 0 and steps % spec.every[p] == 0


@wp.func
def sample(spec: DrawSpec, p: int, stream: wp.uint32, lane: int) -> float:
    """A value of quantity ``p`` from its own sub-stream (``lane`` tells the payload offset's x and y apart)."""
    state = wp.rand_init(wp.int32(stream), p * 2 + lane)
    u = wp.randf(state)
    lo = spec.low[p]
    hi = spec.high[p]
    if spec.log[p] != 0:
        return wp.exp(wp.log(lo) + u * (wp.log(hi) - wp.log(lo)))
    return lo + u * (hi - lo)


@wp.kernel
def draw_physics(
    seed: int,
    phase: int,
    step_dt: float,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    spec: DrawSpec,
    physics: WorldPhysics,
    payload_mass: wp.array(dtype=float),
    payload_offset: wp.array(dtype=wp.vec3),
    delay: ActionDelay,
):
    """Draw the masked worlds' due quantities: at an episode's start (``PHASE_EPISODE``, before the episode
    sampler counts it) or after a step (``PHASE_TICK``, the ``interval`` draws)."""
    world = wp.tid()
    if not mask[world]:
        return
    episode = task.episode[world]
    steps = task.step_count[world]
    stream = world_stream(seed, world, episode)
    if phase == PHASE_TICK:
        stream = wp.rand_init(wp.int32(stream), steps)
    else:
        delay.applied[world] = wp.vec2(0.0, 0.0)  # a new episode starts with the motors at rest
    if due(spec, DRAW_FRICTION, phase, episode, steps):
        physics.friction[world] = sample(spec, DRAW_FRICTION, stream, 0)
    if due(spec, DRAW_PAYLOAD_MASS, phase, episode, steps):
        payload_mass[world] = sample(spec, DRAW_PAYLOAD_MASS, stream, 0)
    if due(spec, DRAW_PAYLOAD_OFFSET, phase, episode, steps):
        payload_offset[world] = wp.vec3(sample(spec, DRAW_PAYLOAD_OFFSET, stream, 0),
                                        sample(spec, DRAW_PAYLOAD_OFFSET, stream, 1), 0.0)
    if due(spec, DRAW_TORQUE_SCALE, phase, episode, steps):
        physics.torque_scale[world] = sample(spec, DRAW_TORQUE_SCALE, stream, 0)
    if due(spec, DRAW_SPEED_LIMIT, phase, episode, steps):
        physics.speed_limit[world] = sample(spec, DRAW_SPEED_LIMIT, stream, 0)
    if due(spec, DRAW_WHEEL_RADIUS, phase, episode, steps):
        physics.wheel_radius[world] = sample(spec, DRAW_WHEEL_RADIUS, stream, 0)
    if due(spec, DRAW_STIFFNESS, phase, episode, steps):
        physics.stiffness[world] = sample(spec, DRAW_STIFFNESS, stream, 0)
    if due(spec, DRAW_LATENCY, phase, episode, steps):
        # whole steps: the spec's range is [low, high + 1), rounded down
        v = sample(spec, DRAW_LATENCY, stream, 0)
        delay.latency[world] = wp.int32(wp.min(int(v), int(spec.high[DRAW_LATENCY]) - 1))
    if due(spec, DRAW_MOTOR_LAG, phase, episode, steps):
        tau = sample(spec, DRAW_MOTOR_LAG, stream, 0)
        alpha = float(1.0)
        if tau > 0.0:
            alpha = 1.0 - wp.exp(-step_dt / tau)
        delay.alpha[world] = alpha
        delay.tau[world] = tau
    if due(spec, DRAW_ODOMETRY_SCALE, phase, episode, steps):
        task.odom_scale[world] = sample(spec, DRAW_ODOMETRY_SCALE, stream, 0)
    if due(spec, DRAW_ODOMETRY_SLIP_GAIN, phase, episode, steps):
        task.odom_slip_gain[world] = sample(spec, DRAW_ODOMETRY_SLIP_GAIN, stream, 0)


@wp.func
def delayed_command(world: int, cmd: wp.vec2, task: TaskBuffers, delay: ActionDelay) -> wp.vec2:
    """Push this step's command into the world's ring buffer; the one chosen ``latency`` steps ago comes out (zero
    before the episode's first)."""
    t = int(task.step_count[world])
    delay.history[world, t % HISTORY] = cmd
    lat = int(delay.latency[world])
    delayed = wp.vec2(0.0, 0.0)
    if t >= lat:
        delayed = delay.history[world, (t - lat) % HISTORY]
    return delayed


@wp.kernel
def delay_actions(
    actions: wp.array2d(dtype=float),
    action_scale: float,
    task: TaskBuffers,
    delay: ActionDelay,
    commands: wp.array(dtype=wp.vec2),
):
    """Wheel torques [N·m] for this step: the world's action (clipped, scaled) goes into its ring buffer, the one
    chosen ``latency`` steps ago comes out (zero torque before the episode's first), through the motor lag."""
    world = wp.tid()
    cmd = wp.vec2(wp.clamp(actions[world, 0], -1.0, 1.0), wp.clamp(actions[world, 1], -1.0, 1.0)) * action_scale
    delayed = delayed_command(world, cmd, task, delay)
    prev = delay.applied[world]
    out = prev + delay.alpha[world] * (delayed - prev)
    delay.applied[world] = out
    commands[world] = out


@wp.kernel
def add_observation_noise(
    seed: int,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    noise: ObservationNoise,
    nonfinite: wp.array(dtype=wp.int32),
    obs: wp.array2d(dtype=float),
):
    """Zero-mean Gaussian noise on the velocity, roll and yaw-rate fields of the masked worlds' observation,
    clipped to the fields' bounds, from the world's (episode, step) stream."""
    world = wp.tid()
    if not mask[world] or nonfinite[world] != 0:
        return
    stream = world_stream(seed, world, task.episode[world])
    state = wp.rand_init(wp.int32(stream) ^ 0x5F3759DF, int(task.step_count[world]))
    vx = obs[world, OBS_ROVER_VX] + noise.velocity * wp.randn(state)
    vy = obs[world, OBS_ROVER_VY] + noise.velocity * wp.randn(state)
    roll = obs[world, OBS_ROLL] + noise.attitude * wp.randn(state)
    rate = obs[world, OBS_YAW_RATE] + noise.gyro * wp.randn(state)
    obs[world, OBS_ROVER_VX] = wp.clamp(vx, -VELOCITY_BOUND, VELOCITY_BOUND)
    obs[world, OBS_ROVER_VY] = wp.clamp(vy, -VELOCITY_BOUND, VELOCITY_BOUND)
    obs[world, OBS_ROLL] = wp.clamp(roll, -ROLL_BOUND, ROLL_BOUND)
    obs[world, OBS_YAW_RATE] = wp.clamp(rate, -YAW_RATE_BOUND, YAW_RATE_BOUND)


@wp.kernel
def delay_twist(
    actions: wp.array2d(dtype=float),
    limits: wp.vec2,
    task: TaskBuffers,
    delay: ActionDelay,
    twist: wp.array(dtype=wp.vec2),
    age: wp.array(dtype=float),
):
    """A delayed /cmd_vel: the world's twist for its action (clipped, times ``limits`` = (max_linear [m/s],
    max_angular [rad/s])) goes into its ring buffer, the one chosen ``latency`` steps ago reaches the driver
    (``twist``, with its command ``age`` [s] restarted). The motor lag is the driver's, per substep."""
    world = wp.tid()
    twist[world] = delayed_command(world, twist_command(actions, world, limits), task, delay)
    age[world] = 0.0


@wp.kernel
def add_robot_observation_noise(
    seed: int,
    mask: wp.array(dtype=bool),
    advance: int,
    step_dt: float,
    task: TaskBuffers,
    noise: ObservationNoise,
    odometry: wp.array(dtype=wp.vec3),
    nonfinite: wp.array(dtype=wp.int32),
    shift: int,
    goal: int,
    obs: wp.array2d(dtype=float),
):
    """The robot observation's noise in the masked worlds, from the world's (episode, step) stream: zero-mean
    Gaussian noise on the odometry's twist (``velocity``, ``odom_angular``), the IMU's roll and pitch
    (``attitude``) and yaw rate (``gyro``), each clipped to its bound; and the fused odometry's drift, a random walk
    over ``step_dt`` [s] of the encoders' speed noise along the heading and of the gyro's noise in the heading
    (``advance`` = 1: a step; 0: a reset or a re-observation), which moves the pose the goal is observed from
    (``goal`` 1). The twist and IMU fields stand ``shift`` columns after the robot observation's (the path
    observation's, after its plan; ``goal`` 0: it sees its plan from the localized pose, not the odometry's)."""
    world = wp.tid()
    if not mask[world] or nonfinite[world] != 0:
        return
    stream = world_stream(seed, world, task.episode[world])
    state = wp.rand_init(wp.int32(stream) ^ 0x5F3759DF, int(task.step_count[world]))
    dv = noise.velocity * wp.randn(state)
    dw = noise.odom_angular * wp.randn(state)
    roll = obs[world, ROBOT_ROLL + shift] + noise.attitude * wp.randn(state)
    pitch = obs[world, ROBOT_PITCH + shift] + noise.attitude * wp.randn(state)
    dg = noise.gyro * wp.randn(state)
    rate = obs[world, ROBOT_YAW_RATE + shift] + dg
    obs[world, ROBOT_ODOM_LINEAR + shift] = wp.clamp(obs[world, ROBOT_ODOM_LINEAR + shift] + dv, -ODOM_LINEAR_BOUND, ODOM_LINEAR_BOUND)
    obs[world, ROBOT_ODOM_ANGULAR + shift] = wp.clamp(obs[world, ROBOT_ODOM_ANGULAR + shift] + dw, -ODOM_ANGULAR_BOUND,
                                              ODOM_ANGULAR_BOUND)
    obs[world, ROBOT_ROLL + shift] = wp.clamp(roll, -IMU_ROLL_BOUND, IMU_ROLL_BOUND)
    obs[world, ROBOT_PITCH + shift] = wp.clamp(pitch, -IMU_PITCH_BOUND, IMU_PITCH_BOUND)
    obs[world, ROBOT_YAW_RATE + shift] = wp.clamp(rate, -IMU_YAW_RATE_BOUND, IMU_YAW_RATE_BOUND)
    drift = task.odom_drift[world]
    if advance != 0:
        yaw = odometry[world][2] + drift[2]
        drift = drift + wp.vec3(dv * step_dt * wp.cos(yaw), dv * step_dt * wp.sin(yaw), dg * step_dt)
        task.odom_drift[world] = drift
    if goal != 0:
        write_goal_observation(obs, world, task.goal_odom[world],
                               scaled_odometry(odometry[world], task.odom_scale[world]) + drift)
