"""Hunt–Crossley penalty contact between the rover's shapes and the arena's planes.

Newton 1.8's built-in contact force is linear in penetration (``ke d``); the reference law
is ``kp d^n + kc d^n d_dot``. The arena is a flat ground and four axis-aligned walls, so
every pair is a convex shape against a half-space and the deepest point has a closed form:
for a cylinder, the rim point furthest along ``-normal``; for a box, each corner. That
closed form is exact, cheap (one thread per world, no broad phase) and differentiable.

Forces are written into ``State.body_f`` (world-frame wrench at the body COM, linear first),
which Newton's solvers add to the articulated dynamics.
"""

from __future__ import annotations

import warp as wp

SHAPE_CYLINDER = wp.constant(0)
SHAPE_BOX = wp.constant(1)

# Bits of the per-world contact flags.
FLAG_WALL = wp.constant(1)
"""Any rover shape touches a wall."""
FLAG_BODY_GROUND = wp.constant(2)
"""A non-wheel shape (the chassis) touches the ground."""


@wp.struct
class ContactParams:
    """Hunt–Crossley law and friction (see :class:`atrv_warp.sim.config.ContactConfig`)."""

    stiffness: float  # kp [N/m^n]
    damping: float  # kc [N·s/m^(n+1)]
    exponent: float  # n [-]
    linear_region: float  # [m]
    linear_coeff: float  # linear_region^(n-1), so the law is continuous at linear_region


@wp.struct
class RoverShapes:
    """The rover's collision shapes, shared by every world (one template)."""

    count: int
    body: wp.array(dtype=int)  # body index within a world
    kind: wp.array(dtype=int)  # SHAPE_CYLINDER or SHAPE_BOX
    is_wheel: wp.array(dtype=int)
    xform: wp.array(dtype=wp.transform)  # shape pose in the body frame; cylinder axis = local z
    size: wp.array(dtype=wp.vec3)  # cylinder (radius, half length, 0); box half extents [m]
    slope_lon: wp.array(dtype=float)  # friction slope along the rolling direction [N·s/m]
    slope_lat: wp.array(dtype=float)  # friction slope along the axle (and for boxes) [N·s/m]


@wp.struct
class ArenaPlanes:
    """Half-spaces ``dot(normal, x) >= offset`` that bound free space: ground, then walls."""

    normal: wp.array(dtype=wp.vec3)
    offset: wp.array(dtype=float)


@wp.func
def hunt_crossley(depth: float, depth_rate: float, p: ContactParams) -> float:
    """Normal force [N] for penetration ``depth`` [m] growing at ``depth_rate`` [m/s]."""
    if depth <= 0.0:
        return 0.0
    s = 0.0
    if depth < p.linear_region:
        s = p.linear_coeff * depth
    else:
        s = wp.pow(depth, p.exponent)
    return wp.max(p.stiffness * s + p.damping * s * depth_rate, 0.0)


CYLINDER_EDGE_TILT = wp.constant(0.02)
"""Axle tilt |n·a| [-] (about 1.1 deg) over which the contact point slides from the middle of the
tyre to its lower edge. A lying cylinder touches a plane along a line; a hard switch to the lower
edge makes the contact point jump the tyre's width whenever the tilt changes sign (wheel
chatter in the forward pass, a gradient blind to the jump in the backward pass). Cost: the
depth is underestimated by at most half_length x 0.02 (0.75 mm) near level."""


@wp.func
def cylinder_deepest_point(xf: wp.transform, radius: float, half_length: float, normal: wp.vec3) -> wp.vec3:
    """Point of a cylinder (axis = local z of ``xf``) furthest along ``-normal``, smoothed near level."""
    c = wp.transform_get_translation(xf)
    a = wp.transform_vector(xf, wp.vec3(0.0, 0.0, 1.0))
    na = wp.dot(normal, a)
    radial = normal - na * a
    rl = wp.length(radial)
    p = c
    if rl > 1.0e-6:
        p = p - radial * (radius / rl)
    return p - a * (half_length * wp.clamp(na / CYLINDER_EDGE_TILT, -1.0, 1.0))


@wp.func
def point_contact_force(
    p: wp.vec3,
    depth: float,
    normal: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope_lon: float,
    slope_lat: float,
    params: ContactParams,
    friction: float,
) -> wp.vec3:
    """Normal plus friction force [N] at contact point ``p`` of a body moving with (v_com, omega)."""
    v = v_com + wp.cross(omega, p - com)
    vn = wp.dot(v, normal)
    fn = hunt_crossley(depth, -vn, params)
    vt = v - vn * normal
    # Directions: lateral = axle projected on the contact plane; longitudinal = normal x lateral.
    lat = axle - wp.dot(axle, normal) * normal
    ll = wp.length(lat)
    ft = wp.vec3(0.0)
    if ll > 1.0e-6:
        lat = lat / ll
        lon = wp.cross(normal, lat)
        ft = -(slope_lon * wp.dot(vt, lon)) * lon - (slope_lat * wp.dot(vt, lat)) * lat
    else:
        ft = -slope_lat * vt
    # Coulomb cap: |ft| <= mu fn
    fmax = friction * fn
    fl = wp.length(ft)
    if fl > fmax:
        ft = ft * (fmax / fl)
    return fn * normal + ft


@wp.func
def contact_wrench(
    p: wp.vec3,
    depth: float,
    normal: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope_lon: float,
    slope_lat: float,
    params: ContactParams,
    friction: float,
) -> wp.spatial_vector:
    """World-frame wrench about the COM [N, N·m] of one contact point."""
    f = point_contact_force(p, depth, normal, com, v_com, omega, axle, slope_lon, slope_lat, params, friction)
    return wp.spatial_vector(f, wp.cross(p - com, f))


@wp.func
def contact_flag(plane: int, is_wheel: int) -> wp.int32:
    """FLAG_WALL for a wall (planes 1-4), FLAG_BODY_GROUND for a non-wheel on the ground (plane 0)."""
    if plane > 0:
        return FLAG_WALL
    if is_wheel == 0:
        return FLAG_BODY_GROUND
    return wp.int32(0)


@wp.kernel
def compute_contact_forces(
    bodies_per_world: int,
    shapes: RoverShapes,
    planes: ArenaPlanes,
    params: ContactParams,
    friction: wp.array(dtype=float),
    body_q: wp.array(dtype=wp.transform),
    body_qd: wp.array(dtype=wp.spatial_vector),
    body_com: wp.array(dtype=wp.vec3),
    body_f: wp.array(dtype=wp.spatial_vector),
    contact_flags: wp.array(dtype=wp.int32),
):
    """One thread per world: add every shape–plane contact wrench to ``body_f``.

    ``friction`` is a one-element array (mu) so that gradients can flow to it.
    """
    world = wp.tid()
    mu = friction[0]
    base = world * bodies_per_world
    flags = contact_flags[world]
    for s in range(shapes.count):
        b = base + shapes.body[s]
        X = body_q[b]
        xf = X * shapes.xform[s]
        com = wp.transform_point(X, body_com[b])
        qd = body_qd[b]
        v_com = wp.spatial_top(qd)
        omega = wp.spatial_bottom(qd)
        axle = wp.transform_vector(xf, wp.vec3(0.0, 0.0, 1.0))
        size = shapes.size[s]
        wheel = shapes.is_wheel[s]
        wrench = wp.spatial_vector()
        for k in range(planes.normal.shape[0]):
            n = planes.normal[k]
            off = planes.offset[k]
            if shapes.kind[s] == SHAPE_CYLINDER:
                p = cylinder_deepest_point(xf, size[0], size[1], n)
                depth = off - wp.dot(n, p)
                if depth > 0.0:
                    wrench += contact_wrench(p, depth, n, com, v_com, omega, axle, shapes.slope_lon[s],
                                             shapes.slope_lat[s], params, mu)
                    flags = flags | contact_flag(k, wheel)
            else:
                for corner in range(8):
                    sx = float(2 * (corner & 1) - 1)
                    sy = float(2 * ((corner >> 1) & 1) - 1)
                    sz = float(2 * ((corner >> 2) & 1) - 1)
                    p = wp.transform_point(xf, wp.vec3(sx * size[0], sy * size[1], sz * size[2]))
                    depth = off - wp.dot(n, p)
                    if depth > 0.0:  # boxes: isotropic friction slope
                        wrench += contact_wrench(p, depth, n, com, v_com, omega, axle, shapes.slope_lat[s],
                                                 shapes.slope_lat[s], params, mu)
                        flags = flags | contact_flag(k, wheel)
        # atomic_add, not read-modify-write: it has an adjoint, so wp.Tape can differentiate it
        wp.atomic_add(body_f, b, wrench)
    contact_flags[world] = flags
