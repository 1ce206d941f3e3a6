"""The simulator's fingerprints: short hashes of what it does, which results files record (``benchmarks/_common.py``)
and the docs build recomputes to flag figures measured on other dynamics (``docs/hooks.py``). The tasks' are in
:mod:`atrv_warp.task.fingerprints`; the measurement protocols (the reference drive, wall impacts, the driver's step
response, ...) in :mod:`atrv_warp.sim.protocols`.
"""

from __future__ import annotations

import hashlib

import numpy as np
import torch

from atrv_warp.sim.config import ContactConfig, SimConfig
from atrv_warp.sim.simulator import RoverSim

__all__ = ["FINGERPRINT_STEPS", "driver_fingerprint", "dynamics_fingerprint"]


FINGERPRINT_STEPS = 40
"""Env-steps of :func:`dynamics_fingerprint`'s rollout (2 s)."""


def dynamics_fingerprint(*, contact: ContactConfig | None = None, sim: SimConfig | None = None) -> str:
    """A short hash of what the simulator does, not of its source: two rovers of the default model
    from fixed poses under fixed wheel torques for :data:`FINGERPRINT_STEPS` env-steps, their final
    chassis poses rounded to 1e-4 (m, quaternion) and hashed.

    A refactor leaves it unchanged; a change to the dynamics (contact, friction, solver, model,
    substeps) changes it. Benchmarks record it in their results files
    (``benchmarks/_common.write_results``) and the docs build recomputes it once to flag figures
    measured on other dynamics (``docs/hooks.py``).

    Returns:
        16 hex digits.
    """
    rovers = RoverSim(2, contact=contact, sim=sim)
    rovers.reset(poses=torch.tensor([[0.0, 0.0, 0.0], [2.0, -3.0, 0.7]]))
    # [left, right] wheel torque [N·m]: a straight drive, and a skid turn with a slipping side
    rovers.commands[:] = torch.tensor([[4.0, 4.0], [-3.0, 9.0]])
    for _ in range(FINGERPRINT_STEPS):
        rovers.step()
    return _hash_poses(rovers.root_pose)


def driver_fingerprint(*, sim: SimConfig | None = None) -> str:
    """A short hash of what the base's motor driver does (:mod:`atrv_warp.sim.driver`), as
    :func:`dynamics_fingerprint` hashes the torque-driven dynamics: two rovers of the default model driven by
    ``/cmd_vel`` (a straight line and an arc) for :data:`FINGERPRINT_STEPS` env-steps, their final chassis poses
    and wheel odometry rounded to 1e-4 and hashed. Results whose figures went through the driver record it.

    Returns:
        16 hex digits.
    """
    rovers = RoverSim(2, sim=sim)
    rovers.reset(poses=torch.tensor([[0.0, 0.0, 0.0], [2.0, -3.0, 0.7]]))
    for _ in range(FINGERPRINT_STEPS):
        rovers.set_twist(torch.tensor([[0.8, 0.0], [0.3, 0.6]]))
        rovers.step()
    return _hash_poses(torch.cat([rovers.root_pose, rovers.driver.odometry], -1))


def _hash_poses(pose: torch.Tensor) -> str:
    pose = pose.detach().cpu().double().numpy()
    text = " ".join(f"{v:.4f}" for v in (np.round(pose, 4) + 0.0).ravel())  # + 0.0: no "-0.0000"
    return hashlib.sha256(text.encode()).hexdigest()[:16]
