"""The flat reference task is bit-identical to the release before terrain, obstacles and the scanner.

``tests/data/flat_reference_rollout.npz`` was written by the release of 2026-11-21 (commit 2d88b0e):
16 worlds, seed 123, 120 steps of seeded random actions with resets. Any change to the reference
path (kernels, contact, sampling) shows up here as a mismatch, not as a tolerance.
"""

from pathlib import Path

import numpy as np
import torch

from atrv_warp.task.env import ATRVjrEnv

GOLDEN = Path(__file__).parent / "data" / "flat_reference_rollout.npz"


def test_flat_reference_rollout_is_bit_identical():
    golden = np.load(GOLDEN)
    env = ATRVjrEnv(16, seed=123)
    td = env.reset()
    g = torch.Generator().manual_seed(0)
    obs, rew, reason = [], [], []
    for _ in range(120):
        td["action"] = torch.rand(16, 2, generator=g) * 2 - 1
        td = env.step(td)
        obs.append(td["next", "observation"].numpy().copy())
        rew.append(td["next", "reward"].numpy().copy())
        reason.append(td["next", "end_reason"].numpy().copy())
        td = env.step_mdp(td)
        td = env.reset(td) if td["done"].any() else td
    np.testing.assert_array_equal(np.stack(obs), golden["observation"])
    np.testing.assert_array_equal(np.stack(rew), golden["reward"])
    np.testing.assert_array_equal(np.stack(reason), golden["end_reason"])
