"""Hunt–Crossley penalty contact between the rover's shapes and the scene: the arena's planes,
the terrain and the obstacles.

Newton 1.8's built-in contact force is linear in penetration (``ke d``); the reference law
is ``kp d^n + kc d^n d_dot``. The reference arena is a flat ground and four axis-aligned walls, so
every pair is a convex shape against a half-space and the deepest point has a closed form:
for a cylinder, the rim point furthest along ``-normal``; for a box, each corner. That
closed form is exact, cheap (one thread per world, no broad phase) and differentiable.

On terrain (``kernels/terrain.py``) the ground is the tangent plane under the shape: for a wheel,
the plane under its centre gives a first deepest rim point, and the plane under that point the
final one; box corners use the plane under each corner. Obstacles (``kernels/obstacles.py``) are
worked out in the ground plane.

Friction here is the regularised law: proportional to slip up to ``mu f_n``, with a slope an
explicit step stays stable with. Under ``ContactConfig.friction_law = "coulomb"`` (the default) the
wheels' ground contacts are left to ``kernels/friction.py``, which solves them as Coulomb friction;
this kernel then handles the walls, obstacles and the chassis.

Forces are written into ``State.body_f`` (world-frame wrench at the body COM, linear first),
which Newton's solvers add to the articulated dynamics.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.grid import SKIP_MARGIN, GridMaps, cell_at, is_wall
from atrv_warp.sim.kernels.obstacles import (
    OBSTACLE_BOX,
    OBSTACLE_CYLINDER,
    ObstacleSet,
    bounding_radius,
    footprint_vs_box,
    footprint_vs_disc,
    rotate2,
)
from atrv_warp.sim.kernels.params import WorldPhysics
from atrv_warp.sim.kernels.terrain import TerrainGrid, terrain_normal, terrain_plane_offset, terrain_sample

SHAPE_CYLINDER = wp.constant(0)
SHAPE_BOX = wp.constant(1)

# Bits of the per-world contact flags.
FLAG_WALL = wp.constant(1)
"""Any rover shape touches a wall."""
FLAG_BODY_GROUND = wp.constant(2)
"""A non-wheel shape (the chassis) touches the ground."""
FLAG_OBSTACLE = wp.constant(4)
"""Any rover shape touches an obstacle or a wall of its map."""

ARENA_PLANES = wp.constant(5)
"""The arena's half-spaces: the ground (plane 0), then the four walls (``ArenaConfig.planes``)."""


@wp.struct
class ContactParams:
    """Hunt–Crossley law and friction (see :class:`atrv_warp.sim.config.ContactConfig`)."""

    stiffness: float  # kp [N/m^n]
    damping: float  # kc [N·s/m^(n+1)]
    exponent: float  # n [-]
    linear_region: float  # [m]
    linear_coeff: float  # linear_region^(n-1), so the law is continuous at linear_region
    wheel_solver: int  # 1: the wheels' ground contacts are solve_wheel_friction's (friction_law "coulomb")
    dt: float  # sim_dt [s]
    damping_cap: float  # ceiling on kc d^n [N·s/m] (ContactConfig.damping_limit)
    patch: float  # a wheel's ground on terrain: the mean over +-patch x radius along the rim (0: one point)


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


@wp.struct
class Scene:
    """Everything a rover can touch besides itself."""

    planes: ArenaPlanes
    terrain: TerrainGrid  # replaces plane 0 when enabled
    obstacles: ObstacleSet
    grids: GridMaps  # each world's map (count 0: none): walls the laser sees and the rover meets


@wp.func
def wheel_size(size: wp.vec3, physics: WorldPhysics, world: int) -> wp.vec3:
    """A wheel cylinder's (radius, half length, 0) with the world's rolling radius [m]."""
    return wp.vec3(physics.wheel_radius[world], size[1], size[2])


@wp.func
def hunt_crossley(depth: float, depth_rate: float, p: ContactParams, stiffness: float) -> float:
    """Normal force [N] for penetration ``depth`` [m] growing at ``depth_rate`` [m/s], with the world's
    ``stiffness`` kp [N/m^n]; the damping coefficient ``kc d^n`` is held at ``damping_cap``
    (``ContactConfig.damping_limit``)."""
    if depth <= 0.0:
        return 0.0
    s = 0.0
    if depth < p.linear_region:
        s = p.linear_coeff * depth
    else:
        s = wp.pow(depth, p.exponent)
    return wp.max(stiffness * s + wp.min(p.damping * s, p.damping_cap) * depth_rate, 0.0)


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
def contact_kinematics(p: wp.vec3, depth: float, normal: wp.vec3, com: wp.vec3, v_com: wp.vec3, omega: wp.vec3,
                       axle: wp.vec3, params: ContactParams, stiffness: float):
    """At contact point ``p`` of a body moving with (v_com, omega): (normal force [N], tangential slip
    velocity [m/s], the axle projected on the contact plane (the lateral direction, not normalised),
    its length)."""
    v = v_com + wp.cross(omega, p - com)
    vn = wp.dot(v, normal)
    fn = hunt_crossley(depth, -vn, params, stiffness)
    vt = v - vn * normal
    # Directions: lateral = axle projected on the contact plane; longitudinal = normal x lateral.
    lat = axle - wp.dot(axle, normal) * normal
    return fn, vt, lat, wp.length(lat)


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
    stiffness: float,
    friction: float,
) -> wp.vec3:
    """Normal plus friction force [N] at contact point ``p`` of a body moving with (v_com, omega)."""
    fn, vt, lat, ll = contact_kinematics(p, depth, normal, com, v_com, omega, axle, params, stiffness)
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
    stiffness: float,
    friction: float,
) -> wp.spatial_vector:
    """World-frame wrench about the COM [N, N·m] of one contact point."""
    f = point_contact_force(p, depth, normal, com, v_com, omega, axle, slope_lon, slope_lat, params, stiffness, friction)
    return wp.spatial_vector(f, wp.cross(p - com, f))


@wp.func
def contact_flag(plane: int, is_wheel: int) -> wp.int32:
    """FLAG_WALL for a wall (planes 1-4), FLAG_BODY_GROUND for a non-wheel on the ground (plane 0)."""
    if plane > 0:
        return FLAG_WALL
    if is_wheel == 0:
        return FLAG_BODY_GROUND
    return wp.int32(0)


@wp.func
def plane_contact(
    wrench: wp.spatial_vector,
    flags: wp.int32,
    plane: int,
    n: wp.vec3,
    off: float,
    kind: int,
    wheel: int,
    xf: wp.transform,
    size: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope_lon: float,
    slope_lat: float,
    params: ContactParams,
    stiffness: float,
    friction: float,
):
    """A cylinder's deepest rim point, or each box corner, against the half-space ``n·x >= off``:
    ``wrench`` and ``flags`` with this plane's wrenches added (one at a time, in corner order) and its
    contact bit set."""
    if kind == SHAPE_CYLINDER:
        p = cylinder_deepest_point(xf, size[0], size[1], n)
        depth = off - wp.dot(n, p)
        if depth > 0.0:
            wrench += contact_wrench(p, depth, n, com, v_com, omega, axle, slope_lon, slope_lat, params, stiffness, friction)
            flags = flags | contact_flag(plane, wheel)
    else:
        # the box's lowest point along -n is its centre's height less this support extent; the corners
        # are tested only when it may be in the half-space (1 µm of margin for rounding: exact either way)
        extent = (size[0] * wp.abs(wp.dot(n, wp.transform_vector(xf, wp.vec3(1.0, 0.0, 0.0))))
                  + size[1] * wp.abs(wp.dot(n, wp.transform_vector(xf, wp.vec3(0.0, 1.0, 0.0))))
                  + size[2] * wp.abs(wp.dot(n, wp.transform_vector(xf, wp.vec3(0.0, 0.0, 1.0)))))
        if wp.dot(n, wp.transform_get_translation(xf)) - off > extent + 1.0e-6:
            return wrench, flags
        for corner in range(8):
            sx = float(2 * (corner & 1) - 1)
            sy = float(2 * ((corner >> 1) & 1) - 1)
            sz = float(2 * ((corner >> 2) & 1) - 1)
            p = wp.transform_point(xf, wp.vec3(sx * size[0], sy * size[1], sz * size[2]))
            depth = off - wp.dot(n, p)
            if depth > 0.0:  # boxes: isotropic friction slope
                wrench += contact_wrench(p, depth, n, com, v_com, omega, axle, slope_lat, slope_lat, params,
                                         stiffness, friction)
                flags = flags | contact_flag(plane, wheel)
    return wrench, flags


@wp.func
def patch_sample(terrain: TerrainGrid, tile: int, xf: wp.transform, p: wp.vec3, along: float, across: float
                 ) -> wp.vec3:
    """The terrain's (height [m] at ``p``, dh/dx, dh/dy) averaged over five points: ``p`` and ``p`` +- ``along``
    [m] in the wheel's rolling direction and +- ``across`` [m] along its axle, each sample's height carried to
    ``p`` along its own tangent plane."""
    a = wp.transform_vector(xf, wp.vec3(0.0, 0.0, 1.0))
    side = wp.vec3(a[0], a[1], 0.0)
    sl = wp.length(side)
    if sl > 1.0e-6:
        side = side / sl
    else:
        side = wp.vec3(0.0, 1.0, 0.0)
    ahead = wp.vec3(side[1], -side[0], 0.0)
    total = terrain_sample(terrain, tile, p[0], p[1])
    for k in range(4):
        d = wp.where(k < 2, ahead * along, side * across) * wp.where(k % 2 == 0, 1.0, -1.0)
        h = terrain_sample(terrain, tile, p[0] + d[0], p[1] + d[1])
        total += wp.vec3(h[0] - h[1] * d[0] - h[2] * d[1], h[1], h[2])
    return total * 0.2


@wp.func
def wheel_ground_point(scene: Scene, tile: int, xf: wp.transform, size: wp.vec3, patch: float):
    """A cylinder's deepest point on the ground (the terrain's tangent plane, or plane 0; with ``patch`` > 0 the
    plane of the terrain's mean over a patch +-``patch`` x radius along the rim and across the width):
    (point [m], ground normal, depth [m], > 0 when touching)."""
    n = scene.planes.normal[0]
    off = scene.planes.offset[0]
    if scene.terrain.enabled != 0:
        c = wp.transform_get_translation(xf)
        h = terrain_sample(scene.terrain, tile, c[0], c[1])
        n = terrain_normal(h)
        off = terrain_plane_offset(n, c[0], c[1], h)
        p0 = cylinder_deepest_point(xf, size[0], size[1], n)
        if patch > 0.0:
            h = patch_sample(scene.terrain, tile, xf, p0, patch * size[0], size[1])
        else:
            h = terrain_sample(scene.terrain, tile, p0[0], p0[1])
        n = terrain_normal(h)
        off = terrain_plane_offset(n, p0[0], p0[1], h)
    p = cylinder_deepest_point(xf, size[0], size[1], n)
    return p, n, off - wp.dot(n, p)


@wp.func
def cylinder_ground_contact(
    scene: Scene,
    tile: int,
    xf: wp.transform,
    size: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope_lon: float,
    slope_lat: float,
    params: ContactParams,
    stiffness: float,
    friction: float,
):
    """A cylinder on the terrain under the regularised law: (wrench about the COM, 1 if touching)."""
    p, n, depth = wheel_ground_point(scene, tile, xf, size, params.patch)
    if depth <= 0.0:
        return wp.spatial_vector(), 0
    f = point_contact_force(p, depth, n, com, v_com, omega, axle, slope_lon, slope_lat, params, stiffness, friction)
    return wp.spatial_vector(f, wp.cross(p - com, f)), 1


@wp.func
def box_terrain_contact(
    scene: Scene,
    tile: int,
    xf: wp.transform,
    size: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope: float,
    params: ContactParams,
    stiffness: float,
    friction: float,
):
    """A box's corners on the terrain, each against the tangent plane under it: (wrench, 1 if touching)."""
    wrench = wp.spatial_vector()
    touching = int(0)
    for corner in range(8):
        sx = float(2 * (corner & 1) - 1)
        sy = float(2 * ((corner >> 1) & 1) - 1)
        sz = float(2 * ((corner >> 2) & 1) - 1)
        p = wp.transform_point(xf, wp.vec3(sx * size[0], sy * size[1], sz * size[2]))
        if p[2] > scene.terrain.high[tile]:  # above the tile's highest point: no contact, skip the lookup
            continue
        h = terrain_sample(scene.terrain, tile, p[0], p[1])
        n = terrain_normal(h)
        depth = terrain_plane_offset(n, p[0], p[1], h) - wp.dot(n, p)
        if depth > 0.0:
            wrench += contact_wrench(p, depth, n, com, v_com, omega, axle, slope, slope, params, stiffness, friction)
            touching = 1
    return wrench, touching


@wp.func
def footprint(kind: int, xf: wp.transform, size: wp.vec3, axle: wp.vec3):
    """A rover shape's footprint on the ground plane, an oriented rectangle about its centre: (unit axis, half size
    along it, half size across; the half sizes 0 for a shape whose axis stands upright)."""
    a1 = wp.vec2(0.0)
    h1 = float(0.0)
    h2 = float(0.0)
    if kind == SHAPE_CYLINDER:  # footprint: the axle's length by the diameter
        a1 = wp.vec2(axle[0], axle[1])
        h1 = size[1]
        h2 = size[0]
    else:  # footprint: the box's x and y extents
        ex = wp.transform_vector(xf, wp.vec3(1.0, 0.0, 0.0))
        a1 = wp.vec2(ex[0], ex[1])
        h1 = size[0]
        h2 = size[1]
    al = wp.length(a1)
    if al < 1.0e-6:
        return a1, 0.0, 0.0
    return a1 / al, h1, h2


@wp.func
def obstacle_contact(
    obstacles: ObstacleSet,
    world: int,
    kind: int,
    xf: wp.transform,
    size: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope: float,
    params: ContactParams,
    stiffness: float,
    friction: float,
):
    """A rover shape's footprint against every obstacle of the world: (wrench, 1 if touching)."""
    c3 = wp.transform_get_translation(xf)
    c = wp.vec2(c3[0], c3[1])
    a1, h1, h2 = footprint(kind, xf, size, axle)
    wrench = wp.spatial_vector()
    touching = int(0)
    if h1 <= 0.0:
        return wrench, touching
    reach = wp.sqrt(h1 * h1 + h2 * h2)
    for o in range(obstacles.count):
        okind = obstacles.kind[world, o]
        if okind == 0:
            continue
        pose = obstacles.pose[world, o]
        osize = obstacles.size[world, o]
        q = wp.vec2(pose[0], pose[1])
        if wp.length(q - c) > reach + bounding_radius(okind, osize) or c3[2] > obstacles.height[world, o]:
            continue
        depth = float(0.0)
        n2 = wp.vec2(0.0)
        p2 = c
        if okind == OBSTACLE_CYLINDER:
            depth, n2, p2 = footprint_vs_disc(c, a1, h1, h2, q, osize[0])
        elif okind == OBSTACLE_BOX:
            depth, n2, p2 = footprint_vs_box(c, a1, h1, h2, q, rotate2(wp.vec2(1.0, 0.0), pose[2]), osize[0],
                                             osize[1])
        if depth > 0.0:
            wrench += contact_wrench(wp.vec3(p2[0], p2[1], c3[2]), depth, wp.vec3(n2[0], n2[1], 0.0), com, v_com,
                                     omega, axle, slope, slope, params, stiffness, friction)
            touching = 1
    return wrench, touching


@wp.func
def grid_contact(
    grids: GridMaps,
    m: int,
    kind: int,
    xf: wp.transform,
    size: wp.vec3,
    com: wp.vec3,
    v_com: wp.vec3,
    omega: wp.vec3,
    axle: wp.vec3,
    slope: float,
    params: ContactParams,
    stiffness: float,
    friction: float,
):
    """A rover shape's footprint against the wall cells of map ``m`` (each a square standing to ``grids.top``): the
    deepest cell's contact, as one obstacle's (a wall of many cells pushes once, not once per cell): (wrench, 1 if
    touching). Far from every wall (the distance field says so at the shape's centre) it reads no cell."""
    c3 = wp.transform_get_translation(xf)
    c = wp.vec2(c3[0], c3[1])
    a1, h1, h2 = footprint(kind, xf, size, axle)
    wrench = wp.spatial_vector()
    if h1 <= 0.0 or c3[2] > grids.top:
        return wrench, 0
    res = grids.resolution[m]
    o2 = grids.origin[m]
    reach = wp.sqrt(h1 * h1 + h2 * h2)
    row0, col0 = cell_at(grids, m, c)
    inside = row0 >= 0 and col0 >= 0 and row0 < grids.rows[m] and col0 < grids.cols[m]
    if inside and (grids.distance[grids.start[m] + row0 * grids.cols[m] + col0] - SKIP_MARGIN) * res > reach:
        return wrench, 0
    span = int(wp.ceil(reach / res)) + 1
    best = float(0.0)
    normal = wp.vec2(0.0)
    point = c
    b1 = wp.vec2(1.0, 0.0)
    half = 0.5 * res
    for dr in range(-span, span + 1):
        for dc in range(-span, span + 1):
            row = row0 + dr
            col = col0 + dc
            if is_wall(grids, m, row, col):
                q = wp.vec2(o2[0] + (float(col) + 0.5) * res, o2[1] + (float(row) + 0.5) * res)
                depth, n2, p2 = footprint_vs_box(c, a1, h1, h2, q, b1, half, half)
                if depth > best:
                    best = depth
                    normal = n2
                    point = p2
    if best <= 0.0:
        return wrench, 0
    wrench = contact_wrench(wp.vec3(point[0], point[1], c3[2]), best, wp.vec3(normal[0], normal[1], 0.0), com, v_com,
                            omega, axle, slope, slope, params, stiffness, friction)
    return wrench, 1


@wp.kernel
def compute_contact_forces(
    bodies_per_world: int,
    shapes: RoverShapes,
    scene: Scene,
    params: ContactParams,
    physics: WorldPhysics,
    body_q: wp.array(dtype=wp.transform),
    body_qd: wp.array(dtype=wp.spatial_vector),
    body_com: wp.array(dtype=wp.vec3),
    body_f: wp.array(dtype=wp.spatial_vector),
    contact_flags: wp.array(dtype=wp.int32),
):
    """One thread per world: add every shape's contact wrenches (planes or terrain, obstacles) to
    ``body_f``, and OR the world's contact bits into ``contact_flags``.

    ``physics`` holds each world's mu, stiffness and wheel radius (arrays, so that gradients can flow
    to them).
    """
    world = wp.tid()
    mu = physics.friction[world]
    kp = physics.stiffness[world]
    base = world * bodies_per_world
    flags = contact_flags[world]
    planes = scene.planes
    tile = int(0)
    if scene.terrain.enabled != 0:
        tile = scene.terrain.tile[world]
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
        if wheel != 0:
            size = wheel_size(size, physics, world)
        wrench = wp.spatial_vector()
        kind = shapes.kind[s]
        # The ground: the terrain or plane 0; a wheel's is solve_wheel_friction's under friction_law "coulomb".
        if kind == SHAPE_CYLINDER and wheel != 0 and params.wheel_solver != 0:
            touching = 0
        elif kind == SHAPE_CYLINDER and scene.terrain.enabled != 0:
            w, touching = cylinder_ground_contact(scene, tile, xf, size, com, v_com, omega, axle, shapes.slope_lon[s],
                                                  shapes.slope_lat[s], params, kp, mu)
            wrench += w
            if touching != 0:
                flags = flags | contact_flag(0, wheel)
        elif kind == SHAPE_BOX and scene.terrain.enabled != 0:
            w, touching = box_terrain_contact(scene, tile, xf, size, com, v_com, omega, axle, shapes.slope_lat[s],
                                              params, kp, mu)
            wrench += w
            if touching != 0:
                flags = flags | contact_flag(0, wheel)
        else:
            wrench, flags = plane_contact(wrench, flags, 0, planes.normal[0], planes.offset[0], kind, wheel, xf, size,
                                          com, v_com, omega, axle, shapes.slope_lon[s], shapes.slope_lat[s], params,
                                          kp, mu)
        # The walls: only those within the shape's bounding sphere (cylinder sqrt(r² + (l/2)²), box half
        # diagonal); a wall beyond it cannot touch any point of the shape, so skipping it is exact.
        centre = wp.transform_get_translation(xf)
        reach = wp.length(size)
        for k in range(1, ARENA_PLANES):  # a constant bound, which Warp unrolls: 1.58x faster than a bound read
            # from the planes array (step_profile.py, the docs' performance page)
            n = planes.normal[k]
            off = planes.offset[k]
            if wp.dot(n, centre) - off <= reach:
                wrench, flags = plane_contact(wrench, flags, k, n, off, kind, wheel, xf, size, com, v_com, omega,
                                              axle, shapes.slope_lon[s], shapes.slope_lat[s], params, kp, mu)
        if scene.obstacles.count > 0:
            w, touching = obstacle_contact(scene.obstacles, world, shapes.kind[s], xf, size, com, v_com, omega, axle,
                                           shapes.slope_lat[s], params, kp, mu)
            wrench += w
            if touching != 0:
                flags = flags | FLAG_OBSTACLE
        if scene.grids.count > 0:  # the world's map: its walls and unknown cells, as obstacles
            m = scene.grids.world_map[world]
            if m >= 0:
                w, touching = grid_contact(scene.grids, m, shapes.kind[s], xf, size, com, v_com, omega, axle,
                                           shapes.slope_lat[s], params, kp, mu)
                wrench += w
                if touching != 0:
                    flags = flags | FLAG_OBSTACLE
        # atomic_add, not read-modify-write: it has an adjoint, so wp.Tape can differentiate it
        wp.atomic_add(body_f, b, wrench)
    contact_flags[world] = flags
