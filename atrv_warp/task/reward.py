"""The reward in torch, from the same table as the environment's: each term's torch twin
(:attr:`~atrv_warp.task.definition.RewardTerm.torch`; the shipped ones are :mod:`atrv_warp.task.twins`'), applied to a
rollout's tensors (:class:`~atrv_warp.task.twins.TorchRollout`), and their weighted sum (:func:`dense_reward`), differentiable where the inputs are: for trajectories from
:class:`~atrv_warp.sim.diff.DiffRollout` (``examples/trajectory_optimisation.py``) and the MuJoCo twin's returns.

``tests/test_task_terms.py`` holds every shipped term's twin to the environment's column, step by step.
"""

from __future__ import annotations

import dataclasses

import torch

from atrv_warp.task.registry import resolve_task
from atrv_warp.task.spec import EndReason
from atrv_warp.task.twins import FAILURES, TorchRollout, step

__all__ = ["TorchRollout", "dense_reward", "live", "progress_reward", "term_values"]


def live(term, r: TorchRollout) -> torch.Tensor | None:
    """(T, N) where ``term`` counts (its ``when``), from the rollout's end reasons; None without them (every step
    counts: a rollout that never ends)."""
    if r.end_reason is None:
        return None
    ended = (r.end_reason == int(EndReason.SUCCESS)) | torch.isin(
        r.end_reason, torch.tensor((*FAILURES, int(EndReason.NONFINITE)), device=r.end_reason.device))
    return {"running": ~ended, "success": r.end_reason == int(EndReason.SUCCESS),
            "failure": torch.isin(r.end_reason, torch.tensor(FAILURES, device=r.end_reason.device))}[term.when]


def term_values(task, r: TorchRollout) -> dict[str, torch.Tensor]:
    """Each of ``task``'s terms (a :class:`~atrv_warp.task.definition.Task`) with a torch twin and a weight: its
    weighted value where it counts, (T, N), by name, in column order; terms of weight 0 are left out."""
    out = {}
    for term in task.terms:
        weight = term.weight_of(task.config)
        if term.torch is None or weight == 0.0:
            continue
        value = weight * term.torch(r)
        mask = live(term, r)
        out[term.name] = value if mask is None else torch.where(mask, value, torch.zeros_like(value))
    return out


def dense_reward(task, r: TorchRollout) -> torch.Tensor:
    """The task's running reward of every step of a rollout that never ends (T, N), differentiable: its running
    terms' twins, weighted, summed in column order (the events of success and failure are discrete and left
    out).

    Raises:
        ValueError: A running term with a weight reads what the rollout does not have (named).
    """
    running = dataclasses.replace(task, terms=tuple(t for t in task.terms if t.when == "running"))
    values = term_values(running, dataclasses.replace(r, end_reason=None))
    return sum(values.values(), torch.zeros_like(step(r)))


def progress_reward(poses: torch.Tensor, targets: torch.Tensor, task=None) -> torch.Tensor:
    """The dense reward of every step of a :class:`~atrv_warp.sim.diff.DiffRollout` (steps, N), differentiable: the
    running terms of ``task`` (a :class:`~atrv_warp.task.definition.Task`, a task's name or a
    :class:`~atrv_warp.task.config.TaskConfig`; default ``reach``) that a rollout of poses alone defines, weighted
    (:func:`dense_reward`; on a flat arena without obstacles the clearance term is 0; terms that read actions or the
    wheels are left out).

    Args:
        poses: (steps + 1, N, 7) chassis poses.
        targets: (N, 2) target x, y [m].
        task: The task (its weights).
    """
    task = resolve_task(task)
    poses_only = dataclasses.replace(task, terms=tuple(t for t in task.terms if set(t.reads) <= {"state", "obstacles"}))
    return dense_reward(poses_only, TorchRollout(poses=poses, targets=targets, config=task.config))
