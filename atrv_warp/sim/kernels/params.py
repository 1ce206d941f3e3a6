"""Per-world physical parameters, read by the motor, contact and friction kernels every substep, and
the kernel that puts a payload on each world's chassis.

One row per world. With every row at the configs' values the kernels compute exactly what they did
with the configs' scalars (``tests/test_reference_task.py`` holds the golden rollouts to it).
"""

from __future__ import annotations

import warp as wp


@wp.struct
class WorldPhysics:
    """Each world's physics, (N,) rows (see :class:`atrv_warp.sim.params.WorldParams`)."""

    friction: wp.array(dtype=float)  # Coulomb mu [-]
    stiffness: wp.array(dtype=float)  # Hunt-Crossley kp [N/m^n]
    wheel_radius: wp.array(dtype=float)  # rolling radius of every wheel [m]
    torque_scale: wp.array(dtype=float)  # motor torque per unit command torque [-]
    speed_limit: wp.array(dtype=float)  # motor no-load speed [rad/s]
    friction_rise: wp.array(dtype=float)  # sliding friction's rise with slip speed [s/m] (ContactConfig.friction_rise)


@wp.struct
class MassProperties:
    """One rigid body's mass [kg], centre of mass [m] and inertia about it [kg·m²], in its frame."""

    mass: float
    com: wp.vec3
    inertia: wp.mat33
    inv_mass: float  # as the model holds them, so that restoring the nominal body is exact
    inv_inertia: wp.mat33


@wp.func
def parallel_axis(mass: float, d: wp.vec3) -> wp.mat33:
    """Inertia [kg·m²] of a point ``mass`` at ``d`` about the origin."""
    return mass * (wp.dot(d, d) * wp.identity(n=3, dtype=float) - wp.outer(d, d))


@wp.func
def add_point_mass(body: MassProperties, mass: float, point: wp.vec3):
    """``body`` with a point ``mass`` [kg] at ``point`` [m] (its frame) added: (mass, com, inertia about it)."""
    total = body.mass + mass
    com = body.com + (mass / total) * (point - body.com)
    inertia = body.inertia + parallel_axis(body.mass, body.com - com) + parallel_axis(mass, point - com)
    return total, com, inertia


@wp.kernel
def apply_payload(
    mask: wp.array(dtype=bool),
    payload_mass: wp.array(dtype=float),
    payload_offset: wp.array(dtype=wp.vec3),
    bodies_per_world: int,
    chassis: int,
    nominal_chassis: MassProperties,
    nominal_rover: MassProperties,
    exact_nominal: int,
    body_mass: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_inertia: wp.array(dtype=wp.mat33),
    body_inv_inertia: wp.array(dtype=wp.mat33),
    body_com: wp.array(dtype=wp.vec3),
    rover_inv_mass: wp.array(dtype=float),
    rover_com: wp.array(dtype=wp.vec3),
    rover_inv_inertia: wp.array(dtype=wp.mat33),
):
    """Masked worlds' chassis and whole-rover mass properties with a point payload [kg] at ``payload_offset``
    [m] from the chassis' nominal centre of mass (chassis frame). The whole rover (``rover_*``, per world) is the
    friction solver's model of it (:class:`~atrv_warp.sim.kernels.friction.RoverInertia`).

    ``exact_nominal`` 1: a payload of 0 restores the model's own values, bit for bit (what the simulator
    does); 0: every world goes through the same formula, so that a tape differentiates it at 0 too."""
    world = wp.tid()
    if not mask[world]:
        return
    b = world * bodies_per_world + chassis
    m = payload_mass[world]
    if m == 0.0 and exact_nominal != 0:
        body_mass[b] = nominal_chassis.mass
        body_inv_mass[b] = nominal_chassis.inv_mass
        body_inertia[b] = nominal_chassis.inertia
        body_inv_inertia[b] = nominal_chassis.inv_inertia
        body_com[b] = nominal_chassis.com
        rover_inv_mass[world] = nominal_rover.inv_mass
        rover_com[world] = nominal_rover.com
        rover_inv_inertia[world] = nominal_rover.inv_inertia
        return
    point = nominal_chassis.com + payload_offset[world]
    mass, com, inertia = add_point_mass(nominal_chassis, m, point)
    body_mass[b] = mass
    body_inv_mass[b] = 1.0 / mass
    body_inertia[b] = inertia
    body_inv_inertia[b] = wp.inverse(inertia)
    body_com[b] = com
    # the whole rover, about its own centre of mass in the chassis frame (the chassis' origin)
    whole_mass, whole_com, whole_inertia = add_point_mass(nominal_rover, m, point)
    rover_inv_mass[world] = 1.0 / whole_mass
    rover_com[world] = whole_com
    rover_inv_inertia[world] = wp.inverse(whole_inertia)
