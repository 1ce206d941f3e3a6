"""A step's outcome, split by job, one thread per world, launched in this order by the environment:

1. :func:`make_ends_kernel`'s kernel: the step counter, the chassis' distance and heading error to the target, and
   how the step ended (the task's success test, then a flip, an obstacle, any other contact, a path-following
   task's progress checker; else a timeout at ``max_steps``), or a blown-up world's containment;
2. :func:`advance_odometry_drift`: the robot observation's odometry drift from the encoders' slip;
3. the observation (:mod:`.observe`);
4. :func:`make_term_kernel`'s kernels, one per reward term: each writes its column, weighted, where its phase
   (running, success, failure) is this step's;
5. :func:`sum_terms`: the reward, the terms' sum in column order, and what the next step's terms compare with.

``params`` is a task config's :func:`~atrv_warp.task.kernels.state.params_struct`; the task's own functions (its
success test and its terms) are captured by the kernel factories, one compiled kernel each.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from atrv_warp.sim.kernels.contact import FLAG_OBSTACLE
from atrv_warp.task.kernels.observe import heading_error, planar_distance
from atrv_warp.task.kernels.state import (
    END_FLIP,
    END_NO_PROGRESS,
    END_NONE,
    END_NONFINITE,
    END_OBSTACLE,
    END_SUCCESS,
    END_TIMEOUT,
    END_WALL,
    RoverState,
    StepOutputs,
    TaskBuffers,
    TermInputs,
)

__all__ = ["advance_odometry_drift", "command_twist", "make_ends_kernel", "make_term_kernel", "sum_terms",
           "twist_command"]



def make_ends_kernel(success):
    """The ends kernel of a task whose success test is ``success(params, inputs: TermInputs, world) -> bool``."""

    @wp.kernel(module="unique")
    def decide_ends(params: Any, inputs: TermInputs, out: StepOutputs):
        world = wp.tid()
        task = inputs.task
        rover = inputs.rover
        steps = task.step_count[world] + 1
        task.step_count[world] = steps
        if rover.nonfinite[world] != 0:  # contain a blown-up world: a neutral step, then a reset
            out.terminated[world] = True
            out.truncated[world] = False
            out.end_reason[world] = END_NONFINITE
            out.distance[world] = task.prev_distance[world]
            return
        pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
        r = rover.rpy[world]
        target = task.target[world]
        d = planar_distance(pose, target)
        task.distance[world] = d
        task.heading_error[world] = wp.abs(heading_error(pose, target, r[2]))
        reason = END_NONE
        if success(params, inputs, world):
            reason = END_SUCCESS
        elif wp.abs(r[0]) > params.flip_roll:
            # before the contact check: a flipping chassis usually also touches the ground
            reason = END_FLIP
        elif (rover.contact_flags[world] & FLAG_OBSTACLE) != 0:
            reason = END_OBSTACLE
        elif rover.contact_flags[world] != 0:
            # wall, or the chassis on the ground: any contact beyond the wheels' ground contacts
            reason = END_WALL
        elif inputs.path.stalled[world] != 0:  # a path-following task's progress checker
            reason = END_NO_PROGRESS
        term = reason != END_NONE
        trunc = (not term) and steps >= params.max_steps
        if trunc:
            reason = END_TIMEOUT
        out.terminated[world] = term
        out.truncated[world] = trunc
        out.end_reason[world] = reason
        out.distance[world] = d

    return decide_ends


@wp.kernel
def advance_odometry_drift(step_dt: float, task: TaskBuffers, rover: RoverState):
    """The encoders' slip this step (their forward speed less the chassis's), amplified by the episode's slip gain
    into the robot observation's odometry drift along its heading (``RandomizationConfig.odometry_slip_gain``)."""
    world = wp.tid()
    gain = task.odom_slip_gain[world]
    if rover.nonfinite[world] != 0 or gain == 0.0:
        return
    pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
    v_true = wp.quat_rotate_inv(wp.transform_get_rotation(pose), rover.lin_vel[world])[0]
    slip = gain * (rover.odom_twist[world][0] - v_true) * step_dt
    yaw = rover.odometry[world][2] + task.odom_drift[world][2]
    task.odom_drift[world] = task.odom_drift[world] + wp.vec3(slip * wp.cos(yaw), slip * wp.sin(yaw), 0.0)


def make_term_kernel(term, column: int, phase: int):
    """The kernel of one reward term ``term(params, inputs: TermInputs, world) -> float``: ``weight`` times its
    value into ``column`` where the step's phase (:data:`~atrv_warp.task.definition.PHASES`) is ``phase``, else 0."""

    @wp.kernel(module="unique")
    def write_term(params: Any, inputs: TermInputs, weight: float, terms: wp.array2d(dtype=float)):
        world = wp.tid()
        reason = inputs.end_reason[world]
        live = False
        if phase == 0:
            live = not inputs.terminated[world]
        elif phase == 1:
            live = reason == END_SUCCESS
        else:
            live = reason == END_FLIP or reason == END_OBSTACLE or reason == END_WALL or reason == END_NO_PROGRESS
        value = float(0.0)
        if live:
            value = weight * term(params, inputs, world)
        terms[world, column] = value

    return write_term


@wp.kernel
def sum_terms(inputs: TermInputs, out: StepOutputs):
    """The reward: its terms' sum, in column order; then what the next step's terms compare with (the distance,
    the heading error, the action). A blown-up world's reward is 0 and it keeps its last."""
    world = wp.tid()
    if inputs.rover.nonfinite[world] != 0:
        out.reward[world] = 0.0
        return
    rew = wp.float32(0.0)
    for i in range(out.reward_terms.shape[1]):
        rew += out.reward_terms[world, i]
    out.reward[world] = rew
    task = inputs.task
    task.prev_distance[world] = task.distance[world]
    task.prev_heading_error[world] = task.heading_error[world]
    task.prev_action[world] = wp.vec2(wp.clamp(inputs.action[world, 0], -1.0, 1.0),
                                      wp.clamp(inputs.action[world, 1], -1.0, 1.0))


@wp.func
def twist_command(actions: wp.array2d(dtype=float), world: int, limits: wp.vec2) -> wp.vec2:
    """The twist (linear [m/s], angular [rad/s]) of a world's action: clipped to [-1, 1], times ``limits``
    (max_linear, max_angular); ``atrv_warp.task.spec.action_to_twist`` is its torch twin."""
    return wp.vec2(wp.clamp(actions[world, 0], -1.0, 1.0) * limits[0], wp.clamp(actions[world, 1], -1.0, 1.0) * limits[1])


@wp.kernel
def command_twist(actions: wp.array2d(dtype=float), limits: wp.vec2, twist: wp.array(dtype=wp.vec2),
                  age: wp.array(dtype=float)):
    """Every world's /cmd_vel for this step (:func:`twist_command`) into the driver's ``twist``, with its command
    ``age`` [s] restarted."""
    world = wp.tid()
    twist[world] = twist_command(actions, world, limits)
    age[world] = 0.0
