"""PPO's learner (``algo=ppo``): a value network, TorchRL's ``GAE`` and ``ClipPPOLoss``, one optimiser
(:class:`PPOLearner`).

On-policy: each collected batch (worlds x steps, collected by the policy being trained, its
log-probabilities recorded) gets GAE advantages from the value network once, then ``epochs``
passes of shuffled minibatches of ``minibatch_size`` transitions, one clipped gradient step each.
Nothing is replayed; the batch is dropped afterwards.
"""

from __future__ import annotations

from collections.abc import Iterator

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.modules import MLP, ValueOperator

from atrv_warp.policy import Normalize
from atrv_warp.rl.config import TrainConfig

__all__ = ["PPO_LOSS_KEYS", "PPOLearner", "make_value"]

PPO_LOSS_KEYS = ("loss_objective", "loss_critic", "loss_entropy", "entropy", "kl_approx", "clip_fraction")
"""The means logged at every evaluation."""


class _VNet(nn.Module):
    def __init__(self, normalize: Normalize, width: int, depth: int):
        super().__init__()
        self.normalize = normalize
        self.mlp = MLP(in_features=normalize.loc.numel(), out_features=1, num_cells=[width] * depth,
                       activation_class=nn.Tanh)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.normalize(observation))


def make_value(width: int = 128, depth: int = 2, normalize: Normalize | None = None) -> ValueOperator:
    """Value network ``observation -> state_value``; shares ``normalize``'s statistics."""
    return ValueOperator(_VNet(normalize if normalize is not None else Normalize(), width, depth),
                         in_keys=["observation"], out_keys=["state_value"])


class PPOLearner:
    """PPO's value network, advantage module, loss and optimiser.

    Built once the observation statistics are final (as SAC's :class:`~atrv_warp.rl.learner.Learner`),
    so every batch it learns from was collected with the normalisation it trains.
    """

    def __init__(self, cfg: TrainConfig, actor, normalize: Normalize):
        from torchrl.objectives import ClipPPOLoss
        from torchrl.objectives.value import GAE

        p = cfg.ppo
        self.cfg = cfg
        self.value = make_value(cfg.network.width, cfg.network.depth, normalize).to(cfg.run.device)
        self.advantage = GAE(gamma=cfg.optim.gamma, lmbda=p.gae_lambda, value_network=self.value, average_gae=False)
        self.loss = ClipPPOLoss(actor, self.value, clip_epsilon=p.clip_epsilon, entropy_coeff=p.entropy_coef,
                                critic_coeff=p.critic_coef, loss_critic_type="smooth_l1", normalize_advantage=True)
        # every trained parameter once (the value network and the actor share Normalize's buffers, not parameters)
        self.params = [q for q in self.loss.parameters() if q.requires_grad]
        self.opts = {"ppo": torch.optim.Adam(self.params, lr=cfg.optim.lr)}

    def learn_batch(self, data: TensorDictBase) -> Iterator[TensorDictBase]:
        """Advantages of ``data`` (worlds, steps), then one gradient step per minibatch of every epoch;
        yields each step's losses (detached)."""
        p = self.cfg.ppo
        with torch.no_grad():
            data = self.advantage(data.exclude("scan", ("next", "scan")))
        flat = data.reshape(-1)
        opt = self.opts["ppo"]
        for _ in range(p.epochs):
            for index in torch.randperm(flat.numel()).to(flat.device).split(p.minibatch_size):
                out = self.loss(flat[index])
                total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
                opt.zero_grad(set_to_none=True)
                total.backward()
                nn.utils.clip_grad_norm_(self.params, p.max_grad_norm)
                opt.step()
                yield out.detach()

    def scalars(self) -> dict[str, float]:
        """Figures of the learner itself, logged at every evaluation (none for PPO)."""
        return {}

    def state_dict(self) -> dict:
        return {"loss": self.loss.state_dict(), "opts": {k: o.state_dict() for k, o in self.opts.items()}}

    def load_state_dict(self, sd: dict) -> None:
        self.loss.load_state_dict(sd["loss"])
        for k, opt in self.opts.items():
            opt.load_state_dict(sd["opts"][k])
