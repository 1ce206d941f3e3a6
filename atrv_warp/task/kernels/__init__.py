"""The task's Warp kernels, one thread per world, by job:

- :mod:`.state`: the structs they read and write, and a task config's values as a struct (:func:`.state.params_struct`);
- :mod:`.sampling`: reset sampling (the reference's and the nav tasks');
- :mod:`.observe`: the observation (the arena's or the robot's leading fields, the scan's sectors, the last actions);
- :mod:`.steps`: a step's outcome (its ends, the odometry's drift, each reward term, the reward);
- :mod:`.terms`: the shipped reward terms and success test, as ``@wp.func``;
- :mod:`.randomization`: the domain randomization's draws, the action latency and motor lag, the observation noise.
"""

from atrv_warp.task.kernels.observe import (
    ScanReading,
    beam_reading,
    scaled_odometry,
    wrap_angle,
    write_goal_observation,
    write_scan_observation,
)
from atrv_warp.task.kernels.state import RoverState, StepOutputs, TaskBuffers, TermInputs, params_of, params_struct
from atrv_warp.task.kernels.steps import twist_command

__all__ = ["RoverState", "ScanReading", "StepOutputs", "TaskBuffers", "TermInputs", "beam_reading", "params_of",
           "params_struct", "scaled_odometry", "twist_command", "wrap_angle", "write_goal_observation",
           "write_scan_observation"]
