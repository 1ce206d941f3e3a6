"""The shipped reward terms and success test, each a small ``@wp.func`` of ``(params, inputs, world)``: ``params``
the task config's values (:func:`~atrv_warp.task.kernels.state.params_struct`), ``inputs`` everything a term may read
(:class:`~atrv_warp.task.kernels.state.TermInputs`). A term returns its value before its weight; the task's table
(:class:`atrv_warp.task.definition.RewardTerm`) gives the weight and when it counts.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from atrv_warp.sim.kernels.grid import wall_distance
from atrv_warp.sim.kernels.obstacles import OBSTACLE_NONE, bounding_radius
from atrv_warp.task.kernels.state import TermInputs

__all__ = ["action_rate", "clearance", "energy", "event", "heading", "progress", "step", "within_reach"]


@wp.func
def within_reach(params: Any, inputs: TermInputs, world: int) -> bool:
    """The reference's success: the chassis origin within ``reach_radius`` of the target."""
    return inputs.task.distance[world] < params.reach_radius


@wp.func
def progress(params: Any, inputs: TermInputs, world: int) -> float:
    """Distance gained toward the target this step [m]."""
    return inputs.task.prev_distance[world] - inputs.task.distance[world]


@wp.func
def heading(params: Any, inputs: TermInputs, world: int) -> float:
    """The reduction of |heading error| this step [rad]."""
    return inputs.task.prev_heading_error[world] - inputs.task.heading_error[world]


@wp.func
def step(params: Any, inputs: TermInputs, world: int) -> float:
    """-1 a step: the cost of time."""
    return -1.0


@wp.func
def event(params: Any, inputs: TermInputs, world: int) -> float:
    """1 on the step its phase names (the goal reached, a failure)."""
    return 1.0


@wp.func
def clearance(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus how far the nearest obstacle's bounding circle, or the world's map's nearest wall cell, reaches inside
    ``clearance_radius`` of the chassis origin [m]."""
    rover = inputs.rover
    obstacles = inputs.obstacles
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    p = wp.transform_get_translation(pose)
    inside = float(0.0)  # a variable the loop changes (Warp)
    for o in range(obstacles.count):
        kind = obstacles.kind[world, o]
        if kind != OBSTACLE_NONE:
            q = obstacles.pose[world, o]
            gap = wp.length(wp.vec2(q[0] - p[0], q[1] - p[1])) - bounding_radius(kind, obstacles.size[world, o])
            inside = wp.max(inside, params.clearance_radius - gap)
    if inputs.maps.count > 0:
        m = inputs.maps.world_map[world]
        if m >= 0:
            inside = wp.max(inside, params.clearance_radius - wall_distance(inputs.maps, m, wp.vec2(p[0], p[1])))
    return -inside


@wp.func
def action_rate(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the squared change of the action (clipped to [-1, 1]) since the step before (zero before a new
    episode's first action)."""
    a = wp.vec2(wp.clamp(inputs.action[world, 0], -1.0, 1.0), wp.clamp(inputs.action[world, 1], -1.0, 1.0))
    d = a - inputs.task.prev_action[world]
    return -wp.dot(d, d)


@wp.func
def energy(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the motors' mechanical work this step [J]: the sum over the wheels of |torque x speed| (the last
    substep's) x the step's duration."""
    power = float(0.0)
    for w in range(inputs.rover.wheel_speed.shape[1]):
        power += wp.abs(inputs.rover.wheel_torque[world, w] * inputs.rover.wheel_speed[world, w])
    return -power * inputs.step_dt
