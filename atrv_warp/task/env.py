"""TorchRL environment: N rovers of one robot driving to targets, one batched ``EnvBase``.

The task math (observations, rewards, terminations, reset sampling) runs in Warp kernels,
one thread per world (``atrv_warp/task/kernels/``); TensorDicts carry zero-copy views
of the Warp buffers, cloned only where TorchRL would otherwise keep a reference to a buffer
the next step overwrites.

Actions (N, 2) in [-1, 1]: wheel torques (``action="torque"``), or a /cmd_vel through each world's motor driver
(``action="twist"``, :data:`~atrv_warp.task.spec.ACTIONS`).

Keys produced (the contract is declared in :mod:`atrv_warp.task.spec`):
    ``observation`` (N, obs_dim) float32: target x, y; rover x, y; vx, vy (world); roll; yaw rate;
    sin and cos of the heading error (``OBSERVATION``), or with ``observation="robot"`` the goal's distance and
    bearing from wheel odometry, the odometry's twist and the IMU's roll, pitch and yaw rate
    (``ROBOT_OBSERVATION``); then the sensors' fields (a task's scan sectors) and its last actions
    (``observation_fields``). Each sensor's full reading under its name (:mod:`atrv_warp.task.sensors`): ``scan``
    (N, beams) [m] with a scanner. ``reward`` (N, 1);
    ``("reward_terms", name)`` (N, 1) for each of the task's reward terms (``env.task.term_names``), which sum to the
    reward;
    ``done`` / ``terminated`` / ``truncated`` (N, 1) bool; ``end_reason`` (N, 1) int64
    (``EndReason``, named by :data:`END_REASONS`); ``distance`` (N, 1) distance to the target [m].
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import torch
import warp as wp
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from atrv_warp.runtime import pin_to_core
from atrv_warp.sim.config import (
    ArenaConfig,
    ContactConfig,
    ObstacleConfig,
    RoverConfig,
    SimConfig,
    nominal_rover_config,
)
from atrv_warp.sim.driver import DRIVE_TWIST, DriverConfig
from atrv_warp.sim.kernel_cache import precompile
from atrv_warp.sim.planner import Planner, PlannerConfig
from atrv_warp.sim.simulator import RoverSim
from atrv_warp.task.config import TaskConfig
from atrv_warp.task.definition import Task
from atrv_warp.task.kernels.observe import (
    clear_actions,
    observe_reset,
    observe_step,
    record_actions,
    write_action_observation,
)
from atrv_warp.task.kernels.paths import FOLLOW_OBSERVE, FOLLOW_RESET, FOLLOW_STEP, follow_paths
from atrv_warp.task.kernels.randomization import (
    DRAW_COUNT,
    HISTORY,
    MODE_CODES,
    PHASE_EPISODE,
    PHASE_TICK,
    ActionDelay,
    DrawSpec,
    ObservationNoise,
    add_observation_noise,
    add_robot_observation_noise,
    delay_actions,
    delay_twist,
    draw_physics,
)
from atrv_warp.task.kernels.sampling import (
    PinnedWorlds,
    locate_goals,
    place_on_plans,
    sample_episodes,
    sample_nav_episodes,
)
from atrv_warp.task.kernels.state import PathState, RoverState, StepOutputs, TaskBuffers, TermInputs, params_of
from atrv_warp.task.kernels.steps import advance_odometry_drift, command_twist, sum_terms
from atrv_warp.task.kernels.tables import ends_kernel, field_kernel, term_kernels
from atrv_warp.task.randomization import PHYSICS_DRAWS, AroundConfig, RandomizationConfig, get_randomization
from atrv_warp.task.registry import load_task_module, resolve_task
from atrv_warp.task.scaling import fit_task
from atrv_warp.task.sensors import LaserSensor, build_sensors
from atrv_warp.task.spec import (
    ACTION_DIM,
    ACTIONS,
    END_REASONS,
    OBSERVATION_KINDS,
    OBSERVATION_NAMES,
    action_to_torque,
    observation_bounds,
    observation_fields,
    scan_sectors,
)
from atrv_warp.world import OccupancyMap

__all__ = ["END_REASONS", "OBSERVATION_NAMES", "SNAPSHOT_FORMAT", "TASK_SNAPSHOT_ADDED", "ATRVjrEnv", "EnvFactory",
           "RoverEnv"]

PATH_STATE = ("segment", "point", "remaining", "prev_to_go", "offset", "reached", "stalled", "baseline", "since",
              "clearance")
"""How each world follows its plan (:class:`~atrv_warp.task.kernels.state.PathState`), a snapshot's ``path_*``
entries."""

TASK_SNAPSHOT_ADDED = ("obstacle_height", "path", "path_length")
"""Task entries of a snapshot that a snapshot of an earlier version lacks: each obstacle's height (restored as the
config's, which every obstacle had then) and each world's plan (planned again from where the rovers are)."""

SNAPSHOT_FORMAT = 3
"""Version of :meth:`RoverEnv.state_dict`'s snapshot (3: everything the next step reads, restored bit for bit, the
reward terms' memory of the last action and the goal's heading included)."""

ODOM_COLUMN = {kind: [f.name for f in OBSERVATION_KINDS[kind]].index("odom_linear") for kind in ("robot", "path")}
"""Where the robot's twist and IMU fields start in the observation kinds that have them (the same five, in one
order: ``atrv_warp.task.kernels.paths`` holds it)."""

OBSERVE_KINDS = {"arena": 0, "robot": 1, "path": 2}
"""The leading fields the shipped observation kernels write (:mod:`atrv_warp.task.kernels.observe`; the path
observation's, :func:`~atrv_warp.task.kernels.paths.follow_paths`); any other kind is a task's own, written field by
field (:func:`~atrv_warp.task.kernels.tables.field_kernel`)."""


def _torch_device(device: wp.context.Device) -> torch.device:
    return torch.device("cpu") if device.is_cpu else torch.device(f"cuda:{device.ordinal}")


class RoverEnv(EnvBase):
    """N skid-steer rovers learning to drive to a target (the reference RL task), on any robot
    (:class:`ATRVjrEnv`, its name before robots had files, is this class).

    Args:
        num_envs: Number of worlds (the batch size).
        device: ``"cpu"`` (default) or a CUDA device; the simulator runs there.
        seed: Seed of the per-world reset streams (and the sensors' noise); ``None`` leaves seed 0.
        robot: A shipped robot's name (``"atrvjr"``, ``"jackal"``, ``"husky"``) or a robot file's path; ``None``:
            ``rover``'s robot, else the ATRV-Jr. The task is fitted to it (:meth:`Task.for_robot
            <atrv_warp.task.definition.Task.for_robot>`: its limits, a control period for its speed, radii for its
            footprint) and so is a randomization preset (:func:`~atrv_warp.task.randomization.scale_preset`).
        variant: Registered ATRV-Jr variant.
        task: A registered task's name (``"reach"``, the default, ``"nav"``, ``"nav_deploy"``, or one of yours:
            :mod:`atrv_warp.task.registry`), a :class:`~atrv_warp.task.definition.Task`, or a :class:`TaskConfig`
            (the shipped reward table, weighted by its fields; taken as it is, not fitted to the robot); keyword
            overrides of its config via ``**task_overrides`` (after the fit).
        task_module: A Python file that registers tasks of your own (:func:`~atrv_warp.task.registry.load_task_module`),
            loaded before ``task`` is looked up (so that a collector's worker process finds it too).
        rover: Rover configuration (see :class:`RoverSim`).
        contact: Contact law (see :class:`RoverSim`).
        arena: Arena geometry (see :class:`RoverSim`).
        sim: Integrator settings (see :class:`RoverSim`).
        randomization: Domain randomization: a preset name (``"none"``, ``"mild"``, ``"wide"``; ``"around"``,
            centred on ``sim_config``) or a :class:`~atrv_warp.task.randomization.RandomizationConfig` (or
            :class:`~atrv_warp.task.randomization.AroundConfig`); ``None``: none (the nominal rover, perfect
            sensors, no delay, bit for bit as without it). One centred on ``sim_config`` is resolved against it
            before the simulator is built (a parameter it draws that the file does not set stops here).
        sim_config: A simulator-config TOML file (see :class:`RoverSim`), e.g. ``atrv-calibrate``'s
            calibration of a real rover.
        driver: The base's motor driver (:class:`~atrv_warp.sim.driver.DriverConfig`), which velocity actions
            go through (see :class:`RoverSim`); the task's acceleration limits fill in those it leaves unset
            (:meth:`TaskConfig.driver`).
        maps: Sites as Nav2 maps (see :class:`RoverSim`), world ``w`` in map ``w % len(maps)``. Each episode there
            starts and ends in the map's free space, clear of the robot's footprint, the target reachable from the
            start (``target_distance`` away where the map allows; obstacles anywhere on the map); the clearance term
            reads its walls. ``()``: the arena.
        planner: Nav2's global planner in the loop, in the worlds with a map (:mod:`atrv_warp.sim.planner`): each
            reset plans the episode's path from its start to its target (an episode without one is drawn again,
            :attr:`~atrv_warp.sim.planner.PlannerConfig.redraws` times at most) and stands the task's
            ``obstacles_on_path`` on it (unseen by the planner), and each world plans again from its robot's pose
            every :attr:`~atrv_warp.sim.planner.PlannerConfig.replan_period`; :attr:`path` and :attr:`path_length`
            hold them. ``None``: no planner (a task that follows a plan, ``observation="path"``: ``PlannerConfig()``
            with the task's :attr:`~atrv_warp.task.config.FollowPathConfig.obstacle_layer`; it needs ``maps``).
        **task_overrides: Fields of :class:`TaskConfig` (e.g. ``max_steps=100``); an unknown
            name raises ``ValueError``.
    """

    batch_locked = True

    def __init__(
        self,
        num_envs: int = 1,
        *,
        device: str = "cpu",
        seed: int | None = None,
        robot: str | None = None,
        variant: str = "realistic",
        task: Task | TaskConfig | str | None = None,
        task_module: str | None = None,
        rover: RoverConfig | None = None,
        contact: ContactConfig | None = None,
        arena: ArenaConfig | None = None,
        sim: SimConfig | None = None,
        randomization: RandomizationConfig | AroundConfig | str | None = None,
        sim_config: str | None = None,
        driver: DriverConfig | None = None,
        maps: Sequence[OccupancyMap | str | Path] = (),
        planner: PlannerConfig | None = None,
        **task_overrides,
    ):
        if task_module:
            load_task_module(task_module)
        rover = nominal_rover_config(robot, variant, rover)
        self.robot = rover.robot_spec
        """The robot (:class:`~atrv_warp.core.robot.Robot`)."""
        self.task = fit_task(resolve_task(task), rover).with_config(**task_overrides)
        """The task (:class:`~atrv_warp.task.definition.Task`) fitted to the robot: its config, reward table, success
        test."""
        self.task_cfg = c = self.task.config
        if c.control_period is not None:
            sim = dataclasses.replace(sim or SimConfig(), step_dt=c.control_period)
        self.randomization = get_randomization(randomization, sim_config=sim_config, rover=rover, contact=contact)
        """What each world randomizes (:class:`~atrv_warp.task.randomization.RandomizationConfig`), in absolute
        ranges (one centred on ``sim_config``, resolved)."""
        self.sim = RoverSim(num_envs, rover=rover, contact=contact, arena=arena, sim=sim,
                            terrain=c.terrain, obstacles=ObstacleConfig(slots=c.obstacles) if c.obstacles else None,
                            device=device, sim_config=sim_config, driver=c.driver(driver), maps=maps)
        self.sensors = build_sensors(self.sim, c, self.robot, self.randomization.noise)
        """The rovers' sensors that the task uses (:mod:`atrv_warp.task.sensors`), in the order they are observed."""
        laser = next((s for s in self.sensors if isinstance(s, LaserSensor) and s.name == "scan"), None)
        self.scanner = laser.scanner if laser is not None else None
        """The robot's laser scanner (``links.laser``; :class:`~atrv_warp.sim.scanner.LaserScanner`), if the task has
        one: the scan its reward terms read."""
        super().__init__(device=_torch_device(self.sim.device), batch_size=torch.Size([num_envs]))
        self.num_envs = num_envs
        self._sensor_fields = tuple(f for sensor in self.sensors for f in sensor.fields)
        self.obs_dim = len(observation_fields(c, self._sensor_fields))
        self._robot = c.observation == "robot"
        self._paths = c.observation == "path"
        if self._paths and not self.sim.maps.maps:
            raise ValueError(f"task {self.task.name!r} follows Nav2's plan over a map: give it maps (maps=[...] here, "
                             "--map on the commands: a Nav2 map's YAML or a procedural place, e.g. building:16)")
        if self._paths and planner is None:
            planner = PlannerConfig(obstacle_layer=c.obstacle_layer)
        self._twist = c.action == "twist"
        self._observe_kind = OBSERVE_KINDS.get(c.observation, -1)  # -1: the task's own fields
        self._lead_dim = len(OBSERVATION_KINDS[c.observation])  # the columns before the sensors' fields
        self._nav = (c.target_distance is not None or c.obstacles > 0 or self.sim.terrain.enabled
                     or bool(self.sim.maps.maps))
        self._wp_device = self.sim.device
        self._make_task_buffers()
        self._make_task_kernels()
        precompile(self.sim.device)  # the task's own kernels (its reward terms, its ends), with the simulator's
        self._make_views()
        self._make_randomization()
        self._make_spec()
        self._make_planner(planner)
        self.nonfinite_count = 0
        """Worlds terminated and reset because their state stopped being finite."""
        self._seed = 0
        self._set_seed(seed)

    # ------------------------------------------------------------------ set-up
    def _make_task_buffers(self) -> None:
        """The task's per-world buffers and a step's outputs, allocated once."""
        n, dev, c = self.num_envs, self._wp_device, self.task_cfg
        t = TaskBuffers()
        for name in ("target", "goal_odom"):
            setattr(t, name, wp.zeros(n, dtype=wp.vec2, device=dev))
        for name in ("target_yaw", "prev_distance", "prev_heading_error", "distance", "heading_error",
                     "odom_slip_gain"):
            setattr(t, name, wp.zeros(n, dtype=float, device=dev))
        t.step_count = wp.zeros(n, dtype=wp.int32, device=dev)
        t.episode = wp.zeros(n, dtype=wp.int32, device=dev)
        t.stream = wp.array(list(range(n)), dtype=wp.int32, device=dev)
        t.odom_drift = wp.zeros(n, dtype=wp.vec3, device=dev)
        t.odom_scale = wp.ones(n, dtype=float, device=dev)
        t.prev_action = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._task = t
        path = PathState()  # the planner's paths replace the placeholders (_make_planner)
        path.points = wp.zeros((n, 1), dtype=wp.vec2, device=dev)
        path.length = wp.zeros(n, dtype=wp.int32, device=dev)
        for name in ("segment", "reached", "stalled", "since"):
            setattr(path, name, wp.zeros(n, dtype=wp.int32, device=dev))
        for name in ("remaining", "prev_to_go", "offset", "clearance"):
            setattr(path, name, wp.zeros(n, dtype=float, device=dev))
        path.baseline = wp.zeros(n, dtype=wp.vec2, device=dev)
        path.point = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._path_state = path
        out = StepOutputs()
        out.obs = self._obs = wp.zeros((n, self.obs_dim), dtype=float, device=dev)
        out.reward = self._reward = wp.zeros(n, dtype=float, device=dev)
        out.reward_terms = self._reward_terms = wp.zeros((n, len(self.task.terms)), dtype=float, device=dev)
        out.terminated = self._terminated = wp.zeros(n, dtype=bool, device=dev)
        out.truncated = self._truncated = wp.zeros(n, dtype=bool, device=dev)
        out.end_reason = self._end_reason = wp.zeros(n, dtype=wp.int32, device=dev)
        out.distance = self._distance = wp.zeros(n, dtype=float, device=dev)
        self._out = out
        self._mask = wp.zeros(n, dtype=bool, device=dev)
        pins = PinnedWorlds()
        pins.pinned = wp.zeros(n, dtype=bool, device=dev)
        pins.start = wp.zeros(n, dtype=wp.vec3, device=dev)
        pins.target = wp.zeros(n, dtype=wp.vec2, device=dev)
        pins.target_yaw = wp.zeros(n, dtype=float, device=dev)
        pins.tile = wp.zeros(n, dtype=wp.int32, device=dev)
        slots = self.sim.obstacles.kernel.kind.shape[1]
        pins.kind = wp.zeros((n, slots), dtype=wp.int32, device=dev)
        pins.pose = wp.zeros((n, slots), dtype=wp.vec3, device=dev)
        pins.size = wp.zeros((n, slots), dtype=wp.vec2, device=dev)
        pins.height = wp.zeros((n, slots), dtype=float, device=dev)
        self._pins = pins
        self._pinned_t = wp.to_torch(pins.pinned)
        self._reset_poses = wp.zeros(n, dtype=wp.vec3, device=dev)  # the sampler's starts (x, y, yaw)
        # the last actions, newest first ([left, right] in [-1, 1]), observed after the sensors' fields
        self._actions = wp.zeros((n, c.action_history), dtype=wp.vec2, device=dev) if c.action_history else None
        self._action = wp.zeros((n, 2), dtype=float, device=dev)  # this step's action, as the reward terms read it
        if self._twist:  # every world drives by velocity, through the driver
            self.sim.driver.mode.fill_(int(DRIVE_TWIST))

    def _make_task_kernels(self) -> None:
        """The kernels' inputs (the simulator's state, the task's buffers, the config's values), once, and the task's
        own kernels: its ends, its reward terms, its observation fields."""
        b, rover, c = self.sim.buffers, RoverState(), self.task_cfg
        rover.body_q, rover.lin_vel, rover.ang_vel, rover.rpy = b.body_q, b.lin_vel, b.ang_vel, b.rpy
        rover.bodies_per_world, rover.chassis_body = b.layout.bodies_per_world, b.layout.chassis_body
        rover.contact_flags, rover.nonfinite = b.contact_flags, b.nonfinite
        rover.wheel_speed, rover.wheel_torque = b.wheel_speed, b.wheel_torque
        # the goal is seen from the base's fused odometry (encoders along the gyro's heading, as robot_localization
        # gives it): skid-steer wheel odometry alone loses its heading on every turn
        rover.odometry, rover.odom_twist = self.sim.driver.state.fused, self.sim.driver.state.odom_twist
        self._rover = rover
        inputs = TermInputs()
        inputs.rover, inputs.task, inputs.obstacles = rover, self._task, self.sim.obstacles.kernel
        inputs.maps = self.sim.maps.struct
        inputs.path = self._path_state
        inputs.action = self._action
        inputs.scan = self.scanner.buffer if self.scanner is not None else wp.zeros((self.num_envs, 1), dtype=float,
                                                                                    device=self._wp_device)
        inputs.end_reason, inputs.terminated = self._end_reason, self._terminated
        inputs.step_dt = self.sim.sim_cfg.step_dt
        self._inputs = inputs
        self._params = params_of(c)
        """The task config's values, as the kernels take them (:func:`~atrv_warp.task.kernels.state.params_of`)."""
        self._ends = ends_kernel(self.task.success)
        self._terms = term_kernels(self.task)
        fields = OBSERVATION_KINDS[c.observation]
        self._fields = [] if self._observe_kind >= 0 else [
            field_kernel(f.warp, i, -f.bound, f.bound) for i, f in enumerate(fields)]
        self._target_distance = wp.vec2(*(c.target_distance or (c.reach_radius, 2.0 * c.spawn_bound)))
        self._tiles = self.sim.terrain.grid.tiles if self.sim.terrain.enabled else 1
        self._passage = 2.0 * float(self.sim.footprint_radii[1])  # beside an unmapped obstacle: room to turn in
        self.scan_sectors = scan_sectors(c)
        """The observed scan's sectors (:class:`~atrv_warp.core.scan.ScanSectors`; ``None`` without them)."""

    def _make_views(self) -> None:
        """Torch views of the buffers (no copies), and the task's state a snapshot holds."""
        n, t = self.num_envs, self._task
        self.target = wp.to_torch(t.target)
        self.step_count = wp.to_torch(t.step_count)
        self.target_distance = wp.to_torch(self._distance)
        """(N,) chassis-to-target distance [m] after the last reset, step or :meth:`observe` (a view)."""
        self.target_yaw = wp.to_torch(t.target_yaw)
        """(N,) each episode's goal heading [rad], drawn on reset (a task that parks observes and judges it; a view)."""
        self._obs_t = wp.to_torch(self._obs)
        self._reward_t = wp.to_torch(self._reward).unsqueeze(-1)
        self._reward_terms_t = wp.to_torch(self._reward_terms)
        self._terminated_t = wp.to_torch(self._terminated).unsqueeze(-1)
        self._truncated_t = wp.to_torch(self._truncated).unsqueeze(-1)
        self._end_reason_t = wp.to_torch(self._end_reason).unsqueeze(-1)
        self._distance_t = wp.to_torch(self._distance).unsqueeze(-1)
        self._mask_t = wp.to_torch(self._mask)
        self._episode_t = wp.to_torch(t.episode)
        self._stream_t = wp.to_torch(t.stream)
        self._action_t = wp.to_torch(self._action)
        self._prev_action_t = wp.to_torch(t.prev_action).view(n, 2)
        self.goal_odom = wp.to_torch(t.goal_odom).view(n, 2)
        """(N, 2) each world's target in its odometry frame (the episode's start pose: the driver's
        ``odometry`` and ``fused`` origin) [m], from which the robot observation's goal is seen (a view)."""
        self.episode_start = wp.to_torch(self._reset_poses).view(n, 3)
        """(N, 3) each world's episode start as its sampler drew it (x [m], y [m], yaw [rad]): the origin of the
        odometry frame its robot observation sees the goal in (``goal_odom``), where the driver's odometry starts;
        the chassis rests there, settled onto the terrain (a view)."""
        self.odom_drift = wp.to_torch(t.odom_drift).view(n, 3)
        """(N, 3) the robot observation's odometry drift this episode (x [m], y [m], yaw [rad]; zero without
        sensor noise or ``odom_slip_gain``): the goal is observed from ``sim.driver.fused`` (its position scaled by ``odom_scale``) plus
        ``odom_drift`` (a view)."""
        self.odom_scale = wp.to_torch(t.odom_scale)
        """(N,) the robot observation's odometry distance per distance driven this episode (1 unless the
        randomization draws :attr:`~atrv_warp.task.randomization.RandomizationConfig.odometry_scale`; a view)."""
        self.odom_slip_gain = wp.to_torch(t.odom_slip_gain)
        """(N,) how much further the robot observation's odometry runs per metre the encoders slip this episode (0
        unless the randomization draws
        :attr:`~atrv_warp.task.randomization.RandomizationConfig.odometry_slip_gain`; a view)."""
        self._task_views = {
            "target": self.target, "target_yaw": self.target_yaw, "prev_distance": wp.to_torch(t.prev_distance),
            "prev_heading_error": wp.to_torch(t.prev_heading_error), "step_count": self.step_count,
            "episode": self._episode_t, "observation": self._obs_t, "prev_action": self._prev_action_t,
        }
        if self._actions is not None:
            self._task_views["action_history"] = wp.to_torch(self._actions)
        if self._robot:
            self._task_views.update({"goal_odom": self.goal_odom, "odom_drift": self.odom_drift,
                                     "odom_scale": self.odom_scale, "odom_slip_gain": self.odom_slip_gain})
        if self._nav:  # the episode's layout is part of the task's state
            obstacles = self.sim.obstacles
            self._task_views.update({"tile": self.sim.terrain.tile, "obstacle_kind": obstacles.kind,
                                     "obstacle_pose": obstacles.pose, "obstacle_size": obstacles.size,
                                     "obstacle_height": obstacles.height})

    def _make_planner(self, cfg: PlannerConfig | None) -> None:
        """Nav2's global planner over the worlds' maps, where asked for and there are maps."""
        self.planner = None
        """The worlds' global planner (:class:`~atrv_warp.sim.planner.Planner`), or ``None``."""
        self.path = self.path_length = self.path_remaining = self.clearance = None
        self.replanned = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        """(N,) the worlds whose plan was searched again in the last step (every ``replan_period``; a reset plans
        too): what a controller is handed anew, e.g. the ROS simulator node's ``plan`` topic."""
        if cfg is None or not self.sim.maps.maps:
            return
        self.planner = Planner(self.sim.maps, self.sim.footprint_radii, cfg, obstacles=self.sim.obstacles.kernel)
        self.path, self.path_length = self.planner.path, self.planner.path_length
        """(N, max_points, 2) each world's last plan [m], start to target, in its first ``path_length`` (N,) rows (0:
        none; a world without a map has none)."""
        self._mapped = torch.as_tensor(self.sim.maps.world_map >= 0, device=self.device)
        self._replan_steps = round(cfg.replan_period / self.sim.sim_cfg.step_dt) if cfg.replan_period else 0
        self._plan_from = torch.zeros(self.num_envs, 2, device=self.device)  # where a path task's robots were a step ago
        self._path_state.points = wp.from_torch(self.path, dtype=wp.vec2)
        self._path_state.length = wp.from_torch(self.path_length)
        self._inputs.path = self._path_state  # a struct member holds a copy: set it again
        self._task_views.update({"path": self.path, "path_length": self.path_length})
        if self._paths:
            self._task_views.update({f"path_{name}": wp.to_torch(getattr(self._path_state, name))
                                     for name in PATH_STATE})
            self.path_remaining = self._task_views["path_remaining"]
            """(N,) a path task's plan length left from its robot's nearest point on it [m] (a view)."""
            self.clearance = self._task_views["path_clearance"]
            """(N,) a path task's robot's distance from its chassis origin to the nearest wall cell or obstacle
            surface after the last reset or step [m] (a view)."""

    def _plan_episodes(self) -> None:
        """The resetting worlds' paths from their starts to their targets; an episode without one drawn again."""
        worlds = torch.nonzero(self._mask_t.reshape(-1) & self._mapped).flatten()
        self.planner.forget(self._mask_t)  # a new episode's costmap has marked nothing yet
        for attempt in range(self.planner.cfg.redraws + 1):
            self.planner.plan(worlds, self.episode_start[:, :2], self.target)
            worlds = worlds[(self.path_length[worlds] == 0) & ~self._pinned_t[worlds]]  # a given layout stays
            if not len(worlds) or attempt == self.planner.cfg.redraws:
                break
            redraw = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
            redraw[worlds] = True
            wp.launch(sample_nav_episodes, dim=self.num_envs,
                      inputs=[self._seed, self._params, self._target_distance, self._tiles, self._passage,
                              wp.from_torch(redraw)],
                      outputs=[self._task, self._reset_poses, self.sim.obstacles.kernel, self.sim.terrain.kernel,
                               self.sim.maps.struct, self._pins], device=self._wp_device)
        if self.task_cfg.obstacles_on_path:  # the obstacles across the way stand on the plan, not the straight line
            wp.launch(place_on_plans, dim=self.num_envs,
                      inputs=[self._seed, self._params, self._mask, self._pins, self._task, self._reset_poses,
                              wp.from_torch(self.path, dtype=wp.vec2), wp.from_torch(self.path_length),
                              self.sim.maps.struct, self._passage],
                      outputs=[self.sim.obstacles.kernel], device=self._wp_device)

    def _replan(self) -> None:
        """The worlds due (every ``replan_period`` of their episode) plan again from their robots' poses (a path
        task's from where they were a step before: the plan a controller is handed was planned a moment ago)."""
        due = (self.step_count.reshape(-1) % self._replan_steps == 0) & self._mapped
        self.replanned = due
        if bool(due.any()):
            self.planner.replan(torch.nonzero(due).flatten(),
                                self._plan_from if self._paths else self.sim.root_pose[:, :2])
            if self._paths:  # a new plan: its nearest point is searched from its start
                wp.to_torch(self._path_state.segment).masked_fill_(due, -1)

    def _follow_paths(self, mode: int, mask: wp.array | None = None) -> None:
        """Where each world's robot is on its plan (:func:`~atrv_warp.task.kernels.paths.follow_paths`)."""
        wp.launch(follow_paths, dim=self.num_envs,
                  inputs=[self._params, self._inputs, mode, mask if mask is not None else self._mask,
                          self.sim.sim_cfg.step_dt], outputs=[self._obs], device=self._wp_device)

    def _make_randomization(self) -> None:
        """The draws' spec, the action delay's buffers and the noise, as the kernels take them."""
        r, n, dev = self.randomization, self.num_envs, self._wp_device
        low, high, log, mode, every = ([0.0] * DRAW_COUNT, [0.0] * DRAW_COUNT, [0] * DRAW_COUNT, [0] * DRAW_COUNT,
                                       [1] * DRAW_COUNT)
        # DrawSpec's rows: the physical parameters, the latency (below), the motor lag, the odometry's scale and slip gain
        draws = [r.physics.get(name) for name in PHYSICS_DRAWS] + [None, r.motor_lag, r.odometry_scale, r.odometry_slip_gain]
        for i, d in enumerate(draws):
            if d is not None:
                low[i], high[i], log[i], mode[i], every[i] = d.low, d.high, int(d.log), MODE_CODES[d.mode], max(d.every, 1)
        if r.latency[1] > 0:  # whole steps in [low, high]: drawn from [low, high + 1) and rounded down
            i = len(PHYSICS_DRAWS)
            low[i], high[i], mode[i] = float(r.latency[0]), float(r.latency[1] + 1), MODE_CODES["reset"]
        spec = DrawSpec()
        spec.low, spec.high = wp.array(low, dtype=float, device=dev), wp.array(high, dtype=float, device=dev)
        spec.log, spec.mode = wp.array(log, dtype=int, device=dev), wp.array(mode, dtype=int, device=dev)
        spec.every = wp.array(every, dtype=int, device=dev)
        self._draw_spec = spec
        self._draws_on_reset = any(m != 0 for m in mode)
        self._draws_on_tick = any(m == MODE_CODES["interval"] for m in mode)
        self._payload_draws = any(name in r.physics for name in ("payload_mass", "payload_offset"))
        self._payload_on_tick = any(r.physics[name].mode == "interval" for name in ("payload_mass", "payload_offset")
                                    if name in r.physics)
        d = ActionDelay()
        d.latency = wp.zeros(n, dtype=wp.int32, device=dev)
        d.alpha = wp.ones(n, dtype=float, device=dev)
        # the drawn motor lag's time constant [s]: a twist action's goes to the driver, which lags per substep
        d.tau = self.sim.driver.lag_array if self._twist else wp.zeros(n, dtype=float, device=dev)
        d.history = wp.zeros((n, HISTORY), dtype=wp.vec2, device=dev)
        d.applied = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._delay = d
        on = ObservationNoise()
        if r.noise is not None:
            on.velocity, on.gyro, on.attitude = r.noise.velocity, r.noise.gyro, r.noise.attitude
            # the encoders' yaw rate (r_R - r_L) / b_eff: each side's speed has sqrt(2) x the velocity noise of
            # their mean, so its noise is 2 x velocity / effective track [rad/s] (and independent of the mean's)
            on.odom_angular = 2.0 * r.noise.velocity / self.sim.driver.kinematics.effective_track
        self._obs_noise = on
        self._all = wp.full(n, True, dtype=bool, device=dev)
        self.latency = wp.to_torch(d.latency)
        """(N,) each world's action latency [steps] in the current episode (a view)."""
        if r.enabled:  # the delay is part of the env's state (state_dict); the physical draws are the simulator's
            self._task_views.update({"delay.latency": self.latency, "delay.alpha": wp.to_torch(d.alpha),
                                     "delay.history": wp.to_torch(d.history), "delay.applied": wp.to_torch(d.applied)})

    def _draw(self, phase: int, mask: wp.array) -> None:
        """Draw the due quantities of the masked worlds (``PHASE_EPISODE`` on reset, ``PHASE_TICK`` after a step)."""
        params = self.sim.params
        wp.launch(draw_physics, dim=self.num_envs,
                  inputs=[self._seed, phase, self.sim.sim_cfg.step_dt, mask, self._task, self._draw_spec,
                          params.physics, params.payload_mass_array, params.payload_offset_array, self._delay],
                  device=self._wp_device)
        if self._payload_draws and (phase == PHASE_EPISODE or self._payload_on_tick):
            self.sim.apply_payload(mask)

    def _add_noise(self, mask: wp.array, *, advance: bool = False) -> None:
        """The sensors' noise on the masked worlds' observation; ``advance``: a step went by (the robot
        observation's odometry drifts). A task's own observation kind takes none: the noise is the shipped kinds'."""
        if self.randomization.noise is None or self._observe_kind < 0:
            return
        if self._robot or self._paths:  # the robot's twist and IMU fields (a path task's stand after its plan)
            shift = ODOM_COLUMN[self.task_cfg.observation] - ODOM_COLUMN["robot"]
            wp.launch(add_robot_observation_noise, dim=self.num_envs,
                      inputs=[self._seed, mask, int(advance), self.sim.sim_cfg.step_dt, self._task, self._obs_noise,
                              self.sim.driver.state.fused, self.sim.buffers.nonfinite, shift, int(self._robot)],
                      outputs=[self._obs], device=self._wp_device)
        else:
            wp.launch(add_observation_noise, dim=self.num_envs,
                      inputs=[self._seed, mask, self._task, self._obs_noise, self.sim.buffers.nonfinite],
                      outputs=[self._obs], device=self._wp_device)

    def _make_spec(self) -> None:
        n, dev, dim = self.num_envs, self.device, self.obs_dim
        low, high = observation_bounds(task=self.task_cfg, sensors=self._sensor_fields)
        bounds = (low.expand(n, dim), high.expand(n, dim))
        terms = Composite({name: Unbounded(shape=(n, 1), dtype=torch.float32, device=dev)
                           for name in self.task.term_names},
                          shape=(n,), device=dev)
        self.observation_spec = Composite(
            observation=Bounded(*bounds, shape=(n, dim), dtype=torch.float32, device=dev),
            end_reason=Categorical(len(END_REASONS), shape=(n, 1), dtype=torch.int64, device=dev),
            distance=Unbounded(shape=(n, 1), dtype=torch.float32, device=dev),
            reward_terms=terms,
            shape=(n,), device=dev,
        )
        for sensor in self.sensors:
            spec = sensor.spec(n, dev)
            if spec is not None:
                self.observation_spec[sensor.name] = spec
        self.action_spec = Bounded(-1.0, 1.0, shape=(n, ACTION_DIM), dtype=torch.float32, device=dev)
        self.reward_spec = Unbounded(shape=(n, 1), dtype=torch.float32, device=dev)
        self.done_spec = Composite(
            done=Categorical(2, shape=(n, 1), dtype=torch.bool, device=dev),
            terminated=Categorical(2, shape=(n, 1), dtype=torch.bool, device=dev),
            truncated=Categorical(2, shape=(n, 1), dtype=torch.bool, device=dev),
            shape=(n,), device=dev,
        )

    # ------------------------------------------------------------------ EnvBase hooks
    def _set_seed(self, seed: int | None) -> None:
        """Seed every world's reset stream; episode k of world w draws from (seed, w, k)."""
        self._seed = 0 if seed is None else int(seed) % (2**31)
        self._episode_t.zero_()
        self._reseed_sensors()

    def _reseed_sensors(self) -> None:
        for sensor in self.sensors:
            sensor.reseed(self._seed)

    def set_worlds(self, worlds: Sequence[int], starts, targets, *, target_yaws=None, obstacles=None, maps=None,
                   tiles=None) -> TensorDictBase:
        """Reset ``worlds`` to given layouts and keep them: every later reset of one of them (an auto-reset too)
        replays its layout instead of drawing one, until :meth:`release_worlds`. For an evaluation or a test that
        replays a place, or a site set up by hand.

        Args:
            worlds: K world indices.
            starts: (K, 3) each world's start: x [m], y [m], yaw [rad].
            targets: (K, 2) each world's target [m].
            target_yaws: (K,) the targets' headings [rad]; default 0.
            obstacles: per world, its obstacles as :meth:`Obstacles.set <atrv_warp.sim.contact.Obstacles.set>`
                takes them (``("box", x, y, yaw, hx, hy)``, ``("cylinder", x, y, radius)``, each with its own height
                above the ground last where it is not the task's), at most the task's slots; default none.
            maps: (K,) each world's map, an index into ``sim.maps.maps``; default the one it has.
            tiles: (K,) each world's terrain tile; default 0.

        Raises:
            ValueError: One line naming the world and the problem (a shape, a non-finite or out-of-arena pose, a
                start or target in a map's wall or off it, an obstacle that does not fit or is malformed, a map
                index out of range); nothing is changed.

        Returns:
            The reset tensordict (as :meth:`reset_to_episodes`).
        """
        worlds = [int(w) for w in worlds]
        k = len(worlds)
        starts = torch.as_tensor(starts, dtype=torch.float32).reshape(-1, 3) if k else torch.zeros(0, 3)
        targets = torch.as_tensor(targets, dtype=torch.float32).reshape(-1, 2) if k else torch.zeros(0, 2)
        yaws = torch.zeros(k) if target_yaws is None else torch.as_tensor(target_yaws, dtype=torch.float32).reshape(-1)
        tiles = torch.zeros(k, dtype=torch.int32) if tiles is None else torch.as_tensor(tiles).reshape(-1).int()
        site = self.sim.maps.world_map.copy()
        if maps is not None:
            if len(maps) != k:
                raise ValueError(f"set_worlds: maps must hold one map index for each of the {k} worlds, got "
                                 f"{len(maps)}")
            site[worlds] = [int(m) for m in maps]
        layouts = self._check_layouts(worlds, starts, targets, yaws, tiles, obstacles, site)
        if maps is not None:  # each world's map, for the kernels and the host alike
            self.sim.maps.world_map[:] = site
            wp.copy(self.sim.maps.struct.world_map, wp.array(site, dtype=wp.int32, device=self._wp_device))
            if self.planner is not None:
                self._mapped = torch.as_tensor(site >= 0, device=self.device)
        index = torch.as_tensor(worlds, dtype=torch.long, device=self.device)
        pins = self._pins
        wp.to_torch(pins.start)[index] = starts.to(self.device)
        wp.to_torch(pins.target)[index] = targets.to(self.device)
        wp.to_torch(pins.target_yaw)[index] = yaws.to(self.device)
        wp.to_torch(pins.tile)[index] = tiles.to(self.device)
        for i, (kind, pose, size, top) in zip(worlds, layouts, strict=True):
            wp.to_torch(pins.kind)[i] = kind.to(self.device)
            wp.to_torch(pins.pose)[i] = pose.to(self.device)
            wp.to_torch(pins.size)[i] = size.to(self.device)
            wp.to_torch(pins.height)[i] = top.to(self.device)
        self._pinned_t[index] = True
        mask = torch.zeros(self.num_envs, 1, dtype=torch.bool, device=self.device)
        mask[index] = True
        return self.reset(TensorDict({"_reset": mask}, batch_size=self.batch_size, device=self.device))

    @property
    def pinned(self) -> torch.Tensor:
        """(N,) bool: the worlds that replay a given layout at every reset (:meth:`set_worlds`), a copy."""
        return self._pinned_t.clone()

    def release_worlds(self, worlds: Sequence[int] | None = None) -> None:
        """Let ``worlds`` (default: every world) draw their layouts again at their next reset (:meth:`set_worlds`)."""
        if worlds is None:
            self._pinned_t.fill_(False)
            return
        worlds = [int(w) for w in worlds]
        if any(not 0 <= w < self.num_envs for w in worlds):
            raise ValueError(f"release_worlds: world indices must be in [0, {self.num_envs}), got {worlds}")
        self._pinned_t[torch.as_tensor(worlds, dtype=torch.long, device=self.device)] = False

    def _check_layouts(self, worlds, starts, targets, yaws, tiles, obstacles, site) -> list:
        """:meth:`set_worlds`'s input checked, each world's obstacles as (kind, pose, size, top) slot tensors."""
        k = len(worlds)
        for name, value, shape in (("starts", starts, (k, 3)), ("targets", targets, (k, 2)),
                                   ("target_yaws", yaws, (k,)), ("tiles", tiles, (k,))):
            if tuple(value.shape) != shape:
                raise ValueError(f"set_worlds: {name} must have shape {shape} for {k} worlds, got {tuple(value.shape)}")
        if any(not 0 <= w < self.num_envs for w in worlds) or len(set(worlds)) != k:
            raise ValueError(f"set_worlds: worlds must be distinct indices in [0, {self.num_envs}), got {worlds}")
        if obstacles is not None and len(obstacles) != k:
            raise ValueError(f"set_worlds: obstacles must hold one layout for each of the {k} worlds, got "
                             f"{len(obstacles)}")
        if ((tiles < 0) | (tiles >= self._tiles)).any():
            raise ValueError(f"set_worlds: tiles must be in [0, {self._tiles}), got {tiles.tolist()}")
        if (site < -1).any() or (site >= len(self.sim.maps.maps)).any() or (
                len(self.sim.maps.maps) and (site[worlds] < 0).any()):
            raise ValueError(f"set_worlds: maps must index the {len(self.sim.maps.maps)} maps, got "
                             f"{site[worlds].tolist()}")
        half = self.sim.arena_cfg.half_size
        for i, w in enumerate(worlds):
            for what, point in (("start", starts[i, :2]), ("target", targets[i])):
                if not bool(torch.isfinite(point).all()) or bool(point.abs().max() >= half):
                    raise ValueError(f"set_worlds: world {w}'s {what} {point.tolist()} is not a finite point inside "
                                     f"the arena (|x|, |y| < {half:g} m)")
                m = int(site[w])
                if m >= 0:
                    row, col = self.sim.maps.maps[m].cell_of(float(point[0]), float(point[1]))
                    walls = self.sim.maps.maps[m].walls
                    if not (0 <= row < walls.shape[0] and 0 <= col < walls.shape[1]) or walls[row, col]:
                        raise ValueError(f"set_worlds: world {w}'s {what} ({float(point[0]):g}, {float(point[1]):g}) m "
                                         f"is in a wall of map {self.sim.maps.maps[m].name} or off it")
            if not bool(torch.isfinite(starts[i]).all() & torch.isfinite(yaws[i])):
                raise ValueError(f"set_worlds: world {w}'s start yaw or target heading is not finite")
        layouts = []
        obstacles_of = self.sim.obstacles
        for i, w in enumerate(worlds):
            try:
                layouts.append(obstacles_of.layout(obstacles[i] if obstacles is not None else ()))
            except ValueError as err:
                raise ValueError(f"set_worlds: world {w}: {err}") from None
        return layouts

    def reset_to_episodes(self, worlds: Sequence[int], episodes: Sequence[int], *, seed: int) -> TensorDictBase:
        """Reset ``worlds`` to episodes of a seeded evaluation set: world ``worlds[i]`` draws what world
        ``episodes[i]`` of an environment seeded ``seed`` draws in its first episode (start, target, terrain tile,
        obstacles), as :func:`atrv_warp.task.evaluation.run_episodes` (``evaluate --seed seed``) runs it; e.g. the
        ROS node's ``reset_episode``, which replays evaluation episode k in a one-world simulator.

        The other worlds keep their state. The seed becomes the environment's (its sensors' noise is reseeded); the
        replayed worlds keep drawing from their episodes' streams on later resets. Domain randomization's
        per-world draws (physics, noise, latency) are not remapped: replay episodes without randomization.

        Returns:
            The reset tensordict (every world's observation; the others' as they are).
        """
        worlds = torch.as_tensor(list(worlds), dtype=torch.long, device=self.device)
        episodes = torch.as_tensor(list(episodes), dtype=torch.int32, device=self.device)
        if worlds.shape != episodes.shape or bool(((worlds < 0) | (worlds >= self.num_envs)).any()):
            raise ValueError(f"reset_to_episodes: {len(worlds)} world indices in [0, {self.num_envs}) and as many "
                             f"episodes expected, got worlds {worlds.tolist()}, episodes {episodes.tolist()}")
        if bool((episodes < 0).any()):
            raise ValueError(f"reset_to_episodes: episode indices must be >= 0, got {episodes.tolist()}")
        seed = int(seed) % (2**31)
        if seed != self._seed:
            self._seed = seed
            self._reseed_sensors()
        self._stream_t[worlds] = episodes
        self._episode_t[worlds] = 0
        mask = torch.zeros(self.num_envs, 1, dtype=torch.bool, device=self.device)
        mask[worlds] = True
        return self.reset(TensorDict({"_reset": mask}, batch_size=self.batch_size, device=self.device))

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None
        if tensordict is not None and "_reset" in tensordict:
            mask = tensordict.get("_reset").reshape(self.num_envs)
        if mask is None:
            self._mask_t.fill_(True)
        else:
            self._mask_t.copy_(mask)
        sim = self.sim
        if self._draws_on_reset:  # before the sampler counts the episode
            self._draw(PHASE_EPISODE, self._mask)
        if self._nav:
            wp.launch(sample_nav_episodes, dim=self.num_envs,
                      inputs=[self._seed, self._params, self._target_distance, self._tiles, self._passage,
                              self._mask],
                      outputs=[self._task, self._reset_poses, sim.obstacles.kernel, sim.terrain.kernel,
                               sim.maps.struct, self._pins],
                      device=self._wp_device)
        else:
            wp.launch(sample_episodes, dim=self.num_envs, inputs=[self._seed, self._params, self._mask, self._pins],
                      outputs=[self._task, self._reset_poses], device=self._wp_device)
        if self.planner is not None:  # before the rovers are placed: an episode without a path is drawn again
            self._plan_episodes()
        sim.reset_worlds(self._mask, self._reset_poses)
        if self._robot:  # a new odometry frame: the start pose, without drift yet
            self.odom_drift.masked_fill_(self._mask_t.unsqueeze(-1), 0.0)
        self._prev_action_t.masked_fill_(self._mask_t.unsqueeze(-1), 0.0)  # a new episode has chosen no action yet
        if self._actions is not None:
            wp.launch(clear_actions, dim=(self.num_envs, self.task_cfg.action_history), inputs=[self._mask],
                      outputs=[self._actions], device=self._wp_device)
        self._launch_observe()
        self._end_reason_t.masked_fill_(self._mask_t.unsqueeze(-1), 0)
        zeros = torch.zeros((self.num_envs, 1), dtype=torch.bool, device=self.device)
        out = {"observation": self._obs_t.clone(), "end_reason": self._end_reason_t.long(),
               "distance": self._distance_t.clone(), "done": zeros, "terminated": zeros.clone(),
               "truncated": zeros.clone(), "reward_terms": self._terms_td(torch.zeros_like(self._reward_terms_t))}
        self._report_sensors(out)
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _report_sensors(self, out: dict) -> None:
        """Each sensor's full reading under its name (a copy)."""
        for sensor in self.sensors:
            reading = sensor.reading()
            if reading is not None:
                out[sensor.name] = reading.clone()

    def _terms_td(self, terms: torch.Tensor) -> TensorDict:
        """``("reward_terms", name)`` entries as (N, 1) views of one (N, K) tensor."""
        return TensorDict({name: terms[:, i:i + 1] for i, name in enumerate(self.task.term_names)},
                          batch_size=self.batch_size, device=self.device)

    def observe(self, targets: torch.Tensor) -> torch.Tensor:
        """Set every world's target (N, 2) [m] and return the observation (N, obs_dim) of the current
        state, from the same kernel as a reset (the progress terms are re-primed from here; a robot observation's
        goal is the target in the odometry frame of the episode's start pose).

        For driving the simulator outside TorchRL's step loop, e.g. the ROS bridge's goal mode."""
        self.target.copy_(torch.as_tensor(targets, dtype=torch.float32, device=self.device).reshape(self.num_envs, 2))
        self._mask_t.fill_(True)
        self._launch_observe()
        return self._obs_t.clone()

    def _launch_observe(self) -> None:
        for sensor in self.sensors:  # only the reset worlds moved
            sensor.read(self._mask)
        if self._robot:
            wp.launch(locate_goals, dim=self.num_envs, inputs=[self._mask, self._reset_poses], outputs=[self._task],
                      device=self._wp_device)
        wp.launch(observe_reset, dim=self.num_envs, inputs=[self._observe_kind, self._mask, self._task, self._rover],
                  outputs=[self._out], device=self._wp_device)
        self._launch_fields()
        if self._paths:
            self._follow_paths(FOLLOW_RESET, self._mask)
        self._launch_observation_tail()
        self._add_noise(self._mask)

    def record_actions(self, actions: torch.Tensor) -> None:
        """Note the actions (N, 2) chosen for every world's next step in the observed action history (a task with
        ``action_history``; nothing otherwise), as :meth:`step` does; for driving outside TorchRL's step loop,
        e.g. the ROS node, whose next :meth:`observe` then shows them."""
        if self._actions is not None:
            actions = torch.as_tensor(actions, dtype=torch.float32, device=self.device).reshape(self.num_envs, 2)
            wp.launch(record_actions, dim=self.num_envs, inputs=[wp.from_torch(actions.contiguous())],
                      outputs=[self._actions], device=self._wp_device)

    def _launch_observation_tail(self) -> None:
        """The observation's columns after its leading fields (:data:`OBSERVATION` or :data:`ROBOT_OBSERVATION`):
        each sensor's fields, then the last actions."""
        column = self._lead_dim
        for sensor in self.sensors:
            sensor.observe(self._obs, column, self.sim.buffers.nonfinite)
            column += len(sensor.fields)
        if self._actions is not None:
            wp.launch(write_action_observation, dim=(self.num_envs, self.task_cfg.action_history),
                      inputs=[self._actions, column], outputs=[self._obs], device=self._wp_device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = self._check_action(tensordict.get("action"))
        self._action_t.copy_(action)  # for the reward terms that read it
        sim = self.sim
        if self._twist:
            self._command_twist(action)
        elif self.randomization.delays_actions:
            wp.launch(delay_actions, dim=self.num_envs,
                      inputs=[wp.from_torch(action.contiguous()), self.task_cfg.action_scale, self._task, self._delay],
                      outputs=[sim.buffers.commands], device=self._wp_device)
        else:
            action_to_torque(action, self.task_cfg.action_scale, out=sim.commands)
        self.record_actions(action)
        if self._paths:  # a plan reaches the controller a period after it was planned: it starts behind the robot
            self._plan_from.copy_(sim.root_pose[:, :2])
        sim.step()
        for sensor in self.sensors:
            sensor.read()
        self._launch_outcome()
        self._launch_observation_tail()
        self._add_noise(self._all, advance=True)
        if self._draws_on_tick:
            self._draw(PHASE_TICK, self._all)
        if self.planner is not None and self._replan_steps:
            b = self.sim.buffers  # the obstacle layer marks what the lasers see now (none without it)
            self.planner.observe(b.body_q, b.layout.bodies_per_world, b.layout.chassis_body, self.task_cfg.scan_fov)
            self._replan()
        if self._paths:  # the observation reads each world's plan as it is now
            self._follow_paths(FOLLOW_OBSERVE)
        if bool(sim.nonfinite.any()):  # one flag read per step; blown-up worlds are rare
            self.nonfinite_count += int(sim.nonfinite.sum())
        out = {"observation": self._obs_t.clone(), "reward": self._reward_t.clone(),
               "done": self._terminated_t | self._truncated_t, "terminated": self._terminated_t.clone(),
               "truncated": self._truncated_t.clone(), "end_reason": self._end_reason_t.long(),
               "distance": self._distance_t.clone(), "reward_terms": self._terms_td(self._reward_terms_t.clone())}
        self._report_sensors(out)
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _launch_outcome(self) -> None:
        """A step's ends, the odometry's drift, the observation's leading fields, each reward term and the reward
        (:mod:`atrv_warp.task.kernels.steps`), in that order."""
        n, dev = self.num_envs, self._wp_device
        if self._paths:  # where each robot is on the plan its step was taken on; the goal and progress checkers
            self._follow_paths(FOLLOW_STEP)
        wp.launch(self._ends, dim=n, inputs=[self._params, self._inputs], outputs=[self._out], device=dev)
        if self._robot:
            wp.launch(advance_odometry_drift, dim=n, inputs=[self.sim.sim_cfg.step_dt, self._task, self._rover],
                      device=dev)
        wp.launch(observe_step, dim=n, inputs=[self._observe_kind, self._task, self._rover], outputs=[self._out],
                  device=dev)
        self._launch_fields()
        for kernel, weight in self._terms:
            wp.launch(kernel, dim=n, inputs=[self._params, self._inputs, weight], outputs=[self._reward_terms],
                      device=dev)
        wp.launch(sum_terms, dim=n, inputs=[self._inputs], outputs=[self._out], device=dev)

    def _launch_fields(self) -> None:
        """An observation kind of the task's own: its leading fields, one kernel each (none for the shipped kinds)."""
        for kernel in self._fields:
            wp.launch(kernel, dim=self.num_envs, inputs=[self._params, self._inputs], outputs=[self._obs],
                      device=self._wp_device)

    def _command_twist(self, action: torch.Tensor) -> None:
        """A twist action's /cmd_vel, (linear, angular) = clip(action) x (max_linear [m/s], max_angular [rad/s]),
        to every world's driver (its timeout restarted), through the latency buffer when actions are delayed."""
        c, d = self.task_cfg, self.sim.driver
        limits = wp.vec2(c.max_linear, c.max_angular)
        actions = wp.from_torch(action.contiguous())
        if self.randomization.delays_actions:
            wp.launch(delay_twist, dim=self.num_envs, inputs=[actions, limits, self._task, self._delay],
                      outputs=[d.twist_array, d.state.age], device=self._wp_device)
        else:
            wp.launch(command_twist, dim=self.num_envs, inputs=[actions, limits],
                      outputs=[d.twist_array, d.state.age], device=self._wp_device)

    def _check_action(self, action: torch.Tensor | None) -> torch.Tensor:
        expected = (self.num_envs, 2)
        if action is None:
            raise KeyError("the input tensordict has no 'action' entry")
        if tuple(action.shape) != expected:
            columns = ", ".join(ACTIONS[self.task_cfg.action].columns)
            raise ValueError(f"action must have shape {expected} (num_envs, [{columns}]), got {tuple(action.shape)}")
        if not action.is_floating_point():
            raise TypeError(f"action must be a floating-point tensor of shape {expected}, got dtype {action.dtype}")
        finite = torch.isfinite(action).all(-1)
        if not bool(finite.all()):
            bad = (~finite).nonzero().flatten().tolist()
            raise ValueError(f"action contains NaN/inf in world(s) {bad[:20]}{' ...' if len(bad) > 20 else ''}; "
                             "nothing was stepped")
        return action.to(self.device, torch.float32)

    # ------------------------------------------------------------------ save / restore
    def _identity(self) -> dict[str, str]:
        """What a snapshot must match to be restored here: the world count, the task and the randomization."""
        return {"num_envs": str(self.num_envs),
                "task": json.dumps(dataclasses.asdict(self.task_cfg), sort_keys=True, default=str),
                "randomization": json.dumps(dataclasses.asdict(self.randomization), sort_keys=True, default=str)}

    def state_dict(self, *args, **kwargs):
        """A snapshot of everything the next step reads: the simulator's :meth:`~RoverSim.get_state`, the task's
        buffers (targets, progress, counters, the episode's layout, the observation, the action history), the
        randomization's delay, the seed and each sensor's noise stream (:meth:`Sensor.state
        <atrv_warp.task.sensors.Sensor.state>`). :meth:`load_state_dict` then steps on bit for
        bit as this env would have (on the CPU)."""
        sd = super().state_dict(*args, **kwargs)
        sd["snapshot.format"] = SNAPSHOT_FORMAT
        sd.update({f"snapshot.{k}": v for k, v in self._identity().items()})
        for k, v in self.sim.get_state().items():
            sd[f"sim.{k}"] = v
        for k, v in self._task_views.items():
            sd[f"task.{k}"] = v.clone()
        sd["task.seed"] = torch.tensor(self._seed)
        sd["task.nonfinite_count"] = torch.tensor(self.nonfinite_count)
        for sensor in self.sensors:
            sd.update({f"task.{k}": v for k, v in sensor.state().items()})
        return sd

    def check_state_dict(self, state_dict: Mapping) -> None:
        """Raise ``ValueError`` in one line naming why ``state_dict`` cannot be restored here (another snapshot
        format, world count, task or randomization, or a missing or misshapen entry); nothing is written."""
        fmt = state_dict.get("snapshot.format")
        if fmt != SNAPSHOT_FORMAT:
            raise ValueError(f"not a snapshot this version restores: format {fmt!r}, expected {SNAPSHOT_FORMAT} (a "
                             "state_dict of this package's RoverEnv; older snapshots left out the friction solver's "
                             "warm start and cannot be restored exactly)")
        here = self._identity()
        saved = {k: state_dict.get(f"snapshot.{k}") for k in here}
        if saved["num_envs"] != here["num_envs"]:
            raise ValueError(f"the snapshot is of {saved['num_envs']} worlds, this env has {here['num_envs']}")
        for what in ("task", "randomization"):
            if saved[what] != here[what]:
                theirs, ours = json.loads(saved[what] or "{}"), json.loads(here[what])
                diff = [f"{k}={theirs.get(k)!r} (here {ours.get(k)!r})" for k in sorted(set(ours) | set(theirs))
                        if theirs.get(k) != ours.get(k)]
                raise ValueError(f"the snapshot's {what} differs from this env's: {', '.join(diff)}")
        self.sim.check_state({k[4:]: v for k, v in state_dict.items() if k.startswith("sim.")})
        need = {**self._task_views, "seed": None, "nonfinite_count": None}
        for sensor in self.sensors:
            need.update(dict.fromkeys(sensor.state()))
        missing = sorted(k for k in need if f"task.{k}" not in state_dict and k not in TASK_SNAPSHOT_ADDED)
        if missing:
            raise ValueError(f"the snapshot lacks task entries {missing}")
        for k, v in self._task_views.items():
            if f"task.{k}" not in state_dict:  # added since (TASK_SNAPSHOT_ADDED)
                continue
            got = tuple(torch.as_tensor(state_dict[f"task.{k}"]).shape)
            if got != tuple(v.shape):
                raise ValueError(f"snapshot entry 'task.{k}' has shape {got}, this env's is {tuple(v.shape)}")

    def load_state_dict(self, state_dict: Mapping, strict: bool = True, assign: bool = False):
        """Restore a snapshot from :meth:`state_dict`, checked first (:meth:`check_state_dict`: a mismatch is a
        ``ValueError`` naming it, and the env is unchanged)."""
        self.check_state_dict(state_dict)
        state_dict = dict(state_dict)
        sim_state = {k[4:]: state_dict.pop(k) for k in list(state_dict) if k.startswith("sim.")}
        task_state = {k[5:]: state_dict.pop(k) for k in list(state_dict) if k.startswith("task.")}
        for k in list(state_dict):
            if k.startswith("snapshot."):
                del state_dict[k]
        for k, v in self._task_views.items():
            if k in task_state:
                v.copy_(task_state[k])
            elif k == "obstacle_height":  # a snapshot from before obstacles had heights: every one the config's
                v.fill_(self.sim.obstacles.kernel.top)
        self.sim.set_state(sim_state)
        self._seed = int(task_state["seed"])
        self.nonfinite_count = int(task_state["nonfinite_count"])
        self._reseed_sensors()
        for sensor in self.sensors:
            sensor.load_state(task_state)
        if self.planner is not None:  # the goals' fields; the plans as they were (planned again if not kept)
            mapped = torch.nonzero(self._mapped).flatten()
            if "path" in task_state:
                self.planner.set_goals(mapped, self.target, self.sim.root_pose[:, :2])
            else:
                self.planner.plan(mapped, self.sim.root_pose[:, :2], self.target)
        return super().load_state_dict(state_dict, strict=strict, assign=assign)

    def __repr__(self) -> str:
        return (f"RoverEnv(robot={self.robot.name!r}, num_envs={self.num_envs}, device={self.device}, "
                f"task={self.task.name!r}, terrain={self.task_cfg.terrain!r}, "
                f"randomized={self.randomization.enabled}, "
                f"obstacles={self.task_cfg.obstacles}, scan_beams={self.task_cfg.scan_beams}, "
                f"urdf={self.sim.description.path!r})")


@dataclasses.dataclass(frozen=True)
class EnvFactory:
    """Picklable env constructor for multi-process collectors (``spawn``-safe).

    Pins the worker process to ``core`` (if given) and to one torch thread before building,
    so two workers on a 2-core machine do not fight over cores.
    """

    num_envs: int = 64
    seed: int | None = None
    core: int | None = None
    env_kwargs: tuple[tuple[str, object], ...] = ()
    """Keyword arguments of :class:`RoverEnv` as (name, value) pairs (a field called ``kwargs`` would be
    taken by TorchRL's collectors for their own)."""

    def __call__(self) -> RoverEnv:
        if self.core is not None:
            pin_to_core(self.core)  # of the run's cores, not of the one the trainer pinned itself to
        torch.set_num_threads(1)
        return RoverEnv(self.num_envs, seed=self.seed, **dict(self.env_kwargs))


ATRVjrEnv = RoverEnv
"""The environment's name before robots had files (issue 59): :class:`RoverEnv`, on the ATRV-Jr by default."""
