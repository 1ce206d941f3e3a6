"""Every shipped task's episodes are pinned: ``nav``, ``nav_deploy``, and ``nav_deploy`` under the ``wide_slip_gain``
randomization (which drives the odometry's drift), each 32 worlds, seed 7, 200 steps with resets, their observations,
rewards, reward terms and end reasons (``reach`` is pinned by ``test_reference_task.py``). The actions are a policy's
plus seeded noise, so that episodes end several ways (reached, timeouts; nav's collide too): the policies are frozen
copies in ``tests/data`` (``golden_*_policy.pt``, the shipped ones of 2026-11-27), so that a retrained shipped policy
does not move these files. Rewritten only where a task changes on purpose, and the commit says why
(``python tests/write_golden.py --tasks``).

**What differs between CPUs, and how these tests hold on any machine.** On a 2-core Xeon with AVX-512 the closed loop
first differed from the files (written on another CPU) at step 0, by two float32 ulps in an action, and by 18.7 at step
200. The source is the policy's forward pass: torch's CPU matrix products (MKL's ``sgemm``, whose kernel is chosen by
the CPU's instruction set: ``MKL_CBWR=AVX2`` changes the actions on that Xeon) and its vectorised element-wise kernels.
The simulator and the task are not: driven by the recorded actions, all three files replay bit for bit on both CPUs
(Warp compiles its CPU kernels with LLVM for the host, one thread per world, and both hosts are x86-64 with FMA). A
200-step closed loop through contact cannot agree bit for bit once one ulp differs, so each file records the actions
it applied and the env's exact snapshot before every step, and three tests split the protocol:

- **each step from the recorded state** (any machine): restore the snapshot, apply the recorded action, and compare
  that step's outputs within :data:`RTOL` / :data:`ATOL` (end reasons exactly);
- **the recorded actions, bit for bit** (what one machine compares with itself, a refactor before and after): the
  whole 200 steps open loop from the reset, exactly; on a CPU whose compiled kernels may round differently (not x86-64
  with FMA) it is skipped, and the per-step test is the check;
- **the frozen policy** gives the recorded actions from the recorded observations within float32 rounding
  (:data:`POLICY_ATOL`).

They pin each task as its module declares it: the ATRV-Jr's configs before robots had files (issue 59). On the ATRV-Jr
``nav_deploy`` is now fitted to its own limits (:mod:`atrv_warp.task.scaling`); the protocol runs the declared config
(a task marked fitted already), so these files still hold the kernels to what they did."""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
TASK_GOLDENS = {"nav": ("nav", None), "nav_deploy": ("nav_deploy", None),
                "nav_deploy_wide_slip_gain": ("nav_deploy", "wide_slip_gain")}
"""Golden file stem -> (task, randomization)."""
STEPS, WORLDS, NOISE = 200, 32, 0.8
RTOL = 1e-4
ATOL = {"observation": 1e-3, "reward": 1e-5, "reward_terms": 1e-5}
"""The per-step tolerance (float32). Measured on these files: every recorded action one ulp larger moves a step's
outputs by at most 2.1e-4 in the observation (a scan sector or the odometry near a contact) and 1.2e-6 in the rewards,
a fifth of this or less; five steps on from a snapshot the same nudge reaches 0.35 (a beam past an obstacle's edge),
so each step starts from its own snapshot. A change to a kernel moves the outputs by far more."""
POLICY_ATOL = 1e-5
"""The frozen policy's actions against the recorded ones (float32 rounding of its 30-128-128-4 matrix products)."""
OUTPUTS = ("observation", "reward", "reward_terms", "end_reason")


def golden_env(task: str, randomization: str | None):
    """The protocol's env: 32 worlds, seed 7, 100-step episodes, the task as declared (not fitted again)."""
    import dataclasses

    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.registry import resolve_task

    declared = dataclasses.replace(resolve_task(task), robot="atrvjr")
    return RoverEnv(WORLDS, seed=7, task=declared, randomization=randomization, max_steps=100)


def _outputs(step) -> dict[str, np.ndarray]:
    from atrv_warp.task.terms import REWARD_TERMS

    nxt = step["next"]
    return {"observation": nxt["observation"].numpy().copy(), "reward": nxt["reward"].numpy().copy(),
            "end_reason": nxt["end_reason"].numpy().copy(),
            "reward_terms": np.concatenate([nxt["reward_terms", name].numpy() for name in REWARD_TERMS[:6]], -1)}


def _snapshot(env) -> dict[str, np.ndarray]:
    import torch

    return {k: v.numpy().copy() for k, v in env.state_dict().items() if isinstance(v, torch.Tensor)}


def _pinned(snapshots: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The snapshots as arrays: ``pin_const.KEY`` for an entry equal before every step, ``pin.KEY`` stacked otherwise."""
    out = {}
    for key in snapshots[0]:
        values = [s[key] for s in snapshots]
        if all(np.array_equal(v, values[0]) for v in values):
            out[f"pin_const.{key}"] = values[0]
        else:
            out[f"pin.{key}"] = np.stack(values)
    return out


def task_rollout(task: str, randomization: str | None) -> dict[str, np.ndarray]:
    """The task golden protocol, closed loop: the frozen policy plus seeded noise, 200 steps; its outputs, the actions
    it applied (``action``) and the env's snapshot before each step."""
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from atrv_warp.policy import load_policy

    policy = load_policy(DATA / f"golden_{task}_policy.pt", task=task)
    env = golden_env(task, randomization)
    td = env.reset()
    g = torch.Generator().manual_seed(1)
    out, snapshots = {k: [] for k in (*OUTPUTS, "action")}, []
    for _ in range(STEPS):
        snapshots.append(_snapshot(env))
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            action = policy(td.clone())["action"]
        td["action"] = (action + NOISE * torch.randn(WORLDS, 2, generator=g)).clamp(-1.0, 1.0)
        out["action"].append(td["action"].numpy().copy())
        step, td = env.step_and_maybe_reset(td)  # the worlds that ended reset, the others drive on
        for k, v in _outputs(step).items():
            out[k].append(v)
    return {**{k: np.stack(v) for k, v in out.items()}, **_pinned(snapshots)}


def restore(env, golden, step: int) -> None:
    """Set ``env`` to the golden's snapshot before step ``step`` (its identity entries are ``env``'s own)."""
    import torch

    from atrv_warp.task.env import TASK_SNAPSHOT_ADDED

    state = env.state_dict()
    for key in [k for k in state if isinstance(state[k], torch.Tensor)]:
        if f"pin.{key}" not in golden and f"pin_const.{key}" not in golden and \
                key.removeprefix("task.") in TASK_SNAPSHOT_ADDED:
            del state[key]  # an entry added since the golden was written: restored as such a snapshot restores it
            continue
        value = golden[f"pin.{key}"][step] if f"pin.{key}" in golden else golden[f"pin_const.{key}"]
        state[key] = torch.from_numpy(np.array(value))
    env.load_state_dict(state)


def replay(env, golden, before_step=None) -> dict[str, np.ndarray]:
    """Drive ``env`` from its reset through the golden's 200 recorded actions, calling ``before_step(t)`` (if given)
    before each step; the outputs, stacked."""
    import torch

    td = env.reset()
    out = {k: [] for k in OUTPUTS}
    for t in range(STEPS):
        if before_step is not None:
            before_step(t)
        td["action"] = torch.from_numpy(np.array(golden["action"][t]))
        step, td = env.step_and_maybe_reset(td)
        for k, v in _outputs(step).items():
            out[k].append(v)
    return {k: np.stack(v) for k, v in out.items()}


def replay_pinned(env, golden) -> dict[str, np.ndarray]:
    """Every step's outputs, each from the golden's snapshot before it and its recorded action."""
    return replay(env, golden, before_step=lambda t: restore(env, golden, t))


def kernels_round_as_recorded() -> bool:
    """Whether this CPU compiles Warp's kernels to the same float32 rounding as the files' writer: x86-64 with FMA,
    as both hosts measured are (Warp compiles for the host with ``-march=native``)."""
    if platform.machine() not in ("x86_64", "AMD64"):
        return False
    try:
        flags = next(line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("flags"))
    except (OSError, StopIteration):
        return False
    return "fma" in flags.split()


@pytest.fixture(scope="module", params=list(TASK_GOLDENS))
def golden(request):
    """``(name, the golden file's arrays)``."""
    with np.load(DATA / f"{request.param}_rollout.npz") as f:
        return request.param, dict(f)


def test_each_step_from_its_recorded_state_gives_the_recorded_outputs(golden):
    name, expected = golden
    got = replay_pinned(golden_env(*TASK_GOLDENS[name]), expected)
    for key in ("observation", "reward", "reward_terms"):
        np.testing.assert_allclose(got[key], expected[key], rtol=RTOL, atol=ATOL[key], err_msg=f"{name}: {key}")
    np.testing.assert_array_equal(got["end_reason"], expected["end_reason"], err_msg=f"{name}: end_reason")
    ends = np.bincount(expected["end_reason"].ravel(), minlength=7)
    assert ends[1] >= 2 and ends[4] >= 1, f"the protocol reaches goals and times out: {ends}"
    assert name != "nav" or ends[2] + ends[6] >= 1, f"nav's protocol collides: {ends}"


def test_the_recorded_actions_replay_bit_for_bit(golden):
    if not kernels_round_as_recorded():
        pytest.skip(f"{platform.machine()} without FMA may round the compiled kernels otherwise: the per-step test "
                    "holds the files here")
    name, expected = golden
    got = replay(golden_env(*TASK_GOLDENS[name]), expected)
    for key in OUTPUTS:
        np.testing.assert_array_equal(got[key], expected[key], err_msg=f"{name}: {key}")


def test_the_frozen_policy_gives_the_recorded_actions(golden):
    """Where a world drove on (no reset), the policy's input at step t is the recorded observation of step t - 1."""
    import torch
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from atrv_warp.policy import load_policy

    name, expected = golden
    task = TASK_GOLDENS[name][0]
    policy = load_policy(DATA / f"golden_{task}_policy.pt", task=task)
    g = torch.Generator().manual_seed(1)
    noise = torch.stack([NOISE * torch.randn(WORLDS, 2, generator=g) for _ in range(STEPS)])[1:]
    obs = torch.from_numpy(expected["observation"][:-1]).reshape(-1, expected["observation"].shape[-1])
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        action = policy(TensorDict({"observation": obs}, batch_size=[len(obs)]))["action"]
    got = (action.reshape(STEPS - 1, WORLDS, 2) + noise).clamp(-1.0, 1.0).numpy()
    drove_on = expected["end_reason"][:-1, :, 0] == 0
    assert drove_on.mean() > 0.9
    np.testing.assert_allclose(got[drove_on], expected["action"][1:][drove_on], rtol=0, atol=POLICY_ATOL,
                               err_msg=f"{name}: the policy's actions")
