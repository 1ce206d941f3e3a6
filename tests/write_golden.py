"""Write golden rollouts: ``python tests/write_golden.py`` (the default configuration's reach rollout) or
``python tests/write_golden.py --tasks`` (every shipped task's, ``test_task_rollouts.py``).

Run it only when a change is meant to change those rollouts; the commit that does so says why.
``flat_reference_rollout.npz`` (the 0.01 s release, commit 2d88b0e) is never rewritten.
"""

import sys

import numpy as np
from test_reference_task import DEFAULT_GOLDEN, reference_rollout  # beside this script, on sys.path when it runs
from test_task_rollouts import DATA, TASK_GOLDENS, task_rollout

if __name__ == "__main__":
    if "--tasks" in sys.argv[1:]:
        for name, (task, randomization) in TASK_GOLDENS.items():
            rollout = task_rollout(task, randomization)
            path = DATA / f"{name}_rollout.npz"
            np.savez_compressed(path, **rollout)
            ends = np.bincount(rollout["end_reason"].ravel())
            print(f"written {path}: 32 worlds x 200 steps, end reasons {ends.tolist()}, "
                  f"reward sum {rollout['reward'].sum():.4f}")
    else:
        rollout = reference_rollout()
        np.savez_compressed(DEFAULT_GOLDEN, **rollout)
        ends = np.bincount(rollout["end_reason"].ravel())
        print(f"written {DEFAULT_GOLDEN}: 16 worlds x 120 steps, end reasons {ends.tolist()}, "
              f"reward sum {rollout['reward'].sum():.4f}")
