"""Evaluate a policy on a fixed, seeded set of episodes: one world per episode, all in parallel."""

from __future__ import annotations

import itertools
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

__all__ = ["EVAL_SEED", "SHIFT_BINS", "VALIDATION_SEED", "EpisodeRecord", "EvalResult", "evaluate", "format_bins",
           "format_result", "range_bins", "run_episodes", "success_by_bin", "write_result"]

EVAL_SEED = 2024
"""Seed of the standard evaluation set, the test set (training never uses it, nor picks its best policy on it)."""
VALIDATION_SEED = 2023
"""Seed of the episodes training evaluates on periodically and picks its best policy by (a validation set: the
evaluation set's episodes stay unseen until the final evaluation)."""


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
    no_progress_rate: float = 0.0
    """Episodes the progress checker ended (a task that follows a plan)."""

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class EpisodeRecord:
    """Each episode of an evaluation: how it ended, and the physics its world drew."""

    end_reason: torch.Tensor
    """(N,) int64 :class:`~atrv_warp.task.spec.EndReason` codes."""
    returns: torch.Tensor
    """(N,) undiscounted returns."""
    steps: torch.Tensor
    """(N,) episode lengths [steps]."""
    params: dict[str, torch.Tensor]
    """Each world's physical parameters during its episode (:data:`atrv_warp.sim.params.PARAMETERS`), and
    ``latency`` [steps]."""
    path_ratio: torch.Tensor | None = None
    """(N,) a path task's: the distance the chassis drove over the length of the episode's first plan."""
    least_clearance: torch.Tensor | None = None
    """(N,) a path task's: the least distance from the chassis origin to a wall cell or an obstacle's surface [m]."""

    @property
    def success(self) -> torch.Tensor:
        """(N,) bool: the episode reached its target."""
        return self.end_reason == 1

    def summary(self) -> EvalResult:
        from atrv_warp.task.spec import END_REASONS

        n = len(self.end_reason)
        counts = torch.bincount(self.end_reason, minlength=len(END_REASONS)).float() / n
        rate = dict(zip(END_REASONS, counts.tolist()))
        return EvalResult(n, rate["success"], self.returns.mean().item(), self.steps.mean().item(), rate["wall"],
                          rate["flip"], rate["timeout"], rate["nonfinite"], rate["obstacle"], rate["no_progress"])


SHIFT_BINS: dict[str, tuple[float, ...]] = {
    "friction": (0.2, 0.3, 0.45, 0.65, 1.0),
    "payload_mass": (0.0, 5.0, 10.0, 15.0, 20.0, 25.0),
    "latency": (-0.5, 0.5, 1.5, 2.5),
}
"""Bin edges of the success-by-parameter table (``evaluate --randomization``): mu [-], payload [kg], latency
[steps] (one bin per whole step)."""


def range_bins(randomization, count: int = 4) -> dict[str, tuple[float, ...]]:
    """Bin edges spanning what ``randomization`` (a :class:`~atrv_warp.task.randomization.RandomizationConfig`)
    draws: ``count`` equal bins over each physical range that is not one value (``payload_offset`` aside), one bin
    per whole step of latency. The success-by-bin table of a randomization centred on a simulator config, whose
    ranges :data:`SHIFT_BINS` would put in one bin."""
    bins = {}
    for name, draw in randomization.physics.items():
        if name != "payload_offset" and draw.high > draw.low:
            edges = [draw.low + (draw.high - draw.low) * k / count for k in range(count + 1)]
            # the ends as the kernels hold them (float32) too, so that the lowest and highest draws fall inside
            edges[0], edges[-1] = min(draw.low, float(np.float32(draw.low))), max(draw.high, float(np.float32(draw.high)))
            bins[name] = tuple(edges)
    lo, hi = randomization.latency
    if hi > 0:
        bins["latency"] = tuple(k - 0.5 for k in range(lo, hi + 2))
    return bins


def success_by_bin(record: EpisodeRecord, bins: dict[str, tuple[float, ...]] = SHIFT_BINS) -> dict[str, list[dict]]:
    """Success rate of the episodes in each bin of each parameter: ``{name: [{low, high, episodes, success}]}``."""
    out = {}
    for name, edges in bins.items():
        values = record.params[name].reshape(len(record.end_reason), -1)[:, 0].double()
        rows = []
        for lo, hi in itertools.pairwise(edges):
            inside = (values >= lo) & ((values < hi) | ((values == hi) & (hi == edges[-1])))
            count = int(inside.sum())
            rate = float(record.success[inside].float().mean()) if count else float("nan")
            rows.append({"low": lo, "high": hi, "episodes": count, "success": rate})
        out[name] = rows
    return out


def format_bins(table: dict[str, list[dict]]) -> str:
    """The success-by-bin table as text lines."""
    lines = []
    for name, rows in table.items():
        cells = []
        for r in rows:
            label = f"{r['low'] + 0.5:g}" if name == "latency" else f"{r['low']:.3g}-{r['high']:.3g}"
            rate = "-" if r["episodes"] == 0 else f"{100 * r['success']:.1f}%"
            cells.append(f"{label}: {rate} ({r['episodes']})")
        lines.append(f"  success by {name}: " + " | ".join(cells))
    return "\n".join(lines)


@torch.no_grad()
def run_episodes(policy, env, *, seed: int = EVAL_SEED, on_step=None) -> EpisodeRecord:
    """Run ``policy`` deterministically for one episode in each of ``env``'s worlds (seeded with ``seed``)."""
    base = getattr(env, "base_env", env)
    n = env.batch_size[0]
    env.set_seed(seed)
    td: TensorDictBase = env.reset()
    params = {name: torch.from_numpy(v) for name, v in base.sim.params.as_dict().items()}
    params["latency"] = base.latency.detach().cpu().clone().float()
    returns = torch.zeros(n)
    steps = torch.zeros(n)
    reason = torch.zeros(n, dtype=torch.long)
    finished = torch.zeros(n, dtype=torch.bool)
    follows = getattr(base, "path_remaining", None) is not None
    if follows:  # a path task's: how far it drove against its plan, and how near it came to a wall or obstacle
        plan = base.path_remaining.detach().cpu().clone()
        driven, least = torch.zeros(n), base.clearance.detach().cpu().clone()
        where = base.sim.root_pose[:, :2].detach().cpu().clone()
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        while not finished.all():
            td = env.step(policy(td))
            nxt = td["next"]
            live = ~finished
            if follows:
                now = base.sim.root_pose[:, :2].detach().cpu().clone()
                driven += torch.where(live, (now - where).norm(dim=-1), 0.0)
                least = torch.where(live, torch.minimum(least, base.clearance.detach().cpu()), least)
                where = now
            returns += torch.where(live, nxt["reward"].reshape(-1).cpu(), 0.0)
            steps += live.float()
            done = nxt["done"].reshape(-1).cpu()
            newly = done & live
            reason[newly] = nxt["end_reason"].reshape(-1).cpu()[newly]
            finished |= done
            if on_step is not None:
                on_step(env, td)
            td = step_mdp(td)
    if follows:
        return EpisodeRecord(reason, returns, steps, params, driven / plan.clamp(min=1e-6), least)
    return EpisodeRecord(reason, returns, steps, params)


def evaluate(policy, *, num_episodes: int = 1000, seed: int = EVAL_SEED, env=None, on_step=None,
             **env_kwargs) -> EvalResult:
    """Run ``policy`` deterministically for one episode in each of ``num_episodes`` worlds.

    Args:
        policy: A TensorDict policy (reads ``observation``, writes ``action``), e.g. a
            ``TensorDictModule`` or TorchRL actor; run under ``ExplorationType.DETERMINISTIC``.
        num_episodes: Number of episodes (= worlds).
        seed: Seed of the evaluation set; the same seed gives the same starts and targets.
        env: An :class:`~atrv_warp.task.env.RoverEnv` (possibly wrapped in transforms) with
            ``num_episodes`` worlds to reuse; built if omitted.
        on_step: Optional callback ``on_step(env, tensordict)`` after every step (recording).
        **env_kwargs: Passed to :class:`~atrv_warp.task.env.RoverEnv` when it is built here.
    """
    from atrv_warp.task.env import RoverEnv

    if env is None:
        env = RoverEnv(num_episodes, **env_kwargs)
    if env.batch_size != torch.Size([num_episodes]):
        raise ValueError(f"env batch size {tuple(env.batch_size)} != ({num_episodes},)")
    return run_episodes(policy, env, seed=seed, on_step=on_step).summary()


def format_result(name: str, r: EvalResult) -> str:
    return (f"{name}: success {100 * r.success_rate:.1f}% over {r.episodes} episodes | return {r.mean_return:.2f} | "
            f"steps {r.mean_steps:.1f} | wall {100 * r.wall_rate:.1f}% flip {100 * r.flip_rate:.1f}% "
            f"obstacle {100 * r.obstacle_rate:.1f}% timeout {100 * r.timeout_rate:.1f}% "
            f"nonfinite {100 * r.nonfinite_rate:.1f}%" + (f" no progress {100 * r.no_progress_rate:.1f}%"
                                                          if r.no_progress_rate else ""))


def write_result(path: str | Path, name: str, task: str, seed: int, r: EvalResult, **extra) -> None:
    """Write an evaluation's figures as JSON (``--json`` of ``python -m atrv_warp.evaluate``); ``extra`` entries
    (the randomization, the success-by-bin table) are added as they are."""
    with open(path, "w") as fh:
        json.dump({"policy": name, "task": task, "seed": seed, **r.as_dict(), **extra}, fh, indent=2)


def __getattr__(name: str):
    if name in ("task_fingerprint", "FINGERPRINT_STEPS"):  # moved to atrv_warp.task.fingerprints (issue 69)
        import warnings

        from atrv_warp.task import fingerprints

        warnings.warn(f"atrv_warp.task.evaluation.{name} moved to atrv_warp.task.fingerprints; this old path goes in "
                      "0.3.0", DeprecationWarning, stacklevel=2)
        return getattr(fingerprints, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
