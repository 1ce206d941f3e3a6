"""Static obstacles in kernels: upright boxes and cylinders, per world, that rovers must not touch.

Obstacles stand from below the ground to their ``ObstacleSet.height`` [m] (by default ``ObstacleSet.top``, taller
than the rover; a lower one passes under the laser), and their contact with the rover is worked out in the ground
plane: each rover shape's footprint (an oriented
rectangle) against each obstacle's (a rectangle or a disc). The deepest point of the pair gets the
same Hunt–Crossley force and friction as the ground, horizontally, at the shape's centre height.
"""

from __future__ import annotations

import warp as wp

OBSTACLE_NONE = wp.constant(0)
OBSTACLE_BOX = wp.constant(1)
OBSTACLE_CYLINDER = wp.constant(2)


@wp.struct
class ObstacleSet:
    """Every world's obstacles: ``count`` slots per world, unused ones of kind ``OBSTACLE_NONE``."""

    count: int  # slots per world (0: no obstacles)
    kind: wp.array2d(dtype=wp.int32)  # (N, count) OBSTACLE_NONE / _BOX / _CYLINDER
    pose: wp.array2d(dtype=wp.vec3)  # (N, count) centre x [m], y [m], yaw [rad]
    size: wp.array2d(dtype=wp.vec2)  # (N, count) box half extents (x, y) [m]; cylinder (radius, 0) [m]
    top: float  # the default obstacle's top [m], absolute: every drawn one's
    height: wp.array2d(dtype=float)  # (N, count) each obstacle's top [m], absolute


@wp.func
def rotate2(v: wp.vec2, yaw: float) -> wp.vec2:
    c = wp.cos(yaw)
    s = wp.sin(yaw)
    return wp.vec2(c * v[0] - s * v[1], s * v[0] + c * v[1])


@wp.func
def surface_distance(kind: int, pose: wp.vec3, size: wp.vec2, p: wp.vec2) -> float:
    """How far ``p`` is from an obstacle's surface in the ground plane [m] (0 inside): a box's (``pose`` x, y, yaw;
    half sides ``size``) or a cylinder's (radius ``size[0]``)."""
    d = wp.vec2(p[0] - pose[0], p[1] - pose[1])
    if kind == OBSTACLE_CYLINDER:
        return wp.max(wp.length(d) - size[0], 0.0)
    c = wp.cos(pose[2])
    s = wp.sin(pose[2])
    out = wp.vec2(wp.max(wp.abs(c * d[0] + s * d[1]) - size[0], 0.0), wp.max(wp.abs(-s * d[0] + c * d[1]) - size[1], 0.0))
    return wp.length(out)


@wp.func
def bounding_radius(kind: int, size: wp.vec2) -> float:
    if kind == OBSTACLE_CYLINDER:
        return size[0]
    return wp.length(size)


@wp.func
def footprint_vs_disc(c: wp.vec2, a1: wp.vec2, h1: float, h2: float, q: wp.vec2, radius: float):
    """Deepest contact of a rectangle (centre ``c``, unit axis ``a1``, half sizes h1 along it, h2
    across) with a disc: (depth [m], unit normal pushing the rectangle out, contact point)."""
    a2 = wp.vec2(-a1[1], a1[0])
    r = q - c
    lx = wp.dot(r, a1)
    ly = wp.dot(r, a2)
    closest = c + wp.clamp(lx, -h1, h1) * a1 + wp.clamp(ly, -h2, h2) * a2
    d = closest - q
    dl = wp.length(d)
    if dl > 1.0e-6:
        return radius - dl, d / dl, closest
    # the disc's centre is inside the rectangle: push out through the nearer side
    if h1 - wp.abs(lx) < h2 - wp.abs(ly):
        return radius + h1 - wp.abs(lx), -wp.sign(lx) * a1, q
    return radius + h2 - wp.abs(ly), -wp.sign(ly) * a2, q


@wp.func
def point_in_rect(p: wp.vec2, c: wp.vec2, a1: wp.vec2, h1: float, h2: float):
    """(depth [m], unit outward normal of the nearest side) of a point inside a rectangle; depth <= 0 outside."""
    a2 = wp.vec2(-a1[1], a1[0])
    r = p - c
    lx = wp.dot(r, a1)
    ly = wp.dot(r, a2)
    dx = h1 - wp.abs(lx)
    dy = h2 - wp.abs(ly)
    if dx <= 0.0 or dy <= 0.0:
        return 0.0, a1
    if dx < dy:
        return dx, wp.sign(lx) * a1
    return dy, wp.sign(ly) * a2


@wp.func
def footprint_vs_box(c: wp.vec2, a1: wp.vec2, h1: float, h2: float, q: wp.vec2, b1: wp.vec2, g1: float, g2: float):
    """Deepest contact of two rectangles, by corners of each inside the other:
    (depth [m], unit normal pushing the first out, contact point)."""
    best = float(0.0)
    normal = wp.vec2(0.0)
    point = c
    a2 = wp.vec2(-a1[1], a1[0])
    b2 = wp.vec2(-b1[1], b1[0])
    for corner in range(4):
        sx = float(2 * (corner & 1) - 1)
        sy = float(2 * ((corner >> 1) & 1) - 1)
        p = c + sx * h1 * a1 + sy * h2 * a2  # rover corner in the obstacle: pushed along its side
        d, n = point_in_rect(p, q, b1, g1, g2)
        if d > best:
            best = d
            normal = n
            point = p
        o = q + sx * g1 * b1 + sy * g2 * b2  # obstacle corner in the rover: pushed against its side
        d2, n2 = point_in_rect(o, c, a1, h1, h2)
        if d2 > best:
            best = d2
            normal = -n2
            point = o
    return best, normal, point


@wp.func
def ray_obstacle(kind: int, pose: wp.vec3, size: wp.vec2, top: float, origin: wp.vec3, direction: wp.vec3,
                 t_max: float) -> float:
    """Distance [m] along a unit ray to an obstacle's side, or ``t_max``; hits above ``top`` miss."""
    d2 = wp.vec2(direction[0], direction[1])
    rel = wp.vec2(origin[0] - pose[0], origin[1] - pose[1])
    t = t_max
    # cheap rejection by the bounding circle: behind the ray, beyond t_max, or passed wide of
    reach = bounding_radius(kind, size)
    a0 = wp.dot(d2, d2)
    b0 = wp.dot(rel, d2)
    if a0 < 1.0e-12 or b0 > 0.0 and wp.dot(rel, rel) > reach * reach:
        return t_max
    if wp.dot(rel, rel) - b0 * b0 / a0 > reach * reach or (wp.length(rel) - reach) * wp.sqrt(a0) > t_max:
        return t_max
    if kind == OBSTACLE_CYLINDER:
        a = wp.dot(d2, d2)
        b = wp.dot(rel, d2)
        cc = wp.dot(rel, rel) - size[0] * size[0]
        disc = b * b - a * cc
        if a > 1.0e-12 and disc >= 0.0:
            t_hit = (-b - wp.sqrt(disc)) / a
            if t_hit >= 0.0:
                t = t_hit
    elif kind == OBSTACLE_BOX:
        # slabs in the box frame
        lo = rotate2(rel, -pose[2])
        ld = rotate2(d2, -pose[2])
        t_near = float(-1.0e30)
        t_far = float(1.0e30)
        hit = True
        for axis in range(2):
            if wp.abs(ld[axis]) < 1.0e-12:
                if wp.abs(lo[axis]) > size[axis]:
                    hit = False
            else:
                ta = (-size[axis] - lo[axis]) / ld[axis]
                tb = (size[axis] - lo[axis]) / ld[axis]
                t_near = wp.max(t_near, wp.min(ta, tb))
                t_far = wp.min(t_far, wp.max(ta, tb))
        if hit and t_near <= t_far and t_near >= 0.0:
            t = t_near
    if t < t_max and origin[2] + t * direction[2] > top:
        return t_max
    return wp.min(t, t_max)
