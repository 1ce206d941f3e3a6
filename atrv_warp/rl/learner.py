"""SAC's learner: the critics, the TorchRL loss of the SAC family, its optimisers and target
update (:class:`Learner`), and the replay buffer it samples (:func:`make_buffer`); and one table,
:data:`ALGOS`, from ``optim.algo`` to the learner the loop builds (PPO's is in :mod:`.ppo`)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn
from torchrl.modules import MLP, ValueOperator

from atrv_warp.policy import Normalize, make_actor
from atrv_warp.rl.config import TrainConfig
from atrv_warp.rl.ppo import PPO_LOSS_KEYS, PPOLearner
from atrv_warp.rl.run import RunSpec, resolve_run
from atrv_warp.runtime import is_verbose
from atrv_warp.task.spec import ACTION_DIM

__all__ = ["ALGOS", "REPLAY_KEYS", "SAC_LOSS_KEYS", "Algo", "Learner", "annealed_lr", "make_buffer", "make_learner",
           "make_loss", "make_qvalue", "make_run_actor", "replay_frames", "set_lr"]

SAC_LOSS_KEYS = ("loss_actor", "loss_qvalue", "loss_alpha", "entropy")
"""The means of SAC's losses logged at every evaluation."""


class _QNet(nn.Module):
    def __init__(self, normalize: Normalize, width: int, depth: int, batch_renorm: bool = False):
        super().__init__()
        self.normalize = normalize
        norm = {}
        if batch_renorm:
            from torchrl.modules.models.batchrenorm import BatchRenorm1d

            norm = {"norm_class": BatchRenorm1d, "norm_kwargs": {"num_features": width, "momentum": 0.01}}
        self.mlp = MLP(in_features=normalize.loc.numel() + ACTION_DIM, out_features=1, num_cells=[width] * depth,
                       activation_class=nn.ReLU, **norm)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.mlp(torch.cat([self.normalize(observation), action], dim=-1))


def make_qvalue(width: int = 128, depth: int = 2, normalize: Normalize | None = None, *,
                batch_renorm: bool = False) -> ValueOperator:
    """Q-network ``(observation, action) -> state_action_value``; shares ``normalize``'s statistics.

    ``batch_renorm``: batch renormalisation after every hidden layer, as CrossQ's critics need.
    """
    return ValueOperator(_QNet(normalize if normalize is not None else Normalize(), width, depth, batch_renorm),
                         in_keys=["observation", "action"])


REPLAY_KEYS = ("observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
               ("next", "terminated"), ("next", "truncated"))
"""What the replay buffer keeps of every frame: what the losses of the SAC family read (their ``in_keys``). The
rest of a collected batch (the scan, the reward terms, the actor's distribution, the episode bookkeeping) is
logged from the batch itself; kept, it would double what every sample gathers and every checkpoint writes."""


def replay_frames(batch, device: str | torch.device = "cpu"):
    """A collected ``batch`` as the replay buffer stores it: its :data:`REPLAY_KEYS`, one frame per row, on
    ``device`` (the run's: no copy where the batch is there already)."""
    return batch.select(*REPLAY_KEYS, strict=False).reshape(-1).to(device)


def make_buffer(cfg: TrainConfig):
    """The replay buffer: ``buffer_size`` frames in the run's device's memory, sampled ``batch_size`` at a time."""
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    storage = LazyTensorStorage(cfg.optim.buffer_size, device=torch.device(cfg.run.device))
    return TensorDictReplayBuffer(storage=storage, batch_size=cfg.optim.batch_size)


def make_loss(cfg: TrainConfig, actor, normalize: Normalize):
    """The TorchRL loss ``cfg.optim.loss`` names, with new critics that share ``normalize``."""
    from torchrl.objectives import CrossQLoss, REDQLoss, SACLoss

    width, depth, device = cfg.network.width, cfg.network.depth, torch.device(cfg.run.device)
    common = {"alpha_init": cfg.optim.init_alpha, "target_entropy": -2.0}
    if cfg.optim.loss == "crossq":
        qvalue = make_qvalue(width, depth, normalize=normalize, batch_renorm=True).to(device)
        loss = CrossQLoss(actor, qvalue, num_qvalue_nets=2, **common)
    elif cfg.optim.loss == "redq":
        qvalue = make_qvalue(width, depth, normalize=normalize).to(device)
        # REDQLoss needs temperature bounds; its default floor (0.1) would outweigh this task's rewards
        loss = REDQLoss(actor, qvalue, num_qvalue_nets=10, sub_sample_len=2, min_alpha=1e-4, max_alpha=10.0,
                        **common)
    else:
        loss = SACLoss(actor, make_qvalue(width, depth, normalize=normalize).to(device), num_qvalue_nets=2, **common)
    loss.make_value_estimator(gamma=cfg.optim.gamma)
    _ = loss.target_entropy  # REDQ registers this buffer lazily: a resumed run's state dict must find it
    return loss.to(device)


class Learner:
    """SAC's critics, loss, target-network update and optimisers.

    Built once the observation statistics are final, so the critics' (copied) normalisation
    matches the actor's.
    """

    def __init__(self, cfg: TrainConfig, actor, normalize: Normalize):
        self.loss = make_loss(cfg, actor, normalize)
        self.target_update = None
        if cfg.optim.loss != "crossq":  # CrossQ has no target networks
            from torchrl.objectives import SoftUpdate

            self.target_update = SoftUpdate(self.loss, tau=cfg.optim.tau)
        # a built update reads its learning rate from a tensor, which the annealing changes in place (a float would be
        # captured as a constant, or recompile the update at every change); on the CPU a tensor rate needs Adam's
        # for-loop implementation, on a GPU its capturable one
        self.compiled = cfg.optim.compile != "off"
        cuda = torch.device(cfg.run.device).type == "cuda"
        if self.compiled:
            adam = {"lr": torch.tensor(cfg.optim.lr, device=cfg.run.device), "capturable": cuda, "foreach": cuda}
        else:
            adam = {"lr": cfg.optim.lr}
        self.opts = {
            "actor": torch.optim.Adam(self.loss.actor_network_params.flatten_keys().values(), **adam),
            "critic": torch.optim.Adam(self.loss.qvalue_network_params.flatten_keys().values(), **adam),
            "alpha": torch.optim.Adam([self.loss.log_alpha], **adam),
        }
        self.step = _built_step(self._step, cfg.optim.compile)
        """One whole update (:meth:`_step`), eager or compiled or captured (``optim.compile``)."""

    def _step(self, batch, phase=None):
        phase = phase or _no_phase
        with phase("loss"):
            out = self.loss(batch)
        with phase("backward"):
            for opt in self.opts.values():
                opt.zero_grad(set_to_none=True)
            (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        with phase("optimiser"):
            for opt in self.opts.values():
                opt.step()
        if self.target_update is not None:
            with phase("target"):
                self.target_update.step()
        return out.detach()

    def update(self, batch, phase=None):
        """One gradient step on every network and the temperature; returns the losses (a detached TensorDict).

        ``phase``: optional ``phase(name)`` context-manager factory that times each part (loss,
        backward, optimiser, target), as ``benchmarks/perf/train_profile.py`` does (eager only: a compiled or captured
        update is one piece).
        """
        return self.step(batch) if self.compiled else self._step(batch, phase)

    @property
    def alpha(self) -> float:
        return float(self.loss.log_alpha.detach().exp())

    def scalars(self) -> dict[str, float]:
        """Figures of the learner itself, logged at every evaluation: the entropy temperature."""
        return {"alpha": self.alpha}

    def state_dict(self) -> dict:
        return {"loss": self.loss.state_dict(), "opts": {k: o.state_dict() for k, o in self.opts.items()}}

    def load_state_dict(self, sd: dict) -> None:
        self.loss.load_state_dict(sd["loss"])
        for k, opt in self.opts.items():
            opt.load_state_dict(sd["opts"][k])


def _no_phase(name: str):
    return contextlib.nullcontext()


def _built_step(step: Callable, how: str) -> Callable:
    """``step`` as ``optim.compile`` says: as is (``off``), ``torch.compile``d, or captured in a CUDA graph after a
    few eager warm-up calls (``cudagraphs``: tensordict's ``CudaGraphModule``, as TorchRL's SAC recipe does)."""
    if how == "compile":
        if not is_verbose():  # what torch.compile says of TorchRL's and tensordict's code is not the user's to act on
            import logging
            import warnings

            logging.getLogger("torch._dynamo").setLevel(logging.ERROR)
            warnings.filterwarnings("ignore", message=".*inline_inbuilt_nn_modules.*", category=FutureWarning)
        return torch.compile(step)
    if how == "cudagraphs":
        from tensordict.nn import CudaGraphModule

        return CudaGraphModule(step, in_keys=[], out_keys=[], warmup=5)
    return step


@dataclass(frozen=True)
class Algo:
    """What differs between the algorithms; the loop asks this, never the algorithm's name."""

    make: Callable
    """``make(cfg, actor, normalize)``: the learner, once the observation statistics are final."""
    loss_keys: tuple[str, ...]
    """Entries of every update's output whose means are logged."""
    on_policy: bool
    """Learns from each batch as it comes, collected by the policy with its log-probabilities (PPO),
    and keeps only the random frames (for the statistics); else from a replay buffer of every frame,
    ``utd_ratio`` updates per frame (SAC)."""


ALGOS: dict[str, Algo] = {
    "sac": Algo(Learner, SAC_LOSS_KEYS, on_policy=False),
    "ppo": Algo(PPOLearner, PPO_LOSS_KEYS, on_policy=True),
}
"""Every ``optim.algo`` (:class:`~atrv_warp.rl.config.OptimConfig`) and what it means for the loop."""


def annealed_lr(cfg: TrainConfig, frames: int) -> float:
    """The learning rate after ``frames`` collected frames: ``lr`` falling linearly to ``lr x lr_final_fraction``
    at ``total_frames``, then held."""
    done = min(frames / cfg.run.total_frames, 1.0)
    return cfg.optim.lr * (1.0 - (1.0 - cfg.optim.lr_final_fraction) * done)


def set_lr(learner, lr: float) -> None:
    """Set every optimiser of ``learner`` (SAC's or PPO's: their ``opts``) to ``lr``."""
    for opt in learner.opts.values():
        for group in opt.param_groups:
            if isinstance(group["lr"], torch.Tensor):  # a captured update's: changed in place, where it reads it
                group["lr"].fill_(lr)
            else:
                group["lr"] = lr


def make_run_actor(cfg: TrainConfig, run: RunSpec | None = None):
    """The actor a run trains, and its observation statistics (not yet set): the task's observation size, the
    network's width and depth, and log-probabilities where the algorithm collects with them (PPO). ``run``: ``cfg``
    resolved (:func:`~atrv_warp.rl.run.resolve_run`, where not given)."""
    from atrv_warp.task.sensors import sensor_fields
    from atrv_warp.task.spec import observation_fields

    run = run or resolve_run(cfg)
    obs_dim = len(observation_fields(run.task.config, sensor_fields(run.task.config, run.robot)))
    normalize = Normalize(obs_dim)
    actor = make_actor(cfg.network.width, cfg.network.depth, normalize=normalize, obs_dim=obs_dim,
                       return_log_prob=ALGOS[cfg.optim.algo].on_policy)
    return actor.to(cfg.run.device), normalize


def make_learner(cfg: TrainConfig, actor, normalize: Normalize):
    """The learner ``cfg.optim.algo`` names (:data:`ALGOS`)."""
    return ALGOS[cfg.optim.algo].make(cfg, actor, normalize)
