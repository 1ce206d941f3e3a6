"""Configuration of the tasks (their contract is :mod:`atrv_warp.task.spec`). The registered tasks are
:mod:`atrv_warp.task.registry`'s: the shipped ``reach`` (the reference drive-to-target task), ``nav`` (over terrain,
around obstacles, seen through the laser scanner) and ``nav_deploy`` (nav as a robot runs it, ``/cmd_vel`` at its
own limits), and any task module of yours."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from atrv_warp.sim.driver import DriverConfig

__all__ = ["FollowPathConfig", "TaskConfig"]


@dataclass(frozen=True)
class TaskConfig:
    """A drive-to-target task. The defaults are the reference task, on the flat arena."""

    spawn_bound: float = 12.0
    """Targets and starts are uniform in [-bound, bound]² [m] (arena half size - 3)."""
    reach_radius: float = 1.0
    """Success when the chassis is this close to the target [m]."""
    flip_roll: float = 0.2
    """|roll| above this is a flip [rad]."""
    max_steps: int = 200
    """Truncation after this many steps (200 × 0.05 s = 10 s)."""
    # ---- the reward table's weights (each a row of the task's table: atrv_warp.task.terms)
    progress_weight: float = 1.0
    """Weight of the progress term (distance gained toward the target) [1/m]."""
    success_reward: float = 4.0
    """Reward on reaching the goal (the episode ends)."""
    failure_reward: float = -4.0
    """Reward on a wall, chassis or obstacle contact, or a flip (the episode ends)."""
    heading_weight: float = 4.0
    """Weight of the heading-progress term (previous |error| - |error|) [1/rad]."""
    step_penalty: float = 0.03
    """Subtracted from every non-terminal reward."""
    action_rate_weight: float = 0.0
    """Weight of the action-rate term (the squared change of the action since the step before); 0: off."""
    energy_weight: float = 0.0
    """Weight of the energy term (the motors' mechanical work this step) [1/J]; 0: off."""
    clearance_weight: float = 0.0
    """Weight of the clearance term [1/m]: each non-terminal step costs this times how far the nearest obstacle's
    bounding circle reaches inside ``clearance_radius`` of the chassis origin (0: no term). A dense cost of
    passing close, which a rare collision penalty alone does not teach a policy that cannot be sure of its grip
    or its delay."""
    clearance_radius: float = 1.0
    """Distance from the chassis origin [m] inside which an obstacle costs: the ATRV-Jr's footprint reaches 0.43 m
    from it at the wheels' outer corners, so 1 m keeps a margin of about 0.6 m (on another robot, the same margin
    over its footprint: :mod:`atrv_warp.task.scaling`)."""
    action_scale: float = 20.0
    """Wheel torque per unit action [N·m] (``action="torque"``). On a robot, its motor's torque limit (the ATRV-Jr's
    20 N·m)."""
    action: str = "torque"
    """What the policy commands (:data:`atrv_warp.task.spec.ACTIONS`): ``"torque"``, each side's wheel torque (the
    reference), or ``"twist"``, a ``/cmd_vel`` (forward speed, yaw rate) through the base's motor driver."""
    max_linear: float = 2.0
    """Forward speed at action 1 [m/s] (``action="twist"``). On a robot, its own ``linear.x.max_velocity``
    (:mod:`atrv_warp.task.scaling`); 2 m/s is the speed the twist tasks were shaped at (the Jackal J100's limit)."""
    max_angular: float = 2.0
    """Yaw rate at action 1 [rad/s] (``action="twist"``). On a robot, its own ``angular.z.max_velocity``."""
    linear_max_acceleration: float | None = None
    """The base's ``linear.x.max_acceleration`` [m/s²] (``action="twist"``; ``None``: no limit): the task's
    :class:`~atrv_warp.sim.driver.DriverConfig` takes it where its own is unset (:meth:`driver`), and an exported
    policy's contract carries it for the robot's base. Without it the driver meets a full-speed command with its
    full torque: the wheels spin, and the encoders' distance runs ahead of the rover's (docs/tasks.md). On a robot,
    its own (:mod:`atrv_warp.task.scaling`)."""
    angular_max_acceleration: float | None = None
    """The base's ``angular.z.max_acceleration`` [rad/s²] (``None``: no limit), as ``linear_max_acceleration``."""
    control_period: float | None = None
    """The control period [s]: one step of the environment (``None``: the simulator's ``step_dt``, 0.05 s). The rule
    that fits a task to its robot (:mod:`atrv_warp.task.scaling`) sets it for a twist task on a robot slower than
    2 m/s, so that a step covers the same distance."""
    observation: str = "arena"
    """What the policy observes (:data:`atrv_warp.task.spec.OBSERVATION_KINDS`): ``"arena"``, positions and
    velocities in the arena's frame (the reference), or ``"robot"``, only what a robot's stack publishes (goal from
    wheel odometry, odometry twist, IMU, scan)."""

    # ---- the scene: terrain, obstacles, scanner (the reference has none of them)
    terrain: str = "flat"
    """Terrain preset (:data:`atrv_warp.sim.terrain.TERRAIN_PRESETS`); each episode draws one of its tiles."""
    target_distance: tuple[float, float] | None = None
    """Start-to-target distance range [m]; ``None``: start and target drawn independently (the reference)."""
    obstacles: int = 0
    """Obstacles per episode (upright boxes and cylinders)."""
    obstacles_on_path: int = 0
    """How many of them stand across the straight line from start to target (at 35–65 % of it,
    within ``path_offset`` of it), so that driving straight at the target runs into them."""
    path_offset: float = 0.4
    """Largest sideways offset of an on-path obstacle's centre from the straight line [m]."""
    obstacle_size: tuple[float, float] = (0.3, 0.6)
    """Range of cylinder radii and box half sides [m]."""
    clearance: float = 1.0
    """No obstacle's bounding circle comes closer than this to the start or the target [m]. (In a map, none comes
    closer to a wall than the robot's circumscribed diameter: a way round it.)"""
    scan_beams: int = 0
    """Scanner beams (0: no scanner). The full scan is the step's ``scan`` entry [m]."""
    scan_fov: float = math.pi
    """The scanner's field of view [rad], centred on its +x (a SICK LMS 2xx: 180 deg)."""
    scan_sectors: int = 0
    """Observed scan: the nearest return in each of this many equal sectors, as min(range, scan_clip) /
    scan_clip in [0, 1]; the sectors' edges are :func:`atrv_warp.task.spec.scan_sectors`'s, and
    ``scan_beams`` must be a multiple of it (so each sector holds as many of the scanner's beams)."""
    scan_clip: float = 5.0
    """Ranges beyond this [m] are observed as 1."""
    action_history: int = 0
    """The actions chosen at the last this-many steps, newest first, observed after the scan: what a rover
    with action latency has commanded but not yet applied (Isaac Lab's ``last_action`` term)."""

    def __post_init__(self):
        from atrv_warp.task.spec import ACTIONS, BASE_LIMITS, OBSERVATION_KINDS

        if self.action not in ACTIONS:
            raise ValueError(f"TaskConfig.action={self.action!r} is not an action kind; known: {sorted(ACTIONS)}")
        if self.observation not in OBSERVATION_KINDS:
            raise ValueError(f"TaskConfig.observation={self.observation!r} is not an observation kind; known: "
                             f"{sorted(OBSERVATION_KINDS)}")
        for f in dataclasses.fields(self):  # every number finite, every count whole and not negative
            value = getattr(self, f.name)
            for part in value if isinstance(value, tuple) else (value,):
                if isinstance(part, float) and not math.isfinite(part):
                    raise ValueError(f"TaskConfig.{f.name} must be finite, got {value!r}")
                if isinstance(part, int) and not isinstance(part, bool) and part < 0:
                    raise ValueError(f"TaskConfig.{f.name} must be >= 0, got {value!r}")
        for name in ("spawn_bound", "reach_radius", "flip_roll", "max_steps", "scan_fov", "scan_clip"):
            if not getattr(self, name) > 0:
                raise ValueError(f"TaskConfig.{name} must be > 0, got {getattr(self, name)!r}")
        limits = [name for name, _ in BASE_LIMITS if getattr(self, name) is not None]
        for name in ("max_linear", "max_angular", "action_scale", *limits):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"TaskConfig.{name} must be a finite number > 0, got {value!r}")
        if self.control_period is not None and not (isinstance(self.control_period, int | float)
                                                    and not isinstance(self.control_period, bool)
                                                    and math.isfinite(self.control_period) and self.control_period > 0):
            raise ValueError(f"TaskConfig.control_period must be a finite number > 0 [s] or None, got "
                             f"{self.control_period!r}")
        if self.observation == "path" and not hasattr(self, "path_search"):
            raise ValueError("TaskConfig.observation='path' follows a plan: its config is a FollowPathConfig (the goal "
                             "and progress checkers' settings)")
        if self.scan_sectors and (self.scan_beams % self.scan_sectors or self.scan_sectors < 0):
            raise ValueError(f"scan_beams={self.scan_beams} must be a multiple of scan_sectors={self.scan_sectors}")
        if self.obstacles_on_path > self.obstacles or self.obstacles < 0:
            raise ValueError(f"need 0 <= obstacles_on_path <= obstacles, got {self.obstacles_on_path}, "
                             f"{self.obstacles}")
        lo, hi = self.obstacle_size
        if not 0 < lo <= hi:
            raise ValueError(f"obstacle_size must be 0 < low <= high, got {self.obstacle_size}")
        if self.action_history < 0:
            raise ValueError(f"action_history must be >= 0 steps, got {self.action_history}")
        if self.clearance_weight < 0 or self.clearance_radius < 0:
            raise ValueError(f"clearance_weight and clearance_radius must be >= 0, got {self.clearance_weight}, "
                             f"{self.clearance_radius}")
        if self.target_distance is not None and not 0 < self.target_distance[0] <= self.target_distance[1]:
            raise ValueError(f"target_distance must be 0 < low <= high, got {self.target_distance}")

    def driver(self, driver: DriverConfig | None = None) -> DriverConfig:
        """The base's motor driver for this task: ``driver`` (default: :class:`~atrv_warp.sim.driver.DriverConfig`'s
        defaults) with the task's limits (:data:`~atrv_warp.task.spec.BASE_LIMITS`) where it sets none."""
        from atrv_warp.sim.driver import DriverConfig
        from atrv_warp.task.spec import BASE_LIMITS

        driver = driver or DriverConfig()
        limits = {name: getattr(self, name) for name, _ in BASE_LIMITS
                  if getattr(self, name) is not None and getattr(driver, name) is None}
        return dataclasses.replace(driver, **limits) if limits else driver


@dataclass(frozen=True)
class FollowPathConfig(TaskConfig):
    """A task that follows Nav2's plan to its goal (``observation="path"``): the goal is reached as Nav2's
    ``SimpleGoalChecker`` judges it (``reach_radius`` and :attr:`yaw_tolerance`, stateful), and an episode fails
    where the robot makes no progress as its ``SimpleProgressChecker`` judges it. Its worlds are maps, planned over by
    :mod:`atrv_warp.sim.planner`."""

    yaw_tolerance: float = 0.25
    """The goal checker's ``yaw_goal_tolerance`` [rad]: once within ``reach_radius`` of the goal (which it then keeps,
    stateful), the goal is reached when the base's heading is this close to the goal's."""
    progress_radius: float = 0.5
    """The progress checker's ``required_movement_radius`` [m]."""
    progress_time: float = 10.0
    """Its ``movement_time_allowance`` [s]: an episode whose robot stays within :attr:`progress_radius` of where it
    last moved that far for this long ends, a failure (``no_progress``)."""
    path_search: float = 2.0
    """How far along the plan past the last nearest point the next is searched for [m] (Nav2's
    ``max_robot_pose_search_dist``)."""
    path_progress_weight: float = 1.0
    """Weight of the path-progress term (the way to go shortened this step: the distance back to the plan plus the
    plan's length left from there) [1/m]."""
    path_offset_weight: float = 0.0
    """Weight of the path-offset term (minus the base's distance from the plan) [1/m]; 0: off."""
    goal_yaw_weight: float = 0.0
    """Weight of the goal-heading term (minus the heading left to turn, once the goal's position is reached)
    [1/rad]; 0: off."""
    prefer_forward_weight: float = 0.0
    """Weight of the prefer-forward term (minus the distance commanded backward this step, Nav2's MPPI
    ``PreferForwardCritic``: the laser looks forward, so reversing is blind) [1/m]; 0: off."""
    prefer_forward_threshold: float = 0.5
    """Within this distance of the goal the prefer-forward term is off, so the robot may back into the goal's pose
    [m] (the critic's ``threshold_to_consider``, default 0.5 m: ros-navigation/navigation2@0cf04629
    ``nav2_mppi_controller/src/critics/prefer_forward_critic.cpp``)."""
    controller_max_linear: float = 0.5
    """The fastest the controller drives [m/s], below the robot's own limit where that is higher: Nav2's controller
    indoors (Clearpath's Nav2 configuration of the Jackal J100 and the Husky A200, MPPI's ``vx_max: 0.5``,
    clearpathrobotics/clearpath_nav2_demos@0ce927b4 ``config/j100/nav2.yaml`` and @9ed975c5 ``config/a200/nav2.yaml``;
    the ATRV-Jr's DWB ``max_vel_x``; Regulated Pure Pursuit's default ``desired_linear_vel``). The base's own limits
    stay the velocity smoother's; the control period follows this speed (:func:`atrv_warp.task.scaling.control_period`).
    The task's fit reads it: a run's ``env.task.`` override, applied after the fit, sets ``max_linear`` instead."""
    controller_max_angular: float = 1.9
    """The fastest the controller turns [rad/s], below the robot's own limit where that is higher (the same files'
    MPPI ``wz_max: 1.9``)."""
    obstacle_layer: bool = True
    """The plan comes from a global costmap with Nav2's obstacle layer (its default ``plugins``: static, obstacle,
    inflation): an unmapped obstacle the laser has seen is marked, and the next replan goes around it
    (:attr:`~atrv_warp.sim.planner.PlannerConfig.obstacle_layer`). False: the plan is over the map alone, through
    what the map does not show. The env's ``planner``, where given, decides instead."""

    def __post_init__(self):
        super().__post_init__()
        if self.observation != "path":
            raise ValueError(f"FollowPathConfig.observation must be 'path' (it follows a plan), got {self.observation!r}")
        for name in ("yaw_tolerance", "progress_radius", "progress_time", "path_search", "controller_max_linear",
                     "controller_max_angular", "prefer_forward_threshold"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FollowPathConfig.{name} must be > 0, got {getattr(self, name)!r}")
