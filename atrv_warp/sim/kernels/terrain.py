"""Heightfield terrain in kernels: bilinear height and slope, the tangent plane under a point,
placing a rover on the ground at reset, and a ray–terrain intersection for the scanner.

Heights are ``ground_top`` + a bilinear interpolation of the world's tile of
:class:`~atrv_warp.sim.terrain.HeightGrid`; outside the grid the edge values continue.
"""

from __future__ import annotations

import warp as wp


@wp.struct
class TerrainGrid:
    """Per-world terrain: which tile each world drives on, and the tiles' height samples."""

    enabled: int  # 0: the flat ground plane (the reference arena)
    heights: wp.array3d(dtype=float)  # (tiles, n, n) [m] above ground_top, x index first
    tile: wp.array(dtype=wp.int32)  # (N,) each world's tile
    low: wp.array(dtype=float)  # (tiles,) lowest sample [m], absolute
    high: wp.array(dtype=float)  # (tiles,) highest sample [m], absolute
    origin: float  # x and y of sample 0 [m] (-half_size)
    inv_resolution: float  # [1/m]
    base: float  # ground_top [m]


@wp.func
def terrain_sample(terrain: TerrainGrid, tile: int, x: float, y: float) -> wp.vec3:
    """(height [m] absolute, dh/dx, dh/dy) at (x, y) [m], bilinear."""
    n = terrain.heights.shape[1]
    fx = wp.clamp((x - terrain.origin) * terrain.inv_resolution, 0.0, float(n - 1) - 1.0e-3)
    fy = wp.clamp((y - terrain.origin) * terrain.inv_resolution, 0.0, float(n - 1) - 1.0e-3)
    i = int(fx)
    j = int(fy)
    u = fx - float(i)
    v = fy - float(j)
    h00 = terrain.heights[tile, i, j]
    h10 = terrain.heights[tile, i + 1, j]
    h01 = terrain.heights[tile, i, j + 1]
    h11 = terrain.heights[tile, i + 1, j + 1]
    h = (1.0 - u) * (1.0 - v) * h00 + u * (1.0 - v) * h10 + (1.0 - u) * v * h01 + u * v * h11
    dx = ((1.0 - v) * (h10 - h00) + v * (h11 - h01)) * terrain.inv_resolution
    dy = ((1.0 - u) * (h01 - h00) + u * (h11 - h10)) * terrain.inv_resolution
    return wp.vec3(terrain.base + h, dx, dy)


@wp.func
def terrain_normal(sample: wp.vec3) -> wp.vec3:
    """Upward unit normal of the surface from a :func:`terrain_sample`."""
    return wp.normalize(wp.vec3(-sample[1], -sample[2], 1.0))


@wp.func
def terrain_plane_offset(normal: wp.vec3, x: float, y: float, sample: wp.vec3) -> float:
    """Offset of the tangent plane ``n·p >= offset`` through the surface point above (x, y)."""
    return wp.dot(normal, wp.vec3(x, y, sample[0]))


@wp.kernel
def place_on_terrain(
    chassis_coord: int,
    coords_per_world: int,
    terrain: TerrainGrid,
    mask: wp.array(dtype=bool),
    poses: wp.array(dtype=wp.vec3),
    height: float,
    footprint: float,
    joint_q: wp.array(dtype=float),
):
    """After a level reset at ``height`` above the flat ground: lift each masked world's chassis by
    the terrain height under it and tilt it to the ground's mean slope over +-``footprint`` [m]."""
    world = wp.tid()
    if not mask[world]:
        return
    pose = poses[world]
    tile = terrain.tile[world]
    x = pose[0]
    y = pose[1]
    hx = terrain_sample(terrain, tile, x + footprint, y)[0] - terrain_sample(terrain, tile, x - footprint, y)[0]
    hy = terrain_sample(terrain, tile, x, y + footprint)[0] - terrain_sample(terrain, tile, x, y - footprint)[0]
    normal = wp.normalize(wp.vec3(-hx / (2.0 * footprint), -hy / (2.0 * footprint), 1.0))
    tilt = wp.quat_between_vectors(wp.vec3(0.0, 0.0, 1.0), normal)
    yaw = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), pose[2])
    q = tilt * yaw
    q0 = world * coords_per_world + chassis_coord
    # the flat-ground clearance, kept perpendicular to the slope
    joint_q[q0 + 2] = terrain_sample(terrain, tile, x, y)[0] + (height - terrain.base) / normal[2]
    joint_q[q0 + 3] = q[0]
    joint_q[q0 + 4] = q[1]
    joint_q[q0 + 5] = q[2]
    joint_q[q0 + 6] = q[3]


@wp.func
def ray_terrain(terrain: TerrainGrid, tile: int, origin: wp.vec3, direction: wp.vec3, t_max: float,
                step: float) -> float:
    """Distance [m] along a unit ray to the terrain, or ``t_max`` if none within it.

    Marches in ``step`` [m] only over the stretch where the ray's height lies within the tile's
    height range, then refines the crossing by bisection (8 halvings: step / 256)."""
    low = terrain.low[tile]
    high = terrain.high[tile]
    dz = direction[2]
    t0 = float(0.0)
    t1 = t_max
    if wp.abs(dz) < 1.0e-9:
        if origin[2] > high or origin[2] < low:
            return t_max
    elif dz < 0.0:
        t0 = wp.max((origin[2] - high) / (-dz), 0.0)
        t1 = wp.min((origin[2] - low) / (-dz) + step, t_max)
    else:
        t1 = wp.min((high - origin[2]) / dz + step, t_max)
    if t0 >= t1:
        return t_max
    prev = t0
    p = origin + direction * t0
    if p[2] <= terrain_sample(terrain, tile, p[0], p[1])[0]:
        return t0
    t = t0
    while t < t1:
        t = wp.min(t + step, t1)
        p = origin + direction * t
        if p[2] <= terrain_sample(terrain, tile, p[0], p[1])[0]:
            lo = prev
            hi = t
            for _ in range(8):
                mid = 0.5 * (lo + hi)
                q = origin + direction * mid
                if q[2] <= terrain_sample(terrain, tile, q[0], q[1])[0]:
                    hi = mid
                else:
                    lo = mid
            return hi
        prev = t
    return t_max
