"""``follow_path``: follow Nav2's plan to a goal and its heading, as Nav2's controller does, in buildings and yards.

- Scene: maps (a run's ``--map``: Nav2 maps or procedural places, e.g. ``building:64 yard:64``), planned over by
  Nav2's planner (:mod:`atrv_warp.sim.planner`), which plans again from the robot every second; flat floors (on
  the nav terrain's hollows the ATRV-Jr's free wheels stall in the plan's turns: Nav2's Regulated Pure Pursuit
  reached 40.6 % of 128 episodes in unseen places there, 95.3 % on flat floors, ``follow_path_baseline.json``);
  four unmapped obstacles, one on the plan: the map does not show them, but the global costmap's obstacle layer
  (Nav2's default) marks each once the laser sees it within 2.5 m, and the next replan goes around it.
- Reset: start and goal in the map's free space, 6-12 m apart, reachable; the goal's heading drawn.
- Observation: the plan's next 10 points 0.4 m apart in the base's frame, its length left, the turn to the goal's
  heading, the odometry's twist, the IMU (``observation="path"``: ``atrv_warp.task.spec.PATH_OBSERVATION``), then
  the scan as 16 sectors and the last three actions.
- Action: a ``/cmd_vel`` at Nav2's controller's speeds (at most 0.5 m/s and 1.9 rad/s, the robot's own where lower),
  through the base's driver at the robot's acceleration limits; one every 0.2 s at 0.5 m/s.
- Ends: Nav2's goal checker (within 0.25 m, then within 0.25 rad of the goal's heading; stateful); a wall, chassis or
  obstacle contact, or a flip; Nav2's progress checker (less than 0.5 m in 10 s); 600 steps.
- Reward: the way to go (back to the plan, then along it), shortened, x 1; -0.03 a step; a clearance cost x 0.5
  inside 0.6 m of a wall or obstacle (the ATRV-Jr's footprint and 17 cm: a corridor must not cost more than
  driving through it gains); minus the distance from the plan x 0.05; minus the turn left to the goal's heading x 0.05 once its
  position is reached; minus the distance commanded backward x 1, but within 0.5 m of the goal (Nav2's MPPI
  ``PreferForwardCritic``: the laser looks forward; with this weight, backing along the plan gains nothing, and the
  Jackal's policy trained without it met 36 of its 54 failures in 300 test episodes backing into an unmapped obstacle);
  +4 on success, -10 on failure.
"""

import dataclasses

from atrv_warp.task.config import FollowPathConfig
from atrv_warp.task.definition import Task
from atrv_warp.task.kernels.paths import goal_checked
from atrv_warp.task.scaling import control_period, scale_to_robot
from atrv_warp.task.terms import (
    ACTION_RATE,
    CLEARANCE,
    FAILURE,
    GOAL_YAW,
    PATH_OFFSET,
    PATH_PROGRESS,
    PREFER_FORWARD,
    STEP_PENALTY,
    SUCCESS,
)

CONFIG = FollowPathConfig(
    observation="path", action="twist", linear_max_acceleration=1.0, terrain="flat", target_distance=(6.0, 12.0),
    obstacles=4, obstacles_on_path=1, max_steps=600, flip_roll=0.5, scan_beams=64, scan_sectors=16, action_history=3,
    reach_radius=0.25, failure_reward=-10.0, clearance_weight=0.5, clearance_radius=0.6, path_offset_weight=0.05,
    goal_yaw_weight=0.05, prefer_forward_weight=1.0)
TERMS = (PATH_PROGRESS, STEP_PENALTY, SUCCESS, FAILURE, CLEARANCE, PATH_OFFSET, GOAL_YAW, PREFER_FORWARD,
         ACTION_RATE)


def _fit(config, robot, footprint):
    """The shipped rule (:func:`~atrv_warp.task.scaling.scale_to_robot`), but the goal checker's tolerance stays
    Nav2's, whatever the robot's size, and the controller drives at most at Nav2's controller's speeds
    (:attr:`~atrv_warp.task.config.FollowPathConfig.controller_max_linear`), its control period by the rule at that
    speed: the Jackal follows its plan at 0.5 m/s and 1.9 rad/s every 0.2 s, as the ATRV-Jr does at its 0.5 m/s."""
    fitted = scale_to_robot(config, robot, footprint)
    linear = min(fitted.max_linear, config.controller_max_linear)
    return dataclasses.replace(fitted, reach_radius=config.reach_radius, max_linear=linear,
                               max_angular=min(fitted.max_angular, config.controller_max_angular),
                               control_period=control_period(linear))


TASK = Task("follow_path", CONFIG, TERMS, goal_checked, description=__doc__.splitlines()[0], source=__file__,
            scale=_fit)
