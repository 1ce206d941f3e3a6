"""Write the default configuration's golden rollout: ``python tests/write_golden.py``.

Run it only when a change is meant to change the default rollouts; the commit that does so says why.
``flat_reference_rollout.npz`` (the 0.01 s release, commit 2d88b0e) is never rewritten.
"""

import numpy as np
from test_reference_task import DEFAULT_GOLDEN, reference_rollout  # beside this script, on sys.path when it runs

if __name__ == "__main__":
    rollout = reference_rollout()
    np.savez_compressed(DEFAULT_GOLDEN, **rollout)
    ends = np.bincount(rollout["end_reason"].ravel())
    print(f"written {DEFAULT_GOLDEN}: 16 worlds x 120 steps, end reasons {ends.tolist()}, "
          f"reward sum {rollout['reward'].sum():.4f}")
