"""The 2-D laser scanner: one ray per (world, beam) against the arena walls, the ground or terrain,
the world's obstacles and its map's walls, with seeded Gaussian range noise and dropout."""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.contact import ARENA_PLANES, Scene
from atrv_warp.sim.kernels.grid import ray_grid
from atrv_warp.sim.kernels.obstacles import ray_obstacle
from atrv_warp.sim.kernels.terrain import ray_terrain


@wp.struct
class ScanParams:
    """The scanner (see :class:`atrv_warp.sim.scanner.ScannerConfig`)."""

    mount: wp.transform  # scanner frame in the chassis frame; beams lie in its x-y plane
    angles: wp.array(dtype=float)  # (B,) beam angles about the frame's z, 0 = forward [rad]
    min_range: float  # [m]
    max_range: float  # [m]; also what a beam without a return reads
    noise_std: float  # Gaussian range noise [m]
    dropout: float  # probability that a beam reads max_range [-]
    march_step: float  # ray-marching step over terrain [m]
    bodies_per_world: int
    chassis_body: int


@wp.func
def ray_plane(normal: wp.vec3, offset: float, origin: wp.vec3, direction: wp.vec3, t_max: float) -> float:
    """Distance [m] along a unit ray from free space (``n·x >= offset``) to the plane, or ``t_max``."""
    dn = wp.dot(normal, direction)
    if dn >= -1.0e-9:
        return t_max
    return wp.clamp((offset - wp.dot(normal, origin)) / dn, 0.0, t_max)


@wp.func
def cast_beam(params: ScanParams, scene: Scene, world: int, beam: int, X: wp.transform, stream: int,
              beams: int) -> float:
    """Range [m] of one beam of one world from the scanner frame ``X``; ``stream`` seeds this scan's noise."""
    origin = wp.transform_get_translation(X)
    a = params.angles[beam]
    direction = wp.transform_vector(X, wp.vec3(wp.cos(a), wp.sin(a), 0.0))
    t = params.max_range
    for k in range(ARENA_PLANES):  # a constant bound, which Warp unrolls
        if k > 0 or scene.terrain.enabled == 0:
            t = wp.min(t, ray_plane(scene.planes.normal[k], scene.planes.offset[k], origin, direction, t))
    obstacles = scene.obstacles
    for o in range(obstacles.count):
        kind = obstacles.kind[world, o]
        if kind != 0:
            t = wp.min(t, ray_obstacle(kind, obstacles.pose[world, o], obstacles.size[world, o],
                                       obstacles.height[world, o], origin, direction, t))
    if scene.grids.count > 0:  # the world's map: walls and unknown cells
        m = scene.grids.world_map[world]
        if m >= 0:
            t = wp.min(t, ray_grid(scene.grids, m, origin, direction, t))
    if scene.terrain.enabled != 0:  # last: the nearest other hit bounds the march
        t = wp.min(t, ray_terrain(scene.terrain, scene.terrain.tile[world], origin, direction, t, params.march_step))
    if params.noise_std > 0.0 or params.dropout > 0.0:
        state = wp.rand_init(stream, world * beams + beam)
        if wp.randf(state) < params.dropout:
            t = params.max_range
        elif t < params.max_range:
            t = t + params.noise_std * wp.randn(state)
    if not wp.isfinite(t):  # a blown-up world (the simulator flags it): no return
        t = params.max_range
    return wp.clamp(t, params.min_range, params.max_range)


@wp.kernel
def cast_scan(
    params: ScanParams,
    scene: Scene,
    body_q: wp.array(dtype=wp.transform),
    seed: int,
    counter: int,
    mask: wp.array(dtype=bool),
    beams_per_thread: int,
    ranges: wp.array2d(dtype=float),
):
    """Range [m] of every beam of every masked world; other worlds keep their ranges.

    dim = (N, ceil(B / beams_per_thread)): each thread casts ``beams_per_thread`` consecutive beams of
    one world. 1 (a thread per beam) suits a GPU; B (a thread per world) suits the CPU, where threads
    run one after another and a masked-out world should cost one call. Same ranges either way."""
    world, group = wp.tid()
    if not mask[world]:
        return
    X = body_q[world * params.bodies_per_world + params.chassis_body] * params.mount
    stream = wp.int32(wp.rand_init(seed, counter))
    beams = ranges.shape[1]
    first = group * beams_per_thread
    for beam in range(first, wp.min(first + beams_per_thread, beams)):
        ranges[world, beam] = cast_beam(params, scene, world, beam, X, stream, beams)
