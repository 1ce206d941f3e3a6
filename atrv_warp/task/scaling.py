"""How a task follows the robot it runs on: the rule every shipped task declares (:attr:`Task.scale
<atrv_warp.task.definition.Task.scale>`), and a task of your own may replace.

The tasks' worlds are the same for every robot (the arena, the goals 5-10 m away, the obstacles): a robot meets the
world at its own limits and its own size. The rule (:func:`scale_to_robot`):

- **Limits.** A twist task's action 1 is the robot's own ``linear.x.max_velocity`` and ``angular.z.max_velocity``,
  and its base applies the robot's acceleration limits (its file's ``[limits]``). A torque task's action 1 is the
  robot's motor torque limit.
- **Time, by the control period.** The twist tasks were shaped at 2 m/s (:data:`REFERENCE_SPEED`, action 1 before
  robots had files: the Jackal J100's limit) and a 0.05 s period. A robot whose limit is lower controls at a period
  longer by the same ratio (:data:`REFERENCE_STEP_DT` x 2 m/s / its speed, on the solver's substep grid): every
  step covers the distance it did, so an episode's ``max_steps`` give a robot at its own speed the margin they gave
  at 2 m/s, the discount spans the same distance, and the policy sees the same number of decisions per metre. The
  ATRV-Jr's 0.5 m/s controls at 0.2 s (5 Hz; its rFLEX driver runs at 10 Hz), the Husky's 1 m/s at 0.1 s (its ROS 1
  base ran at 10 Hz), the Jackal's 2 m/s at 0.05 s. Scaling the time budget instead would make a slow robot's
  episodes 4 times as many steps, which costs frames and stretches the discount's horizon; scaling the distances
  would shrink goals and obstacles below the robot's own size.
- **Footprint.** The reach radius, the clearance radius and the obstacles' clearance from the start and the goal keep
  the margin they had over the ATRV-Jr's footprint (:data:`REFERENCE_FOOTPRINT`, 0.43 m from its origin to the
  farthest corner of its body or wheels): each is its value plus the robot's footprint radius minus the ATRV-Jr's.

On the ATRV-Jr every torque task is unchanged (its torque limit is the reference's 20 N·m); its twist task
(``nav_deploy``) takes its 0.5 m/s and 1.0 rad/s.
"""

from __future__ import annotations

import dataclasses
import math

__all__ = ["REFERENCE_FOOTPRINT", "REFERENCE_SPEED", "REFERENCE_STEP_DT", "control_period", "fit_task",
           "footprint_radius", "scale_to_robot"]

REFERENCE_SPEED = 2.0
"""[m/s] The forward speed the twist tasks were shaped at (their action 1 before robots had files)."""
REFERENCE_STEP_DT = 0.05
"""[s] The control period they were shaped at (the simulator's default ``step_dt``)."""
REFERENCE_FOOTPRINT = 0.4265
"""[m] The ATRV-Jr's :func:`footprint_radius`: the footprint the radii below were chosen for
(``tests/test_robot_task.py`` holds it to the shipped ATRV-Jr's)."""
SUBSTEP = 0.01
"""[s] The control period is a whole number of these (the simulator's reference substep)."""


def footprint_radius(description, rover) -> float:
    """How far the robot reaches in the ground plane from its chassis origin [m]: the farthest corner of its chassis
    box or of its wheels' contact cylinders (``description``: its :class:`~atrv_warp.sim.urdf.RoverDescription`;
    ``rover``: its :class:`~atrv_warp.sim.config.RoverConfig`, whose cylinder the model uses)."""
    import numpy as np

    from atrv_warp.sim.urdf import footprint_points

    return float(max(np.linalg.norm(p) for p in footprint_points(description, rover)))


def scale_to_robot(config, robot, footprint: float):
    """``config`` (a :class:`~atrv_warp.task.config.TaskConfig`) for ``robot`` (a
    :class:`~atrv_warp.core.robot.Robot`) whose :func:`footprint_radius` is ``footprint`` [m], by the module's rule."""
    lim = robot.limits
    changes: dict[str, object] = {"action_scale": robot.torque_limit}
    grow = round(footprint - REFERENCE_FOOTPRINT, 3)  # [m], to the millimetre: 0 on the ATRV-Jr
    for name in ("reach_radius", "clearance_radius", "clearance"):
        changes[name] = round(max(0.1, getattr(config, name) + grow), 3)
    if config.action == "twist":
        changes.update(max_linear=lim.linear_velocity, max_angular=lim.angular_velocity,
                       linear_max_acceleration=lim.linear_acceleration,
                       angular_max_acceleration=lim.angular_acceleration)
        changes["control_period"] = control_period(lim.linear_velocity)
    return dataclasses.replace(config, **changes)


def control_period(speed: float) -> float:
    """The control period of a twist task whose action 1 drives at ``speed`` [m/s], by the rule: longer than
    :data:`REFERENCE_STEP_DT` by :data:`REFERENCE_SPEED` / ``speed`` (never shorter), on the :data:`SUBSTEP` grid."""
    period = REFERENCE_STEP_DT * max(1.0, REFERENCE_SPEED / speed)
    return max(1, math.ceil(period / SUBSTEP - 1e-9)) * SUBSTEP


def fit_task(task, rover):
    """``task`` (a :class:`~atrv_warp.task.definition.Task`) fitted to ``rover``'s robot (a
    :class:`~atrv_warp.sim.config.RoverConfig`, its nominal rover): :meth:`Task.for_robot
    <atrv_warp.task.definition.Task.for_robot>` with its footprint."""
    from atrv_warp.sim.urdf import load_rover

    if task.robot is not None:  # fitted already (a resolved run's task): as it is
        return task
    return task.for_robot(rover.robot_spec, footprint_radius(load_rover(rover), rover))
