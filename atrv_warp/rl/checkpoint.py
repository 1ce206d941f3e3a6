"""Where a run stands (:class:`RunState`) and the checkpoint that saves and restores it
(:class:`Checkpoint`, mirrored; :func:`load_checkpoint` reads one safely)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import torch

from atrv_warp.policy import Normalize, check_policy_task, policy_payload
from atrv_warp.rl.config import TrainConfig
from atrv_warp.rl.learner import make_learner
from atrv_warp.storage import FileFormatError, atomic_save, load_weights

__all__ = ["CHECKPOINT_KEYS", "Checkpoint", "RunState", "load_checkpoint"]

CHECKPOINT_KEYS = ("frames", "updates", "best_success", "elapsed_s", "next_eval", "stats_ready", "rng", "policy")
"""Entries every training checkpoint holds (``loss`` and ``opts`` too once learning has started)."""


@dataclass
class RunState:
    """Where a run stands; saved in every checkpoint and restored by ``--resume``."""

    frames: int = 0
    updates: int = 0
    best_success: float = -1.0
    best_return: float = -math.inf
    """Mean return of the best policy's evaluation: the tie-break between equal success rates."""
    elapsed_s: float = 0.0
    next_eval: int = 0
    stats_ready: bool = False
    """Observation statistics are frozen and the learner exists (after ``init_random_frames``)."""
    tracking_id: str = ""
    """The W&B or MLflow run the scalars go to (``logger=wandb|mlflow``): a resumed run continues it."""


def load_checkpoint(path: Path) -> dict:
    """Read a training checkpoint (``weights_only``); a damaged one is a ``FileFormatError`` naming it."""
    ck = load_weights(path, "training checkpoint", CHECKPOINT_KEYS)
    if ck["stats_ready"] and not ({"loss", "opts"} <= ck.keys()):
        raise FileFormatError(f"{path}: not a complete training checkpoint: learner state missing")
    if not isinstance(ck["rng"], torch.Tensor) or ck["rng"].dtype != torch.uint8:
        raise FileFormatError(f"{path}: not a complete training checkpoint: bad random-generator state")
    return ck


class Checkpoint:
    """``checkpoint.pt`` (atomic) and the replay buffer beside it; :meth:`save` and :meth:`restore`
    mirror each other."""

    def __init__(self, run_dir: Path):
        self.path, self.buffer_dir = run_dir / "checkpoint.pt", run_dir / "buffer"

    def save(self, cfg: TrainConfig, state: RunState, actor, learner, buffer) -> None:
        """Write the checkpoint atomically, then the replay buffer beside it (``learner``: SAC's
        :class:`~atrv_warp.rl.learner.Learner`, PPO's :class:`~atrv_warp.rl.ppo.PPOLearner`, or ``None``
        before learning starts)."""
        payload = {**dataclasses.asdict(state), "rng": torch.get_rng_state(), "config": dataclasses.asdict(cfg),
                   "policy": policy_payload(actor, width=cfg.network.width, depth=cfg.network.depth,
                                          meta={"frames": state.frames, "task": cfg.env.task})}
        if learner is not None:
            payload.update(learner.state_dict())
        atomic_save(payload, self.path)
        if learner is not None and len(buffer):
            buffer.dumps(self.buffer_dir)

    def restore(self, ck: dict, cfg: TrainConfig, actor, normalize: Normalize, buffer) -> tuple[RunState, object]:
        """Load a checkpoint read by :func:`load_checkpoint` into fresh networks and buffer."""
        # keys added after a checkpoint was written take their defaults
        state = RunState(**{f.name: ck[f.name] for f in dataclasses.fields(RunState) if f.name in ck})
        learner = None
        check_policy_task(ck["policy"], cfg.env.task, source=self.path)  # a policy that cannot drive the task
        try:
            actor.load_state_dict(ck["policy"]["state_dict"])
            if state.stats_ready:
                learner = make_learner(cfg, actor, normalize)
                learner.load_state_dict(ck)
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            raise FileFormatError(f"{self.path}: does not match this run's networks (width={cfg.network.width}, "
                                  f"depth={cfg.network.depth}): {_first_line(err)}") from None
        torch.set_rng_state(ck["rng"])
        if self.buffer_dir.is_dir():
            try:
                buffer.loads(self.buffer_dir)
            except Exception as err:  # noqa: BLE001 - any failure here means a damaged buffer folder
                raise FileFormatError(f"{self.buffer_dir}: damaged replay buffer ({type(err).__name__}: "
                                      f"{_first_line(err)})") from None
        return state, learner


def warm_start(path: str | Path, cfg: TrainConfig, actor, normalize: Normalize) -> object | None:
    """Load the actor (with its observation statistics) and the learner of the checkpoint at ``path`` into a
    new run's networks (``run.init_from``); ``None`` when that run had not started learning. A checkpoint whose
    policy commands or observes another kind than ``cfg.env.task``'s is refused
    (:class:`~atrv_warp.policy.PolicyTaskMismatch`), before anything is loaded."""
    ck = load_checkpoint(Path(path))
    check_policy_task(ck["policy"], cfg.env.task, source=path)
    try:
        actor.load_state_dict(ck["policy"]["state_dict"])
        if not ck["stats_ready"]:
            return None
        learner = make_learner(cfg, actor, normalize)
        learner.load_state_dict(ck)
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise FileFormatError(f"{path}: does not match this run's networks (algo={cfg.optim.algo}, width="
                              f"{cfg.network.width}, depth={cfg.network.depth}): {_first_line(err)}") from None
    return learner


def _first_line(err: Exception) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:200]
