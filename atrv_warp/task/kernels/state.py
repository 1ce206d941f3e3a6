"""What the task kernels read and write, as Warp structs built once: the simulator's state (:class:`RoverState`),
the task's per-world buffers (:class:`TaskBuffers`), a step's outputs (:class:`StepOutputs`), everything a reward
term may read (:class:`TermInputs`), and a task config's values (:func:`params_struct`, generated from the config's
dataclass: no field is copied into a kernel parameter by hand).
"""

from __future__ import annotations

import dataclasses
import typing

import warp as wp

from atrv_warp.sim.kernels.grid import GridMaps
from atrv_warp.sim.kernels.obstacles import ObstacleSet
from atrv_warp.task.spec import EndReason

__all__ = ["END_FLIP", "END_NONE", "END_NONFINITE", "END_NO_PROGRESS", "END_OBSTACLE", "END_SUCCESS", "END_TIMEOUT",
           "END_WALL", "PathState", "RoverState", "StepOutputs", "TaskBuffers", "TermInputs", "params_of", "params_struct"]

# Why an episode ended (``end_reason``), from task_spec.EndReason.
END_NONE = wp.constant(int(EndReason.RUNNING))
END_SUCCESS = wp.constant(int(EndReason.SUCCESS))
END_WALL = wp.constant(int(EndReason.WALL))
END_FLIP = wp.constant(int(EndReason.FLIP))
END_TIMEOUT = wp.constant(int(EndReason.TIMEOUT))
END_NONFINITE = wp.constant(int(EndReason.NONFINITE))
END_OBSTACLE = wp.constant(int(EndReason.OBSTACLE))
END_NO_PROGRESS = wp.constant(int(EndReason.NO_PROGRESS))


@wp.struct
class RoverState:
    """The simulator state the task reads, one struct so that a launch cannot reorder it
    (built once from :attr:`atrv_warp.sim.RoverSim.buffers`)."""

    body_q: wp.array(dtype=wp.transform)
    bodies_per_world: int
    chassis_body: int
    lin_vel: wp.array(dtype=wp.vec3)
    ang_vel: wp.array(dtype=wp.vec3)
    rpy: wp.array(dtype=wp.vec3)
    contact_flags: wp.array(dtype=wp.int32)
    nonfinite: wp.array(dtype=wp.int32)
    odometry: wp.array(dtype=wp.vec3)  # the base's fused odometry x [m], y [m], yaw [rad] (odometry frame; encoders
    # and gyro, the driver's ``fused``)
    odom_twist: wp.array(dtype=wp.vec2)  # the encoders' linear [m/s], angular [rad/s]
    wheel_speed: wp.array2d(dtype=float)  # (N, W) forward-positive wheel speeds [rad/s]
    wheel_torque: wp.array2d(dtype=float)  # (N, W) torques applied in the last substep [N·m]


@wp.struct
class StepOutputs:
    """What one step writes per world (all length N; ``obs`` and ``reward_terms`` have columns)."""

    obs: wp.array2d(dtype=float)
    reward: wp.array(dtype=float)
    reward_terms: wp.array2d(dtype=float)
    terminated: wp.array(dtype=bool)
    truncated: wp.array(dtype=bool)
    end_reason: wp.array(dtype=wp.int32)
    distance: wp.array(dtype=float)


@wp.struct
class TaskBuffers:
    """Per-world task state (all length N)."""

    target: wp.array(dtype=wp.vec2)
    target_yaw: wp.array(dtype=float)  # the goal's heading [rad] (a task that parks reads it; drawn last on reset)
    prev_distance: wp.array(dtype=float)
    prev_heading_error: wp.array(dtype=float)  # |heading error| at the previous step [rad]
    distance: wp.array(dtype=float)  # the chassis' distance to the target after this step [m]
    heading_error: wp.array(dtype=float)  # |heading error| after this step [rad]
    step_count: wp.array(dtype=wp.int32)
    episode: wp.array(dtype=wp.int32)  # episodes started in this world since seeding
    stream: wp.array(dtype=wp.int32)  # the reset stream this world draws from: its index, unless replaying another's
    goal_odom: wp.array(dtype=wp.vec2)  # the target in the odometry frame (the episode's start pose) [m]
    odom_drift: wp.array(dtype=wp.vec3)  # the odometry noise's random walk (x [m], y [m], yaw [rad]) this episode
    odom_scale: wp.array(dtype=float)  # the wheel odometry's distance per distance driven this episode [-] (1: exact)
    odom_slip_gain: wp.array(dtype=float)  # the odometry's extra distance per metre the encoders slip, this episode [-]
    prev_action: wp.array(dtype=wp.vec2)  # the action of the step before, clipped to [-1, 1] (zero after a reset)


@wp.struct
class PathState:
    """Each world's plan and how its robot follows it (:mod:`atrv_warp.task.kernels.paths`; arrays of one row where
    the task follows no plan)."""

    points: wp.array2d(dtype=wp.vec2)  # (N, max_points) the planner's paths [m], start to goal (map frame)
    length: wp.array(dtype=wp.int32)  # (N,) points in each path (0: none: the target alone)
    segment: wp.array(dtype=wp.int32)  # the segment the base's nearest point lies on (searched forward from here;
    # -1: a new plan, searched from its start)
    point: wp.array(dtype=wp.vec2)  # the base's nearest point on the plan [m]
    remaining: wp.array(dtype=float)  # the plan's length from the nearest point to the goal [m], after this step
    prev_to_go: wp.array(dtype=float)  # the way to go (offset + remaining) as the last observation saw it [m]
    offset: wp.array(dtype=float)  # the base's distance from the plan [m]
    reached: wp.array(dtype=wp.int32)  # 1 once the goal checker has found the goal's position reached (stateful)
    stalled: wp.array(dtype=wp.int32)  # 1 where the progress checker fails the episode this step
    baseline: wp.array(dtype=wp.vec2)  # the progress checker's last pose [m]
    since: wp.array(dtype=wp.int32)  # steps since the robot was last there
    clearance: wp.array(dtype=float)  # the base's distance to the nearest wall cell or obstacle surface [m]


@wp.struct
class TermInputs:
    """Everything a reward term (or a success test) may read, one struct: the rover, the task's buffers, the
    obstacles and maps, this step's action and the step's scan, and the step's end."""

    rover: RoverState
    task: TaskBuffers
    obstacles: ObstacleSet
    maps: GridMaps  # the worlds' maps (``count`` 0 where none has one)
    path: PathState  # each world's plan and how it is followed (a path-following task's; stalled 0 otherwise)
    action: wp.array2d(dtype=float)  # (N, 2) this step's action as given (a term clips it where it needs to)
    scan: wp.array2d(dtype=float)  # (N, beams) this step's ranges [m]; (N, 1) of zeros without a scanner
    end_reason: wp.array(dtype=wp.int32)  # this step's end (END_*; END_TIMEOUT on truncation)
    terminated: wp.array(dtype=bool)
    step_dt: float  # [s]


_PARAMS_TYPES: dict[type, type] = {}


def params_struct(config_cls: type) -> type:
    """The Warp struct of a task config dataclass: one member per field of a kernel-readable type, of the same
    name (a float, an int, a bool as an int, a pair of floats as ``wp.vec2``); other fields (names, optional values)
    stay on the host. Made once per class, so that kernels specialise once."""
    if config_cls in _PARAMS_TYPES:
        return _PARAMS_TYPES[config_cls]
    hints = typing.get_type_hints(config_cls)
    members = {}
    for f in dataclasses.fields(config_cls):
        kind = hints[f.name]
        if kind is float:
            members[f.name] = float
        elif kind is int or kind is bool:
            members[f.name] = int
        elif kind == tuple[float, float]:
            members[f.name] = wp.vec2
    name = f"{config_cls.__name__}Params"
    struct = wp.struct(type(name, (), {"__annotations__": members, "__module__": config_cls.__module__,
                                       "__qualname__": name, "__doc__": f"{config_cls.__name__}'s kernel values."}))
    _PARAMS_TYPES[config_cls] = struct
    return struct


def params_of(config) -> object:
    """A task config's values in its :func:`params_struct` (what the task kernels take as ``params``)."""
    struct = params_struct(type(config))
    p = struct()
    for name, kind in struct.cls.__annotations__.items():
        value = getattr(config, name)
        setattr(p, name, wp.vec2(*value) if kind is wp.vec2 else kind(value))
    return p
