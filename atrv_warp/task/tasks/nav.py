"""``nav``: drive to a goal over rolling terrain, around obstacles seen through a laser scanner.

- Scene: rolling terrain (a tile drawn per episode), six obstacles (one across the straight line to the goal), a
  64-beam scanner over 180°.
- Reset: the goal 5–10 m from the start, obstacles clear of both by 1 m.
- Observation: the arena's, then the scan as 16 sectors, then the last three actions (a delayed rover's pending
  commands: docs/randomization.md).
- Action: each side's wheel torque, ±20 N·m.
- Ends: within 1 m of the goal; a wall, chassis or obstacle contact, or a flip beyond 0.5 rad; 300 steps (15 s).
- Reward: progress, heading progress x 1, -0.03 a step, a clearance cost x 0.5 inside 1 m of an obstacle; +4 on
  success, -10 on failure.
"""

from atrv_warp.task.config import TaskConfig
from atrv_warp.task.definition import Task
from atrv_warp.task.kernels.terms import within_reach
from atrv_warp.task.terms import REFERENCE_TERMS

CONFIG = TaskConfig(terrain="rolling", target_distance=(5.0, 10.0), obstacles=6, obstacles_on_path=1, max_steps=300,
                    flip_roll=0.5, scan_beams=64, scan_sectors=16, action_history=3, failure_reward=-10.0,
                    heading_weight=1.0, clearance_weight=0.5)
TASK = Task("nav", CONFIG, REFERENCE_TERMS, within_reach, description=__doc__.splitlines()[0], source=__file__)
