"""The task's dense reward in torch, differentiable: for trajectories from
:class:`~atrv_warp.sim.diff.DiffRollout` (``examples/trajectory_optimisation.py``).

The environment computes the same terms in its Warp kernels (:mod:`atrv_warp.task.kernels`);
``tests/test_diff.py`` checks the two against each other.
"""

from __future__ import annotations

import torch

from atrv_warp.core.geometry import quat_to_yaw, wrap_angle
from atrv_warp.task.config import TaskConfig

__all__ = ["progress_reward"]


def progress_reward(poses: torch.Tensor, targets: torch.Tensor, task: TaskConfig | None = None) -> torch.Tensor:
    """The task's dense reward of every step of a rollout, differentiable: (steps, N).

    ``(previous distance - distance) + heading_weight * (previous |heading error| - |heading error|)
    - step_penalty``: the non-terminal terms of :data:`atrv_warp.task.spec.REWARD_TERMS`
    (progress, heading, step_penalty), as the environment's ``compute_step_outcome`` kernel
    computes them (tested against the environment). The terminal rewards (``success_reward`` within
    ``reach_radius``, ``failure_reward`` on a wall or flip) are discrete events without a gradient and are
    left out, and so is the clearance term, which needs obstacles (a :class:`~atrv_warp.sim.diff.DiffRollout`
    has none).

    Args:
        poses: (steps + 1, N, 7) chassis poses from :class:`~atrv_warp.sim.diff.DiffRollout`.
        targets: (N, 2) target x, y [m].
        task: Reward weights (default :class:`~atrv_warp.task.config.TaskConfig`).
    """
    task = task or TaskConfig()
    yaw = quat_to_yaw(poses[..., 3:7])
    to_target = targets.to(poses).unsqueeze(0) - poses[..., :2]
    distance = to_target.norm(dim=-1)
    bearing = torch.atan2(to_target[..., 1], to_target[..., 0]) - yaw
    heading_error = wrap_angle(bearing).abs()
    return ((distance[:-1] - distance[1:]) + task.heading_weight * (heading_error[:-1] - heading_error[1:])
            - task.step_penalty)

