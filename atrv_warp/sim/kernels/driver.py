"""The base's motor driver, per world, inside every solver substep: a (v, ω) command through speed and
acceleration limits and the skid-steer kinematics to each side's wheel-speed target, a PI loop on the side's
encoders within the torque limit (anti-windup), a first-order motor lag, and wheel odometry.

One thread per world. :func:`drive_wheels` replaces the torque kernel: a world in ``DRIVE_TORQUE`` mode applies
its torque commands as before (bit for bit), a world in ``DRIVE_TWIST`` mode runs the driver. Both integrate
wheel odometry, as a real base always reports it. :class:`atrv_warp.sim.driver.DriverConfig` documents the
figures; :mod:`atrv_warp.core.kinematics` is the kinematics' torch twin.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.params import WorldPhysics
from atrv_warp.sim.kernels.rover import MAX_WHEELS, RoverLayout, motor_torque

DRIVE_TORQUE = wp.constant(0)
"""A world whose ``commands`` are wheel torques [N·m]."""
DRIVE_TWIST = wp.constant(1)
"""A world whose ``twist`` (linear [m/s], angular [rad/s]) goes through the driver."""


@wp.struct
class DriverParams:
    """The driver's configuration (every world's the same: one base model). ``inf`` switches a limit off."""

    wheel_radius: float  # configured, not the physical (per-world) radius [m]
    effective_track: float  # configured track x effective track factor [m]
    kp: float  # [N·m per rad/s]
    ki: float  # [N·m per rad]
    torque_limit: float  # [N·m]
    max_linear: float  # [m/s]
    max_linear_accel: float  # [m/s²]
    max_angular: float  # [rad/s]
    max_angular_accel: float  # [rad/s²]
    timeout: float  # [s] without a command, the target drops to zero
    accel_time: float  # the fused odometry's complementary filter time constant [s] (0: the encoders' speed alone)
    dt: float  # the substep [s]
    implicit: int  # 1: the loop's proportional term acts on the wheel's speed at the substep's end (DriverConfig)


@wp.struct
class DriverState:
    """Each world's driver state, (N,) arrays: what the next substep reads (and a snapshot keeps)."""

    reference: wp.array(dtype=wp.vec2)  # the limited (linear, angular) being tracked
    integral: wp.array(dtype=wp.vec2)  # each side's PI integral [rad]
    applied: wp.array(dtype=wp.vec2)  # each side's torque after the motor lag [N·m]
    age: wp.array(dtype=float)  # time since the last command [s]
    odometry: wp.array(dtype=wp.vec3)  # x [m], y [m], yaw [rad] in the odometry frame (the pose at reset)
    odom_twist: wp.array(dtype=wp.vec2)  # linear [m/s], angular [rad/s] from the encoders
    fused: wp.array(dtype=wp.vec3)  # x [m], y [m], yaw [rad]: the encoders' distance along the gyro's heading
    fused_velocity: wp.array(dtype=wp.vec2)  # the fused odometry's velocity [m/s], odometry frame (accel_time > 0)
    velocity: wp.array(dtype=wp.vec3)  # the chassis' velocity at the last substep [m/s] (the accelerometer's)


@wp.func
def limit_twist(params: DriverParams, command: wp.vec2, reference: wp.vec2) -> wp.vec2:
    """``reference`` moved toward ``command`` clipped to the speed limits, by at most one substep of the
    acceleration limits (``diff_drive_controller``'s speed limiter, without jerk limits)."""
    v = wp.clamp(command[0], -params.max_linear, params.max_linear)
    w = wp.clamp(command[1], -params.max_angular, params.max_angular)
    dv = params.max_linear_accel * params.dt
    dw = params.max_angular_accel * params.dt
    return wp.vec2(reference[0] + wp.clamp(v - reference[0], -dv, dv),
                   reference[1] + wp.clamp(w - reference[1], -dw, dw))


@wp.func
def pi_side(target: float, speed: float, integral: float, kp: float, ki: float, limit: float, dt: float):
    """One side's wheel-speed PI: torque [N·m] within ``limit``, the new integral [rad], which integrates up to
    where the output meets the limit and no further (anti-windup), never moving away from the integral it had past
    it. Continuous in every input: a hold that switched on past the limit made a drive's path a rough function of
    the rover's parameters, and stalled the calibration's Gauss-Newton steps (the Jackal's, with its gain at the
    implicit rule's cap); and the output before the clamp [N·m] (an implicit loop's)."""
    error = target - speed
    candidate = integral + error * dt
    new = candidate
    if ki > 0.0:
        low = wp.min(integral, (-limit - kp * error) / ki)
        high = wp.max(integral, (limit - kp * error) / ki)
        new = wp.clamp(candidate, low, high)
    raw = kp * error + ki * new
    return wp.clamp(raw, -limit, limit), new, raw


@wp.func
def lag_factor(tau: float, dt: float) -> float:
    """First-order lag over ``dt`` with time constant ``tau`` [s] (0: none)."""
    if tau > 0.0:
        return 1.0 - wp.exp(-dt / tau)
    return 1.0


@wp.func
def driver_torques(params: DriverParams, command: wp.vec2, fresh: bool, speeds: wp.vec2, reference: wp.vec2,
                   integral: wp.vec2, applied: wp.vec2, lag: float):
    """One substep of the driver for one world: the new reference twist, integral and lagged side torques, and each
    side's output before its clamp and lag.
    ``fresh``: a command arrived within the timeout (else the target is zero)."""
    target = wp.vec2(0.0, 0.0)
    if fresh:
        target = command
    ref = limit_twist(params, target, reference)
    half = 0.5 * ref[1] * params.effective_track
    left, i_left, raw_left = pi_side((ref[0] - half) / params.wheel_radius, speeds[0], integral[0], params.kp,
                                     params.ki, params.torque_limit, params.dt)
    right, i_right, raw_right = pi_side((ref[0] + half) / params.wheel_radius, speeds[1], integral[1], params.kp,
                                        params.ki, params.torque_limit, params.dt)
    out = wp.vec2(left, right)
    new_applied = applied + lag_factor(lag, params.dt) * (out - applied)
    return ref, wp.vec2(i_left, i_right), new_applied, wp.vec2(raw_left, raw_right)


@wp.func
def side_speeds(layout: RoverLayout, joint_qd: wp.array(dtype=float), world: int) -> wp.vec2:
    """Mean forward speed of each side's wheels [rad/s] (the encoders)."""
    left = float(0.0)
    right = float(0.0)
    n_left = float(0.0)
    n_right = float(0.0)
    for k in range(MAX_WHEELS):
        if k < layout.wheel_count:
            v = layout.wheel_sign[k] * joint_qd[world * layout.dofs_per_world + layout.wheel_dof[k]]
            if layout.wheel_side[k] == 0:
                left = left + v
                n_left = n_left + 1.0
            else:
                right = right + v
                n_right = n_right + 1.0
    return wp.vec2(left / wp.max(n_left, 1.0), right / wp.max(n_right, 1.0))


@wp.func
def implicit_drive(command: float, beyond: float, speed: float, speed_limit: float, gain: float):
    """An implicit loop's drive on one wheel: (its torque [N·m], its slope [N·m per rad/s] in the wheel's speed change
    over the substep), the motor's torque for the loop's unclamped output (``command`` plus ``beyond``, its part past
    the limit, both through the motor's scale) and the loop's proportional ``gain`` through the scale and the taper.
    The friction solve integrates the slope with the wheel's contact and holds a wheel whose end torque would pass
    the limit at its clamped torque (:func:`~atrv_warp.sim.kernels.friction.friction_kernels`): the loop solved
    implicitly through its limit, where a saturated output driven explicitly flips between the limits every substep
    on a light, slipping wheel."""
    unclamped = command + beyond
    taper = motor_torque(1.0, speed, speed_limit)
    if unclamped < 0.0:
        taper = -motor_torque(-1.0, speed, speed_limit)
    return motor_torque(unclamped, speed, speed_limit), gain * taper


@wp.func
def geared_speeds(layout: RoverLayout, joint_qd: wp.array(dtype=float), world: int, command: wp.vec2,
                  beyond: wp.vec2, gain: wp.vec2, speed_limit: float, dt: float) -> wp.vec2:
    """Each side's forward speed [rad/s] at the end of a substep with its wheels geared together and driven by its
    motor's torque: the side's spin momentum plus its motor's impulse (each wheel's share of ``command`` through the
    taper, or an implicit loop's :func:`implicit_drive` where ``gain`` > 0), over the side's spin inertia. A torque of
    ``J_k (geared - speed_k) / dt`` on each wheel brings them all to it; over the side it sums to the motor's torque
    (the chain moves momentum between the wheels and adds none)."""
    momentum = wp.vec2(0.0, 0.0)
    inertia = wp.vec2(0.0, 0.0)
    for k in range(MAX_WHEELS):
        if k < layout.wheel_count:
            j = layout.wheel_inertia[k]
            side = layout.wheel_side[k]
            v = layout.wheel_sign[k] * joint_qd[world * layout.dofs_per_world + layout.wheel_dof[k]]
            tau = motor_torque(command[side], v, speed_limit)
            if gain[side] > 0.0:
                tau, _slope = implicit_drive(command[side], beyond[side], v, speed_limit, gain[side])
            p = j * v + tau * dt
            if side == 0:
                momentum = wp.vec2(momentum[0] + p, momentum[1])
                inertia = wp.vec2(inertia[0] + j, inertia[1])
            else:
                momentum = wp.vec2(momentum[0], momentum[1] + p)
                inertia = wp.vec2(inertia[0], inertia[1] + j)
    return wp.vec2(momentum[0] / wp.max(inertia[0], 1.0e-12), momentum[1] / wp.max(inertia[1], 1.0e-12))


@wp.func
def integrate_odometry(params: DriverParams, pose: wp.vec3, speeds: wp.vec2):
    """Wheel odometry over one substep (midpoint rule) from side speeds [rad/s], with the configured radius and
    effective track: the new pose and the twist (linear, angular)."""
    r = params.wheel_radius
    v = r * (speeds[0] + speeds[1]) * 0.5
    w = r * (speeds[1] - speeds[0]) / params.effective_track
    mid = pose[2] + 0.5 * w * params.dt
    yaw = pose[2] + w * params.dt
    yaw = wp.atan2(wp.sin(yaw), wp.cos(yaw))
    return wp.vec3(pose[0] + v * wp.cos(mid) * params.dt, pose[1] + v * wp.sin(mid) * params.dt, yaw), wp.vec2(v, w)


@wp.func
def integrate_fused(pose: wp.vec3, linear: float, yaw_rate: float, dt: float) -> wp.vec3:
    """The pose a base's filter keeps (``robot_localization`` fusing wheel odometry with an IMU): the encoders'
    forward speed along the heading the gyro's yaw rate integrates, over one substep (midpoint rule)."""
    mid = pose[2] + 0.5 * yaw_rate * dt
    yaw = pose[2] + yaw_rate * dt
    yaw = wp.atan2(wp.sin(yaw), wp.cos(yaw))
    return wp.vec3(pose[0] + linear * wp.cos(mid) * dt, pose[1] + linear * wp.sin(mid) * dt, yaw)


@wp.func
def accel_aided_velocity(estimate: wp.vec2, encoders: float, velocity_change: wp.vec3, forward: wp.vec3, left: wp.vec3,
                         yaw: float, accel_time: float, dt: float) -> wp.vec2:
    """The fused odometry's velocity [m/s] (odometry frame) one substep on: the accelerometer's reading integrated
    (the chassis' ``velocity_change`` [m/s] over the substep along its ``forward`` and ``left`` axes, gravity removed,
    turned to the odometry frame by the fused heading ``yaw``), pulled toward the encoders' velocity (their forward
    speed along ``yaw``) with time constant ``accel_time`` [s]. A complementary filter, as ``robot_localization``
    fuses an IMU's linear acceleration with wheel odometry: the encoders' velocity over spans longer than
    ``accel_time``, the accelerometer's over shorter ones, where the wheels slip (launches, turns)."""
    c = wp.cos(yaw)
    s = wp.sin(yaw)
    ax = wp.dot(velocity_change, forward)
    ay = wp.dot(velocity_change, left)
    integrated = estimate + wp.vec2(c * ax - s * ay, s * ax + c * ay)
    return integrated + (wp.vec2(c * encoders, s * encoders) - integrated) * (dt / accel_time)


@wp.func
def integrate_fused_velocity(pose: wp.vec3, velocity: wp.vec2, yaw_rate: float, dt: float) -> wp.vec3:
    """The fused pose over one substep from an odometry-frame ``velocity`` [m/s] and the gyro's yaw rate."""
    yaw = pose[2] + yaw_rate * dt
    return wp.vec3(pose[0] + velocity[0] * dt, pose[1] + velocity[1] * dt, wp.atan2(wp.sin(yaw), wp.cos(yaw)))


@wp.kernel
def drive_wheels(
    layout: RoverLayout,
    params: DriverParams,
    mode: wp.array(dtype=wp.int32),
    commands: wp.array(dtype=wp.vec2),
    twist: wp.array(dtype=wp.vec2),
    lag: wp.array(dtype=float),
    physics: WorldPhysics,
    joint_q: wp.array(dtype=float),
    joint_qd: wp.array(dtype=float),
    state_in: DriverState,
    state_out: DriverState,
    joint_f: wp.array(dtype=float),
    wheel_torque: wp.array2d(dtype=float),
    damping: wp.array2d(dtype=float),
    torque_cap: wp.array2d(dtype=float),
):
    """Each wheel's joint torque for one substep: the world's torque ``commands`` (``DRIVE_TORQUE``), or the
    driver's output for its ``twist`` (``DRIVE_TWIST``), through the world's motor (torque scale, no-load taper);
    and the wheel odometry. ``state_in`` and ``state_out`` may be the same arrays (the simulator) or one per
    substep (a differentiable rollout's tape).

    ``wheel_torque`` (N, W) [N·m]: each wheel's motor torque for the clamped loop output, forward-positive (what a
    base reports as its effort). ``damping`` (N, W) [N·m per rad/s],
    written only with ``params.implicit``: the slope of each wheel's torque in its own speed change over the substep
    (the loop's proportional gain through the motor, :func:`implicit_drive`; 0 for torque commands). The friction solve (:func:`~atrv_warp.sim.kernels.friction.friction_kernels`) integrates
    it implicitly, with the wheel's ground contact, so that no gain is bounded by the substep. ``torque_cap`` (N, W)
    [N·m, >= 0], written only with ``params.implicit``: the motor's torque at the loop's limit (``torque_limit``
    through the scale and the taper, in the unclamped output's direction), the most the friction solve lets an
    implicit wheel's end torque reach (the clamped torque where the loop saturates; above it where it does not)."""
    world = wp.tid()
    speeds = side_speeds(layout, joint_qd, world)
    pose, odom_twist = integrate_odometry(params, state_in.odometry[world], speeds)
    state_out.odometry[world] = pose
    state_out.odom_twist[world] = odom_twist
    chassis = world * layout.dofs_per_world + layout.chassis_dof
    gyro = joint_qd[chassis + 5]  # the chassis' yaw rate (world z)
    fused = state_in.fused[world]
    if params.accel_time > 0.0:
        c = world * layout.coords_per_world + layout.chassis_coord
        q = wp.quat(joint_q[c + 3], joint_q[c + 4], joint_q[c + 5], joint_q[c + 6])
        velocity = wp.vec3(joint_qd[chassis], joint_qd[chassis + 1], joint_qd[chassis + 2])  # the COM's, world frame
        estimate = accel_aided_velocity(state_in.fused_velocity[world], odom_twist[0],
                                        velocity - state_in.velocity[world], wp.quat_rotate(q, wp.vec3(1.0, 0.0, 0.0)),
                                        wp.quat_rotate(q, wp.vec3(0.0, 1.0, 0.0)), fused[2] + 0.5 * gyro * params.dt,
                                        params.accel_time, params.dt)
        state_out.velocity[world] = velocity
        state_out.fused_velocity[world] = estimate
        state_out.fused[world] = integrate_fused_velocity(fused, estimate, gyro, params.dt)
    else:
        state_out.fused[world] = integrate_fused(fused, odom_twist[0], gyro, params.dt)
    side = commands[world]
    reference = state_in.reference[world]
    integral = state_in.integral[world]
    applied = state_in.applied[world]
    age = state_in.age[world]
    slope = wp.vec2(0.0, 0.0)  # each side's torque per rad/s of its wheels' speed change, before the motor
    beyond = wp.vec2(0.0, 0.0)  # an implicit loop's output past its limit, before the clamp [N·m]
    if mode[world] == DRIVE_TWIST:
        reference, integral, applied, raw = driver_torques(params, twist[world], age <= params.timeout, speeds,
                                                           reference, integral, applied, lag[world])
        side = applied
        if params.implicit != 0:
            slope = wp.vec2(params.kp, params.kp)
            beyond = raw - wp.vec2(wp.clamp(raw[0], -params.torque_limit, params.torque_limit),
                                   wp.clamp(raw[1], -params.torque_limit, params.torque_limit))
    state_out.reference[world] = reference
    state_out.integral[world] = integral
    state_out.applied[world] = applied
    state_out.age[world] = age + params.dt
    scale = physics.torque_scale[world]
    cmd = side * scale
    gain = slope * scale
    over = beyond * scale
    speed_limit = physics.speed_limit[world]
    geared = wp.vec2(0.0, 0.0)
    if layout.sides_coupled != 0:
        geared = geared_speeds(layout, joint_qd, world, cmd, over, gain, speed_limit, params.dt)
    for k in range(layout.wheel_count):
        dof = world * layout.dofs_per_world + layout.wheel_dof[k]
        sign = layout.wheel_sign[k]
        side_k = layout.wheel_side[k]
        tau = motor_torque(cmd[side_k], sign * joint_qd[dof], speed_limit)
        drive = tau
        slope_k = float(0.0)
        if gain[side_k] > 0.0:  # implicit: the unclamped output, its proportional part on the substep's end speed
            drive, slope_k = implicit_drive(cmd[side_k], over[side_k], sign * joint_qd[dof], speed_limit, gain[side_k])
        if layout.sides_coupled != 0:  # the side's motor torque through the chain: its wheels at one speed, friction aside
            drive = layout.wheel_inertia[k] * (geared[layout.wheel_side[k]] - sign * joint_qd[dof]) / params.dt
        joint_f[dof] = sign * drive
        wheel_torque[world, k] = tau
        if params.implicit != 0:
            damping[world, k] = slope_k
            toward = wp.where(cmd[side_k] + over[side_k] < 0.0, -1.0, 1.0)
            torque_cap[world, k] = wp.abs(motor_torque(toward * params.torque_limit * scale, sign * joint_qd[dof],
                                                       speed_limit))


@wp.kernel
def reset_driver(mask: wp.array(dtype=bool), twist: wp.array(dtype=wp.vec2), state: DriverState):
    """A masked world's driver at rest: no command, zero integral and torque, odometry at the origin of a new
    odometry frame (the pose it was reset to)."""
    world = wp.tid()
    if not mask[world]:
        return
    twist[world] = wp.vec2(0.0, 0.0)
    state.reference[world] = wp.vec2(0.0, 0.0)
    state.integral[world] = wp.vec2(0.0, 0.0)
    state.applied[world] = wp.vec2(0.0, 0.0)
    state.age[world] = 0.0
    state.odometry[world] = wp.vec3(0.0, 0.0, 0.0)
    state.odom_twist[world] = wp.vec2(0.0, 0.0)
    state.fused[world] = wp.vec3(0.0, 0.0, 0.0)
    state.fused_velocity[world] = wp.vec2(0.0, 0.0)
    state.velocity[world] = wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def replay_driver(
    params: DriverParams,
    commands: wp.array2d(dtype=wp.vec2),
    fresh: wp.array2d(dtype=bool),
    speeds: wp.array2d(dtype=wp.vec2),
    substeps: int,
    reference: wp.array2d(dtype=wp.vec2),
    integral: wp.array2d(dtype=wp.vec2),
    applied: wp.array2d(dtype=wp.vec2),
):
    """The driver replayed open loop along a recorded drive (one thread per log): ``commands`` (L, T) each
    step's twist and whether it was ``fresh``, ``speeds`` (L, T + 1) each side's recorded wheel speed at the step
    boundaries, linearly interpolated over the ``substeps``. Writes the driver's state at every step boundary
    (L, T + 1): what a replay that starts at that step starts from (the calibration's segments)."""
    log = wp.tid()
    ref = wp.vec2(0.0, 0.0)
    acc = wp.vec2(0.0, 0.0)
    out = wp.vec2(0.0, 0.0)
    steps = commands.shape[1]
    for t in range(steps):
        reference[log, t] = ref
        integral[log, t] = acc
        applied[log, t] = out
        for s in range(substeps):
            f = float(s) / float(substeps)
            v = speeds[log, t] * (1.0 - f) + speeds[log, t + 1] * f
            ref, acc, out, _raw = driver_torques(params, commands[log, t], fresh[log, t], v, ref, acc, out, 0.0)
    reference[log, steps] = ref
    integral[log, steps] = acc
    applied[log, steps] = out
