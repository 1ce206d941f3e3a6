"""The shipped reward terms as table rows (:class:`~atrv_warp.task.definition.RewardTerm`): each names its
``@wp.func`` (:mod:`atrv_warp.task.kernels.terms`), the :class:`~atrv_warp.task.config.TaskConfig` field that weights
it, when it counts, what it reads, and its torch twin (:mod:`atrv_warp.task.reward`). A task's module picks its rows;
a task of your own adds its own beside them (``docs/your-own-task.md``).
"""

from __future__ import annotations

from atrv_warp.task import twins
from atrv_warp.task.definition import RewardTerm
from atrv_warp.task.kernels import paths
from atrv_warp.task.kernels import terms as k

__all__ = ["ACTION_RATE", "CLEARANCE", "ENERGY", "FAILURE", "GOAL_YAW", "HEADING", "PATH_OFFSET", "PATH_PROGRESS",
           "PREFER_FORWARD", "PROGRESS", "REFERENCE_TERMS", "REWARD_TERMS", "STEP_PENALTY", "SUCCESS"]

PROGRESS = RewardTerm("progress", k.progress, "progress_weight", torch=twins.progress,
                      description="the distance gained toward the target this step [m]")
HEADING = RewardTerm("heading", k.heading, "heading_weight", torch=twins.heading,
                     description="the reduction of |heading error| this step [rad]")
STEP_PENALTY = RewardTerm("step_penalty", k.step, "step_penalty", torch=twins.step,
                          description="-1 on every step that does not end the episode")
SUCCESS = RewardTerm("success", k.event, "success_reward", when="success", reads=("events",),
                     torch=twins.succeeded, description="1 on reaching the goal")
FAILURE = RewardTerm("failure", k.event, "failure_reward", when="failure", reads=("events",), torch=twins.failed,
                     description="1 on a wall, chassis or obstacle contact, a flip, or no progress (a task that "
                                 "follows a plan)")
CLEARANCE = RewardTerm("clearance", k.clearance, "clearance_weight", reads=("state", "obstacles"),
                       torch=twins.clearance,
                       description="minus how far the nearest obstacle reaches inside clearance_radius of the chassis "
                                   "origin [m]")
ACTION_RATE = RewardTerm("action_rate", k.action_rate, "action_rate_weight", reads=("action", "previous action"),
                         torch=twins.action_rate,
                         description="minus the squared change of the action since the step before")
ENERGY = RewardTerm("energy", k.energy, "energy_weight", reads=("wheels",), torch=twins.energy,
                    description="minus the motors' mechanical work this step [J]")

REFERENCE_TERMS = (PROGRESS, HEADING, STEP_PENALTY, SUCCESS, FAILURE, CLEARANCE, ACTION_RATE, ENERGY)
"""The shipped tasks' table, in column order: the reference's progress, heading, step penalty, success and failure,
then the clearance, the action rate and the energy (0 unless their weights are set)."""
REWARD_TERMS: tuple[str, ...] = tuple(t.name for t in REFERENCE_TERMS)
"""The shipped tasks' reward terms' names, in column order (their ``("reward_terms", name)`` entries)."""

# A path-following task's rows (atrv_warp.task.config.FollowPathConfig's weights). Their twin is the plan's reader,
# atrv_warp.core.path.PathTracker, held to the kernels by tests/test_follow_path.py: a rollout of poses alone has no plan.
PATH_PROGRESS = RewardTerm("path_progress", paths.path_progress, "path_progress_weight", reads=("state", "path"),
                           description="the way to go (back to the plan, then along it) shortened this step [m]")
PATH_OFFSET = RewardTerm("path_offset", paths.path_offset, "path_offset_weight", reads=("state", "path"),
                         description="minus the base's distance from the plan [m]")
GOAL_YAW = RewardTerm("goal_yaw", paths.goal_yaw, "goal_yaw_weight", reads=("state", "path"),
                      description="minus the turn left to the goal's heading [rad], once its position is reached")
PREFER_FORWARD = RewardTerm("prefer_forward", paths.prefer_forward, "prefer_forward_weight",
                            reads=("action", "state"),
                            description="minus the distance commanded backward this step [m], except near the goal "
                                        "(Nav2's MPPI PreferForwardCritic)")
