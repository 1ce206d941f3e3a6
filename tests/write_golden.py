"""Write golden rollouts: ``python tests/write_golden.py`` (the default configuration's reach rollout),
``python tests/write_golden.py --tasks`` (every shipped task's, ``test_task_rollouts.py``: the closed loop of the frozen
policy, its actions and the env's snapshots), or ``python tests/write_golden.py --tasks --replay`` (the task files'
snapshots recorded again by replaying each file's own actions, its outputs kept: for a new snapshot format; refused
unless the replay reproduces the file bit for bit).

Run it only when a change is meant to change those rollouts; the commit that does so says why.
``flat_reference_rollout.npz`` (the 0.01 s release, commit 2d88b0e) is never rewritten.
"""

import sys

import numpy as np
from test_reference_task import DEFAULT_GOLDEN, reference_rollout  # beside this script, on sys.path when it runs
from test_task_rollouts import (
    DATA,
    OUTPUTS,
    TASK_GOLDENS,
    _pinned,
    _snapshot,
    golden_env,
    replay,
    task_rollout,
)


def recorded_actions(golden: dict, env) -> np.ndarray:
    """The file's actions, or (a file from before they were stored) its observations' newest last actions."""
    if "action" in golden:
        return golden["action"]
    from atrv_warp.task.spec import observation_fields

    names = [f.name for f in observation_fields(env.task_cfg)]
    return golden["observation"][..., [i for i, n in enumerate(names) if n.startswith("last_action_1_")]]


def replayed(name: str) -> dict[str, np.ndarray]:
    """The golden ``name`` with its snapshots recorded again from its own actions; exits unless bit for bit."""
    with np.load(DATA / f"{name}_rollout.npz") as f:
        golden = {k: f[k] for k in (*OUTPUTS, "action") if k in f}
    env = golden_env(*TASK_GOLDENS[name])
    golden["action"] = recorded_actions(golden, env)
    snapshots = []
    got = replay(env, golden, before_step=lambda _: snapshots.append(_snapshot(env)))
    for key in OUTPUTS:
        if not np.array_equal(got[key], golden[key]):
            sys.exit(f"{name}: the replay of its actions differs from the file ({key}): the task changed, or this "
                     "CPU rounds the kernels otherwise; nothing written")
    return {**golden, **_pinned(snapshots)}


if __name__ == "__main__":
    if "--tasks" in sys.argv[1:]:
        for name, (task, randomization) in TASK_GOLDENS.items():
            rollout = replayed(name) if "--replay" in sys.argv[1:] else task_rollout(task, randomization)
            path = DATA / f"{name}_rollout.npz"
            np.savez_compressed(path, **rollout)
            ends = np.bincount(rollout["end_reason"].ravel())
            print(f"written {path}: 32 worlds x 200 steps, end reasons {ends.tolist()}, "
                  f"reward sum {rollout['reward'].sum():.4f}, a snapshot before each step")
    else:
        rollout = reference_rollout()
        np.savez_compressed(DEFAULT_GOLDEN, **rollout)
        ends = np.bincount(rollout["end_reason"].ravel())
        print(f"written {DEFAULT_GOLDEN}: 16 worlds x 120 steps, end reasons {ends.tolist()}, "
              f"reward sum {rollout['reward'].sum():.4f}")
