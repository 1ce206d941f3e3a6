"""The tasks' fingerprints: short hashes that results files record (``benchmarks/_common.py``) and the docs build
recomputes to flag figures measured on other tasks (``docs/hooks.py``); the simulator's are
:mod:`atrv_warp.sim.fingerprints`.

- :func:`task_fingerprint`: what ``reach`` and ``nav`` do on the ATRV-Jr, from short rollouts (a behaviour, not a
  source: a refactor keeps it);
- :func:`task_robot_fingerprint`: what a task is on a robot as declared, any task on any robot (its fitted config,
  its reward table and success test, the robot file and its URDF), which a rollout of two tasks on one robot cannot
  see.
"""

from __future__ import annotations

import hashlib
import json

import torch
from torchrl.envs.utils import step_mdp

__all__ = ["FINGERPRINT_STEPS", "task_fingerprint", "task_robot_fingerprint", "task_robot_key"]

FINGERPRINT_STEPS = 30
"""Env-steps of :func:`task_fingerprint`'s rollouts."""


@torch.no_grad()
def task_fingerprint() -> str:
    """A short hash of what the tasks do, not of their source: each task (``reach``, ``nav``) with 4 worlds under
    the ``wide`` randomization, seed 0, driven by fixed actions for :data:`FINGERPRINT_STEPS` env-steps; every
    step's observations and rewards rounded to 1e-3 and its end reasons, hashed.

    It moves with the observation, reward, resets, randomization, sensors and the simulator under them, and not
    with a refactor. Benchmarks that run the environment record it (``benchmarks/_common.write_results``);
    the docs build recomputes it once to flag their figures when it changes (``docs/hooks.py``).

    Returns:
        16 hex digits.
    """
    from atrv_warp.task.env import RoverEnv

    digest = hashlib.sha256()
    for task in ("reach", "nav"):
        env = RoverEnv(4, task=task, seed=0, randomization="wide")
        td = env.reset()
        # [left, right] in [-1, 1]: straight, a skid turn each way, and a stop
        action = torch.tensor([[0.8, 0.8], [-0.6, 0.9], [0.9, -0.6], [0.0, 0.0]])
        for _ in range(FINGERPRINT_STEPS):
            td = env.step(td.set("action", action))
            nxt = td["next"]
            for value in (nxt["observation"], nxt["reward"]):
                digest.update(" ".join(f"{v:.3f}" for v in (value.double().round(decimals=3) + 0.0).flatten().tolist()).encode())
            digest.update(str(nxt["end_reason"].flatten().tolist()).encode())
            td = step_mdp(td)
    return digest.hexdigest()[:16]


def task_robot_key(task: str, robot: str) -> str:
    """``'task@robot'``: how results files name a task on a robot beside its :func:`task_robot_fingerprint`."""
    return f"{task}@{robot}"


def task_robot_fingerprint(task: str, robot) -> str:
    """A short hash of what the registered task ``task`` is on ``robot`` (a name, a robot file or a
    :class:`~atrv_warp.core.robot.Robot`), as declared: the task fitted to the robot (every config field, each reward
    term's row: its weight field and value, when it counts, what it reads, its kernel's name; the success test's
    name; not the module's path or its description), the robot file (less its ``[deploy]`` table) and its URDF.

    It moves when a task's field, weight or term changes, or when the robot's file or URDF does, for any task and
    robot (``nav_deploy``, a task of your own, the Jackal); :func:`task_fingerprint` moves with the kernels' behaviour
    under ``reach`` and ``nav`` on the ATRV-Jr. Results files record both (``benchmarks/_common.provenance``).

    Raises:
        ValueError: An unknown task (the known ones named).
        RobotFileError: A robot that does not load (named).

    Returns:
        16 hex digits.
    """
    from atrv_warp.core.robot import Robot, load_robot, robot_file_sha256
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.scaling import fit_task

    spec = robot if isinstance(robot, Robot) else load_robot(robot)
    fitted = fit_task(resolve_task(task), nominal_rover_config(spec.path))
    record = {k: v for k, v in fitted.record().items() if k not in ("source", "description")}
    digest = hashlib.sha256(json.dumps(record, sort_keys=True, default=str).encode())
    digest.update(robot_file_sha256(spec.path).encode())  # the file less its [deploy] table: what the robot is
    digest.update(str(spec.urdf_sha256).encode())
    return digest.hexdigest()[:16]
