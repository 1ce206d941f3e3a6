"""Gymnasium adapters, for users of the reference's Gymnasium + Stable-Baselines3 stack.

Registered ids (importing this module registers them; ``gymnasium.make`` accepts the
``"atrv_warp.integrations.gymnasium:ATRVjr-v0"`` form, which imports it for you):

- ``ATRVjr-v0``: one rover, a ``gymnasium.Env`` (what SB3's ``DummyVecEnv`` wraps);
  ``gymnasium.make_vec("ATRVjr-v0", num_envs=N)`` gives the batched ``ATRVjrVectorEnv``.
- ``ATRVjrNav-v0``: the same on the navigation task (terrain, obstacles, the scan in the
  observation and the full scan in ``info["scan"]``).

Both run on :class:`atrv_warp.task.env.RoverEnv` and take its keywords: ``gymnasium.make("ATRVjr-v0",
robot="jackal")`` drives the Jackal (a shipped robot's name or a robot file's path). The episode limit (200 steps) is
the task's own truncation, so no ``TimeLimit`` wrapper is added.
"""

from __future__ import annotations

from typing import ClassVar

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from tensordict import TensorDict

from atrv_warp.task.env import END_REASONS, RoverEnv

__all__ = ["ATRVjrGymEnv", "ATRVjrVectorEnv"]


def _spaces(env: RoverEnv) -> tuple[spaces.Box, spaces.Box]:
    spec = env.observation_spec["observation"]
    obs = spaces.Box(spec.space.low[0].numpy(), spec.space.high[0].numpy(), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    return obs, act


class ATRVjrGymEnv(gymnasium.Env):
    """Single-rover Gymnasium environment: the reference's interface."""

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(self, **env_kwargs):
        self._env = RoverEnv(1, **env_kwargs)
        self.observation_space, self.action_space = _spaces(self._env)
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None or not self._started:
            self._env.set_seed(seed if seed is not None else 0)
            self._started = True
        td = self._env.reset()
        return td["observation"][0].numpy().copy(), self._info(td)

    def step(self, action):
        a = torch.as_tensor(np.asarray(action, dtype=np.float32)).reshape(1, 2)
        nxt = self._env.step(TensorDict(action=a, batch_size=[1]))["next"]
        return (nxt["observation"][0].numpy().copy(), float(nxt["reward"][0, 0]), bool(nxt["terminated"][0, 0]),
                bool(nxt["truncated"][0, 0]), self._info(nxt))

    @staticmethod
    def _info(td) -> dict:
        info = {"end_reason": END_REASONS[int(td["end_reason"][0, 0])], "distance": float(td["distance"][0, 0])}
        if "scan" in td:
            info["scan"] = td["scan"][0].numpy().copy()
        return info


class ATRVjrVectorEnv(VectorEnv):
    """N rovers as a Gymnasium ``VectorEnv`` (autoreset on the next step, Gymnasium's default)."""

    metadata: ClassVar[dict] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, **env_kwargs):
        self._env = RoverEnv(num_envs, **env_kwargs)
        self.num_envs = num_envs
        self.single_observation_space, self.single_action_space = _spaces(self._env)
        self.observation_space = gymnasium.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(self.single_action_space, num_envs)
        self._needs_reset = torch.zeros(num_envs, dtype=torch.bool)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._env.set_seed(seed)
        td = self._env.reset()
        self._needs_reset.zero_()
        return td["observation"].numpy().copy(), {"distance": td["distance"][:, 0].numpy().copy()}

    def step(self, actions):
        a = torch.as_tensor(np.asarray(actions, dtype=np.float32))
        nxt = self._env.step(TensorDict(action=a, batch_size=[self.num_envs]))["next"]
        obs = nxt["observation"].clone()
        reward = nxt["reward"][:, 0].clone()
        term = nxt["terminated"][:, 0].clone()
        trunc = nxt["truncated"][:, 0].clone()
        if self._needs_reset.any():  # NEXT_STEP autoreset: these worlds' actions are ignored
            mask = self._needs_reset.clone()
            td = self._env.reset(TensorDict(_reset=mask.unsqueeze(-1), batch_size=[self.num_envs]))
            obs[mask] = td["observation"][mask]
            reward[mask] = 0.0
            term[mask] = False
            trunc[mask] = False
        self._needs_reset = term | trunc
        info = {"end_reason": nxt["end_reason"][:, 0].numpy().copy(), "distance": nxt["distance"][:, 0].numpy().copy()}
        if "scan" in nxt:
            info["scan"] = nxt["scan"].numpy().copy()
        return obs.numpy(), reward.numpy(), term.numpy(), trunc.numpy(), info


if "ATRVjr-v0" not in gymnasium.registry:
    gymnasium.register(id="ATRVjr-v0", entry_point=ATRVjrGymEnv, vector_entry_point=ATRVjrVectorEnv)
if "ATRVjrNav-v0" not in gymnasium.registry:
    gymnasium.register(id="ATRVjrNav-v0", entry_point=ATRVjrGymEnv, vector_entry_point=ATRVjrVectorEnv,
                       kwargs={"task": "nav"})
