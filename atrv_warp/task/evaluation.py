"""Evaluate a policy on a fixed, seeded set of episodes: one world per episode, all in parallel."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

__all__ = ["EVAL_SEED", "EvalResult", "evaluate", "format_result", "write_result"]

EVAL_SEED = 2024
"""Seed of the standard evaluation set (training never uses it)."""


@dataclass(frozen=True)
class EvalResult:
    episodes: int
    success_rate: float
    mean_return: float
    mean_steps: float
    wall_rate: float
    flip_rate: float
    timeout_rate: float
    nonfinite_rate: float
    obstacle_rate: float = 0.0

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@torch.no_grad()
def evaluate(policy, *, num_episodes: int = 1000, seed: int = EVAL_SEED, env=None, on_step=None,
             **env_kwargs) -> EvalResult:
    """Run ``policy`` deterministically for one episode in each of ``num_episodes`` worlds.

    Args:
        policy: A TensorDict policy (reads ``observation``, writes ``action``), e.g. a
            ``TensorDictModule`` or TorchRL actor; run under ``ExplorationType.DETERMINISTIC``.
        num_episodes: Number of episodes (= worlds).
        seed: Seed of the evaluation set; the same seed gives the same starts and targets.
        env: An :class:`~atrv_warp.task.env.ATRVjrEnv` (possibly wrapped in transforms) with
            ``num_episodes`` worlds to reuse; built if omitted.
        on_step: Optional callback ``on_step(env, tensordict)`` after every step (recording).
        **env_kwargs: Passed to :class:`~atrv_warp.task.env.ATRVjrEnv` when it is built here.
    """
    from atrv_warp.task.env import END_REASONS, ATRVjrEnv

    if env is None:
        env = ATRVjrEnv(num_episodes, **env_kwargs)
    if env.batch_size != torch.Size([num_episodes]):
        raise ValueError(f"env batch size {tuple(env.batch_size)} != ({num_episodes},)")
    env.set_seed(seed)
    td: TensorDictBase = env.reset()
    returns = torch.zeros(num_episodes)
    steps = torch.zeros(num_episodes)
    reason = torch.zeros(num_episodes, dtype=torch.long)
    finished = torch.zeros(num_episodes, dtype=torch.bool)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        while not finished.all():
            td = env.step(policy(td))
            nxt = td["next"]
            live = ~finished
            returns += torch.where(live, nxt["reward"].reshape(-1).cpu(), 0.0)
            steps += live.float()
            done = nxt["done"].reshape(-1).cpu()
            newly = done & live
            reason[newly] = nxt["end_reason"].reshape(-1).cpu()[newly]
            finished |= done
            if on_step is not None:
                on_step(env, td)
            td = step_mdp(td)
    counts = torch.bincount(reason, minlength=len(END_REASONS)).float() / num_episodes
    rate = dict(zip(END_REASONS, counts.tolist()))
    return EvalResult(num_episodes, rate["success"], returns.mean().item(), steps.mean().item(), rate["wall"],
                      rate["flip"], rate["timeout"], rate["nonfinite"], rate["obstacle"])


def format_result(name: str, r: EvalResult) -> str:
    return (f"{name}: success {100 * r.success_rate:.1f}% over {r.episodes} episodes | return {r.mean_return:.2f} | "
            f"steps {r.mean_steps:.1f} | wall {100 * r.wall_rate:.1f}% flip {100 * r.flip_rate:.1f}% "
            f"timeout {100 * r.timeout_rate:.1f}% nonfinite {100 * r.nonfinite_rate:.1f}%"
            + (f" obstacle {100 * r.obstacle_rate:.1f}%" if r.obstacle_rate else ""))


def write_result(path: str | Path, name: str, task: str, seed: int, r: EvalResult) -> None:
    """Write an evaluation's figures as JSON (``--json`` of ``python -m atrv_warp.evaluate``)."""
    with open(path, "w") as fh:
        json.dump({"policy": name, "task": task, "seed": seed, **r.as_dict()}, fh, indent=2)
