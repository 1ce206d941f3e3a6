"""Following a plan: where each world's robot is on its plan, the path observation's leading fields
(:data:`~atrv_warp.task.spec.PATH_OBSERVATION`), Nav2's goal and progress checkers, and the path-following reward
terms and success test. One thread per world; :class:`atrv_warp.core.path.PathTracker` is the torch twin of
:func:`nearest_on_path`, :func:`advance_on_path` and the observation (``tests/test_follow_path.py`` holds them equal).

The environment launches :func:`follow_paths` three ways: after a reset (``FOLLOW_RESET``: the masked worlds' checkers
start again, their plans' nearest points are searched from the start, and they are observed), after a step before its
ends are judged (``FOLLOW_STEP``: the nearest point on the plan the step was taken on, the checkers), and after the
step's replans (``FOLLOW_OBSERVE``: the nearest point on a new plan, searched from its start; the observation, and the
way to go that the next step's progress is measured from). So the nearest point is searched once a step on each
plan, as a robot's controller searches it once a period.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from atrv_warp.sim.kernels.grid import wall_distance
from atrv_warp.sim.kernels.obstacles import OBSTACLE_NONE, surface_distance
from atrv_warp.task.kernels.observe import (
    IMU_PITCH_BOUND,
    IMU_ROLL_BOUND,
    IMU_YAW_RATE_BOUND,
    ODOM_ANGULAR_BOUND,
    ODOM_LINEAR_BOUND,
    body_yaw_rate,
    wrap_angle,
)
from atrv_warp.task.kernels.state import PathState, TermInputs
from atrv_warp.task.spec import (
    PATH_BOUND,
    PATH_OBSERVATION,
    PATH_POINTS,
    PATH_REMAINING_BOUND,
    PATH_SPACING,
    ROBOT_OBSERVATION,
)

__all__ = ["FOLLOW_OBSERVE", "FOLLOW_RESET", "FOLLOW_STEP", "advance_on_path", "clearance_at", "follow_paths",
           "goal_checked", "goal_yaw", "nearest_on_path", "path_offset", "path_progress", "prefer_forward"]

FOLLOW_RESET = wp.constant(0)
FOLLOW_STEP = wp.constant(1)
FOLLOW_OBSERVE = wp.constant(2)

_INDEX = {f.name: i for i, f in enumerate(PATH_OBSERVATION)}
POINTS = wp.constant(PATH_POINTS)
SPACING = wp.constant(PATH_SPACING)
POINT_BOUND = wp.constant(PATH_BOUND)
REMAINING_BOUND = wp.constant(PATH_REMAINING_BOUND)
REMAINING = wp.constant(_INDEX["path_remaining"])
SIN_GOAL_YAW = wp.constant(_INDEX["sin_goal_yaw"])
COS_GOAL_YAW = wp.constant(_INDEX["cos_goal_yaw"])
ODOM_LINEAR = wp.constant(_INDEX["odom_linear"])
ODOM_ANGULAR = wp.constant(_INDEX["odom_angular"])
IMU_ROLL = wp.constant(_INDEX["imu_roll"])
IMU_PITCH = wp.constant(_INDEX["imu_pitch"])
IMU_YAW_RATE = wp.constant(_INDEX["imu_yaw_rate"])
assert [_INDEX[f"path_{k}_x"] for k in range(PATH_POINTS)] == list(range(0, 2 * PATH_POINTS, 2))
# the robot's twist and IMU fields, in the robot observation's order (its noise kernel shifts them as one block)
assert [f.name for f in PATH_OBSERVATION[-5:]] == [f.name for f in ROBOT_OBSERVATION[-5:]]


@wp.func
def clearance_at(inputs: TermInputs, world: int, p: wp.vec2) -> float:
    """The distance from ``p`` to the nearest wall cell of the world's map or obstacle surface [m] (1e6: none)."""
    obstacles = inputs.obstacles
    best = float(1.0e6)
    for o in range(obstacles.count):
        kind = obstacles.kind[world, o]
        if kind != OBSTACLE_NONE:
            best = wp.min(best, surface_distance(kind, obstacles.pose[world, o], obstacles.size[world, o], p))
    if inputs.maps.count > 0:
        m = inputs.maps.world_map[world]
        if m >= 0:
            best = wp.min(best, wall_distance(inputs.maps, m, p))
    return best


@wp.func
def path_point(path: PathState, target: wp.vec2, world: int, i: int) -> wp.vec2:
    """Point ``i`` of ``world``'s plan (a world without one: its target alone)."""
    if path.length[world] == 0:
        return target
    return path.points[world, i]


@wp.func
def path_count(path: PathState, world: int) -> int:
    return wp.max(path.length[world], 1)


@wp.func
def nearest_on_path(path: PathState, target: wp.vec2, world: int, q: wp.vec2, search: float):
    """(segment, the nearest point, its distance [m]) of ``world``'s plan to ``q``: the segments from
    ``path.segment`` on that start within ``search`` [m] of the plan from its start; the first of equal ones."""
    count = path_count(path, world)
    first = wp.max(path.segment[world], 0)
    if count == 1:
        p0 = path_point(path, target, world, 0)
        return int(0), p0, wp.length(q - p0)
    best = float(1.0e30)
    segment = first
    point = path_point(path, target, world, first)
    travelled = float(0.0)
    i = first
    while i < count - 1:
        a = path_point(path, target, world, i)
        ab = path_point(path, target, world, i + 1) - a
        length2 = wp.dot(ab, ab)
        t = float(0.0)
        if length2 > 0.0:
            t = wp.clamp(wp.dot(q - a, ab) / length2, 0.0, 1.0)
        c = a + t * ab
        d = wp.length(q - c)
        if d < best:
            best = d
            segment = i
            point = c
        travelled += wp.sqrt(length2)
        if travelled > search:
            break
        i += 1
    return segment, point, best


@wp.func
def advance_on_path(path: PathState, target: wp.vec2, world: int, segment: int, point: wp.vec2, distance: float):
    """(segment, point) ``distance`` [m] further along ``world``'s plan from ``point`` on ``segment`` (its end past
    the end)."""
    last = path_count(path, world) - 1
    seg = segment
    p = point
    left = distance
    while seg < last:
        end = path_point(path, target, world, seg + 1)
        gap = wp.length(end - p)
        if left <= gap:
            if gap > 0.0:
                return seg, p + (end - p) * (left / gap)
            return seg, end
        left -= gap
        seg += 1
        p = end
    return last, path_point(path, target, world, last)


@wp.func
def remaining_on_path(path: PathState, target: wp.vec2, world: int, segment: int, point: wp.vec2) -> float:
    """The plan's length from ``point`` on ``segment`` to its end [m]."""
    last = path_count(path, world) - 1
    if last == 0:
        return float(0.0)
    total = wp.length(path_point(path, target, world, segment + 1) - point)
    for j in range(segment + 1, last):
        total += wp.length(path_point(path, target, world, j + 1) - path_point(path, target, world, j))
    return total


@wp.func
def write_plan_observation(obs: wp.array2d(dtype=float), world: int, inputs: TermInputs, segment: int,
                           point: wp.vec2, q: wp.vec2, yaw: float):
    """The path observation's plan fields: the plan's points ahead in the base's frame, its length left, the turn to
    the goal's heading, each clipped to its bound."""
    path = inputs.path
    task = inputs.task
    target = task.target[world]
    c = wp.cos(yaw)
    s = wp.sin(yaw)
    seg = segment
    p = point
    for k in range(POINTS):
        if k > 0:
            seg, p = advance_on_path(path, target, world, seg, p, SPACING)
        d = p - q
        obs[world, 2 * k] = wp.clamp(c * d[0] + s * d[1], -POINT_BOUND, POINT_BOUND)
        obs[world, 2 * k + 1] = wp.clamp(-s * d[0] + c * d[1], -POINT_BOUND, POINT_BOUND)
    obs[world, REMAINING] = wp.clamp(path.remaining[world], -REMAINING_BOUND, REMAINING_BOUND)
    turn = wrap_angle(task.target_yaw[world] - yaw)
    obs[world, SIN_GOAL_YAW] = wp.sin(turn)
    obs[world, COS_GOAL_YAW] = wp.cos(turn)


@wp.func
def write_robot_fields(obs: wp.array2d(dtype=float), world: int, inputs: TermInputs, pose: wp.transform):
    """The path observation's robot fields: the encoders' twist and the IMU's, each clipped to its bound (the
    sensors' noise is added after them)."""
    task = inputs.task
    rover = inputs.rover
    scale = task.odom_scale[world]
    twist = rover.odom_twist[world]
    r = rover.rpy[world]
    obs[world, ODOM_LINEAR] = wp.clamp(scale * twist[0], -ODOM_LINEAR_BOUND, ODOM_LINEAR_BOUND)
    obs[world, ODOM_ANGULAR] = wp.clamp(twist[1], -ODOM_ANGULAR_BOUND, ODOM_ANGULAR_BOUND)
    obs[world, IMU_ROLL] = wp.clamp(r[0], -IMU_ROLL_BOUND, IMU_ROLL_BOUND)
    obs[world, IMU_PITCH] = wp.clamp(r[1], -IMU_PITCH_BOUND, IMU_PITCH_BOUND)
    obs[world, IMU_YAW_RATE] = wp.clamp(body_yaw_rate(pose, rover.ang_vel[world]), -IMU_YAW_RATE_BOUND,
                                        IMU_YAW_RATE_BOUND)


@wp.kernel
def follow_paths(params: Any, inputs: TermInputs, mode: int, mask: wp.array(dtype=bool), dt: float,
                 obs: wp.array2d(dtype=float)):
    """Each world's nearest point on its plan and the plan's length left; the checkers and the observation's robot
    fields after a step (``FOLLOW_STEP``) or from a reset (``FOLLOW_RESET``, masked worlds only); the observation's
    plan fields and the way to go the next progress counts from (``FOLLOW_RESET``, ``FOLLOW_OBSERVE``)."""
    world = wp.tid()
    if mode == FOLLOW_RESET and not mask[world]:
        return
    path = inputs.path
    rover = inputs.rover
    if rover.nonfinite[world] != 0:  # a blown-up world: at rest, the goal where it was
        if mode != FOLLOW_OBSERVE:
            for i in range(ODOM_LINEAR, IMU_YAW_RATE + 1):
                obs[world, i] = 0.0
        if mode != FOLLOW_STEP:
            for i in range(COS_GOAL_YAW):
                obs[world, i] = 0.0
            obs[world, REMAINING] = wp.clamp(path.remaining[world], -REMAINING_BOUND, REMAINING_BOUND)
            obs[world, COS_GOAL_YAW] = 1.0
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    t = wp.transform_get_translation(pose)
    q = wp.vec2(t[0], t[1])
    yaw = rover.rpy[world][2]
    target = inputs.task.target[world]
    if mode == FOLLOW_RESET:
        path.segment[world] = -1
        path.reached[world] = 0
        path.stalled[world] = 0
        path.since[world] = 0
        path.baseline[world] = q
    if mode != FOLLOW_OBSERVE or path.segment[world] < 0:  # once a step, and once more on a new plan
        segment, point, offset = nearest_on_path(path, target, world, q, params.path_search)
        path.segment[world] = segment
        path.point[world] = point
        path.offset[world] = offset
        path.remaining[world] = remaining_on_path(path, target, world, segment, point)
    if mode != FOLLOW_OBSERVE:  # after a reset or a step, before the sensors' noise
        path.clearance[world] = clearance_at(inputs, world, q)
        write_robot_fields(obs, world, inputs, pose)
    if mode == FOLLOW_STEP:
        # Nav2's SimpleGoalChecker (stateful: the position, once reached, stays reached) and SimpleProgressChecker
        if wp.length(q - target) <= params.reach_radius:
            path.reached[world] = 1
        if wp.length(q - path.baseline[world]) > params.progress_radius:
            path.baseline[world] = q
            path.since[world] = 0
        else:
            path.since[world] = path.since[world] + 1
        stalled = int(0)
        if float(path.since[world]) * dt > params.progress_time:
            stalled = 1
        path.stalled[world] = stalled
        return
    path.prev_to_go[world] = path.offset[world] + path.remaining[world]
    write_plan_observation(obs, world, inputs, path.segment[world], path.point[world], q, yaw)


@wp.func
def goal_checked(params: Any, inputs: TermInputs, world: int) -> bool:
    """Nav2's ``SimpleGoalChecker``, stateful: the goal's position reached (within ``reach_radius``, once) and the
    base's heading within ``yaw_tolerance`` of the goal's."""
    if inputs.path.reached[world] == 0:
        return False
    yaw = inputs.rover.rpy[world][2]
    return wp.abs(wrap_angle(inputs.task.target_yaw[world] - yaw)) <= params.yaw_tolerance


@wp.func
def path_progress(params: Any, inputs: TermInputs, world: int) -> float:
    """The way to go shortened this step [m], on the plan the step was taken on: the distance back to the plan plus
    the plan's length left from there (at the plan's end, the distance to the goal)."""
    path = inputs.path
    return path.prev_to_go[world] - (path.offset[world] + path.remaining[world])


@wp.func
def path_offset(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the base's distance from the plan [m]."""
    return -inputs.path.offset[world]


@wp.func
def prefer_forward(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the distance commanded backward this step [m] (the action's linear part, clipped, times ``max_linear``
    and the step's duration), except within ``prefer_forward_threshold`` of the goal: Nav2's MPPI
    ``PreferForwardCritic``."""
    if inputs.task.distance[world] <= params.prefer_forward_threshold:
        return 0.0
    return wp.min(wp.clamp(inputs.action[world, 0], -1.0, 1.0), 0.0) * params.max_linear * inputs.step_dt


@wp.func
def goal_yaw(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the turn left to the goal's heading [rad], once the goal's position is reached (0 before)."""
    if inputs.path.reached[world] == 0:
        return 0.0
    return -wp.abs(wrap_angle(inputs.task.target_yaw[world] - inputs.rover.rpy[world][2]))
