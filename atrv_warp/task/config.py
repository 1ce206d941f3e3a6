"""Configuration of the drive-to-target task (its contract is :mod:`atrv_warp.task.spec`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TaskConfig"]


@dataclass(frozen=True)
class TaskConfig:
    """The reference drive-to-target task."""

    spawn_bound: float = 12.0
    """Targets and starts are uniform in [-bound, bound]² [m] (arena half size - 3)."""
    reach_radius: float = 1.0
    """Success when the chassis is this close to the target [m]."""
    flip_roll: float = 0.2
    """|roll| above this is a flip [rad]."""
    max_steps: int = 200
    """Truncation after this many steps (200 × 0.05 s = 10 s)."""
    success_reward: float = 4.0
    failure_reward: float = -4.0
    """Reward on a wall contact or a flip (the episode ends)."""
    heading_weight: float = 4.0
    """Weight of the heading-progress term (previous |error| - |error|) [1/rad]."""
    step_penalty: float = 0.03
    """Subtracted from every non-terminal reward."""
    action_scale: float = 20.0
    """Wheel torque per unit action [N·m]."""
