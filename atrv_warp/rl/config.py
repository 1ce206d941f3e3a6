"""Configuration of SAC training, grouped: run / env / collector / optim / network / logging.

Every field is documented where it is defined (that text is also the command line's ``--help``).
A configuration comes from, in order: the defaults here, a TOML preset or file (tables per
group, or flat ``key = value`` with the field names, as older runs wrote them), then the command
line, parsed by `tyro <https://brentyi.github.io/tyro/>`_: ``--optim.lr 1e-3``, or the short
form ``lr=1e-3`` with a field's name alone. An unknown key or a bad value stops before any work.
"""

from __future__ import annotations

import dataclasses
import tomllib
import typing
from dataclasses import dataclass, field
from importlib import resources
from typing import Literal

__all__ = [
    "CollectorConfig",
    "EnvConfig",
    "LoggingConfig",
    "NetworkConfig",
    "OptimConfig",
    "RunConfig",
    "TrainConfig",
    "cli_args",
    "load_train_config",
    "preset_names",
    "to_toml",
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
    threads: int = 1
    """torch threads of the trainer (benchmarks/sac_update_cost.py: a second thread saves about 20 % per
    update, and the async collector needs that core)."""


@dataclass(frozen=True)
class EnvConfig:
    """The training environments."""

    task: str = "reach"
    """Registered task (:data:`atrv_warp.task.config.TASK_VARIANTS`): ``reach`` (the reference) or ``nav``."""
    num_envs: int = 256
    """Worlds stepped together by the collector."""
    steps_per_batch: int = 8
    """Steps per world in one collected batch (frames per batch = num_envs x steps_per_batch)."""
    substeps: int = 5
    """Solver substeps per 0.05 s step, in training and its evaluations: 5 (``sim_dt`` 0.01 s, the
    simulator's default) or 3 (:data:`~atrv_warp.sim.FAST_SIM_DT`, a step about 1.4x cheaper, learning a
    little less per frame; README, 'Simulator speed')."""

    def env_kwargs(self) -> tuple[tuple[str, object], ...]:
        """:class:`~atrv_warp.task.env.ATRVjrEnv` keyword arguments of these environments, as
        (name, value) pairs (:class:`~atrv_warp.task.env.EnvFactory` takes them so)."""
        from atrv_warp.sim.config import SimConfig

        step_dt = SimConfig().step_dt
        return (("task", self.task), ("sim", SimConfig(sim_dt=step_dt / self.substeps)))


@dataclass(frozen=True)
class CollectorConfig:
    """How frames are collected."""

    kind: Literal["async", "sync", "ray"] = "async"
    """``async``: a separate worker process collects on its own core while the trainer updates;
    ``sync``: collect and update in turn, in this process (bit-reproducible); ``ray``:
    ``num_collectors`` Ray actors collect, on this machine or a Ray cluster (needs the ``ray``
    extra; README, 'Scale out on Ray')."""
    init_random_frames: int = 20_000
    """Frames collected with uniform random actions before learning starts (also the data the
    observation statistics are computed from)."""
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
    """SAC's updates: the loss, replay, batch, learning rates and targets."""

    loss: Literal["sac", "crossq", "redq"] = "sac"
    """TorchRL loss of the SAC family: ``sac`` (two critics with target networks); ``crossq``
    (CrossQ: batch-renormalised critics and no target networks, ``tau`` unused); ``redq`` (REDQ: ten
    critics with targets, the minimum of two drawn at random per update)."""

    buffer_size: int = 1_000_000
    """Replay capacity [frames]."""
    batch_size: int = 256
    """Transitions per gradient step (256: a step costs ~25 % less than at 512 and learns as well,
    README 'Training')."""
    utd_ratio: float = 0.03125
    """Gradient steps per collected frame (1/32: one update per 32 frames)."""
    lr: float = 1e-3
    """Adam learning rate, actor, critics and temperature (on the reach task 1e-3 first passes 90 %
    after about 2,500 gradient steps, 3e-4 after about 12,000: README 'Training')."""
    gamma: float = 0.99
    """Discount."""
    tau: float = 0.005
    """Target-network soft-update rate."""
    init_alpha: float = 1.0
    """Initial entropy temperature (learned)."""


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
    """Seeded episodes per periodic evaluation (fixed set, seed EVAL_SEED)."""
    final_eval_episodes: int = 1000
    """Episodes of the final evaluation of the best policy."""
    logger: Literal["csv", "tensorboard", "rerun"] = "csv"
    """Scalars always go to CSV (the learning curve is drawn from it); ``tensorboard`` adds a
    TensorBoard log, ``rerun`` a Rerun recording (``train.rrd``) that also holds two worlds of
    every periodic evaluation."""
    progress: bool = True
    """Show a progress bar on a terminal (one line per evaluation otherwise)."""


@dataclass(frozen=True)
class TrainConfig:
    """SAC training of the drive-to-target task (``python -m atrv_warp.train``).

    Defaults are chosen by measurement on a 2-core CPU (README, 'Training').
    """

    run: RunConfig = field(default_factory=RunConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
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
                    "network": ("width", "depth"),
                    "logging": ("eval_every_frames", "eval_episodes", "final_eval_episodes")}
        for group, names in positive.items():
            for name in names:
                value = getattr(getattr(self, group), name)
                if not value > 0:
                    raise ValueError(f"train config: {name} must be > 0, got {value}")
        if not 0.0 < self.optim.gamma <= 1.0:
            raise ValueError(f"train config: gamma must be in (0, 1], got {self.optim.gamma}")
        if self.run.max_minutes < 0 or self.collector.init_random_frames < 0 or self.collector.envs_per_collector < 0:
            raise ValueError("train config: max_minutes, init_random_frames and envs_per_collector must be >= 0")
        if self.optim.batch_size > self.optim.buffer_size:
            raise ValueError("train config: batch_size must not exceed buffer_size")
        from atrv_warp.task.config import get_task

        get_task(self.env.task)  # names the known tasks if this one is not
        return self


_GROUP_TYPES = typing.get_type_hints(TrainConfig)
_FIELD_GROUP: dict[str, str] = {f.name: g for g, cls in _GROUP_TYPES.items() for f in dataclasses.fields(cls)}
"""Field name -> its group: every field name is unique across groups, so ``lr=3e-4`` is enough."""
_ALIASES = {"collector": ("collector", "kind")}
"""Short keys that are not field names: ``collector=sync`` is ``collector.kind``."""


def _locate(key: str) -> tuple[str, str]:
    """``(group, field)`` of a short (``lr``, ``collector``) or dotted (``optim.lr``) key; ``("", key)``
    if there is none."""
    if key in _ALIASES:
        return _ALIASES[key]
    group, _, name = key.rpartition(".")
    group = group or _FIELD_GROUP.get(name, "")
    if group in _GROUP_TYPES and name in _field_types(group):
        return group, name
    return "", key


def _known() -> list[str]:
    return sorted(set(_FIELD_GROUP) | set(_ALIASES))


def _field_types(group: str) -> dict:
    return typing.get_type_hints(_GROUP_TYPES[group])


def _coerce(kind, name: str, value):
    """Convert a TOML value or command-line string to a field's type, naming the field on failure."""
    if typing.get_origin(kind) is Literal:
        choices = typing.get_args(kind)
        if value not in choices:
            raise ValueError(f"train config: {name} must be one of {list(choices)}, got {value!r}")
        return value
    label = kind.__name__
    if isinstance(value, str) and kind is not str:
        text = value.strip().lower()
        if kind is bool:
            if text in ("1", "true", "yes", "on"):
                return True
            if text in ("0", "false", "no", "off"):
                return False
            raise ValueError(f"train config: {name} expects true/false, got {value!r}")
        try:
            value = float(text.replace("_", "")) if kind is float else int(text.replace("_", ""))
        except ValueError:
            raise ValueError(f"train config: {name} expects {label}, got {value!r}") from None
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind is int and isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise ValueError(f"train config: {name} expects {label}, got {value!r}")
    return value


def _grouped(values: dict, where: str) -> dict[str, dict]:
    """``{group: {field: value}}`` from TOML tables and/or flat ``field`` / ``group.field`` keys."""
    out: dict[str, dict] = {g: {} for g in _GROUP_TYPES}
    unknown = []
    for key, value in values.items():
        if key in _GROUP_TYPES and isinstance(value, dict):
            for name, v in value.items():
                if name in _field_types(key):
                    out[key][name] = v
                else:
                    unknown.append(f"{key}.{name}")
            continue
        group, name = _locate(key)
        if group:
            out[group][name] = value
        else:
            unknown.append(key)
    if unknown:
        raise ValueError(f"unknown train config key(s) {sorted(unknown)}{where}; known: {_known()}")
    return out


def preset_names() -> list[str]:
    """Names of the training presets shipped inside the package (``atrv_warp/rl/configs/*.toml``)."""
    folder = resources.files("atrv_warp.rl").joinpath("configs")
    return sorted(f.name.removesuffix(".toml") for f in folder.iterdir() if f.name.endswith(".toml"))


def _read_config_source(source: str) -> tuple[str, bytes]:
    """``(label, TOML bytes)`` for a preset name (``smoke``) or a file path (``my.toml``)."""
    import os

    if os.path.isfile(source):
        with open(source, "rb") as fh:
            return source, fh.read()
    name = source
    if source.endswith(".toml") and os.path.basename(os.path.dirname(source)) == "configs":
        name = os.path.basename(source).removesuffix(".toml")  # `configs/smoke.toml`: the packaged preset
    if name in preset_names():  # packaged, so a non-editable install has the same defaults
        return f"preset {name!r}", resources.files("atrv_warp.rl").joinpath(f"configs/{name}.toml").read_bytes()
    raise FileNotFoundError(f"config {source!r} is neither a file nor a preset; presets: {preset_names()}")


def load_train_config(source: str | None = None, overrides: dict | None = None) -> TrainConfig:
    """Read a TOML config, apply ``overrides`` (``{"lr": "1e-3"}`` or ``{"optim.lr": ...}``), check
    every key and value.

    ``source`` is a preset name (:func:`preset_names`: ``default``, ``nav``, ``smoke``), a file path
    (``configs/<preset>.toml`` that is not a file names the packaged preset), or ``None`` for the
    :class:`TrainConfig` defaults alone.
    """
    values: dict = {}
    label = None
    if source is not None:
        label, text = _read_config_source(str(source))
        try:
            values.update(tomllib.loads(text.decode()))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise ValueError(f"{label}: not valid TOML: {err}") from None
    grouped = _grouped(values, f" in {label}" if label else "")
    for group, fields in _grouped(dict(overrides or {}), "").items():
        grouped[group].update(fields)
    parts = {}
    for group, fields in grouped.items():
        types = _field_types(group)
        parts[group] = _GROUP_TYPES[group](**{k: _coerce(types[k], k, v) for k, v in fields.items()})
    return TrainConfig(**parts).validate()


def cli_args(tokens: list[str]) -> list[str]:
    """Command-line tokens for tyro: ``lr=1e-3`` or ``optim.lr=1e-3`` become ``--optim.lr 1e-3``;
    everything else passes through. An unknown short key is a ``ValueError`` naming it."""
    out = []
    for token in tokens:
        key, eq, value = token.partition("=")
        if not eq or token.startswith("-"):
            out.append(token)
            continue
        group, name = _locate(key)
        if not group:
            raise ValueError(f"unknown train config key(s) [{key!r}]; known: {_known()}")
        if _field_types(group)[name] is bool:  # tyro's spelling; a bad value is tyro's error to name
            value = {"1": "True", "true": "True", "yes": "True", "on": "True", "0": "False", "false": "False",
                     "no": "False", "off": "False"}.get(value.strip().lower(), value)
        out += [f"--{group}.{name.replace('_', '-')}", value]
    return out


def to_toml(cfg: TrainConfig) -> str:
    """The configuration as TOML, one table per group (what ``load_train_config`` reads back)."""
    import json

    lines = []
    for group in _GROUP_TYPES:
        lines.append(f"[{group}]")
        for f in dataclasses.fields(getattr(cfg, group)):
            v = getattr(getattr(cfg, group), f.name)
            lines.append(f"{f.name} = {str(v).lower() if isinstance(v, bool) else json.dumps(v)}")
        lines.append("")
    return "\n".join(lines)
