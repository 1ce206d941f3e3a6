"""Per-world rover kernels: the motor, derived state, masked resets (the wheels' drive is
:func:`atrv_warp.sim.kernels.driver.drive_wheels`).

One thread per world (``world = wp.tid()``); indices inside a world come from
:class:`RoverLayout`, derived from the Newton model by name at build time.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.core import robot

MAX_WHEELS = wp.constant(robot.MAX_WHEELS)
"""The encoders' per-wheel loops have this fixed length (the most wheels a rover may have), so Warp unrolls them
and differentiates them (the friction solve is built for each wheel count: ``kernels.friction.friction_kernels``)."""
MOTOR_TAPER_START = wp.constant(0.8)
"""Fraction of the no-load speed at which drive torque starts to taper to zero."""


@wp.struct
class RoverLayout:
    """Where one world's rover lives in Newton's flat arrays (all worlds are identical)."""

    bodies_per_world: int
    coords_per_world: int  # joint_q entries per world
    dofs_per_world: int  # joint_qd entries per world
    chassis_body: int  # body index within a world
    chassis_coord: int  # first joint_q entry of the free joint within a world
    chassis_dof: int  # first joint_qd entry of the free joint within a world
    wheel_count: int
    wheel_coord: wp.array(dtype=int)
    wheel_dof: wp.array(dtype=int)
    wheel_side: wp.array(dtype=int)  # 0 = left command, 1 = right command
    wheel_sign: wp.array(dtype=float)  # +1 if positive joint torque drives forward
    wheel_inertia: wp.array(dtype=float)  # spin inertia about the axle [kg·m²]
    sides_coupled: int  # 1: one motor per side, its wheels geared to one speed (Robot.motor_per_side)


@wp.func
def motor_torque(command: float, forward_speed: float, speed_limit: float) -> float:
    """Torque [N·m] a DC-like motor delivers for ``command`` at ``forward_speed`` [rad/s].

    Full torque while braking or below ``MOTOR_TAPER_START * speed_limit``; then a linear
    taper to zero at the no-load ``speed_limit``.
    """
    if command * forward_speed <= 0.0:
        return command
    s = wp.abs(forward_speed) / speed_limit
    scale = wp.clamp((1.0 - s) / (1.0 - MOTOR_TAPER_START), 0.0, 1.0)
    return command * scale


@wp.func
def quat_to_rpy(q: wp.quat) -> wp.vec3:
    """Roll, pitch, yaw [rad] (intrinsic Z-Y-X) of a unit quaternion (x, y, z, w)."""
    x = q[0]
    y = q[1]
    z = q[2]
    w = q[3]
    roll = wp.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = wp.asin(wp.clamp(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = wp.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return wp.vec3(roll, pitch, yaw)


@wp.func
def is_finite_range(a: wp.array(dtype=float), start: int, count: int) -> bool:
    for i in range(count):
        if not wp.isfinite(a[start + i]):
            return False
    return True


@wp.kernel
def compute_rover_state(
    layout: RoverLayout,
    body_q: wp.array(dtype=wp.transform),
    body_qd: wp.array(dtype=wp.spatial_vector),
    body_com: wp.array(dtype=wp.vec3),
    joint_q: wp.array(dtype=float),
    joint_qd: wp.array(dtype=float),
    lin_vel: wp.array(dtype=wp.vec3),
    ang_vel: wp.array(dtype=wp.vec3),
    rpy: wp.array(dtype=wp.vec3),
    wheel_speed: wp.array2d(dtype=float),
    nonfinite: wp.array(dtype=wp.int32),
):
    """Chassis-origin velocity and roll/pitch/yaw, wheel speeds, and a non-finite flag per world."""
    world = wp.tid()
    b = world * layout.bodies_per_world + layout.chassis_body
    X = body_q[b]
    qd = body_qd[b]
    omega = wp.spatial_bottom(qd)
    # body_qd holds the COM velocity; report the chassis origin's.
    r = wp.transform_get_translation(X) - wp.transform_point(X, body_com[b])
    lin_vel[world] = wp.spatial_top(qd) + wp.cross(omega, r)
    ang_vel[world] = omega
    rpy[world] = quat_to_rpy(wp.transform_get_rotation(X))
    for k in range(layout.wheel_count):
        wheel_speed[world, k] = layout.wheel_sign[k] * joint_qd[world * layout.dofs_per_world + layout.wheel_dof[k]]
    ok = is_finite_range(joint_q, world * layout.coords_per_world, layout.coords_per_world)
    ok = ok and is_finite_range(joint_qd, world * layout.dofs_per_world, layout.dofs_per_world)
    if not ok:
        nonfinite[world] = 1


@wp.kernel
def reset_worlds(
    layout: RoverLayout,
    mask: wp.array(dtype=bool),
    poses: wp.array(dtype=wp.vec3),
    height: float,
    joint_q: wp.array(dtype=float),
    joint_qd: wp.array(dtype=float),
    contact_flags: wp.array(dtype=wp.int32),
    nonfinite: wp.array(dtype=wp.int32),
):
    """Put masked worlds' chassis at (x [m], y [m], yaw [rad]) and ``height`` [m], level and at rest."""
    world = wp.tid()
    if not mask[world]:
        return
    pose = poses[world]
    q0 = world * layout.coords_per_world + layout.chassis_coord
    joint_q[q0 + 0] = pose[0]
    joint_q[q0 + 1] = pose[1]
    joint_q[q0 + 2] = height
    joint_q[q0 + 3] = 0.0
    joint_q[q0 + 4] = 0.0
    joint_q[q0 + 5] = wp.sin(0.5 * pose[2])
    joint_q[q0 + 6] = wp.cos(0.5 * pose[2])
    for k in range(layout.wheel_count):
        joint_q[world * layout.coords_per_world + layout.wheel_coord[k]] = 0.0
    for i in range(layout.dofs_per_world):
        joint_qd[world * layout.dofs_per_world + i] = 0.0
    contact_flags[world] = 0
    nonfinite[world] = 0
