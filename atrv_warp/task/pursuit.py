"""Nav2's Regulated Pure Pursuit as a policy of the path observation: the baseline a learned path follower is
measured against (``atrv-evaluate --baseline`` on a path-following task).

It reads what the learned policy reads (:data:`~atrv_warp.task.spec.PATH_OBSERVATION`: the plan's points ahead in
the base's frame, the length left, the turn to the goal's heading, the odometry's speed, the scan sectors) and
commands a ``/cmd_vel`` as Nav2's ``RegulatedPurePursuitController`` does (``nav2_regulated_pure_pursuit_controller``,
its README's algorithm and defaults at navigation2 commit 01c1b2b), with these settings:

- lookahead scaled with speed: ``lookahead_time`` 1.5 s of the odometry's speed, within ``min_lookahead_dist`` 0.3 m
  and ``max_lookahead_dist`` 0.9 m; the carrot is the plan's point that far along it (its end past the end);
- the curvature to the carrot, ``2 y / (x² + y²)``, times the linear speed is the yaw rate;
- the linear speed is ``desired_linear_vel`` (the robot's limit), slowed on tight turns (a radius under
  ``regulated_linear_scaling_min_radius`` 0.9 m, in proportion) and near obstacles (the scan's nearest return under
  ``cost_scaling_dist`` 0.3 m, in proportion, ``cost_scaling_gain`` 1; Nav2 reads the costmap there, this the
  scan), never below ``regulated_linear_scaling_min_speed`` 0.25 m/s; then slowed in proportion to the plan left
  within ``approach_velocity_scaling_dist`` 1.0 m, never below ``min_approach_linear_velocity`` 0.05 m/s;
- it rotates in place toward the carrot where it lies more than ``rotate_to_heading_min_angle`` 0.785 rad off the
  heading, and toward the goal's heading once the goal is within the goal checker's tolerance, at
  ``rotate_to_heading_angular_vel`` 1.8 rad/s (or the robot's limit), reached from the odometry's yaw rate at
  ``max_angular_accel`` 3.2 rad/s² over a control period;
- every command within the robot's limits.

Its collision detection (stopping where the commanded arc meets the costmap) is not modelled, nor is a global
costmap's obstacle layer: the plan it follows is the planner's, over the map alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict.nn import TensorDictModule
from torch import nn

from atrv_warp.task.scaling import REFERENCE_STEP_DT
from atrv_warp.task.sensors import sensor_fields
from atrv_warp.task.spec import PATH_POINTS, PATH_SPACING, observation_fields

__all__ = ["PursuitSettings", "RegulatedPurePursuit", "pursuit_policy"]


@dataclass(frozen=True)
class PursuitSettings:
    """RPP's parameters, named and valued as Nav2's README gives their defaults (the speed-scaled lookahead and the
    obstacle regulation on)."""

    lookahead_time: float = 1.5
    min_lookahead_dist: float = 0.3
    max_lookahead_dist: float = 0.9
    regulated_linear_scaling_min_radius: float = 0.9
    regulated_linear_scaling_min_speed: float = 0.25
    cost_scaling_dist: float = 0.3
    cost_scaling_gain: float = 1.0
    approach_velocity_scaling_dist: float = 1.0
    min_approach_linear_velocity: float = 0.05
    rotate_to_heading_min_angle: float = 0.785
    rotate_to_heading_angular_vel: float = 1.8
    max_angular_accel: float = 3.2


class RegulatedPurePursuit(nn.Module):
    """RPP on the path observation of ``task`` (a :class:`~atrv_warp.task.config.FollowPathConfig`, fitted to
    ``robot``, a :class:`~atrv_warp.core.robot.Robot` whose sensors it observes: its speed limits and the goal
    checker's tolerance); observation (..., D) -> twist action (..., 2)."""

    def __init__(self, task, robot=None, settings: PursuitSettings | None = None):
        super().__init__()
        if getattr(task, "observation", None) != "path":
            raise ValueError("the pure-pursuit baseline follows a plan: it needs a task with observation='path' "
                             "(e.g. follow_path)")
        self.s = settings or PursuitSettings()
        sensors = sensor_fields(task, robot) if robot is not None else None
        names = [f.name for f in observation_fields(task, sensors)]
        index = {n: i for i, n in enumerate(names)}
        self.points = [(index[f"path_{k}_x"], index[f"path_{k}_y"]) for k in range(PATH_POINTS)]
        self.remaining, self.speed, self.yaw_rate = index["path_remaining"], index["odom_linear"], index["odom_angular"]
        self.period = task.control_period or REFERENCE_STEP_DT
        self.goal_yaw = (index["sin_goal_yaw"], index["cos_goal_yaw"])
        self.scan = [i for n, i in index.items() if n.startswith("scan_")]
        self.clip = task.scan_clip
        self.max_linear, self.max_angular = task.max_linear, task.max_angular
        self.tolerance = task.reach_radius

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        s, obs = self.s, observation
        xy = torch.stack([torch.stack([obs[..., i], obs[..., j]], -1) for i, j in self.points], -2)  # (..., K, 2)
        remaining = obs[..., self.remaining]
        lookahead = (obs[..., self.speed].abs() * s.lookahead_time).clamp(s.min_lookahead_dist, s.max_lookahead_dist)
        carrot = _along(xy, lookahead, remaining)
        x, y = carrot[..., 0], carrot[..., 1]
        curvature = 2.0 * y / (x * x + y * y).clamp(min=1e-9)
        v = torch.full_like(x, self.max_linear)
        radius = 1.0 / curvature.abs().clamp(min=1e-9)
        v = torch.where(radius < s.regulated_linear_scaling_min_radius,
                        v * radius / s.regulated_linear_scaling_min_radius, v)
        if self.scan:
            near = torch.stack([obs[..., i] for i in self.scan], -1).amin(-1) * self.clip
            v = torch.where(near < s.cost_scaling_dist, torch.minimum(v, v * s.cost_scaling_gain * near /
                                                                      s.cost_scaling_dist), v)
        v = v.clamp(min=s.regulated_linear_scaling_min_speed)
        v = torch.where(remaining < s.approach_velocity_scaling_dist,
                        (v * remaining / s.approach_velocity_scaling_dist).clamp(min=s.min_approach_linear_velocity),
                        v)
        v = v.clamp(max=self.max_linear)
        w = v * curvature
        spin = min(s.rotate_to_heading_angular_vel, self.max_angular)
        bearing = torch.atan2(y, x)
        to_path = bearing.abs() > s.rotate_to_heading_min_angle
        turn = torch.atan2(obs[..., self.goal_yaw[0]], obs[..., self.goal_yaw[1]])
        at_goal = _along(xy, remaining, remaining).norm(dim=-1) <= self.tolerance
        v = torch.where(to_path | at_goal, torch.zeros_like(v), v)
        w = torch.where(to_path, spin * torch.sign(bearing), w)
        w = torch.where(at_goal, spin * torch.sign(turn), w)
        rate = obs[..., self.yaw_rate]  # a rotation in place within max_angular_accel of the yaw rate now
        step = s.max_angular_accel * self.period
        w = torch.where(to_path | at_goal, w.clamp(rate - step, rate + step), w)
        return torch.stack([v / self.max_linear, (w / self.max_angular).clamp(-1.0, 1.0)], -1)


def _along(xy: torch.Tensor, distance: torch.Tensor, remaining: torch.Tensor) -> torch.Tensor:
    """The point ``distance`` [m] along the observed plan from its point 0, of a plan ``remaining`` [m] long from
    there (linear between the observed points, which lie :data:`PATH_SPACING` apart but for the last before the
    plan's end; its end past it)."""
    d = torch.minimum(distance, remaining).clamp(0.0, PATH_SPACING * (PATH_POINTS - 1))
    lo = (d / PATH_SPACING).floor().long().clamp(max=PATH_POINTS - 2)
    start = lo * PATH_SPACING
    gap = torch.minimum(torch.full_like(d, PATH_SPACING), remaining - start).clamp(min=1e-6)
    t = ((d - start) / gap).clamp(0.0, 1.0).unsqueeze(-1)
    a = xy.gather(-2, lo[..., None, None].expand(*lo.shape, 1, 2)).squeeze(-2)
    b = xy.gather(-2, (lo + 1)[..., None, None].expand(*lo.shape, 1, 2)).squeeze(-2)
    return a + t * (b - a)


def pursuit_policy(task, robot=None, settings: PursuitSettings | None = None) -> TensorDictModule:
    """The baseline as a TorchRL policy module (``observation`` -> ``action``) for ``task``'s path observation on
    ``robot``."""
    return TensorDictModule(RegulatedPurePursuit(task, robot, settings), in_keys=["observation"], out_keys=["action"])
