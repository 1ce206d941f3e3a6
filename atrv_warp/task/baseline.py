"""Scripted baseline driver: turn toward the target (with yaw-rate damping), drive when roughly aligned.

It reads only the observation (sin and cos of the heading error), so it is a TorchRL policy
like any learned one: ``scripted_policy()`` returns a ``TensorDictModule`` writing ``action``.
Its success rate on the fixed evaluation set tells what is reachable in 200 steps on our
physics (see ``python -m atrv_warp.evaluate --baseline``).
"""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModule
from torch import nn

from atrv_warp.task.spec import OBS_INDEX

__all__ = ["ScriptedDriver", "scripted_policy"]


class ScriptedDriver(nn.Module):
    """Heading control (proportional, damped by the yaw rate) with a forward drive that fades out when
    misaligned.

    The damping matters on Coulomb friction: a turn in place starts only once the sides' torque
    difference overcomes the wheels' sideways grip, and then nothing but the motors slows it, so a
    purely proportional turn overshoots its heading.

    Args:
        turn_gain: Differential action per radian of heading error.
        damping: Differential action per rad/s of yaw rate, against it.
        drive: Forward action when aligned (1 = 20 N·m per wheel).
        align: Heading error [rad] beyond which the rover turns in place.
    """

    def __init__(self, turn_gain: float = 2.0, damping: float = 0.5, drive: float = 0.45, align: float = 0.6):
        super().__init__()
        self.turn_gain, self.damping, self.drive, self.align = turn_gain, damping, drive, align

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        err = torch.atan2(observation[..., OBS_INDEX["sin_heading_error"]],
                          observation[..., OBS_INDEX["cos_heading_error"]])
        turn = (self.turn_gain * err - self.damping * observation[..., OBS_INDEX["yaw_rate"]]).clamp(-1.0, 1.0)
        fwd = self.drive * (1.0 - err.abs() / self.align).clamp(min=0.0)
        return torch.stack([fwd - turn, fwd + turn], dim=-1).clamp(-1.0, 1.0)


def scripted_policy(**kwargs) -> TensorDictModule:
    """The baseline as a TorchRL policy module (``observation`` -> ``action``)."""
    return TensorDictModule(ScriptedDriver(**kwargs), in_keys=["observation"], out_keys=["action"])
