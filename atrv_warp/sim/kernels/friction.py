"""Wheel–ground friction as a velocity-level Coulomb problem, solved per world every substep.

Why not a force law: a wheel's rim is light along its rolling direction (its spin inertia, 0.02
kg·m², is 1.25 kg at the rim), so an explicit step of 0.01 s can only apply a friction force that
grows slowly with slip. Such a viscous law never reaches ``mu f_n`` in a turn, and a skid-steer
rover then turns as the ratio of its viscous slopes dictates (8.3x slower than its wheels command,
whatever mu), not as Coulomb friction does (about 1.6x).

What this kernel does instead, for all the wheels of one world at once (one thread per world; 2 to
``MAX_WHEELS``, a kernel built for each wheel count, :func:`friction_kernels`):

1. each wheel's deepest rim point on the ground (plane 0 or the terrain's tangent plane), its
   Hunt–Crossley normal force and the contact point's velocity;
2. the velocity each contact point would have at the end of the substep without friction, from the
   forces already known for it: gravity, the normal forces and the wheels' drive torques, applied to
   a model of the rover as one rigid body plus its free-spinning wheels;
3. friction impulses by projected Gauss–Seidel over the wheels' contacts, starting from the previous
   substep's impulses: each contact in turn either sticks (its end-of-substep slip is zero, with an
   impulse inside the Coulomb disc ``mu f_n dt``) or slides (impulse ``mu f_n dt`` against its
   end-of-substep slip), given the others' impulses;
4. normal plus friction force on each wheel body (``body_f``), which Newton's solver integrates.

Step 3 is exact for the per-contact problem (the sliding direction solves a scalar equation by
Newton's method). One sweep per substep, warm-started, lets successive substeps' sweeps converge to
the coupled problem together, where several sweeps from zero each substep would cost several times
as much and still leave a parked rover creeping. What is left, and the gap between the rigid-body
model and Newton's articulation, is slip that the next substep removes
(``benchmarks/physics/skid_calibration.py`` measures what that leaves on slopes). The result is Coulomb friction: no
creep at rest on a slope below ``atan(mu)``, rolling without slip under traction below
``mu f_n``, and turning set by the directions of the sliding forces, not by their magnitude.
With ``ContactConfig.friction_rise`` a sliding contact's disc grows with its slip speed at the substep's
start (``mu (1 + rise x slip)``, a substep late, as the warm start is): friction that rises with sliding speed.

Every loop has a constant bound (Warp unrolls it), so ``wp.Tape`` differentiates the kernel. The law
is piecewise smooth: a contact that switches between sticking and sliding has a kink there.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from atrv_warp.sim.kernels.contact import (
    ContactParams,
    RoverShapes,
    Scene,
    hunt_crossley,
    wheel_ground_point,
    wheel_size,
)
from atrv_warp.sim.kernels.params import WorldPhysics

FRICTION_SWEEPS = wp.constant(1)
"""Gauss–Seidel sweeps over the wheels per substep, each starting where the previous substep ended."""
SLIDE_ITERATIONS = wp.constant(3)
"""Newton iterations for a sliding contact's slip speed (relative error under 1e-4 after three)."""

# Per-wheel values live in the rows of small matrices (and entries of vectors), one row per wheel: the kernel is
# built for each wheel count (:func:`friction_kernels`), so that a four-wheel rover's runs on 4-row values and
# unrolled loops of four. A row is replaced by building a new matrix, not written in place: Warp 1.19's adjoint of a
# repeated in-place row write is wrong (its gradients disagree with finite differences), while a rebuilt value is
# plain SSA and differentiates exactly.
@wp.func
def with_row2(m: Any, i: int, row: Any):
    """``m`` (2 rows) with row ``i`` replaced by ``row``."""
    r0 = m[0]
    r1 = m[1]
    if i == 0:
        r0 = row
    if i == 1:
        r1 = row
    return wp.matrix_from_rows(r0, r1)


@wp.func
def with_row4(m: Any, i: int, row: Any):
    """``m`` (4 rows) with row ``i`` replaced by ``row``."""
    r0 = m[0]
    r1 = m[1]
    r2 = m[2]
    r3 = m[3]
    if i == 0:
        r0 = row
    if i == 1:
        r1 = row
    if i == 2:
        r2 = row
    if i == 3:
        r3 = row
    return wp.matrix_from_rows(r0, r1, r2, r3)


@wp.func
def with_row6(m: Any, i: int, row: Any):
    """``m`` (6 rows) with row ``i`` replaced by ``row``."""
    r0 = m[0]
    r1 = m[1]
    r2 = m[2]
    r3 = m[3]
    r4 = m[4]
    r5 = m[5]
    if i == 0:
        r0 = row
    if i == 1:
        r1 = row
    if i == 2:
        r2 = row
    if i == 3:
        r3 = row
    if i == 4:
        r4 = row
    if i == 5:
        r5 = row
    return wp.matrix_from_rows(r0, r1, r2, r3, r4, r5)


@wp.func
def with_row8(m: Any, i: int, row: Any):
    """``m`` (8 rows) with row ``i`` replaced by ``row``."""
    r0 = m[0]
    r1 = m[1]
    r2 = m[2]
    r3 = m[3]
    r4 = m[4]
    r5 = m[5]
    r6 = m[6]
    r7 = m[7]
    if i == 0:
        r0 = row
    if i == 1:
        r1 = row
    if i == 2:
        r2 = row
    if i == 3:
        r3 = row
    if i == 4:
        r4 = row
    if i == 5:
        r5 = row
    if i == 6:
        r6 = row
    if i == 7:
        r7 = row
    return wp.matrix_from_rows(r0, r1, r2, r3, r4, r5, r6, r7)


WITH_ROW = {2: with_row2, 4: with_row4, 6: with_row6, 8: with_row8}
"""Each wheel count's row replacement (a Warp matrix's row count is part of its type)."""

vec6 = wp.types.vector(length=6, dtype=float)
vec8 = wp.types.vector(length=8, dtype=float)


@wp.func
def with_entry2(v: wp.vec2, i: int, x: float):
    """``v`` with entry ``i`` replaced by ``x``."""
    return wp.vec2(wp.where(i == 0, x, v[0]), wp.where(i == 1, x, v[1]))


@wp.func
def with_entry4(v: wp.vec4, i: int, x: float):
    """``v`` with entry ``i`` replaced by ``x``."""
    return wp.vec4(wp.where(i == 0, x, v[0]), wp.where(i == 1, x, v[1]), wp.where(i == 2, x, v[2]),
                   wp.where(i == 3, x, v[3]))


@wp.func
def with_entry6(v: vec6, i: int, x: float):
    """``v`` with entry ``i`` replaced by ``x``."""
    return vec6(wp.where(i == 0, x, v[0]), wp.where(i == 1, x, v[1]), wp.where(i == 2, x, v[2]),
                wp.where(i == 3, x, v[3]), wp.where(i == 4, x, v[4]), wp.where(i == 5, x, v[5]))


@wp.func
def with_entry8(v: vec8, i: int, x: float):
    """``v`` with entry ``i`` replaced by ``x``."""
    return vec8(wp.where(i == 0, x, v[0]), wp.where(i == 1, x, v[1]), wp.where(i == 2, x, v[2]),
                wp.where(i == 3, x, v[3]), wp.where(i == 4, x, v[4]), wp.where(i == 5, x, v[5]),
                wp.where(i == 6, x, v[6]), wp.where(i == 7, x, v[7]))


WITH_ENTRY = {2: (wp.vec2, with_entry2), 4: (wp.vec4, with_entry4), 6: (vec6, with_entry6), 8: (vec8, with_entry8)}
"""Each wheel count's vector type and entry replacement."""


@wp.struct
class RoverInertia:
    """Each world's rover as one rigid body (wheels included as if locked): what the solver predicts
    the contact velocities with. Per world, so a payload can change it."""

    inv_mass: wp.array(dtype=float)  # (N,) 1 / total mass [1/kg]
    com: wp.array(dtype=wp.vec3)  # (N,) centre of mass in the chassis body frame [m]
    inv_inertia: wp.array(dtype=wp.mat33)  # (N,) inverse inertia about the COM, chassis frame [1/(kg·m²)]


@wp.struct
class WheelSlots:
    """The wheels the solver handles, in :class:`~atrv_warp.sim.kernels.rover.RoverLayout` wheel order."""

    count: int  # wheels (2 to MAX_WHEELS): the stride of the impulse arrays
    side_inertia: wp.vec2  # each side's wheels' spin inertia together [kg·m²]
    chassis: int  # chassis body index within a world
    dofs_per_world: int
    shape: wp.array(dtype=int)  # (count,) the wheel's cylinder in RoverShapes
    dof: wp.array(dtype=int)  # the wheel joint's joint_f entry within a world
    axis: wp.array(dtype=wp.vec3)  # the joint axis in the wheel body frame (positive joint_f spins about it)
    inv_spin_inertia: wp.array(dtype=float)  # 1 / inertia about the axle [1/(kg·m²)]
    side: wp.array(dtype=int)  # 0 left, 1 right
    sign: wp.array(dtype=float)  # +1 where a positive joint speed drives forward


@wp.func
def coulomb_impulse(v0: wp.vec2, d: wp.vec2, inv_d: wp.vec2, limit: float) -> wp.vec2:
    """Tangential impulse ``P`` [N·s] of one contact whose end-of-substep slip is ``v0 + d * P``
    (componentwise, ``d`` [1/kg] > 0, ``inv_d = 1 / d``): zero slip if that takes ``|P| <= limit``, else
    ``P = -limit v / |v|`` with ``v`` the resulting slip (the sliding direction solves
    ``sum_i (v0_i / (s + limit d_i))^2 = 1`` for the slip speed ``s``)."""
    stick = wp.vec2(-v0[0] * inv_d[0], -v0[1] * inv_d[1])
    if wp.dot(stick, stick) <= limit * limit:
        return stick
    if limit <= 0.0:
        return wp.vec2(0.0)
    c0 = limit * d[0]
    c1 = limit * d[1]
    s = wp.max(wp.length(v0) - wp.max(c0, c1), 0.0)  # a lower bound on the root
    for _ in range(SLIDE_ITERATIONS):
        # Newton on 1 / |(v0_i / (s + c_i))| = 1, a function exactly linear in s for a single term
        e0 = 1.0 / (s + c0)
        e1 = 1.0 / (s + c1)
        a = v0[0] * e0
        b = v0[1] * e1
        q = a * a + b * b
        s = wp.max(s - (1.0 - wp.sqrt(q)) * q / (a * a * e0 + b * b * e1), 0.0)
    a = v0[0] / (s + c0)
    b = v0[1] / (s + c1)
    return wp.vec2(a, b) * (-limit / wp.sqrt(a * a + b * b))


@wp.func
def effective_inverse_mass(t: wp.vec3, r: wp.vec3, inv_mass: float, inv_inertia: wp.mat33, spin: wp.vec3,
                           inv_spin_inertia: float) -> float:
    """Slip velocity change along ``t`` per unit impulse along ``t`` [1/kg] at a point ``r`` [m] from the
    rover's COM on a wheel whose spin moves the point at ``spin`` [m/s per rad/s]."""
    rt = wp.cross(r, t)
    st = wp.dot(spin, t)
    return inv_mass + wp.dot(rt, inv_inertia * rt) + inv_spin_inertia * st * st


@wp.func
def relax_contact(pk: wp.vec2, t1: wp.vec3, t2: wp.vec3, r: wp.vec3, spin: wp.vec3, free: wp.vec3,
                  d: wp.vec2, inv_d: wp.vec2, inv_spin_inertia: float, limit: float, dv: wp.vec3, dw: wp.vec3,
                  inv_mass: float, inv_inertia: wp.mat33):
    """One Gauss–Seidel update of a contact whose impulse is ``pk``: its impulse given the others' (carried by the
    rigid body's velocity change ``dv``, ``dw``). Returns (its new impulse, dv, dw)."""
    p3 = t1 * pk[0] + t2 * pk[1]
    v = free + dv + wp.cross(dw, r) + spin * (inv_spin_inertia * wp.dot(spin, p3))
    v0 = wp.vec2(wp.dot(v, t1) - d[0] * pk[0], wp.dot(v, t2) - d[1] * pk[1])
    new = coulomb_impulse(v0, d, inv_d, limit)
    change = t1 * (new[0] - pk[0]) + t2 * (new[1] - pk[1])
    return new, dv + change * inv_mass, dw + inv_inertia * wp.cross(r, change)


@wp.func
def relax_geared(pk: wp.vec2, t1: wp.vec3, t2: wp.vec3, r: wp.vec3, spin: wp.vec3, sign: float, side: int,
                 free: wp.vec3, d: wp.vec2, inv_d: wp.vec2, inv_side: float, limit: float, dv: wp.vec3, dw: wp.vec3,
                 turn: wp.vec2, inv_mass: float, inv_inertia: wp.mat33):
    """:func:`relax_contact` for a wheel geared to its side's others: its impulse turns the whole side (``turn``,
    each side's forward spin change from the impulses so far [rad/s], its inverse inertia ``inv_side``), and the
    side's turn moves this contact. Returns (its new impulse, dv, dw, turn)."""
    v = free + dv + wp.cross(dw, r) + spin * (sign * turn[side])
    v0 = wp.vec2(wp.dot(v, t1) - d[0] * pk[0], wp.dot(v, t2) - d[1] * pk[1])
    new = coulomb_impulse(v0, d, inv_d, limit)
    change = t1 * (new[0] - pk[0]) + t2 * (new[1] - pk[1])
    step = sign * wp.dot(spin, change) * inv_side
    return (new, dv + change * inv_mass, dw + inv_inertia * wp.cross(r, change),
            wp.where(side == 0, wp.vec2(turn[0] + step, turn[1]), wp.vec2(turn[0], turn[1] + step)))


@wp.func
def drive_regime(s: float, torque: float, damping: float, held: float, inertia: float, dt: float) -> float:
    """An implicit drive's regime for a friction spin impulse ``s`` [N·m·s] on its wheel (side): 0 damped (its end
    torque ``torque - damping x spin change`` within ``held``), +1 / -1 held at ``+held`` / ``-held``."""
    end = torque - damping * (torque * dt + s) / (inertia + damping * dt)
    up = wp.where(end > held, 1.0, 0.0)
    down = wp.where(end < -held, -1.0, 0.0)
    return wp.where(damping > 0.0, up + down, 0.0)


@wp.func
def drive_spin_change(s: float, regime: float, torque: float, damping: float, held: float, inertia: float,
                      dt: float) -> float:
    """The wheel's (side's) spin change [rad/s] under a friction spin impulse ``s`` in ``regime``
    (:func:`drive_regime`): damped ``(torque dt + s) / (J + damping dt)``, held ``(+-held dt + s) / J`` (continuous
    where they meet)."""
    return wp.where(regime == 0.0, (torque * dt + s) / (inertia + damping * dt), (regime * held * dt + s) / inertia)


@wp.func
def relax_drive_solve(pk: wp.vec2, t1: wp.vec3, t2: wp.vec3, base: wp.vec3, spin: wp.vec3, sign: float, others: float,
                      regime: float, dd: wp.vec2, inv_dd: wp.vec2, dh: wp.vec2, inv_dh: wp.vec2, limit: float,
                      torque: float, damping: float, held: float, inertia: float, dt: float):
    """:func:`relax_drive`'s contact impulse in one regime, and the wheel's (side's) friction spin impulse with it."""
    dk = wp.where(regime == 0.0, dd, dh)
    inv_dk = wp.where(regime == 0.0, inv_dd, inv_dh)
    own = sign * wp.dot(spin, t1 * pk[0] + t2 * pk[1])
    v = base + spin * (sign * drive_spin_change(others + own, regime, torque, damping, held, inertia, dt))
    v0 = wp.vec2(wp.dot(v, t1) - dk[0] * pk[0], wp.dot(v, t2) - dk[1] * pk[1])
    new = coulomb_impulse(v0, dk, inv_dk, limit)
    return new, others + sign * wp.dot(spin, t1 * new[0] + t2 * new[1])


@wp.func
def relax_drive(pk: wp.vec2, t1: wp.vec3, t2: wp.vec3, r: wp.vec3, spin: wp.vec3, sign: float, free: wp.vec3,
                dd: wp.vec2, inv_dd: wp.vec2, dh: wp.vec2, inv_dh: wp.vec2, limit: float, dv: wp.vec3, dw: wp.vec3,
                s: float, torque: float, damping: float, held: float, inertia: float, dt: float, inv_mass: float,
                inv_inertia: wp.mat33):
    """:func:`relax_contact` for an implicit drive held at its torque limit inside the solve: the wheel (a geared
    side: ``sign`` its forward sign, ``torque``, ``damping``, ``held``, ``inertia`` the side's) spins by
    :func:`drive_spin_change` of its friction spin impulse ``s`` (this contact's included), a continuous, monotone,
    piecewise-linear function. The update solves in the regime ``s`` is in, and again in the regime its result is in
    where that differs (twice at most). ``free`` is the contact's end velocity without friction and without the
    drive's spin change, ``dd`` / ``dh`` its inverse masses damped / held. Returns (its new impulse, dv, dw, s)."""
    others = s - sign * wp.dot(spin, t1 * pk[0] + t2 * pk[1])
    base = free + dv + wp.cross(dw, r)
    regime = drive_regime(s, torque, damping, held, inertia, dt)
    new, s_new = relax_drive_solve(pk, t1, t2, base, spin, sign, others, regime, dd, inv_dd, dh, inv_dh, limit,
                                   torque, damping, held, inertia, dt)
    for _ in range(2):
        after = drive_regime(s_new, torque, damping, held, inertia, dt)
        if after != regime:
            regime = after
            new, s_new = relax_drive_solve(pk, t1, t2, base, spin, sign, others, regime, dd, inv_dd, dh, inv_dh,
                                           limit, torque, damping, held, inertia, dt)
    change = t1 * (new[0] - pk[0]) + t2 * (new[1] - pk[1])
    return new, dv + change * inv_mass, dw + inv_inertia * wp.cross(r, change), s_new


@functools.cache
def friction_kernels(wheels: int, geared: bool = False, implicit: bool = False):
    """The (``solve_wheel_friction``, ``clear_impulses``) kernels for rovers of ``wheels`` wheels (2 to
    ``MAX_WHEELS``, even): per-wheel values in ``wheels``-row matrices, loops of ``wheels`` unrolled; with ``geared``
    each side's wheels turned as one inside the solve (``ContactConfig.solve_geared_sides``), with ``implicit`` the
    drive's ``damping`` solved with the friction. What a kernel does not do is not in its code: the four-wheel rover's default kernel is
    the one this solve has always been."""
    if wheels not in WITH_ROW:
        raise ValueError(f"the friction solve takes {sorted(WITH_ROW)} wheels, not {wheels}")
    WHEELS = wheels
    GEARED, IMPLICIT, EXTRAS = bool(geared), bool(implicit), bool(geared or implicit)
    mat3 = wp.types.matrix(shape=(wheels, 3), dtype=float)
    mat2 = wp.types.matrix(shape=(wheels, 2), dtype=float)
    with_row_n = WITH_ROW[wheels]
    vec, with_entry = WITH_ENTRY[wheels]

    @wp.kernel(module="unique")
    def solve_wheel_friction(
        bodies_per_world: int,
        shapes: RoverShapes,
        slots: WheelSlots,
        rover: RoverInertia,
        scene: Scene,
        params: ContactParams,
        gravity: wp.vec3,
        physics: WorldPhysics,
        body_q: wp.array(dtype=wp.transform),
        body_qd: wp.array(dtype=wp.spatial_vector),
        body_com: wp.array(dtype=wp.vec3),
        joint_f: wp.array(dtype=float),
        damping: wp.array2d(dtype=float),
        torque_cap: wp.array2d(dtype=float),
        warm_start: wp.array(dtype=wp.vec3),
        body_f: wp.array(dtype=wp.spatial_vector),
        impulses: wp.array(dtype=wp.vec3),
    ):
        """One thread per world: the wheels' ground contact forces (normal and Coulomb friction), added to
        ``body_f``. ``joint_f`` holds this substep's drive torques; ``physics`` each world's mu (and its rise with
        slip), stiffness and wheel radius.

        ``damping`` (N, W) [N·m per rad/s] is how each wheel's drive torque falls with its speed's change over the
        substep (an implicit wheel-speed loop's proportional action through the motor,
        :func:`~atrv_warp.sim.kernels.driver.drive_wheels`; read only by an ``implicit`` kernel): the wheel then spins
        as if its inertia were ``J + damping dt`` under ``joint_f``'s torque, the friction solved with it, and the
        torque's change is applied between wheel and chassis (a damping integrated implicitly, which no gain can make
        unstable). ``torque_cap`` (N, W) [N·m, >= 0] is each wheel's motor torque at the loop's limit: a damped
        wheel's (a geared side's) end torque goes no further (a wheel the ground holds against its drive), its spin a
        piecewise-linear function of its friction impulse that each contact's update solves (:func:`relax_drive`).

        ``warm_start`` (N x ``slots.count``) holds the previous substep's friction impulses [N·s], where the
        sweeps start; ``impulses`` receives this substep's (the simulator passes one array as both; a tape
        passes one per substep)."""
        world = wp.tid()
        mu = physics.friction[world]
        rise = physics.friction_rise[world]
        kp = physics.stiffness[world]
        dt = params.dt
        base = world * bodies_per_world
        tile = int(0)
        if scene.terrain.enabled != 0:
            tile = scene.terrain.tile[world]
        chassis = body_q[base + slots.chassis]
        centre = wp.transform_point(chassis, rover.com[world])
        rot = wp.quat_to_matrix(wp.transform_get_rotation(chassis))
        inv_inertia = rot * rover.inv_inertia[world] * wp.transpose(rot)
        inv_mass = rover.inv_mass[world]

        # 1. Contacts, and the known forces' wrench about the rover's COM (gravity, normal forces, the
        # drive torques' reaction on the body).
        lever = mat3()  # contact point - wheel COM [m]
        arm = mat3()  # contact point - rover COM [m]
        lon = mat3()  # rolling direction in the contact plane
        lat = mat3()  # axle direction in the contact plane
        spin = mat3()  # contact point velocity per unit wheel spin rate [m/s per rad/s]
        free = mat3()  # contact point velocity without friction at the end of the substep (spin part) [m/s]
        normal = mat3()  # normal force [N]
        limit = vec()  # Coulomb disc radius mu f_n dt [N·s]
        ispins = vec()  # 1 / the spin inertia the wheel moves with (its own, or its side's; + damping x dt) [1/(kg·m²)]
        taus = vec()  # the drive torque [N·m]
        axle = mat3()  # the joint axis, world frame
        force = gravity / inv_mass
        torque = wp.vec3()
        shrink = wp.vec2()  # geared sides: how much the drive's damping lowers the side's end speed [rad/s]
        side_damping = wp.vec2()  # geared sides: the side's drive damping [N·m per rad/s]
        side_torque = wp.vec2()  # geared sides: the side's motor torque, forward [N·m]
        side_held = wp.vec2()  # geared sides: the side's motor torque at the loop's limit, forward [N·m]
        cs = vec()  # implicit: each wheel's drive damping [N·m per rad/s] (0: a wheel under torque commands)
        if wp.static(GEARED):
            for k in range(WHEELS):
                t = slots.sign[k] * joint_f[world * slots.dofs_per_world + slots.dof[k]]
                c = damping[world, k]
                h = torque_cap[world, k]
                if slots.side[k] == 0:
                    side_torque = wp.vec2(side_torque[0] + t, side_torque[1])
                    side_damping = wp.vec2(side_damping[0] + c, side_damping[1])
                    side_held = wp.vec2(side_held[0] + h, side_held[1])
                else:
                    side_torque = wp.vec2(side_torque[0], side_torque[1] + t)
                    side_damping = wp.vec2(side_damping[0], side_damping[1] + c)
                    side_held = wp.vec2(side_held[0], side_held[1] + h)
            for q in range(2):
                j = slots.side_inertia[q]
                cq = side_damping[q] * dt
                lowered = side_torque[q] * dt * cq / (j * (j + cq))
                shrink = wp.where(q == 0, wp.vec2(lowered, shrink[1]), wp.vec2(shrink[0], lowered))
        for k in range(WHEELS):
            s = slots.shape[k]
            b = base + shapes.body[s]
            X = body_q[b]
            p, n, depth = wheel_ground_point(scene, tile, X * shapes.xform[s],
                                             wheel_size(shapes.size[s], physics, world), params.patch)
            hub = wp.transform_point(X, body_com[b])
            qd = body_qd[b]
            lever = with_row_n(lever, k, p - hub)
            v = wp.spatial_top(qd) + wp.cross(wp.spatial_bottom(qd), p - hub)
            fn = float(0.0)
            if depth > 0.0:
                fn = hunt_crossley(depth, -wp.dot(v, n), params, kp)
            u = wp.transform_vector(X, slots.axis[k])
            tau = joint_f[world * slots.dofs_per_world + slots.dof[k]]
            ispin = slots.inv_spin_inertia[k]
            tau_end = tau  # the drive torque at the substep's end, friction aside
            spin_change = float(0.0)  # geared: the wheel's speed change without friction [rad/s]
            if wp.static(GEARED):  # the side's inertia answers the impulse; its damping lowers its end speed
                q = slots.side[k]
                ispin = 1.0 / (slots.side_inertia[q] + side_damping[q] * dt)
                spin_change = tau * dt * slots.inv_spin_inertia[k] - slots.sign[k] * shrink[q]
            elif wp.static(IMPLICIT):
                c = damping[world, k]
                cs = with_entry(cs, k, c)
                if c > 0.0:
                    ispin = 1.0 / (1.0 / slots.inv_spin_inertia[k] + c * dt)
                    tau_end = tau - c * tau * dt * ispin
            if wp.static(EXTRAS):
                ispins = with_entry(ispins, k, ispin)
                taus = with_entry(taus, k, tau)
                axle = with_row_n(axle, k, u)
            w = wp.cross(u, p - hub)
            a = u - wp.dot(u, n) * n
            al = wp.length(a)
            if al > 1.0e-6:
                a = a / al
            else:  # axle along the normal (a wheel on its side): any tangent pair will do
                a = wp.normalize(wp.cross(n, wp.vec3(1.0, 0.0, 0.0)) + wp.vec3(0.0, 1.0e-3, 0.0))
            arm = with_row_n(arm, k, p - centre)
            lat = with_row_n(lat, k, a)
            lon = with_row_n(lon, k, wp.cross(n, a))
            spin = with_row_n(spin, k, w)
            if wp.static(GEARED and IMPLICIT):  # the side's spin change is the solve's (relax_drive)
                q = slots.side[k]
                own = tau * dt * slots.inv_spin_inertia[k] - slots.sign[k] * side_torque[q] * dt / slots.side_inertia[q]
                free = with_row_n(free, k, v + w * own)
            elif wp.static(GEARED):
                free = with_row_n(free, k, v + w * spin_change)
            elif wp.static(IMPLICIT):  # a damped wheel's spin change is the solve's (relax_drive)
                free = with_row_n(free, k, wp.where(cs[k] > 0.0, v, v + w * (tau * ispin * dt)))
            else:
                free = with_row_n(free, k, v + w * (tau * ispin * dt))
            normal = with_row_n(normal, k, fn * n)
            mu_k = mu
            if rise > 0.0:  # friction rising with the slip speed at the substep's start (ContactConfig.friction_rise)
                vt = v - wp.dot(v, n) * n
                mu_k = mu * (1.0 + rise * wp.sqrt(wp.dot(vt, vt) + 1.0e-12))
            limit = with_entry(limit, k, mu_k * fn * dt)
            force += fn * n
            torque += wp.cross(p - centre, fn * n) - tau_end * u
        dv = force * (inv_mass * dt)
        dw = inv_inertia * torque * dt

        # 2. Projected Gauss-Seidel on the friction impulses, from the previous substep's (clamped to this
        # one's Coulomb discs); dv, dw carry the rigid body's velocity change.
        impulse = mat2()
        d = mat2()
        inv_d = mat2()
        turn = wp.vec2()  # geared sides: each side's forward spin change from the friction impulses [rad/s]
        dh = mat2()  # implicit: the contacts' inverse masses with the drive held at its limit [1/kg]
        inv_dh = mat2()
        side_spin = wp.vec2()  # implicit, geared: each side's forward friction spin impulse [N·m·s]
        wheel_spin = vec()  # implicit: each wheel's friction spin impulse [N·m·s]
        for k in range(WHEELS):
            ispin = slots.inv_spin_inertia[k]
            if wp.static(EXTRAS):
                ispin = ispins[k]
            dk = wp.vec2(effective_inverse_mass(lon[k], arm[k], inv_mass, inv_inertia, spin[k], ispin),
                         effective_inverse_mass(lat[k], arm[k], inv_mass, inv_inertia, spin[k], ispin))
            d = with_row_n(d, k, dk)
            inv_d = with_row_n(inv_d, k, wp.vec2(1.0 / dk[0], 1.0 / dk[1]))
            if wp.static(IMPLICIT):
                ihold = slots.inv_spin_inertia[k]
                if wp.static(GEARED):
                    ihold = 1.0 / slots.side_inertia[slots.side[k]]
                dhk = wp.vec2(effective_inverse_mass(lon[k], arm[k], inv_mass, inv_inertia, spin[k], ihold),
                              effective_inverse_mass(lat[k], arm[k], inv_mass, inv_inertia, spin[k], ihold))
                dh = with_row_n(dh, k, dhk)
                inv_dh = with_row_n(inv_dh, k, wp.vec2(1.0 / dhk[0], 1.0 / dhk[1]))
            prev = warm_start[world * slots.count + k]
            pk = wp.vec2(wp.dot(prev, lon[k]), wp.dot(prev, lat[k]))
            size = wp.length(pk)
            if size > limit[k]:
                pk = pk * (limit[k] / size)
            impulse = with_row_n(impulse, k, pk)
            p3 = lon[k] * pk[0] + lat[k] * pk[1]
            dv += p3 * inv_mass
            dw += inv_inertia * wp.cross(arm[k], p3)
            if wp.static(GEARED and IMPLICIT):
                own = slots.sign[k] * wp.dot(spin[k], p3)
                side_spin = wp.where(slots.side[k] == 0, wp.vec2(side_spin[0] + own, side_spin[1]),
                                     wp.vec2(side_spin[0], side_spin[1] + own))
            elif wp.static(GEARED):
                step = slots.sign[k] * wp.dot(spin[k], p3) * ispin
                turn = wp.where(slots.side[k] == 0, wp.vec2(turn[0] + step, turn[1]), wp.vec2(turn[0], turn[1] + step))
            elif wp.static(IMPLICIT):
                wheel_spin = with_entry(wheel_spin, k, wp.dot(spin[k], p3))
        for _sweep in range(FRICTION_SWEEPS):
            for k in range(WHEELS):
                if wp.static(GEARED and IMPLICIT):
                    q = slots.side[k]
                    new, dv, dw, sq = relax_drive(impulse[k], lon[k], lat[k], arm[k], spin[k], slots.sign[k], free[k],
                                                  d[k], inv_d[k], dh[k], inv_dh[k], limit[k], dv, dw, side_spin[q],
                                                  side_torque[q], side_damping[q], wp.abs(side_held[q]),
                                                  slots.side_inertia[q], dt, inv_mass, inv_inertia)
                    side_spin = wp.where(q == 0, wp.vec2(sq, side_spin[1]), wp.vec2(side_spin[0], sq))
                    impulse = with_row_n(impulse, k, new)
                elif wp.static(IMPLICIT):  # a wheel under torque commands as the kernels without the drive solve it
                    if cs[k] > 0.0:
                        new, dv, dw, sk = relax_drive(impulse[k], lon[k], lat[k], arm[k], spin[k], 1.0, free[k], d[k],
                                                      inv_d[k], dh[k], inv_dh[k], limit[k], dv, dw, wheel_spin[k],
                                                      taus[k], cs[k], wp.abs(torque_cap[world, k]),
                                                      1.0 / slots.inv_spin_inertia[k], dt, inv_mass, inv_inertia)
                        wheel_spin = with_entry(wheel_spin, k, sk)
                        impulse = with_row_n(impulse, k, new)
                    else:
                        new, dv, dw = relax_contact(impulse[k], lon[k], lat[k], arm[k], spin[k], free[k], d[k],
                                                    inv_d[k], ispins[k], limit[k], dv, dw, inv_mass, inv_inertia)
                        impulse = with_row_n(impulse, k, new)
                elif wp.static(GEARED):
                    new, dv, dw, turn = relax_geared(impulse[k], lon[k], lat[k], arm[k], spin[k], slots.sign[k],
                                                     slots.side[k], free[k], d[k], inv_d[k], ispins[k], limit[k], dv,
                                                     dw, turn, inv_mass, inv_inertia)
                    impulse = with_row_n(impulse, k, new)
                else:
                    ispin = slots.inv_spin_inertia[k]
                    if wp.static(EXTRAS):
                        ispin = ispins[k]
                    new, dv, dw = relax_contact(impulse[k], lon[k], lat[k], arm[k], spin[k], free[k], d[k], inv_d[k],
                                                ispin, limit[k], dv, dw, inv_mass, inv_inertia)
                    impulse = with_row_n(impulse, k, new)

        # 3. Normal plus friction force on each wheel, as a wrench about its COM.
        for k in range(WHEELS):
            pk = impulse[k]
            p3 = lon[k] * pk[0] + lat[k] * pk[1]
            impulses[world * slots.count + k] = p3
            f = normal[k] + p3 / dt
            wheel = base + shapes.body[slots.shape[k]]
            wp.atomic_add(body_f, wheel, wp.spatial_vector(f, wp.cross(lever[k], f)))
            if wp.static(GEARED and IMPLICIT):  # the chain's and drive's torque that turn this wheel with its side
                q = slots.side[k]
                sq = side_spin[q]
                jq = slots.side_inertia[q]
                hq = wp.abs(side_held[q])
                regime = drive_regime(sq, side_torque[q], side_damping[q], hq, jq, dt)
                target = (taus[k] * dt * slots.inv_spin_inertia[k] - slots.sign[k] * side_torque[q] * dt / jq
                          + slots.sign[k] * drive_spin_change(sq, regime, side_torque[q], side_damping[q], hq, jq, dt))
                change = (target / slots.inv_spin_inertia[k] - wp.dot(spin[k], p3)) / dt - taus[k]
                wp.atomic_add(body_f, wheel, wp.spatial_vector(wp.vec3(0.0), change * axle[k]))
                wp.atomic_add(body_f, base + slots.chassis, wp.spatial_vector(wp.vec3(0.0), -change * axle[k]))
            elif wp.static(GEARED):  # the chain's torque that turns this wheel with its side, wheel against chassis
                q = slots.side[k]
                change = (((taus[k] * dt * slots.inv_spin_inertia[k] - slots.sign[k] * shrink[q]
                            + slots.sign[k] * turn[q]) / slots.inv_spin_inertia[k] - wp.dot(spin[k], p3)) / dt
                          - taus[k])
                wp.atomic_add(body_f, wheel, wp.spatial_vector(wp.vec3(0.0), change * axle[k]))
                wp.atomic_add(body_f, base + slots.chassis, wp.spatial_vector(wp.vec3(0.0), -change * axle[k]))
            elif wp.static(IMPLICIT):  # noqa: SIM102 (wp.static stands alone: Warp resolves it as it builds the kernel)
                # the drive torque's change with the wheel's speed (or to its held torque), wheel against chassis
                if cs[k] > 0.0:
                    hk = wp.abs(torque_cap[world, k])
                    jk = 1.0 / slots.inv_spin_inertia[k]
                    sk = wheel_spin[k]
                    regime = drive_regime(sk, taus[k], cs[k], hk, jk, dt)
                    change = ((drive_spin_change(sk, regime, taus[k], cs[k], hk, jk, dt) * jk - wp.dot(spin[k], p3)) / dt
                              - taus[k])
                    wp.atomic_add(body_f, wheel, wp.spatial_vector(wp.vec3(0.0), change * axle[k]))
                    wp.atomic_add(body_f, base + slots.chassis, wp.spatial_vector(wp.vec3(0.0), -change * axle[k]))


    @wp.kernel(module="unique")
    def clear_impulses(mask: wp.array(dtype=bool), count: int, impulses: wp.array(dtype=wp.vec3)):
        """Zero the masked worlds' friction impulses (on reset; ``count`` wheels per world)."""
        world = wp.tid()
        if not mask[world]:
            return
        for k in range(count):
            impulses[world * count + k] = wp.vec3(0.0)

    return solve_wheel_friction, clear_impulses


friction_kernels(4)  # the default rover's, defined at import so that ``kernel_cache.precompile`` compiles it ahead
