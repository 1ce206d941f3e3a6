"""Write the default configuration's golden rollout: ``python tests/write_golden.py``.

Run it only when a change to the physics is meant to change the reference rollouts; the commit
that does so says why. ``flat_reference_rollout.npz`` (the 0.01 s release) is never rewritten.
"""

import numpy as np
from test_reference_task import DATA, reference_rollout  # beside this script, on sys.path when it runs

from atrv_warp.sim.config import SimConfig

if __name__ == "__main__":
    rollout = reference_rollout(SimConfig())
    out = DATA / "flat_reference_rollout_3substeps.npz"
    np.savez_compressed(out, **rollout)
    ends = np.bincount(rollout["end_reason"].ravel())
    print(f"written {out}: 16 worlds x 120 steps, end reasons {ends.tolist()}, reward sum {rollout['reward'].sum():.4f}")
