"""Temporally correlated exploration for SAC's tanh-Gaussian actor: the collection policy.

SAC explores by sampling its actor's Gaussian afresh at every step. That suits wheel torques, whose random
steps add up to a random walk of the rover's speed; it does not suit a ``/cmd_vel`` through a motor driver,
which tracks each command within a few tenths of a second: independent commands every 0.05 s average out, and
a rover exploring that way stays where it started (5 s of uniform random actions move it 0.68 m under twist
actions, 1.89 m under torque actions). :class:`CorrelatedExploration` draws the Gaussian's noise from a
per-world first-order autoregressive process instead (Ornstein-Uhlenbeck noise sampled every step, as in
Lillicrap et al. 2016 for DDPG; Eberhard et al. 2023, "Pink noise is all you need", for SAC): each step's
noise is still standard normal, so the action's distribution at every step is the actor's own, but successive
actions agree over about ``1 / (1 - correlation)`` steps, and the rover drives somewhere.

Only collection uses it (``ExplorationType.RANDOM``); the losses, the evaluations and the saved policy see the
actor alone.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, exploration_type

__all__ = ["CorrelatedExploration", "collection_policy"]


class CorrelatedExploration(TensorDictModuleBase):
    """``actor`` (a tanh-Gaussian :class:`~torchrl.modules.ProbabilisticActor` writing ``loc`` and ``scale``)
    whose exploring action is ``tanh(loc + scale * noise)``, with each world's ``noise`` an AR(1) process of unit
    variance: ``noise <- correlation * noise + sqrt(1 - correlation²) * N(0, 1)``.

    The module holds the noise of the batch it last saw (one row per world); a batch of another shape starts
    afresh. Its parameters are the actor's (``actor.*``), so a collector's copy takes the learner's weights
    from ``TensorDict.from_module`` of this module. Outside ``ExplorationType.RANDOM`` it is the actor.

    Args:
        actor: The SAC actor.
        correlation: In [0, 1): the noise's correlation from one step to the next (0: the actor's own
            independent sampling).
        seed: Seed of the noise's generator (a collector's copy draws the same stream as the original).
    """

    def __init__(self, actor, correlation: float, seed: int = 0):
        super().__init__()
        if not 0.0 <= correlation < 1.0:
            raise ValueError(f"the exploration noise's correlation must be in [0, 1), got {correlation!r}")
        self.actor = actor
        self.in_keys, self.out_keys = list(actor.in_keys), list(actor.out_keys)
        self.correlation, self.seed = float(correlation), int(seed)
        self.noise: torch.Tensor | None = None
        self.generator: torch.Generator | None = None

    def __getstate__(self):  # a collector's copy (another process) starts its own stream from the seed
        state = self.__dict__.copy()
        state["noise"], state["generator"] = None, None
        return state

    def draw(self, like: torch.Tensor) -> torch.Tensor:
        """The next noise (shape and device of ``like``), advancing every world's process one step."""
        if self.generator is None or self.generator.device != like.device:
            self.generator = torch.Generator(device=like.device).manual_seed(self.seed)
            self.noise = None
        fresh = torch.randn(like.shape, generator=self.generator, device=like.device, dtype=like.dtype)
        if self.noise is None or self.noise.shape != like.shape:
            self.noise = fresh
        else:
            self.noise = self.correlation * self.noise + math.sqrt(1.0 - self.correlation ** 2) * fresh
        return self.noise

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = self.actor(tensordict)
        if exploration_type() == ExplorationType.RANDOM and self.correlation > 0.0:
            loc, scale = tensordict.get("loc"), tensordict.get("scale")
            tensordict.set("action", torch.tanh(loc + scale * self.draw(loc)))
        return tensordict


def collection_policy(actor, correlation: float, seed: int):
    """The policy the collectors step: ``actor`` itself (``correlation`` 0, SAC's own sampling), else
    :class:`CorrelatedExploration` around it."""
    return actor if correlation == 0.0 else CorrelatedExploration(actor, correlation, seed)
