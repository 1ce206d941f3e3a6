"""Configuration of training (SAC or PPO), grouped: run / env / collector / optim / ppo / network / logging.

Every field is documented where it is defined (that text is also the command line's ``--help``). A configuration
comes from, in order: the defaults here, a TOML preset or file (one table per group), then the command line; both
are read by :mod:`atrv_warp.rl.command_line` (:func:`~atrv_warp.rl.command_line.load_train_config`,
:func:`~atrv_warp.rl.command_line.parse_command`). :func:`to_toml` writes a configuration as such a file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import tyro

from atrv_warp.rl.run import resolve_run, task_field_values, toml_value

__all__ = [
    "GROUP_TYPES",
    "CollectorConfig",
    "EnvConfig",
    "LoggingConfig",
    "NetworkConfig",
    "OptimConfig",
    "PPOConfig",
    "RunConfig",
    "TrainConfig",
    "flat_config",
    "to_toml",
    "toml_text",
]

@dataclass(frozen=True)
class RunConfig:
    """Where outputs go, the seed, and the budgets that end a run."""

    name: str = "default"
    """Run name; outputs go to ``<out_dir>/<name>``."""
    out_dir: str = "runs"
    """Parent folder of run folders."""
    seed: int = 0
    """Seeds torch, the training envs and the exploration noise (not the evaluation set)."""
    max_minutes: float = 10.0
    """Wall-clock budget for training, evaluations included [min]; 0 = no limit."""
    total_frames: int = 3_000_000
    """Environment steps (all worlds together) to collect at most."""
    init_from: str = ""
    """A training ``checkpoint.pt`` whose actor, critics and observation statistics start this run (fine-tuning:
    e.g. a policy trained on the nominal rover, continued under ``randomization=wide``); a new run, with its own
    frame count, best policy and evaluations. Empty: start from scratch."""
    threads: int = 1
    """torch threads of the trainer (a second thread makes an update a little cheaper, and the async
    collector needs that core: docs/studies/training.md, from benchmarks/perf/sac_update_cost.py)."""
    device: str = "cpu"
    """Where the whole loop runs: the worlds, the collector, the replay buffer, the networks, their updates and the
    periodic validation (``cpu``, or a CUDA device: ``cuda``, ``cuda:0``). On a GPU the collector is ``sync`` and
    the validation runs in the trainer; the preset ``nav_deploy_gpu`` is shaped for it (docs/gpu.md)."""


@dataclass(frozen=True)
class EnvConfig:
    """The training environments."""

    robot: str = "atrvjr"
    """The robot: a shipped robot's name (``atrvjr``, ``jackal``, ``husky``) or a robot file's path (docs/robots.md).
    The task is fitted to it (its limits, a control period for its speed, radii for its footprint:
    :mod:`atrv_warp.task.scaling`)."""
    task: str = "reach"
    """The task's name (:mod:`atrv_warp.task.registry`): ``reach`` (the reference), ``nav``, ``nav_deploy``, or one
    of yours (``task_module``). Its config's fields are set with ``env.task.<field>=VALUE`` (an ``[env.task]`` table
    in a TOML file, beside ``name``)."""
    task_module: str = ""
    """A Python file that registers tasks of your own (:func:`atrv_warp.task.registry.load_task_module`); empty: the
    shipped tasks only. Imported by every process that builds the task's environments."""
    task_fields: Annotated[tuple[tuple[str, str], ...], tyro.conf.Suppress] = ()
    """The task config's fields this run sets, each as (name, TOML text of its value): ``env.task.reach_radius=0.5``
    on the command line or ``reach_radius = 0.5`` in an ``[env.task]`` table. Checked by name against the task's
    config (:meth:`TrainConfig.task`)."""
    num_envs: int = 256
    """Worlds stepped together by the collector."""
    steps_per_batch: int = 8
    """Steps per world in one collected batch (frames per batch = num_envs x steps_per_batch)."""
    substeps: int = 5
    """Solver substeps per 0.05 s step, in training and its evaluations: 5 (``sim_dt`` 0.01 s, the
    simulator's default) or 3 (:data:`~atrv_warp.sim.FAST_SIM_DT`, a cheaper step that learns a little
    less per frame; docs/performance.md has the figures)."""
    randomization: str = "none"
    """Domain randomization of the training envs and of the evaluations during training: a preset of
    :data:`atrv_warp.task.randomization.RANDOMIZATION_PRESETS` (``none``, ``mild``, ``wide``, ``wide_slip``, ``wide_slip_gain``), or ``around``: each
    physical draw centred on ``sim_config``'s value (:data:`~atrv_warp.task.randomization.AROUND_PRESETS`;
    docs/randomization.md). The run folder's ``randomization.json`` records the ranges it resolved to."""
    eval_randomization: str = ""
    """The periodic (validation) and final (test) evaluations' randomization, a name as :attr:`randomization`'s;
    empty: the training's. A policy may train on a wider distribution than the one it is judged on, e.g.
    ``env.randomization=wide_slip env.eval_randomization=wide`` (validated and tested under ``wide``, the
    evaluation's test distribution: docs/tasks.md)."""
    sim_config: str = ""
    """A simulator-config TOML file applied to every world (``[rover]`` and ``[contact]`` tables), e.g. the
    calibration ``atrv-calibrate`` fitted to a real rover's bag (docs/calibration.md); empty: the nominal rover."""
    map: tuple[str, ...] = ()
    """Nav2 ``map_server`` maps (YAML files) or procedural places sized for the robot (``building:64``: 64 buildings,
    seeds 0-63; ``yard:16@100``: seeds 100-115) the worlds drive in, world ``w`` in map ``w % len(maps)``, each
    episode's start and target in a map's free space (``env.map=site.yaml``, ``env.map=[building:32,yard:32]``,
    ``--map site.yaml``); empty: the task's arena."""

    def env_kwargs(self) -> tuple[tuple[str, object], ...]:
        """:class:`~atrv_warp.task.env.RoverEnv` keyword arguments of these environments, as
        (name, value) pairs (:class:`~atrv_warp.task.env.EnvFactory` takes them so)."""
        from atrv_warp.sim.config import SimConfig

        step_dt = SimConfig().step_dt
        kwargs = (("task", self.task), ("sim", SimConfig(sim_dt=step_dt / self.substeps)),
                  ("randomization", self.randomization), ("robot", self.robot))
        if self.task_module:
            kwargs = (*kwargs, ("task_module", self.task_module))
        kwargs = (*kwargs, *task_field_values(self).items())
        if self.map:
            kwargs = (*kwargs, ("maps", self.map))
        return (*kwargs, ("sim_config", self.sim_config)) if self.sim_config else kwargs

    def eval_env_kwargs(self) -> tuple[tuple[str, object], ...]:
        """:meth:`env_kwargs` of the evaluations' environments (:attr:`eval_randomization`, if set)."""
        return tuple((k, self.eval_randomization or v) if k == "randomization" else (k, v)
                     for k, v in self.env_kwargs())


def toml_text(value) -> str:
    """A field's value as TOML writes it (``true``, ``0.5``, ``"rolling"``, ``[5.0, 8.0]``)."""
    return str(value).lower() if isinstance(value, bool) else json.dumps(value)


@dataclass(frozen=True)
class CollectorConfig:
    """How frames are collected."""

    kind: Literal["async", "sync", "ray"] = "async"
    """``async``: a separate worker process collects on its own core while the trainer updates;
    ``sync``: collect and update in turn, in this process (bit-reproducible); ``ray``:
    ``num_collectors`` Ray actors collect, on this machine or a Ray cluster (needs the ``ray``
    extra; docs/training.md, 'Scale out on Ray')."""
    init_random_frames: int = 20_000
    """Frames collected with uniform random actions before learning starts (also the data the
    observation statistics are computed from)."""
    noise_correlation: float = 0.0
    """SAC only: correlation in [0, 1) of the collectors' exploration noise from one step to the next (0: SAC's
    own independent sampling; :mod:`atrv_warp.rl.exploration`). Velocity actions need it: a motor driver averages
    independent commands away (the ``nav_deploy`` preset: 0.9, about 0.5 s)."""
    num_collectors: int = 2
    """``ray`` only: collector actors, one CPU each; each delivers its own batches, first ready
    first served, and gets the learner's weights after each."""
    envs_per_collector: int = 0
    """``ray`` only: worlds stepped together by each collector; 0 = ``num_envs``."""
    ray_address: str = ""
    """``ray`` only: empty = start a local Ray sized to this machine (stopped at the end of the run);
    ``auto`` = join the cluster this node is part of (``ray start``); or the head's ``HOST:PORT``."""
    ray_resource: str = ""
    """``ray`` only: a custom Ray resource each collector needs one unit of, to place collectors on
    the nodes started with ``ray start --resources='{"NAME": N}'``; empty = any node with a free CPU."""


@dataclass(frozen=True)
class OptimConfig:
    """The algorithm, and SAC's updates: the loss, replay, batch, learning rates and targets."""

    algo: Literal["sac", "ppo"] = "sac"
    """``sac``: off-policy, from a replay buffer (the ``loss`` below); ``ppo``: on-policy, TorchRL's
    ``ClipPPOLoss`` on GAE advantages of each collected batch (the ``ppo`` group; ``lr`` and ``gamma``
    apply to both; presets ``ppo`` and ``nav_ppo``)."""
    loss: Literal["sac", "crossq", "redq"] = "sac"
    """TorchRL loss of the SAC family: ``sac`` (two critics with target networks); ``crossq``
    (CrossQ: batch-renormalised critics and no target networks, ``tau`` unused); ``redq`` (REDQ: ten
    critics with targets, the minimum of two drawn at random per update)."""

    buffer_size: int = 1_000_000
    """Replay capacity [frames]."""
    batch_size: int = 256
    """Transitions per gradient step (256: a step is cheaper than at 512 and learns as well;
    docs/studies/training.md has the figures)."""
    utd_ratio: float = 0.03125
    """Gradient steps per collected frame (1/32: one update per 32 frames)."""
    lr: float = 1e-3
    """Adam learning rate, actor, critics and temperature (on the reach task 1e-3 first passes 90 % in
    several times fewer gradient steps than 3e-4; docs/studies/training.md has the figures)."""
    lr_final_fraction: float = 1.0
    """The learning rate falls linearly with the frames collected, from ``lr`` at the start to ``lr`` x this at
    ``total_frames`` (1: constant), so that a run's last updates are small ones (the nav preset: 0.1)."""
    gamma: float = 0.99
    """Discount."""
    tau: float = 0.005
    """Target-network soft-update rate."""
    init_alpha: float = 1.0
    """Initial entropy temperature (learned)."""
    compile: Literal["off", "compile", "cudagraphs"] = "off"
    """SAC's update as one function, built once and replayed: ``off`` (eager, as every CPU figure was measured);
    ``compile`` (``torch.compile`` of the update: loss, backward, optimiser steps and target update); ``cudagraphs``
    (CUDA only: the update captured in a CUDA graph, ``tensordict.nn.CudaGraphModule``, with capturable Adam). Built,
    the learning rate is a tensor the annealing changes in place. The first updates compile or capture; the figures
    are the same function's (docs/gpu.md)."""


@dataclass(frozen=True)
class PPOConfig:
    """PPO's updates (``algo=ppo``): several passes of minibatches over each collected batch."""

    epochs: int = 4
    """Passes over each collected batch."""
    minibatch_size: int = 4096
    """Transitions per gradient step (a batch of ``num_envs x steps_per_batch`` frames is split into these)."""
    clip_epsilon: float = 0.2
    """Clip range of the probability ratio."""
    gae_lambda: float = 0.95
    """GAE's lambda (bias-variance trade-off of the advantages)."""
    entropy_coef: float = 0.001
    """Weight of the entropy bonus."""
    critic_coef: float = 0.5
    """Weight of the value loss."""
    max_grad_norm: float = 1.0
    """Gradient-norm clip of every step."""


@dataclass(frozen=True)
class NetworkConfig:
    """Actor and critic networks."""

    width: int = 128
    """Hidden units per layer, actor and critics."""
    depth: int = 2
    """Hidden layers, actor and critics."""


@dataclass(frozen=True)
class LoggingConfig:
    """Evaluations, scalars and the console."""

    eval_every_frames: int = 100_000
    """Deterministic evaluation interval [frames]."""
    eval_episodes: int = 256
    """Seeded episodes per periodic evaluation (a fixed validation set, seed ``VALIDATION_SEED``; the best policy is
    picked on it, and only the final evaluation sees the test set, seed ``EVAL_SEED``)."""
    final_eval_episodes: int = 1000
    """Episodes of the final evaluation of the best policy."""
    eval_in_background: bool = True
    """Run the periodic evaluation in a process of its own on the second core, while the training goes on (its
    figures are logged at the frames of the weights it judged, once it ends; ``eval_known_wall_s`` says when);
    ``false``: in the trainer, which waits for it. ``logger=rerun`` keeps it in the trainer, whose recording
    holds the evaluation's worlds."""
    logger: Literal["csv", "tensorboard", "rerun", "wandb", "mlflow"] = "csv"
    """Scalars always go to CSV (the learning curve is drawn from it); ``tensorboard`` adds a
    TensorBoard log, ``rerun`` a Rerun recording (``train.rrd``) that also holds two worlds of
    every periodic evaluation; ``wandb`` a Weights & Biases run, ``mlflow`` an MLflow run (the
    ``track`` extra). Every one but CSV also gets the hyperparameters and the evaluation videos."""
    project: str = "atrv_warp"
    """``wandb``: the W&B project; ``mlflow``: the MLflow experiment."""
    wandb_mode: Literal["offline", "online"] = "offline"
    """``offline``: the W&B run folder is written under ``logs/wandb`` (upload it later with ``wandb
    sync``); ``online``: logged live (needs ``wandb login``)."""
    mlflow_uri: str = ""
    """MLflow tracking URI; empty = a SQLite store in the run folder (``logs/mlflow.db``, artifacts in
    ``logs/mlflow_artifacts``)."""
    video_episodes: int = 4
    """Episodes of every periodic evaluation drawn top down into an MP4 (``videos/`` in the run
    folder, and to the logger); 0 = no video."""
    progress: bool = True
    """Show a progress bar on a terminal (one line per evaluation otherwise)."""


@dataclass(frozen=True)
class TrainConfig:
    """Training of the drive-to-target task, SAC or PPO (``python -m atrv_warp.train``).

    Defaults are chosen by measurement on a 2-core CPU (docs/training.md; the figures in docs/studies/training.md).
    """

    run: RunConfig = field(default_factory=RunConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    logging: LoggingConfig = field(default_factory=LoggingConfig)

    @property
    def worlds_per_collector(self) -> int:
        """Worlds one collector steps: ``envs_per_collector`` (or ``num_envs``) for ``ray``, else ``num_envs``."""
        if self.collector.kind == "ray" and self.collector.envs_per_collector:
            return self.collector.envs_per_collector
        return self.env.num_envs

    @property
    def frames_per_batch(self) -> int:
        """Frames in one batch the trainer receives (``ray``: one collector's batch)."""
        return self.worlds_per_collector * self.env.steps_per_batch

    def validate(self) -> TrainConfig:
        """Raise ``ValueError`` naming the first bad value."""
        positive = {"run": ("total_frames", "threads"), "env": ("num_envs", "steps_per_batch", "substeps"),
                    "collector": ("num_collectors",),
                    "optim": ("buffer_size", "batch_size", "lr", "tau", "init_alpha", "utd_ratio"),
                    "ppo": ("epochs", "minibatch_size", "clip_epsilon", "max_grad_norm"),
                    "network": ("width", "depth"),
                    "logging": ("eval_every_frames", "eval_episodes", "final_eval_episodes")}
        for group, names in positive.items():
            for name in names:
                value = getattr(getattr(self, group), name)
                if not value > 0:
                    raise ValueError(f"train config: {name} must be > 0, got {value}")
        if not 0.0 <= self.optim.lr_final_fraction <= 1.0:
            raise ValueError(f"train config: lr_final_fraction must be in [0, 1], got {self.optim.lr_final_fraction}")
        if not 0.0 < self.optim.gamma <= 1.0:
            raise ValueError(f"train config: gamma must be in (0, 1], got {self.optim.gamma}")
        if self.run.max_minutes < 0 or self.collector.init_random_frames < 0 or self.collector.envs_per_collector < 0:
            raise ValueError("train config: max_minutes, init_random_frames and envs_per_collector must be >= 0")
        if not 0.0 <= self.collector.noise_correlation < 1.0:
            raise ValueError(f"train config: noise_correlation must be in [0, 1), got {self.collector.noise_correlation}")
        if self.collector.noise_correlation and self.optim.algo == "ppo":
            raise ValueError("train config: noise_correlation is for SAC; PPO learns from its own samples' "
                             "log-probabilities (set noise_correlation=0)")
        if self.logging.video_episodes < 0:
            raise ValueError(f"train config: video_episodes must be >= 0, got {self.logging.video_episodes}")
        if not 0.0 <= self.ppo.gae_lambda <= 1.0:
            raise ValueError(f"train config: gae_lambda must be in [0, 1], got {self.ppo.gae_lambda}")
        self._validate_device()
        if self.optim.batch_size > self.optim.buffer_size:
            raise ValueError("train config: batch_size must not exceed buffer_size")
        self._validate_values()
        name = self.run.name
        if not name or name in (".", "..") or "/" in name or "\\" in name or name != name.strip():
            raise ValueError(f"train config: name must be a folder name inside out_dir (no '/', not '..'), got {name!r}")
        out_dir = Path(self.run.out_dir)
        if out_dir.exists() and not out_dir.is_dir():
            raise ValueError(f"train config: out_dir {out_dir} is a file, not a folder")
        # the task, its fields, the sim config file and the randomizations: named where they fail
        self._validate_memory(resolve_run(self))
        return self

    def _validate_values(self) -> None:
        """Every number is finite and every text free of control characters (a NaN ``max_minutes`` trained for ever,
        a NUL in ``name`` made a folder no tool could open), named."""
        for group in dataclasses.fields(self):
            for f in dataclasses.fields(getattr(self, group.name)):
                value = getattr(getattr(self, group.name), f.name)
                for item in (value if isinstance(value, tuple) else (value,)):
                    for part in (item if isinstance(item, tuple) else (item,)):
                        if isinstance(part, float) and not math.isfinite(part):
                            raise ValueError(f"train config: {group.name}.{f.name} must be a finite number, got "
                                             f"{value!r}")
                        if isinstance(part, str) and any(ord(c) < 32 or ord(c) == 127 for c in part):
                            raise ValueError(f"train config: {group.name}.{f.name} holds a control character: "
                                             f"{part!r}")

    def _validate_memory(self, run) -> None:
        """Refuse, before anything is allocated, a run whose replay buffer, batches and worlds would not fit in the
        machine's memory (the host's; the GPU's for the buffer on a CUDA device), naming the largest."""
        import os

        from atrv_warp.task.sensors import sensor_fields
        from atrv_warp.task.spec import observation_fields

        obs = len(observation_fields(run.task.config, sensor_fields(run.task.config, run.robot)))
        frame = 4 * (2 * obs + 8) + 8  # observation and next observation, action, reward, flags [bytes]
        needs = {"optim.buffer_size": self.optim.buffer_size * frame,
                 "env.num_envs x env.steps_per_batch": 2 * self.frames_per_batch * self.collector.num_collectors * frame,
                 "env.num_envs": (self.env.num_envs * self.collector.num_collectors + self.logging.eval_episodes)
                 * WORLD_BYTES}
        if self.run.device != "cpu":
            import torch

            gpu = torch.cuda.get_device_properties(torch.device(self.run.device)).total_memory
            if needs["optim.buffer_size"] > gpu:
                raise ValueError(f"train config: buffer_size={self.optim.buffer_size:,} needs about "
                                 f"{needs['optim.buffer_size'] / 2**30:.1f} GiB on {self.run.device}, which has "
                                 f"{gpu / 2**30:.1f} GiB")
            needs.pop("optim.buffer_size")
        ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        if sum(needs.values()) > ram:
            largest = max(needs, key=needs.get)
            raise ValueError(f"train config: this run needs about {sum(needs.values()) / 2**30:,.1f} GiB of memory "
                             f"({largest} alone {needs[largest] / 2**30:,.1f} GiB), and the machine has "
                             f"{ram / 2**30:.1f} GiB: lower {largest.replace(' x ', ' or ')}")

    def _validate_device(self) -> None:
        import torch

        device, kind = self.run.device, self.collector.kind
        try:
            parsed = torch.device(device)
        except (RuntimeError, TypeError) as err:
            raise ValueError(f"train config: device must be cpu or a CUDA device (cuda, cuda:0), got {device!r}: "
                             f"{err}") from None
        if parsed.type not in ("cpu", "cuda") or (parsed.type == "cpu" and parsed.index not in (None, 0)):
            raise ValueError(f"train config: device must be cpu (one device, whatever its cores) or a CUDA device "
                             f"(cuda, cuda:0), got {device!r}")
        if parsed.type == "cuda":
            if not torch.cuda.is_available():
                raise ValueError(f"train config: device={device} but this torch ({torch.__version__}) sees no CUDA "
                                 "device; train on device=cpu, or install a CUDA build of torch on a machine with a "
                                 "GPU")
            if parsed.index is not None and parsed.index >= torch.cuda.device_count():
                raise ValueError(f"train config: device={device} but there are {torch.cuda.device_count()} CUDA "
                                 "device(s)")
            if kind != "sync":
                raise ValueError(f"train config: device={device} steps the worlds in the trainer's process, on the "
                                 f"GPU: set collector.kind=sync (collector {kind} steps them in CPU processes; the "
                                 "preset nav_deploy_gpu sets it)")
        if self.optim.compile == "cudagraphs" and parsed.type != "cuda":
            raise ValueError("train config: compile=cudagraphs captures CUDA graphs: it needs device=cuda (on the "
                             "CPU: compile=off or compile=compile)")
        if self.optim.compile != "off" and self.optim.algo != "sac":
            raise ValueError(f"train config: compile={self.optim.compile} builds SAC's update; PPO runs eager "
                             "(compile=off)")


WORLD_BYTES = 64 << 10
"""Memory one simulated world takes, at most [bytes] (``nav_deploy``'s measured 26 KB a world at 1,024 worlds, with a
margin): what :meth:`TrainConfig.validate` counts the worlds at before any is built."""

GROUP_TYPES: dict[str, type] = typing.get_type_hints(TrainConfig)
"""Each group's name and its config class, in :class:`TrainConfig`'s order (``run``, ``env``, ...)."""


def flat_config(cfg: TrainConfig) -> dict[str, object]:
    """Every field as ``{"group.field": value}``: the hyperparameters a logger records."""
    return {f"{group}.{f.name}": getattr(getattr(cfg, group), f.name)
            for group in GROUP_TYPES for f in dataclasses.fields(getattr(cfg, group))}


def to_toml(cfg: TrainConfig) -> str:
    """The configuration as TOML, one table per group (what ``load_train_config`` reads back)."""
    lines = []
    for group in GROUP_TYPES:
        lines.append(f"[{group}]")
        for f in dataclasses.fields(getattr(cfg, group)):
            if (group, f.name) in (("env", "task"), ("env", "task_fields")):
                continue  # the [env.task] table below
            v = getattr(getattr(cfg, group), f.name)
            lines.append(f"{f.name} = {toml_text(v)}")
        if group == "env":
            lines += ["", "[env.task]", f"name = {json.dumps(cfg.env.task)}",
                      *(f"{name} = {text if toml_value(text) is not text else json.dumps(text)}"
                        for name, text in cfg.env.task_fields)]
        lines.append("")
    return "\n".join(lines)
