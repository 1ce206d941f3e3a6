"""Every shipped task's episodes are pinned bit for bit: ``nav``, ``nav_deploy``, and ``nav_deploy`` under the
``wide_slip_gain`` randomization (which drives the odometry's drift), each 32 worlds, seed 7, 200 steps with resets,
their observations, rewards, reward terms and end reasons (``reach`` is pinned by ``test_reference_task.py``). The
actions are a policy's plus seeded noise, so that episodes end several ways (reached, timeouts; nav's collide too):
the policies are frozen copies in ``tests/data`` (``golden_*_policy.pt``, the shipped ones of 2026-11-27), so that a
retrained shipped policy does not move these files. Written by ``python tests/write_golden.py --tasks`` before the
task refactor of issue 58; rewritten only where a task changes on purpose, and the commit says why.

They pin each task as its module declares it: the ATRV-Jr's configs before robots had files (issue 59). On the ATRV-Jr
``nav_deploy`` is now fitted to its own limits (:mod:`atrv_warp.task.scaling`); the protocol runs the declared config
(a task marked fitted already), so these files still hold the kernels to what they did."""

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
TASK_GOLDENS = {"nav": ("nav", None), "nav_deploy": ("nav_deploy", None),
                "nav_deploy_wide_slip_gain": ("nav_deploy", "wide_slip_gain")}
"""Golden file stem -> (task, randomization)."""


def task_rollout(task: str, randomization: str | None) -> dict[str, np.ndarray]:
    """The task golden protocol: 32 worlds, seed 7, 200 steps of the frozen policy plus seeded noise."""
    import dataclasses

    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from atrv_warp.policy import load_policy
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.spec import REWARD_TERMS

    policy = load_policy(DATA / f"golden_{task}_policy.pt", task=task)
    declared = dataclasses.replace(resolve_task(task), robot="atrvjr")  # as declared: not fitted again
    env = RoverEnv(32, seed=7, task=declared, randomization=randomization, max_steps=100)
    td = env.reset()
    g = torch.Generator().manual_seed(1)
    out = {"observation": [], "reward": [], "end_reason": [], "reward_terms": []}
    for _ in range(200):
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            action = policy(td.clone())["action"]
        td["action"] = (action + 0.8 * torch.randn(32, 2, generator=g)).clamp(-1.0, 1.0)
        step, td = env.step_and_maybe_reset(td)  # the worlds that ended reset, the others drive on
        nxt = step["next"]
        out["observation"].append(nxt["observation"].numpy().copy())
        out["reward"].append(nxt["reward"].numpy().copy())
        out["end_reason"].append(nxt["end_reason"].numpy().copy())
        out["reward_terms"].append(np.concatenate([nxt["reward_terms", name].numpy() for name in REWARD_TERMS[:6]], -1))
    return {k: np.stack(v) for k, v in out.items()}


@pytest.mark.parametrize("name", list(TASK_GOLDENS))
def test_task_rollout_is_bit_identical(name):
    expected = np.load(DATA / f"{name}_rollout.npz")
    got = task_rollout(*TASK_GOLDENS[name])
    for key in ("observation", "reward", "end_reason", "reward_terms"):
        np.testing.assert_array_equal(got[key], expected[key], err_msg=f"{name}: {key}")
    ends = np.bincount(got["end_reason"].ravel(), minlength=7)
    assert ends[1] >= 2 and ends[4] >= 1, f"the protocol reaches goals and times out: {ends}"
    assert name != "nav" or ends[2] + ends[6] >= 1, f"nav's protocol collides: {ends}"
