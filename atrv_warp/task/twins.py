"""The shipped reward terms' torch twins (:attr:`~atrv_warp.task.definition.RewardTerm.torch`): each term's value before
its weight, as its ``@wp.func`` in ``task/kernels/terms.py`` computes it, from a rollout's tensors
(:class:`TorchRollout`). :mod:`atrv_warp.task.reward` weights and sums them; ``tests/test_task_terms.py`` holds each
to the environment's column, step by step.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from atrv_warp.core.geometry import quat_to_yaw, wrap_angle
from atrv_warp.task.spec import EndReason

__all__ = ["FAILURES", "TorchRollout", "action_rate", "clearance", "energy", "failed", "heading", "progress",
           "step", "succeeded"]

FAILURES = (int(EndReason.WALL), int(EndReason.FLIP), int(EndReason.OBSTACLE), int(EndReason.NO_PROGRESS))
"""The end reasons a ``failure`` term counts on."""


@dataclass(frozen=True)
class TorchRollout:
    """A rollout's tensors, as the terms' torch twins read them: T steps of N worlds."""

    poses: torch.Tensor
    """(T + 1, N, 7) chassis poses (x, y, z, qx, qy, qz, qw), the first before the first step."""
    targets: torch.Tensor
    """(N, 2) the targets [m]."""
    config: object
    """The task config (``clearance_radius`` and the like)."""
    actions: torch.Tensor | None = None
    """(T, N, 2) each step's action as given."""
    first_prev_action: torch.Tensor | None = None
    """(N, 2) the action before the first step (clipped; zero at an episode's start)."""
    obstacles: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None
    """Each world's obstacles: kind (N, K) (0 none, 1 box, 2 cylinder), pose (N, K, 3), size (N, K, 2)."""
    wheel_torque: torch.Tensor | None = None
    """(T, N, W) the wheels' torques [N·m] (the last substep's of each step)."""
    wheel_speed: torch.Tensor | None = None
    """(T, N, W) their speeds [rad/s]."""
    end_reason: torch.Tensor | None = None
    """(T, N) each step's end (:class:`~atrv_warp.task.spec.EndReason`)."""
    step_dt: float = 0.05

    def distance(self) -> torch.Tensor:
        """(T + 1, N) the chassis' distance to the target [m]."""
        return (self.targets.to(self.poses).unsqueeze(0) - self.poses[..., :2]).norm(dim=-1)

    def heading_error(self) -> torch.Tensor:
        """(T + 1, N) |angle from the heading to the target's direction| [rad]."""
        to_target = self.targets.to(self.poses).unsqueeze(0) - self.poses[..., :2]
        bearing = torch.atan2(to_target[..., 1], to_target[..., 0]) - quat_to_yaw(self.poses[..., 3:7])
        return wrap_angle(bearing).abs()

    def need(self, name: str, term: str) -> torch.Tensor:
        value = getattr(self, name)
        if value is None:
            raise ValueError(f"reward term {term!r} reads the rollout's {name}, which it does not have")
        return value


def progress(r: TorchRollout) -> torch.Tensor:
    d = r.distance()
    return d[:-1] - d[1:]


def heading(r: TorchRollout) -> torch.Tensor:
    e = r.heading_error()
    return e[:-1] - e[1:]


def step(r: TorchRollout) -> torch.Tensor:
    return -torch.ones(r.poses.shape[0] - 1, r.poses.shape[1], dtype=r.poses.dtype, device=r.poses.device)


def succeeded(r: TorchRollout) -> torch.Tensor:
    return (r.need("end_reason", "success") == int(EndReason.SUCCESS)).to(r.poses.dtype)


def failed(r: TorchRollout) -> torch.Tensor:
    reason = r.need("end_reason", "failure")
    return torch.isin(reason, torch.tensor(FAILURES, device=reason.device)).to(r.poses.dtype)


def clearance(r: TorchRollout) -> torch.Tensor:
    """Without obstacles (a :class:`~atrv_warp.sim.diff.DiffRollout`'s flat arena), 0."""
    if r.obstacles is None:
        return torch.zeros_like(step(r))
    kind, pose, size = r.obstacles
    radius = torch.where(kind == 1, size.norm(dim=-1), size[..., 0])  # a box's corner, a cylinder's radius
    gap = (pose[None, :, :, :2] - r.poses[1:, :, None, :2]).norm(dim=-1) - radius[None]
    inside = torch.where(kind[None] != 0, r.config.clearance_radius - gap, torch.zeros_like(gap))
    return -inside.amax(-1).clamp(min=0.0)


def action_rate(r: TorchRollout) -> torch.Tensor:
    a = r.need("actions", "action_rate").clamp(-1.0, 1.0)
    first = r.first_prev_action if r.first_prev_action is not None else torch.zeros_like(a[0])
    prev = torch.cat([first[None], a[:-1]])
    return -((a - prev) ** 2).sum(-1)


def energy(r: TorchRollout) -> torch.Tensor:
    torque, speed = r.need("wheel_torque", "energy"), r.need("wheel_speed", "energy")
    return -(torque * speed).abs().sum(-1) * r.step_dt
