"""``reach``: the reference task. Drive to a target on the flat 30 m arena.

- Scene: flat ground, four walls, no obstacles, no scanner.
- Reset: target and start uniform in ±12 m, the yaw uniform.
- Observation: the arena's (:data:`~atrv_warp.task.spec.OBSERVATION`): positions and velocities in the arena's frame.
- Action: each side's wheel torque, ±20 N·m.
- Ends: within 1 m of the target (success); a wall or chassis contact or a flip beyond 0.2 rad (failure); 200 steps.
- Reward: progress toward the target, heading progress x 4, -0.03 a step; +4 on success, -4 on failure.
"""

from atrv_warp.task.config import TaskConfig
from atrv_warp.task.definition import Task
from atrv_warp.task.kernels.terms import within_reach
from atrv_warp.task.terms import REFERENCE_TERMS

CONFIG = TaskConfig()
TASK = Task("reach", CONFIG, REFERENCE_TERMS, within_reach, description=__doc__.splitlines()[0], source=__file__)
