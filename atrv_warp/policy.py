"""Saved policies: the actor network, its file format, and the policies that ship.

This module sits below training and the integrations: :mod:`atrv_warp.evaluate`, the ROS node
and the exporter load a policy from here without importing the trainer (:mod:`atrv_warp.rl`).

Observation normalisation lives *inside* the networks (:class:`Normalize`, statistics as
buffers): it is saved with the policy, frozen for evaluation, and a saved policy runs on raw
``ATRVjrEnv`` observations with no transform to rebuild.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal

from atrv_warp.storage import FileFormatError, atomic_save, load_weights
from atrv_warp.task.spec import ACTION_DIM, OBS_DIM, observation_fields

__all__ = ["POLICY_FORMAT", "Normalize", "load_policy", "make_actor", "policy_payload", "policy_task",
           "pretrained_nav_policy_path", "pretrained_policy_path", "save_policy"]

POLICY_FORMAT = "atrv_warp.policy/1"
"""Format tag of a saved policy (``save_policy``, and the ``policy`` entry of a training checkpoint)."""


class Normalize(nn.Module):
    """``(x - loc) / scale`` with frozen statistics stored as buffers."""

    def __init__(self, dim: int = OBS_DIM):
        super().__init__()
        self.register_buffer("loc", torch.zeros(dim))
        self.register_buffer("scale", torch.ones(dim))

    def set_stats(self, loc: torch.Tensor, scale: torch.Tensor) -> None:
        self.loc.copy_(loc)
        self.scale.copy_(scale.clamp(min=1e-3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.loc) / self.scale


def make_actor(width: int = 128, depth: int = 2, normalize: Normalize | None = None, *,
               obs_dim: int = OBS_DIM, return_log_prob: bool = False) -> ProbabilisticActor:
    """Tanh-Gaussian actor ``observation`` (``obs_dim``: the task's) ``-> action`` in [-1, 1]².

    ``return_log_prob``: also write the sampled action's log-probability (``action_log_prob``), as
    PPO's collection needs; the weights, and so the saved policy, are the same.
    """
    net = nn.Sequential(
        normalize if normalize is not None else Normalize(obs_dim),
        MLP(in_features=obs_dim, out_features=2 * ACTION_DIM, num_cells=[width] * depth, activation_class=nn.ReLU),
        NormalParamExtractor(),
    )
    module = TensorDictModule(net, in_keys=["observation"], out_keys=["loc", "scale"])
    return ProbabilisticActor(module, in_keys=["loc", "scale"], out_keys=["action"], distribution_class=TanhNormal,
                              distribution_kwargs={"low": -1.0, "high": 1.0}, return_log_prob=return_log_prob)


def save_policy(actor: ProbabilisticActor, path: str | Path, *, width: int, depth: int, meta: dict | None = None):
    """Write the actor's weights (normalisation included) atomically, loadable with weights_only.
    ``meta["task"]`` names the task the policy observes (``reach`` if absent)."""
    atomic_save(policy_payload(actor, width=width, depth=depth, meta=meta), path)


def policy_payload(actor: ProbabilisticActor, *, width: int, depth: int, meta: dict | None = None) -> dict:
    """The saved form of a policy (``POLICY_FORMAT``), as :func:`load_policy` reads it."""
    sd = {k: v.detach().cpu() for k, v in actor.state_dict().items()}
    obs_dim = next(v.numel() for k, v in sd.items() if k.endswith("loc") and v.ndim == 1)
    return {"format": POLICY_FORMAT, "width": width, "depth": depth, "obs_dim": obs_dim, "state_dict": sd,
            "meta": meta or {}}


def policy_task(path: str | Path) -> str:
    """The task a saved policy was trained on (``meta["task"]``; ``reach`` for older files)."""
    payload = load_weights(Path(path), "policy file")
    payload = payload["policy"] if isinstance(payload.get("policy"), dict) else payload
    return str(payload.get("meta", {}).get("task", "reach"))


def pretrained_nav_policy_path(randomized: bool = True) -> Path:
    """The navigation policy shipped inside the package, trained by ``python -m atrv_warp.train --config nav``
    under the ``wide`` domain randomization (the default); ``randomized=False``: the earlier one, trained on the
    nominal rover with perfect sensors (``nav_policy_plain.pt``)."""
    name = "nav_policy.pt" if randomized else "nav_policy_plain.pt"
    return Path(str(resources.files("atrv_warp").joinpath(f"assets/{name}")))


def pretrained_policy_path() -> Path:
    """The policy shipped inside the package (trained by ``python -m atrv_warp.train``)."""
    return Path(str(resources.files("atrv_warp").joinpath("assets/pretrained_policy.pt")))


def load_policy(path: str | Path | None = None, *, deterministic: bool = True, task=None,
                device: str | torch.device = "cpu") -> TensorDictSequential:
    """Load a saved policy (default: the shipped one) as a TorchRL policy module.

    The module reads raw ``observation`` from :class:`~atrv_warp.task.env.ATRVjrEnv` and writes
    ``action``; with ``deterministic=True`` it returns the distribution's mode. ``task`` (a task name or
    :class:`~atrv_warp.task.config.TaskConfig`): the policy must observe that task's observation.

    Raises ``FileNotFoundError``, or :class:`~atrv_warp.storage.FileFormatError` naming the file
    and the problem for anything that is not a complete policy (nothing is unpickled), or for a policy
    that observes another observation than ``task``'s. ``device``: where the weights go; the env's
    (``env.device``) for an :class:`~atrv_warp.task.env.ATRVjrEnv` on a GPU.
    """
    path = Path(path) if path is not None else pretrained_policy_path()
    payload = load_weights(path, "policy file")
    if isinstance(payload.get("policy"), dict):  # a training checkpoint: take its policy
        payload = payload["policy"]
    if payload.get("format") != POLICY_FORMAT:
        raise FileFormatError(f"{path}: not an atrv_warp policy (format {payload.get('format')!r}, "
                              f"expected {POLICY_FORMAT!r})")
    if task is not None:
        _check_observes(path, int(payload.get("obs_dim", OBS_DIM)), task)
    try:
        actor = make_actor(int(payload["width"]), int(payload["depth"]), obs_dim=int(payload.get("obs_dim", OBS_DIM)))
        actor.load_state_dict(payload["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise FileFormatError(f"{path}: damaged atrv_warp policy ({detail[:200]})") from None
    bad = [k for k, v in actor.state_dict().items() if v.is_floating_point() and not torch.isfinite(v).all()]
    if bad:
        raise FileFormatError(f"{path}: damaged atrv_warp policy (non-finite values in {bad[:3]})")
    actor.to(device).eval()
    if not deterministic:
        return actor
    from torchrl.envs.utils import ExplorationType

    return _Deterministic(actor, ExplorationType.DETERMINISTIC)


def _check_observes(path: Path, obs_dim: int, task) -> None:
    from atrv_warp.task.config import get_task

    fields = observation_fields(get_task(task))
    if obs_dim != len(fields):
        name = f"task {task!r}" if isinstance(task, str) else "the task"
        raise FileFormatError(
            f"{path}: the policy observes {obs_dim} values, {name} observes {len(fields)} "
            f"({fields[0].name} … {fields[-1].name}); it was trained on another version of the task: train it again")


class _Deterministic(TensorDictSequential):
    """Runs the wrapped actor under a fixed exploration type."""

    def __init__(self, actor, exploration_type):
        super().__init__(actor)
        self._exploration_type = exploration_type

    def forward(self, tensordict, *args, **kwargs):
        from torchrl.envs.utils import set_exploration_type

        with set_exploration_type(self._exploration_type), torch.no_grad():
            return super().forward(tensordict, *args, **kwargs)
