"""A task of your own, in one file: ``parking``. Drive to a pose (a spot and a heading) and stop there.

Train it, evaluate it and export it with the package's own commands (``docs/your-own-task.md`` walks through it)::

    python -m atrv_warp.train --config examples/parking.toml                         # about 10 minutes on 2 cores
    python -m atrv_warp.evaluate runs/parking/best_policy.pt --task-module examples/custom_task.py
    python -m atrv_warp.export runs/parking/best_policy.pt parking.pt2 --task-module examples/custom_task.py

What a task declares, all here:

- its **config**: :class:`ParkingConfig` adds its own fields to :class:`~atrv_warp.task.config.TaskConfig`'s (the
  tolerances of a parked pose, its reward weights); every field is set from the command line as
  ``env.task.<field>=VALUE`` or in an ``[env.task]`` table;
- its **scene** and **reset**: the config's fields (a flat arena, no obstacles, a goal 1.5–4 m away; the goal's
  heading is drawn on every reset, ``env.target_yaw``);
- its **observation**: a kind of its own, :data:`PARKING_OBSERVATION`, each field a ``@wp.func`` (the goal in the
  rover's frame, the heading still to turn, the rover's speeds);
- its **ends**: :func:`parked`, the success test (a wall or a flip fails, the time runs out, as in every task);
- its **reward**: a table of :class:`~atrv_warp.task.definition.RewardTerm` rows, the shipped ``progress``,
  ``step_penalty``, ``success`` and ``failure`` beside three of its own, ``alignment``, ``stopping`` and ``posed``.

A term is one ``@wp.func`` of ``(params, inputs, world)`` and one row: ``params`` has every field of the config by
name (``params.park_radius``), ``inputs`` everything a term may read (the rover's state, the task's buffers, the
action, the scan: :class:`~atrv_warp.task.kernels.state.TermInputs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import warp as wp

from atrv_warp.task import terms
from atrv_warp.task.config import TaskConfig
from atrv_warp.task.definition import RewardTerm, Task
from atrv_warp.task.kernels.state import TermInputs
from atrv_warp.task.registry import register_task
from atrv_warp.task.spec import ObservationField, register_observation


@dataclass(frozen=True)
class ParkingConfig(TaskConfig):
    """The parking task's config: :class:`TaskConfig`'s fields, and its own."""

    park_radius: float = 0.3
    """A parked chassis origin is this close to the spot [m]."""
    park_yaw: float = math.radians(15.0)
    """... its heading this close to the goal's [rad] ..."""
    park_speed: float = 0.1
    """... and it stands: its forward speed below this [m/s] (and its yaw rate below this [rad/s])."""
    near: float = 1.5
    """Within this distance of the spot [m], turning to the goal's heading pays."""
    alignment_weight: float = 1.0
    """Weight of the alignment term [1/rad]."""
    stopping_weight: float = 1.0
    """Weight of the stopping term [1/m]."""
    posed_weight: float = 0.1
    """Weight of the posed term (a step on the spot at the goal's heading)."""


# ---- the observation: the goal in the rover's frame, the heading still to turn, the rover's speeds

@wp.func
def _chassis(inputs: TermInputs, world: int) -> wp.transform:
    rover = inputs.rover
    return rover.body_q[world * rover.bodies_per_world + rover.chassis_body]


@wp.func
def _goal_in_chassis(inputs: TermInputs, world: int) -> wp.vec3:
    pose = _chassis(inputs, world)
    target = inputs.task.target[world]
    p = wp.transform_get_translation(pose)
    return wp.quat_rotate_inv(wp.transform_get_rotation(pose), wp.vec3(target[0] - p[0], target[1] - p[1], 0.0))


@wp.func
def _yaw_error(inputs: TermInputs, world: int) -> float:
    """The heading still to turn to the goal's [rad], in [-pi, pi]."""
    e = inputs.task.target_yaw[world] - inputs.rover.rpy[world][2]
    return wp.atan2(wp.sin(e), wp.cos(e))


@wp.func
def _forward_speed(inputs: TermInputs, world: int) -> float:
    return wp.quat_rotate_inv(wp.transform_get_rotation(_chassis(inputs, world)), inputs.rover.lin_vel[world])[0]


@wp.func
def goal_forward(params: Any, inputs: TermInputs, world: int) -> float:
    return _goal_in_chassis(inputs, world)[0]


@wp.func
def goal_left(params: Any, inputs: TermInputs, world: int) -> float:
    return _goal_in_chassis(inputs, world)[1]


@wp.func
def sin_yaw_error(params: Any, inputs: TermInputs, world: int) -> float:
    return wp.sin(_yaw_error(inputs, world))


@wp.func
def cos_yaw_error(params: Any, inputs: TermInputs, world: int) -> float:
    return wp.cos(_yaw_error(inputs, world))


@wp.func
def forward_speed(params: Any, inputs: TermInputs, world: int) -> float:
    return _forward_speed(inputs, world)


@wp.func
def yaw_rate(params: Any, inputs: TermInputs, world: int) -> float:
    return inputs.rover.ang_vel[world][2]


PARKING_OBSERVATION = register_observation("parking", (
    ObservationField("goal_forward", 12.0, "the spot ahead of the chassis origin", "m", "chassis", goal_forward),
    ObservationField("goal_left", 12.0, "the spot to the chassis' left", "m", "chassis", goal_left),
    ObservationField("sin_yaw_error", 1.0, "sine of the heading still to turn to the goal's", "-", "chassis",
                     sin_yaw_error),
    ObservationField("cos_yaw_error", 1.0, "its cosine", "-", "chassis", cos_yaw_error),
    ObservationField("forward_speed", 3.0, "the chassis' forward speed", "m/s", "chassis", forward_speed),
    ObservationField("yaw_rate", 3.0, "its yaw rate", "rad/s", "world z", yaw_rate),
))


# ---- the ends: parked is the spot, the heading and standing still

@wp.func
def parked(params: Any, inputs: TermInputs, world: int) -> bool:
    return (inputs.task.distance[world] < params.park_radius
            and wp.abs(_yaw_error(inputs, world)) < params.park_yaw
            and wp.abs(_forward_speed(inputs, world)) < params.park_speed
            and wp.abs(inputs.rover.ang_vel[world][2]) < params.park_speed)


# ---- three reward terms of its own: turning to the goal's heading near the spot, standing still on it, being on it

@wp.func
def _nearness(params: Any, inputs: TermInputs, world: int) -> float:
    return wp.max(0.0, 1.0 - inputs.task.distance[world] / params.near)


@wp.func
def alignment(params: Any, inputs: TermInputs, world: int) -> float:
    """How far the rover turned toward the goal's heading this step [rad] (the yaw rate's share that closes the
    error), near the spot."""
    turned = wp.sign(_yaw_error(inputs, world)) * inputs.rover.ang_vel[world][2] * inputs.step_dt
    return _nearness(params, inputs, world) * turned


@wp.func
def stopping(params: Any, inputs: TermInputs, world: int) -> float:
    """Minus the distance driven this step [m], on the spot (within twice ``park_radius``, fading out)."""
    on_spot = wp.max(0.0, 1.0 - inputs.task.distance[world] / (2.0 * params.park_radius))
    return -on_spot * wp.abs(_forward_speed(inputs, world)) * inputs.step_dt


@wp.func
def posed(params: Any, inputs: TermInputs, world: int) -> float:
    """1 on a step that ends on the spot at the goal's heading (moving or not): what standing still there builds on."""
    on_spot = inputs.task.distance[world] < params.park_radius and wp.abs(_yaw_error(inputs, world)) < params.park_yaw
    return wp.where(on_spot, 1.0, 0.0)


ALIGNMENT = RewardTerm("alignment", alignment, "alignment_weight", description="turning to the goal's heading, near "
                       "the spot [rad]")
STOPPING = RewardTerm("stopping", stopping, "stopping_weight", description="minus the distance driven on the spot "
                      "[m]")
POSED = RewardTerm("posed", posed, "posed_weight", description="1 a step on the spot at the goal's heading")

CONFIG = ParkingConfig(action="twist", observation="parking", max_linear=1.0, max_angular=1.5,
                       linear_max_acceleration=1.0, target_distance=(1.5, 4.0), max_steps=200, reach_radius=0.3,
                       success_reward=10.0, failure_reward=-5.0, step_penalty=0.01)
TASK = register_task(Task("parking", CONFIG, (terms.PROGRESS, ALIGNMENT, STOPPING, POSED, terms.STEP_PENALTY,
                                              terms.SUCCESS, terms.FAILURE), parked, description=__doc__.splitlines()[0]),
                     replace=True)
