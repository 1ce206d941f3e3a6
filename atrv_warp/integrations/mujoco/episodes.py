"""A deployable policy driving the MuJoCo twin on our evaluation episodes, through the torch-only observation
builder a robot runs (:class:`~atrv_warp.core.observation.RobotObservation`).

- :func:`draw_episodes`: each episode's world, start and goal, drawn by our environment's own reset for an
  evaluation seed (what ``python -m atrv_warp.evaluate`` runs: episode k of the set is world k's first episode);
- :class:`DeployablePolicy`: a ``.pt`` policy file (or a shipped name) or an exported ``.pt2``, with its contract;
  a policy that commands wheel torques or observes the arena is refused, naming why;
- :func:`run_twin_episodes`: one twin per episode, the policy in the loop at the task's control period; the same
  end reasons, in the same order, as the environment's ends kernel (``task/kernels/steps.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from atrv_warp.core.contract import read_exported
from atrv_warp.core.observation import RobotObservation, Scan
from atrv_warp.sim.config import RoverConfig, SimConfig
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.scanner import ScannerConfig
from atrv_warp.sim.terrain import HeightGrid
from atrv_warp.task.config import TaskConfig
from atrv_warp.task.evaluation import EVAL_SEED, EpisodeRecord
from atrv_warp.task.reward import progress_reward
from atrv_warp.task.spec import EndReason, action_to_twist, policy_contract

from .mjcf import MujocoContact, Obstacle
from .twin import FLAG_OBSTACLE, MujocoTwin

__all__ = ["ODOMETRY_SOURCES", "DeployablePolicy", "TwinEpisode", "TwinEpisodes", "draw_episodes", "run_twin_episode",
           "run_twin_episodes"]


@dataclass(frozen=True)
class TwinEpisode:
    """One episode of an evaluation set, as our environment's reset drew it."""

    tile: int
    """The terrain tile it drives on."""
    obstacles: tuple[Obstacle, ...]
    start: tuple[float, ...]
    """The chassis' start pose: position (x, y, z) [m] and orientation quaternion (x, y, z, w), world frame."""
    target: tuple[float, float]
    """The goal (x, y) [m], world frame."""
    goal: tuple[float, float]
    """The goal (x, y) [m] in the odometry frame (the start pose), as the robot observes it."""


@dataclass(frozen=True)
class TwinEpisodes:
    """An evaluation set's episodes and the world they share."""

    task: TaskConfig
    seed: int
    terrain: HeightGrid | None
    """The terrain's height grids (``None``: the flat arena)."""
    obstacle_height: float
    """Obstacles stand this high above the flat ground's top [m]."""
    episodes: tuple[TwinEpisode, ...]
    rover: RoverConfig | None = None
    """The robot's nominal rover (``None``: the ATRV-Jr's)."""

    def twin(self, episode: TwinEpisode, *, friction: float | None = None,
             driver: DriverConfig | None = None, contact: MujocoContact | None = None) -> MujocoTwin:
        """The twin of ``episode``'s world (its terrain tile and obstacles, the task's scanner) at Coulomb
        ``friction`` (default: the nominal µ), through the task's base: ``driver`` with the task's limits filling
        those it leaves unset (:meth:`~atrv_warp.task.config.TaskConfig.driver`); ``contact``: MuJoCo's contact
        settings (default :class:`~.mjcf.MujocoContact`, the tyre's compliance)."""
        task = self.task
        scanner = ScannerConfig(beams=task.scan_beams, fov=task.scan_fov) if task.scan_beams else ScannerConfig()
        sim = SimConfig(step_dt=task.control_period) if task.control_period else None
        return MujocoTwin(terrain=self.terrain, tile=episode.tile, obstacles=episode.obstacles, friction=friction,
                          obstacle_height=self.obstacle_height, scanner=scanner, driver=task.driver(driver),
                          contact=contact, rover=self.rover, sim=sim)


def draw_episodes(task, count: int, *, seed: int = EVAL_SEED, robot: str | None = None) -> TwinEpisodes:
    """The first ``count`` episodes of evaluation set ``seed`` of ``task`` (a name, a
    :class:`~atrv_warp.task.definition.Task` or a config) on ``robot`` (a name or a robot file; ``None``: the
    ATRV-Jr): our environment with ``count`` worlds, seeded and reset as :func:`~atrv_warp.task.evaluation.run_episodes`
    does, read through its public views (each world's terrain tile, obstacles, chassis pose, target and goal in the
    odometry frame). Nothing is stepped."""
    from atrv_warp.sim.contact import OBSTACLE_KINDS
    from atrv_warp.task.env import RoverEnv

    env = RoverEnv(count, task=task, robot=robot)
    env.set_seed(seed)
    env.reset()
    sim, names = env.sim, {code: name for name, code in OBSTACLE_KINDS.items()}
    kind, pose, size = (t.cpu().numpy() for t in (sim.obstacles.kind, sim.obstacles.pose, sim.obstacles.size))
    tiles, start = sim.terrain.tile.cpu().numpy(), sim.root_pose.cpu().double().numpy()
    target, goal = env.target.cpu().double().numpy(), env.goal_odom.cpu().double().numpy()
    episodes = []
    for w in range(count):
        obstacles = tuple(Obstacle(names[int(k)], float(p[0]), float(p[1]), float(p[2]), (float(s[0]), float(s[1])))
                          for k, p, s in zip(kind[w], pose[w], size[w]) if names[int(k)] != "none")
        episodes.append(TwinEpisode(int(tiles[w]), obstacles, tuple(start[w].tolist()), tuple(target[w].tolist()),
                                    tuple(goal[w].tolist())))
    height = sim.obstacles.cfg.height if sim.obstacles.cfg is not None else 0.0
    return TwinEpisodes(env.task_cfg, int(seed), sim.terrain.grid, height, tuple(episodes), env.sim.rover_cfg)


class DeployablePolicy:
    """A policy that runs on a robot: ``/cmd_vel`` actions (``twist``) from the robot observation.

    Call it with one observation (D,) float32 for its action (2,) in [-1, 1]. :attr:`contract` is what the
    observation builder reads (:func:`atrv_warp.task.spec.policy_contract`, or an exported file's
    ``atrv_warp.json``); :attr:`task` the task it was trained on.
    """

    def __init__(self, act: Callable[[torch.Tensor], torch.Tensor], contract: dict, task, name: str,
                 robot: str | None = "atrvjr", record=None):
        action, observation = contract["action"]["kind"], contract.get("observation_kind", "arena")
        if (action, observation) != ("twist", "robot"):
            raise ValueError(f"{name} is not a deployable policy: it commands {action} and observes the {observation} "
                             "observation; a robot (and the MuJoCo twin) takes twist actions from the robot "
                             "observation (train one with: python -m atrv_warp.train --config nav_deploy)")
        self.act, self.contract, self.name = act, contract, name
        self.task = task
        """The task it was trained on: a name, or the :class:`~atrv_warp.task.definition.Task` its file records."""
        self.robot = robot
        """The shipped robot it was trained on (its name), or ``None``: a robot of one's own (in :attr:`record`)."""
        self.record = record
        """The task and robot it was trained with (:class:`~atrv_warp.policy.PolicyRecord`; ``None`` for a file
        exported before exported files kept them)."""
        self.build = RobotObservation.from_contract(contract)
        """The torch-only observation builder a robot runs (:class:`~atrv_warp.core.observation.RobotObservation`)."""

    @classmethod
    def load(cls, path: str | Path) -> DeployablePolicy:
        """A policy file (``.pt``, or a shipped policy's name) or an exported program (``.pt2``, its contract
        inside). Raises ``ValueError`` naming why a policy is not deployable, ``FileNotFoundError`` for a missing
        file (a shipped policy not trained yet: naming the command that trains it)."""
        from atrv_warp.core.robot import robot_spec
        from atrv_warp.policy import exported_policy_record, load_policy, policy_kinds, policy_record, policy_task

        if str(path).endswith(".pt2"):
            if not Path(path).is_file():
                raise FileNotFoundError(f"exported policy not found: {path}")
            program, contract = read_exported(path)  # checked first: nothing in the file can run code
            module = program.module()
            if "trained_with" in contract:
                record = exported_policy_record(path, contract)
                return cls(lambda obs: module(obs[None])[0], contract, record.task, str(path),
                           robot_spec(record.robot), record)
            robot = contract.get("robot", {}).get("name", "atrvjr")  # exported before files kept their records
            return cls(lambda obs: module(obs[None])[0], contract, contract.get("task", "reach"), str(path), robot)
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        task = policy_task(path)
        record = policy_record(path)
        if record.robot.sensors:  # the twin casts links.laser's scan only
            raise ValueError(f"{path}: the policy observes its robot file's [[sensors]] "
                             f"({', '.join(s['name'] for s in record.robot.sensors)}); the MuJoCo twin simulates "
                             "links.laser's scan only")
        action, observation = policy_kinds(path)
        contract = policy_contract(record.task.config)
        if (action, observation) != ("twist", "robot"):  # refused before its network is built
            cls(lambda obs: obs, {**contract, "action": {"kind": action}, "observation_kind": observation}, task,
                str(path))
        module = load_policy(path, task=task)

        def act(obs: torch.Tensor) -> torch.Tensor:
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                return module(TensorDict({"observation": obs[None]}, batch_size=[1]))["action"][0]

        return cls(act, contract, record.task, str(path), robot_spec(record.robot), record)

    @torch.no_grad()
    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        return self.act(observation).clamp(-1.0, 1.0)


ODOMETRY_SOURCES = ("fused", "truth")
"""Where a twin episode's policy sees its pose from: ``fused``, the base's encoder-and-gyro odometry (as on a
robot); ``truth``, the chassis' true pose in the odometry frame (a study of what the odometry's error costs)."""


def run_twin_episode(policy: DeployablePolicy, twin: MujocoTwin, episode: TwinEpisode, task: TaskConfig,
                     on_step: Callable[[MujocoTwin], None] | None = None, *,
                     odometry: str = "fused") -> tuple[int, float, int]:
    """Drive one episode: the twin reset to the episode's start, the policy fed by :attr:`DeployablePolicy.build`
    every ``step_dt``, until the task's end. Returns (end reason code, return, steps).

    ``odometry``: the pose the policy's goal is seen from (:data:`ODOMETRY_SOURCES`).
    The return is the task's progress, heading and step terms (:func:`atrv_warp.task.reward.progress_reward`) plus
    its success or failure reward; the clearance term is left out."""
    if odometry not in ODOMETRY_SOURCES:
        raise ValueError(f"odometry={odometry!r} is not a pose source; known: {list(ODOMETRY_SOURCES)}")
    twin.reset(episode.start[:3], episode.start[3:])
    origin, yaw0 = twin.root_pose[:2].copy(), float(twin.rpy[2])

    def pose() -> np.ndarray:
        if odometry == "fused":
            return twin.fused
        c, s = math.cos(yaw0), math.sin(yaw0)
        d = twin.root_pose[:2] - origin
        yaw = float(twin.rpy[2]) - yaw0
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], math.atan2(math.sin(yaw), math.cos(yaw))])

    cfg = twin.scanner_cfg
    angle_step = float(twin.beam_angles[1] - twin.beam_angles[0]) if len(twin.beam_angles) > 1 else 1.0
    history = torch.zeros(max(policy.build.action_history, 1), 2, dtype=torch.float64)
    target = torch.tensor(episode.target, dtype=torch.float64)
    goal = torch.tensor(episode.goal, dtype=torch.float64)
    poses, reward, reason, steps = [torch.from_numpy(twin.root_pose)], 0.0, EndReason.TIMEOUT, task.max_steps
    for step in range(1, task.max_steps + 1):
        q, omega = twin.imu()
        obs = policy.build(odom_pose=pose(), odom_twist=twin.odom_twist, imu_orientation=q,
                           imu_angular_velocity=omega, goal=goal,
                           scan=Scan(twin.scan(), float(twin.beam_angles[0]), angle_step, cfg.min_range, cfg.max_range),
                           last_actions=history[: policy.build.action_history] if policy.build.action_history else None)
        action = policy(obs).double()
        history = torch.cat([action[None], history[:-1]])
        twin.command(*action_to_twist(action, task.max_linear, task.max_angular).tolist())
        twin.step()
        if on_step is not None:
            on_step(twin)
        if not twin.finite:
            reason, steps = EndReason.NONFINITE, step
            break
        poses.append(torch.from_numpy(twin.root_pose))
        distance = float((torch.from_numpy(twin.root_pose[:2]) - target).norm())
        roll = float(twin.rpy[0])
        end = (EndReason.SUCCESS if distance < task.reach_radius else EndReason.FLIP if abs(roll) > task.flip_roll
               else EndReason.OBSTACLE if twin.contact_flags & FLAG_OBSTACLE else EndReason.WALL if twin.contact_flags
               else None)
        if end is not None:
            reason, steps = end, step
            reward += task.success_reward if end == EndReason.SUCCESS else task.failure_reward
            break
    if len(poses) > 1:  # the terminal step earns no progress terms, as in the environment
        dense = progress_reward(torch.stack(poses)[:, None], target[None], task)[:, 0]
        reward += float(dense[: steps if reason == EndReason.TIMEOUT else steps - 1].sum())
    return int(reason), reward, steps


def run_twin_episodes(policy: DeployablePolicy, episodes: TwinEpisodes, *, friction: float | None = None,
                      on_episode: Callable[[int, int], None] | None = None, odometry: str = "fused",
                      driver: DriverConfig | None = None) -> EpisodeRecord:
    """Run ``policy`` once on each of ``episodes`` in a twin of its world at Coulomb ``friction`` (default: the
    nominal µ), deterministically. ``on_episode(index, end_reason)`` is called after each (progress output);
    ``odometry`` as :func:`run_twin_episode` takes it; ``driver``: the base's motor driver (e.g. a wheel radius
    calibrated on the twin), the task's limits filling those it leaves unset (default: the task's base).

    Returns an :class:`~atrv_warp.task.evaluation.EpisodeRecord` (its ``params`` hold ``friction``)."""
    task = episodes.task
    n = len(episodes.episodes)
    reasons, returns, steps = torch.zeros(n, dtype=torch.long), torch.zeros(n), torch.zeros(n)
    mu = None
    for i, episode in enumerate(episodes.episodes):
        twin = episodes.twin(episode, friction=friction, driver=driver)
        mu = twin.friction
        reasons[i], returns[i], steps[i] = run_twin_episode(policy, twin, episode, task, odometry=odometry)
        if on_episode is not None:
            on_episode(i, int(reasons[i]))
    return EpisodeRecord(reasons, returns, steps, {"friction": torch.full((n,), float(mu or 0.0), dtype=torch.float64)})

