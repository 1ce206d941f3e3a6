"""Reset sampling: each masked world's episode (start, target and, on the nav tasks, a terrain tile and an obstacle
layout) from a per-(world, episode) random stream, and the target in the episode's odometry frame.

One thread per world. ``params`` is a task config's :func:`~atrv_warp.task.kernels.state.params_struct` (any task
config class: the kernels specialise on it).
"""

from __future__ import annotations

from typing import Any

import warp as wp

from atrv_warp.sim.kernels.grid import GridMaps, spawn_point, wall_distance
from atrv_warp.sim.kernels.obstacles import OBSTACLE_BOX, OBSTACLE_CYLINDER, ObstacleSet, bounding_radius
from atrv_warp.sim.kernels.terrain import TerrainGrid
from atrv_warp.task.kernels.state import TaskBuffers

__all__ = ["PLAN_STREAM", "PinnedWorlds", "locate_goals", "obstacle_clear", "place_on_plans", "sample_episodes",
           "sample_nav_episodes"]

PLAN_STREAM = wp.constant(0x5EED)
"""Offsets the seed of :func:`place_on_plans`' stream from the episode sampler's, whose draws it leaves alone."""


@wp.struct
class PinnedWorlds:
    """Layouts given to some worlds (``RoverEnv.set_worlds``): a pinned world's every reset replays its own instead of
    drawing one."""

    pinned: wp.array(dtype=bool)  # (N,)
    start: wp.array(dtype=wp.vec3)  # (N,) x [m], y [m], yaw [rad]
    target: wp.array(dtype=wp.vec2)  # (N,) [m]
    target_yaw: wp.array(dtype=float)  # (N,) [rad]
    tile: wp.array(dtype=wp.int32)  # (N,) the terrain tile
    kind: wp.array2d(dtype=wp.int32)  # (N, slots) as ObstacleSet's
    pose: wp.array2d(dtype=wp.vec3)
    size: wp.array2d(dtype=wp.vec2)
    height: wp.array2d(dtype=float)


@wp.func
def replay_pinned(world: int, pins: PinnedWorlds, task: TaskBuffers, poses: wp.array(dtype=wp.vec3)):
    """A pinned world's given start, target and the target's heading, as a draw would write them; the episode
    counted as a draw counts it."""
    poses[world] = pins.start[world]
    task.target[world] = pins.target[world]
    task.target_yaw[world] = pins.target_yaw[world]
    task.episode[world] = task.episode[world] + 1
    task.step_count[world] = 0


@wp.kernel
def sample_episodes(seed: int, params: Any, mask: wp.array(dtype=bool), pins: PinnedWorlds, task: TaskBuffers,
                    poses: wp.array(dtype=wp.vec3)):
    """Draw target, start position and yaw for masked worlds from a per-(world, episode) stream; the goal's heading
    last (so the draws before it are the reference's). A pinned world replays its given layout."""
    world = wp.tid()
    if not mask[world]:
        return
    if pins.pinned[world]:
        replay_pinned(world, pins, task, poses)
        return
    h = wp.rand_init(seed, task.stream[world])
    state = wp.rand_init(wp.int32(h), task.episode[world])
    b = params.spawn_bound
    task.target[world] = wp.vec2(wp.randf(state, -b, b), wp.randf(state, -b, b))
    poses[world] = wp.vec3(wp.randf(state, -b, b), wp.randf(state, -b, b), wp.randf(state, -wp.pi, wp.pi))
    task.target_yaw[world] = wp.randf(state, -wp.pi, wp.pi)
    task.episode[world] = task.episode[world] + 1
    task.step_count[world] = 0


@wp.func
def obstacle_clear(q: wp.vec2, r: float, start: wp.vec2, target: wp.vec2, clearance: float) -> bool:
    return wp.length(q - start) > r + clearance and wp.length(q - target) > r + clearance


@wp.func
def leaves_a_way(grids: GridMaps, m: int, q: wp.vec2, r: float, passage: float) -> bool:
    """Whether an obstacle of bounding radius ``r`` at ``q`` leaves ``passage`` [m] free between it and the nearest
    wall of map ``m`` (a way round it, whatever else it stands in); anywhere where there is no map."""
    if m < 0:
        return True
    return wall_distance(grids, m, q) >= r + passage


MAP_TRIES = wp.constant(32)
"""Places an obstacle in a map world tries (in the arena: 8)."""


@wp.kernel
def sample_nav_episodes(
    seed: int,
    params: Any,
    distance: wp.vec2,
    tiles: int,
    passage: float,
    mask: wp.array(dtype=bool),
    task: TaskBuffers,
    poses: wp.array(dtype=wp.vec3),
    obstacles: ObstacleSet,
    terrain: TerrainGrid,
    grids: GridMaps,
    pins: PinnedWorlds,
):
    """Draw a masked world's episode: start and yaw, a target ``distance`` (min, max) [m] away, one of ``tiles``
    terrain tiles and an obstacle layout (``params.obstacles``, ``obstacles_on_path`` of them across the straight
    line, ``obstacle_size``) that keeps ``params.clearance`` from both ends, from a per-(world, episode) stream; the
    goal's heading last.

    In a world with a map (``grids``), the start and the target are cells of the map's ``spawn`` list (clear of the
    robot's footprint), the target in the start's group (reachable) and ``distance`` away (after 16 starts of 32
    targets each, the last drawn), and the obstacles anywhere on the map where each leaves a way round it (``passage``
    to the nearest wall). A pinned world (``pins``) replays its given layout: start, target, terrain tile and
    obstacles."""
    world = wp.tid()
    if not mask[world]:
        return
    if pins.pinned[world]:
        replay_pinned(world, pins, task, poses)
        terrain.tile[world] = pins.tile[world]
        for o in range(obstacles.count):
            obstacles.kind[world, o] = pins.kind[world, o]
            obstacles.pose[world, o] = pins.pose[world, o]
            obstacles.size[world, o] = pins.size[world, o]
            obstacles.height[world, o] = pins.height[world, o]
        return
    h = wp.rand_init(seed, task.stream[world])
    state = wp.rand_init(wp.int32(h), task.episode[world])
    b = params.spawn_bound
    half = b + 2.0
    low = wp.vec2(-half, -half)  # where the obstacles may stand
    high = wp.vec2(half, half)
    m = int(-1)
    if grids.count > 0:
        m = grids.world_map[world]
    start = wp.vec2(0.0)
    target = start
    if m >= 0:
        first = grids.spawn_start[m]
        count = grids.spawn_count[m]
        entry = first
        goal = first
        found = int(0)
        for _ in range(16):  # a start with a target at the asked distance in its group
            entry = first + wp.min(int(wp.randf(state) * float(count)), count - 1)
            group = grids.spawn_group[entry]
            members = grids.spawn_group_count[entry]
            for _draw in range(32):
                goal = group + wp.min(int(wp.randf(state) * float(members)), members - 1)
                d = wp.length(spawn_point(grids, m, goal) - spawn_point(grids, m, entry))
                if d >= distance[0] and d <= distance[1]:
                    found = 1
                    break
            if found == 1:
                break
        start = spawn_point(grids, m, entry)
        target = spawn_point(grids, m, goal)
        poses[world] = wp.vec3(start[0], start[1], wp.randf(state, -wp.pi, wp.pi))
        low = grids.origin[m]
        high = low + grids.resolution[m] * wp.vec2(float(grids.cols[m]), float(grids.rows[m]))
    else:
        start = wp.vec2(wp.randf(state, -b, b), wp.randf(state, -b, b))
        poses[world] = wp.vec3(start[0], start[1], wp.randf(state, -wp.pi, wp.pi))
        target = start
        for _ in range(32):  # a direction whose target lies inside the bound (the last try is clamped)
            a = wp.randf(state, -wp.pi, wp.pi)
            d = wp.randf(state, distance[0], distance[1])
            target = start + d * wp.vec2(wp.cos(a), wp.sin(a))
            if wp.abs(target[0]) <= b and wp.abs(target[1]) <= b:
                break
        target = wp.vec2(wp.clamp(target[0], -b, b), wp.clamp(target[1], -b, b))
    task.target[world] = target
    terrain.tile[world] = wp.int32(wp.min(int(wp.randf(state) * float(tiles)), tiles - 1))
    line = target - start
    length = wp.max(wp.length(line), 1.0e-6)
    along = line / length
    across = wp.vec2(-along[1], along[0])
    size = params.obstacle_size
    for o in range(obstacles.count):
        obstacles.kind[world, o] = 0
        obstacles.height[world, o] = obstacles.top  # a drawn obstacle is the config's height
        if o >= params.obstacles:
            continue
        tries = int(8)
        if m >= 0:
            tries = MAP_TRIES
        for _ in range(tries):  # retry a layout that would crowd the start or the target, or close a way
            kind = OBSTACLE_CYLINDER
            if wp.randf(state) < 0.5:
                kind = OBSTACLE_BOX
            extent = wp.vec2(wp.randf(state, size[0], size[1]), 0.0)
            if kind == OBSTACLE_BOX:
                extent = wp.vec2(extent[0], wp.randf(state, size[0], size[1]))
            q = wp.vec2(wp.randf(state, low[0], high[0]), wp.randf(state, low[1], high[1]))
            if o < params.obstacles_on_path:
                q = start + wp.randf(state, 0.35, 0.65) * line + wp.randf(state, -1.0, 1.0) * params.path_offset * across
            yaw = wp.randf(state, -wp.pi, wp.pi)
            r = bounding_radius(kind, extent)
            if obstacle_clear(q, r, start, target, params.clearance) and leaves_a_way(grids, m, q, r, passage):
                obstacles.kind[world, o] = kind
                obstacles.pose[world, o] = wp.vec3(q[0], q[1], yaw)
                obstacles.size[world, o] = extent
                break
    task.target_yaw[world] = wp.randf(state, -wp.pi, wp.pi)
    task.episode[world] = task.episode[world] + 1
    task.step_count[world] = 0


@wp.kernel
def place_on_plans(
    seed: int,
    params: Any,
    mask: wp.array(dtype=bool),
    pins: PinnedWorlds,
    task: TaskBuffers,
    starts: wp.array(dtype=wp.vec3),
    path: wp.array2d(dtype=wp.vec2),
    path_length: wp.array(dtype=wp.int32),
    grids: GridMaps,
    passage: float,
    obstacles: ObstacleSet,
):
    """Move a masked world's first ``params.obstacles_on_path`` obstacles from the straight line onto its plan (a
    world with a path of two points or more, not pinned): each at 35-65 % of the plan's length, within
    ``params.path_offset`` of it across, keeping ``params.clearance`` from the start and the target and ``passage``
    between it and the nearest wall (a way round; else it stays where the sampler put it), from a stream of its
    own. The planner does not see them: what a saved map does not
    show stands on the path it plans, as a chair or a person does."""
    world = wp.tid()
    n = path_length[world]
    if not mask[world] or pins.pinned[world] or n < 2:
        return
    h = wp.rand_init(seed + PLAN_STREAM, task.stream[world])
    state = wp.rand_init(wp.int32(h), task.episode[world])
    total = float(0.0)
    for i in range(n - 1):
        total = total + wp.length(path[world, i + 1] - path[world, i])
    s0 = starts[world]
    start = wp.vec2(s0[0], s0[1])
    target = task.target[world]
    for o in range(wp.min(params.obstacles_on_path, obstacles.count)):
        if obstacles.kind[world, o] == 0:
            continue
        for _ in range(MAP_TRIES):
            want = wp.randf(state, 0.35, 0.65) * total
            offset = wp.randf(state, -1.0, 1.0) * params.path_offset
            walked = float(0.0)
            q = path[world, n - 1]
            for i in range(n - 1):
                a = path[world, i]
                b = path[world, i + 1]
                step = wp.length(b - a)
                if walked + step >= want and step > 0.0:
                    along = (b - a) / step
                    q = a + (want - walked) * along + offset * wp.vec2(-along[1], along[0])
                    break
                walked = walked + step
            r = bounding_radius(obstacles.kind[world, o], obstacles.size[world, o])
            if obstacle_clear(q, r, start, target, params.clearance) and leaves_a_way(
                    grids, grids.world_map[world], q, r, passage):
                pose = obstacles.pose[world, o]
                obstacles.pose[world, o] = wp.vec3(q[0], q[1], pose[2])
                break


@wp.kernel
def locate_goals(mask: wp.array(dtype=bool), starts: wp.array(dtype=wp.vec3), task: TaskBuffers):
    """The masked worlds' targets in their odometry frame, whose origin is the episode's start pose (x [m],
    y [m], yaw [rad]): ``R(-yaw) (target - start)`` [m]."""
    world = wp.tid()
    if not mask[world]:
        return
    s = starts[world]
    d = task.target[world] - wp.vec2(s[0], s[1])
    c = wp.cos(s[2])
    n = wp.sin(s[2])
    task.goal_odom[world] = wp.vec2(c * d[0] + n * d[1], -n * d[0] + c * d[1])
