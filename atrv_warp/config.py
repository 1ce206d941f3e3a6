"""Configuration of the rover, the contact law, the arena and the integrator.

Every physical quantity carries its SI unit. Configs are frozen dataclasses: derive a
variant with :func:`dataclasses.replace`, never mutate a shared default.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from importlib import resources

__all__ = [
    "VARIANTS",
    "ArenaConfig",
    "ContactConfig",
    "InertialOverride",
    "RoverConfig",
    "SimConfig",
    "default_urdf_path",
    "get_variant",
    "load_train_config",
    "preset_names",
    "replace_checked",
]


def default_urdf_path() -> str:
    """Path of the ATRV-Jr URDF shipped inside the package."""
    return str(resources.files("atrv_warp").joinpath("assets/atrvjr.urdf"))


@dataclass(frozen=True)
class InertialOverride:
    """Replaces the mass properties a URDF gives one link (used by the ``reference`` variant)."""

    link: str
    """Name of the link whose inertial is replaced."""
    mass: float
    """Mass [kg]."""
    inertia_diag: tuple[float, float, float] | None = None
    """Principal moments about the link's inertial frame [kg·m²]; ``None`` keeps the
    URDF's inertia tensor scaled by the mass ratio."""


@dataclass(frozen=True)
class RoverConfig:
    """Which URDF to load, which links play which role, and how the wheels are driven."""

    urdf: str | None = None
    """Path of the URDF; ``None`` uses the packaged ``atrvjr.urdf``."""
    chassis_link: str = "center_link"
    """Link joined to the world by the free 6-DOF joint."""
    left_wheels: tuple[str, ...] = ("left_front_wheel_link", "left_rear_wheel_link")
    """Wheel links driven by the first (left) command."""
    right_wheels: tuple[str, ...] = ("right_front_wheel_link", "right_rear_wheel_link")
    """Wheel links driven by the second (right) command."""
    sensor_frames: tuple[str, ...] = ("cbimu_frame", "mpuimu_frame", "arm_base_frame", "lrf_frame", "novatel")
    """Links fixed to the chassis that must exist; kept as named frames."""
    wheel_radius: float = 0.125
    """Radius of the wheel collision cylinder [m]."""
    wheel_length: float = 0.075
    """Length (width) of the wheel collision cylinder [m]."""
    wheel_offset: float = 0.03
    """Offset of the cylinder centre from the wheel joint along the axle, outward [m]."""
    wheel_speed_limit: float = 50.0
    """Motor no-load speed [rad/s] (50 rad/s = 6.25 m/s at the rim). Drive torque tapers linearly
    from full at 80 % of this speed to zero at it, like a DC motor's back-EMF; an
    unbounded torque source otherwise spins a slipping wheel to 1000+ rad/s."""
    inertial_overrides: tuple[InertialOverride, ...] = ()
    """Mass-property replacements applied after loading the URDF."""


@dataclass(frozen=True)
class ContactConfig:
    """Hunt–Crossley penalty contact with regularised Coulomb friction.

    Normal force per contact point, penetration ``d`` [m] and its rate ``d_dot`` [m/s]:
    ``f_n = kp d^n + kc d^n d_dot`` (clamped at 0, no adhesion). Below ``linear_region``
    the ``d^n`` factor is replaced by its secant ``linear_region^(n-1) d`` so the stiffness
    stays finite at first touch. Defaults are the reference simulation's figures.
    """

    stiffness: float = 1.0e5
    """kp [N/m^n]."""
    damping: float = 2.0e4
    """kc [N·s/m^(n+1)]."""
    exponent: float = 1.5
    """n, Hertz-like exponent [-]."""
    linear_region: float = 1.0e-3
    """Penetration below which the law is linear [m]."""
    friction: float = 0.3
    """Coulomb coefficient mu [-]."""
    friction_slope_fraction: float = 0.5
    """Low-slip viscous slope of the friction law as a fraction of the largest slope an
    explicit step of ``sim_dt`` stays stable with (``m_eff / sim_dt`` per contact direction).
    Friction is ``mu f_n`` once slip exceeds ``mu f_n dt / (fraction m_eff)``; below it,
    proportional to slip. 0.5 halves the slip velocity twice per substep without overshoot."""


@dataclass(frozen=True)
class ArenaConfig:
    """Ground box and four walls of the reference arena."""

    size: float = 30.0
    """Side of the square ground [m]."""
    ground_thickness: float = 0.25
    """[m]"""
    ground_center_z: float = -0.1
    """Height of the ground box centre [m]; the top is at centre + thickness/2 = 0.025 m."""
    wall_thickness: float = 0.25
    """[m]"""
    wall_height: float = 2.5
    """[m]"""
    target_radius: float = 0.25
    """Radius of the target disc (graphics only) [m]."""

    @property
    def ground_top(self) -> float:
        """Height of the driving surface [m]."""
        return self.ground_center_z + 0.5 * self.ground_thickness

    @property
    def half_size(self) -> float:
        """Distance from the centre to each wall's inner face [m]."""
        return 0.5 * self.size


@dataclass(frozen=True)
class SimConfig:
    """Integrator settings. Chosen by measurement (see README, 'Choices')."""

    step_dt: float = 0.05
    """Simulated time of one environment step [s]."""
    sim_dt: float = 0.01
    """Solver substep [s]; the reference integrated RK4 at 0.01 s."""
    gravity: float = -9.81
    """[m/s²] along z."""
    mass_matrix_interval: int | None = None
    """Featherstone mass-matrix refresh interval in substeps; ``None`` = once per step
    (``substeps``), aligned with step boundaries so a reset never meets a stale matrix."""
    use_tile_gemm: bool = True
    """Use Warp's tile API for the mass-matrix factorisation: 2.1x faster at N=1024 on CPU
    (50k vs 24k env-steps/s, benchmarks/sim_throughput.py)."""
    use_graph: bool = True
    """Record the whole step once (``wp.ScopedCapture``) and replay it."""

    @property
    def substeps(self) -> int:
        """Solver substeps per environment step."""
        n = round(self.step_dt / self.sim_dt)
        if n < 1 or not math.isclose(n * self.sim_dt, self.step_dt, rel_tol=1e-9):
            raise ValueError(f"step_dt={self.step_dt} is not a whole multiple of sim_dt={self.sim_dt}")
        return n


_REFERENCE_INERTIALS = (
    InertialOverride("center_link", 50.0),
    *(
        InertialOverride(w, 1.0, (1.0, 1.0, 1.0))
        for w in ("left_front_wheel_link", "left_rear_wheel_link", "right_front_wheel_link", "right_rear_wheel_link")
    ),
)

VARIANTS: dict[str, RoverConfig] = {
    "realistic": RoverConfig(),
    "reference": RoverConfig(inertial_overrides=_REFERENCE_INERTIALS),
}
"""Registered rover variants. ``realistic``: masses and inertias from geometry (58 kg).
``reference``: the reference simulation's chassis 50 kg, wheels 1 kg with a placeholder
1 kg·m² inertia, which is why it accelerated at only ~0.4 m/s²."""


def get_variant(name: str) -> RoverConfig:
    """Return the registered :class:`RoverConfig` called ``name``."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown rover variant {name!r}; known: {sorted(VARIANTS)}") from None


def replace_checked(cfg, **changes):
    """:func:`dataclasses.replace` that names an unknown field instead of a TypeError."""
    names = {f.name for f in dataclasses.fields(cfg)}
    unknown = sorted(set(changes) - names)
    if unknown:
        raise ValueError(f"unknown {type(cfg).__name__} key(s) {unknown}; known: {sorted(names)}")
    return dataclasses.replace(cfg, **changes)



@dataclass(frozen=True)
class TaskConfig:
    """The reference drive-to-target task."""

    spawn_bound: float = 12.0
    """Targets and starts are uniform in [-bound, bound]² [m] (arena half size - 3)."""
    reach_radius: float = 1.0
    """Success when the chassis is this close to the target [m]."""
    flip_roll: float = 0.2
    """|roll| above this is a flip [rad]."""
    max_steps: int = 200
    """Truncation after this many steps (200 × 0.05 s = 10 s)."""
    success_reward: float = 4.0
    failure_reward: float = -4.0
    """Reward on a wall contact or a flip (the episode ends)."""
    heading_weight: float = 4.0
    """Weight of the heading-progress term (previous |error| - |error|) [1/rad]."""
    step_penalty: float = 0.03
    """Subtracted from every non-terminal reward."""
    action_scale: float = 20.0
    """Wheel torque per unit action [N·m]."""


@dataclass(frozen=True)
class TrainConfig:
    """SAC training of the drive-to-target task (``python -m atrv_warp.train``).

    Defaults are chosen by measurement on a 2-core CPU (README, 'Training').
    """

    # -- run
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
    # -- collection
    num_envs: int = 256
    """Worlds stepped together by the collector."""
    steps_per_batch: int = 8
    """Steps per world in one collected batch (frames per batch = num_envs x steps_per_batch)."""
    collector: str = "async"
    """``async``: a separate worker process collects on its own core while the trainer updates;
    ``sync``: collect and update in turn, in this process."""
    init_random_frames: int = 20_000
    """Frames collected with uniform random actions before learning starts (also the data the
    observation statistics are computed from)."""
    # -- SAC
    buffer_size: int = 1_000_000
    """Replay capacity [frames]."""
    batch_size: int = 512
    """Transitions per gradient step."""
    utd_ratio: float = 0.03125
    """Gradient steps per collected frame (1/32: one update per 32 frames)."""
    width: int = 128
    """Hidden units per layer, actor and critics."""
    depth: int = 2
    """Hidden layers, actor and critics."""
    lr: float = 3e-4
    """Adam learning rate, actor, critics and temperature."""
    gamma: float = 0.99
    """Discount."""
    tau: float = 0.005
    """Target-network soft-update rate."""
    init_alpha: float = 1.0
    """Initial entropy temperature (learned)."""
    threads: int = 1
    """torch threads of the trainer (benchmarks/sac_update_cost.py: a second thread saves about 20 % per
    update, and the async collector needs that core)."""
    # -- evaluation, logging, checkpoints
    eval_every_frames: int = 200_000
    """Deterministic evaluation interval [frames]."""
    eval_episodes: int = 256
    """Seeded episodes per periodic evaluation (fixed set, seed EVAL_SEED)."""
    final_eval_episodes: int = 1000
    """Episodes of the final evaluation of the best policy."""
    logger: str = "csv"
    """Scalars always go to CSV (the learning curve is drawn from it); ``tensorboard`` adds a
    TensorBoard log, ``rerun`` a Rerun recording (``train.rrd``) that also holds two worlds of
    every periodic evaluation."""
    progress: bool = True
    """Show a progress bar (frames, success rate, reward, ETA)."""

    @property
    def frames_per_batch(self) -> int:
        return self.num_envs * self.steps_per_batch

    def validate(self) -> TrainConfig:
        """Raise ``ValueError`` naming the first bad value."""
        positive = ("num_envs", "steps_per_batch", "buffer_size", "batch_size", "width", "depth",
                    "eval_every_frames", "eval_episodes", "final_eval_episodes", "total_frames", "threads")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"train config: {name} must be > 0, got {getattr(self, name)}")
        for name in ("lr", "tau", "init_alpha", "utd_ratio"):
            if not getattr(self, name) > 0:
                raise ValueError(f"train config: {name} must be > 0, got {getattr(self, name)}")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"train config: gamma must be in (0, 1], got {self.gamma}")
        if self.max_minutes < 0 or self.init_random_frames < 0:
            raise ValueError("train config: max_minutes and init_random_frames must be >= 0")
        if self.collector not in ("async", "sync"):
            raise ValueError(f"train config: collector must be 'async' or 'sync', got {self.collector!r}")
        if self.logger not in ("csv", "tensorboard", "rerun"):
            raise ValueError(f"train config: logger must be 'csv', 'tensorboard' or 'rerun', got {self.logger!r}")
        if self.batch_size > self.buffer_size:
            raise ValueError("train config: batch_size must not exceed buffer_size")
        return self


def _coerce(field_type, name: str, value):
    """Convert a TOML value or command-line string to a field's type, naming the field on failure."""
    kind = {"int": int, "float": float, "str": str, "bool": bool}[field_type]
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
            raise ValueError(f"train config: {name} expects {field_type}, got {value!r}") from None
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind is int and isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise ValueError(f"train config: {name} expects {field_type}, got {value!r}")
    return value


def preset_names() -> list[str]:
    """Names of the training presets shipped inside the package (``atrv_warp/configs/*.toml``)."""
    folder = resources.files("atrv_warp").joinpath("configs")
    return sorted(f.name.removesuffix(".toml") for f in folder.iterdir() if f.name.endswith(".toml"))


def _read_config_source(source: str) -> tuple[str, bytes]:
    """``(label, TOML bytes)`` for a preset name (``smoke``) or a file path (``my.toml``)."""
    import os

    if os.path.isfile(source):
        with open(source, "rb") as fh:
            return source, fh.read()
    if source in preset_names():  # packaged, so a non-editable install has the same defaults
        return f"preset {source!r}", resources.files("atrv_warp").joinpath(f"configs/{source}.toml").read_bytes()
    raise FileNotFoundError(f"config {source!r} is neither a file nor a preset; presets: {preset_names()}")


def load_train_config(source: str | None = None, overrides: dict | None = None) -> TrainConfig:
    """Read a TOML config (flat ``key = value``), apply overrides, check every key and value.

    ``source`` is a preset name (:func:`preset_names`: ``default``, ``smoke``), a file path, or
    ``None`` for the :class:`TrainConfig` defaults alone.
    """
    import tomllib

    values: dict = {}
    label = None
    if source is not None:
        label, text = _read_config_source(str(source))
        try:
            values.update(tomllib.loads(text.decode()))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise ValueError(f"{label}: not valid TOML: {err}") from None
    values.update(overrides or {})
    fields = {f.name: f for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        where = f" in {label}" if label else ""
        raise ValueError(f"unknown train config key(s) {unknown}{where}; known: {sorted(fields)}")
    typed = {k: _coerce(fields[k].type, k, v) for k, v in values.items()}
    return TrainConfig(**typed).validate()
