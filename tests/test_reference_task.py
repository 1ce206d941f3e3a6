"""The flat reference task's rollouts are pinned bit for bit.

``tests/data/flat_reference_rollout.npz`` was written by the release of 2026-11-21 (commit 2d88b0e),
which integrated at the reference's 0.01 s with the plain Hunt–Crossley law and viscous friction: 16
worlds, seed 123, 120 steps of seeded random actions with resets. ``SimConfig(sim_dt=REFERENCE_SIM_DT)``
with ``ContactConfig(damping_limit=None, friction_law="viscous")`` must still reproduce it exactly. The
defaults (the same step, the damping ceiling, Coulomb friction at the wheels) are pinned the same way by
``flat_default_rollout.npz``, written by ``python tests/write_golden.py``. Any change to either path (kernels, contact, sampling) shows up
here as a mismatch, not as a tolerance.
"""

from pathlib import Path

import numpy as np
import pytest

from atrv_warp.sim.config import REFERENCE_SIM_DT, ContactConfig, SimConfig

DATA = Path(__file__).parent / "data"
DEFAULT_GOLDEN = DATA / "flat_default_rollout.npz"


def reference_rollout(sim: SimConfig | None = None, contact: ContactConfig | None = None) -> dict[str, np.ndarray]:
    """The golden protocol: 16 worlds, seed 123, 120 seeded random-action steps with resets."""
    import torch

    from atrv_warp.task.env import ATRVjrEnv

    env = ATRVjrEnv(16, seed=123, sim=sim, contact=contact)
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
    return {"observation": np.stack(obs), "reward": np.stack(rew), "end_reason": np.stack(reason)}


@pytest.mark.parametrize(("sim", "contact", "golden"), [
    (SimConfig(sim_dt=REFERENCE_SIM_DT), ContactConfig(damping_limit=None, friction_law="viscous"),
     DATA / "flat_reference_rollout.npz"),
    (None, None, DEFAULT_GOLDEN),
], ids=["reference-as-2d88b0e", "default"])
def test_flat_reference_rollout_is_bit_identical(sim, contact, golden):
    expected = np.load(golden)
    got = reference_rollout(sim, contact)
    for key in ("observation", "reward", "end_reason"):
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
