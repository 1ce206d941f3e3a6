"""Domain randomization: each world's physics, its sensors' noise and its action latency, drawn per world.

What robot-learning users know from Isaac Lab's event terms and MuJoCo Playground's ``domain_randomize``,
on the device next to the state: every draw happens in a Warp kernel, from a stream of its own per
(world, episode) (and step, for the ``interval`` mode) under the environment's seed, so the same seed
gives the same draws. The drawn physics lands in :attr:`atrv_warp.sim.RoverSim.params`, which the
simulator's kernels read every substep.

- :class:`Draw`: one parameter's range (uniform or log-uniform) and when it is drawn.
- :class:`RandomizationConfig`: what is randomized, with :class:`~atrv_warp.sim.config.SensorNoise`.
- :data:`RANDOMIZATION_PRESETS`: ``none``, ``mild`` and ``wide``, absolute ranges; :func:`get_randomization`.
- :class:`AroundConfig` and :data:`AROUND_PRESETS` (``around``): ranges centred on a simulator-config file (a
  calibrated rover), resolved against it by :func:`resolve_around` into a :class:`RandomizationConfig` of absolute
  ranges, so the kernels see no difference.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from atrv_warp.sim.config import SENSOR_NOISE, ContactConfig, RoverConfig, SensorNoise
from atrv_warp.sim.config_file import read_sim_config
from atrv_warp.sim.params import PARAMETER_KEYS, PARAMETERS, check_parameter, parameter_values

__all__ = [
    "AROUND_PRESETS",
    "DRAW_MODES",
    "MAX_LATENCY",
    "PHYSICS_DRAWS",
    "RANDOMIZATION_PRESETS",
    "AroundConfig",
    "Draw",
    "RandomizationConfig",
    "get_randomization",
    "randomization_names",
    "resolve_around",
    "scale_preset",
]

DRAW_MODES = ("startup", "reset", "interval")
"""When a parameter is drawn: ``startup`` once per world (its first episode after seeding), ``reset`` at the
start of every episode, ``interval`` at every episode start and then every :attr:`Draw.every` steps."""

MAX_LATENCY = 8
"""Longest action latency [steps] the device ring buffer holds (0.4 s at 0.05 s a step)."""

PHYSICS_DRAWS = tuple(PARAMETERS)
"""The fields of :class:`RandomizationConfig` that draw a per-world physical parameter
(:data:`atrv_warp.sim.params.PARAMETERS` says what each is and its unit)."""


@dataclass(frozen=True)
class Draw:
    """One parameter's distribution, and when it is drawn."""

    low: float
    """Lower end of the range (the parameter's unit)."""
    high: float
    """Upper end of the range."""
    log: bool = False
    """Log-uniform instead of uniform (for scale-like parameters: friction, stiffness)."""
    mode: str = "reset"
    """``startup``, ``reset`` or ``interval`` (:data:`DRAW_MODES`)."""
    every: int = 0
    """``interval`` mode: steps between draws within an episode."""

    def check(self, key: str) -> None:
        """Raise a one-line ``ValueError`` naming ``key`` if this draw is malformed."""
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            raise ValueError(f"{key}: low and high must be finite, got {self.low!r}, {self.high!r}")
        if self.low > self.high:
            raise ValueError(f"{key}: low {self.low:g} > high {self.high:g}")
        if self.log and self.low <= 0:
            raise ValueError(f"{key}: a log-uniform range needs low > 0, got {self.low:g}")
        if self.mode not in DRAW_MODES:
            raise ValueError(f"{key}: unknown mode {self.mode!r}; known: {list(DRAW_MODES)}")
        if self.mode == "interval" and self.every < 1:
            raise ValueError(f"{key}: the interval mode needs every >= 1 step, got {self.every}")


@dataclass(frozen=True)
class RandomizationConfig:
    """What each world randomizes. ``None`` leaves a parameter at the simulator's configured value.

    Physical parameters (per world, :attr:`atrv_warp.sim.RoverSim.params`):
    """

    friction: Draw | None = None
    """Coulomb coefficient mu of the ground [-]."""
    payload_mass: Draw | None = None
    """Point payload on the chassis [kg]."""
    payload_offset: Draw | None = None
    """Payload position from the chassis' centre of mass: x and y each drawn from this range [m] (z = 0)."""
    torque_scale: Draw | None = None
    """Motor torque per unit of commanded torque [-] (a worn or strong motor, a battery's charge)."""
    speed_limit: Draw | None = None
    """Motor no-load speed [rad/s]."""
    wheel_radius: Draw | None = None
    """Rolling radius [m] (worn or soft tyres; odometry keeps assuming the nominal radius)."""
    stiffness: Draw | None = None
    """Contact stiffness kp [N/m^n] (hard or soft ground; keep within 0.5-1.5x the nominal: stiffer ground
    rings under the explicit step, ``tests/test_params.py``)."""
    latency: tuple[int, int] = (0, 0)
    """Action latency, a whole number of steps drawn uniformly in [low, high] per world and episode: the
    command applied at a step is the one chosen that many steps before (zero torque before the first)."""
    motor_lag: Draw | None = None
    """First-order lag of the applied torque behind the delayed command, time constant [s] (0: none)."""
    noise: SensorNoise | None = None
    """Sensor noise in the observations and the scan (:class:`~atrv_warp.sim.config.SensorNoise`, the
    same settings the ROS node reads); ``None``: perfect sensors."""
    odometry_scale: Draw | None = None
    """The wheel odometry's distance per distance driven [-] (a robot observation's odometry pose and twist; 1: no
    error). Wheels that creep or slip on slippery ground turn further than the rover moves, so a base's encoders
    over-read (``benchmarks/transfer/mujoco_odometry.py`` measures how much in our simulator and in the MuJoCo twin), and a
    policy that steers to a goal seen from odometry stops short of it; drawn above 1, training meets that."""

    odometry_slip_gain: Draw | None = None
    """How much further the wheel odometry's pose runs per metre the encoders slip [-] (0: the encoders' own reading). Each
    step the encoders' forward speed less the chassis's, times this gain, moves the pose the goal is seen from
    along its heading (``odom_drift``; the odometry's twist is left as it reads). The MuJoCo twin's wheels slip
    more than ours in launches and on tight arcs (``benchmarks/transfer/mujoco_odometry.py``), so its odometry over-reads
    where ours slips; unlike :attr:`odometry_scale`, a policy can lower this error by how it drives."""

    def __post_init__(self):
        for name in (*PHYSICS_DRAWS, "motor_lag", "odometry_scale", "odometry_slip_gain"):
            draw = getattr(self, name)
            if draw is None:
                continue
            if not isinstance(draw, Draw):
                raise TypeError(f"randomization.{name} must be a Draw(low, high, ...), got {draw!r}")
            key = f"randomization.{name}"
            draw.check(key)
            if name == "motor_lag":
                if draw.low < 0:
                    raise ValueError(f"{key}: a time constant must be >= 0 s, got low {draw.low:g}")
            elif name == "odometry_slip_gain":
                if draw.low < 0:
                    raise ValueError(f"{key}: a gain must be >= 0, got low {draw.low:g}")
            elif name == "odometry_scale":
                if draw.low <= 0:
                    raise ValueError(f"{key}: a scale must be > 0, got low {draw.low:g}")
            elif name != "payload_offset":
                for end in (draw.low, draw.high):
                    try:
                        check_parameter(name, end)
                    except ValueError as err:
                        raise ValueError(f"{key}: {err}") from None
        lo, hi = self.latency
        if int(lo) != lo or int(hi) != hi or lo < 0 or lo > hi:
            raise ValueError(f"randomization.latency: need whole steps 0 <= low <= high, got {self.latency}")
        if hi > MAX_LATENCY:
            raise ValueError(f"randomization.latency: {hi} steps exceed the action buffer ({MAX_LATENCY} steps)")

    @property
    def physics(self) -> dict[str, Draw]:
        """The physical parameters this config draws, by name."""
        return {name: getattr(self, name) for name in PHYSICS_DRAWS if getattr(self, name) is not None}

    @property
    def delays_actions(self) -> bool:
        """Whether actions go through the latency buffer and motor lag."""
        return self.latency[1] > 0 or self.motor_lag is not None

    @property
    def enabled(self) -> bool:
        """Whether anything is randomized or noisy."""
        odometry = self.odometry_scale is not None or self.odometry_slip_gain is not None
        return bool(self.physics) or self.delays_actions or self.noise is not None or odometry

    def describe(self) -> dict[str, object]:
        """A plain dict of the settings (for run folders and reports)."""
        return dataclasses.asdict(self)


RANDOMIZATION_PRESETS: dict[str, RandomizationConfig] = {
    "none": RandomizationConfig(),
    "mild": RandomizationConfig(
        friction=Draw(0.3, 0.8, log=True), payload_mass=Draw(0.0, 10.0), payload_offset=Draw(-0.1, 0.1),
        torque_scale=Draw(0.9, 1.1), speed_limit=Draw(45.0, 55.0), wheel_radius=Draw(0.12, 0.13),
        stiffness=Draw(0.8e5, 1.25e5, log=True), latency=(0, 1), noise=SENSOR_NOISE),
    "wide": RandomizationConfig(
        friction=Draw(0.2, 1.0, log=True), payload_mass=Draw(0.0, 25.0), payload_offset=Draw(-0.15, 0.15),
        torque_scale=Draw(0.8, 1.2), speed_limit=Draw(40.0, 60.0), wheel_radius=Draw(0.115, 0.135),
        stiffness=Draw(0.5e5, 1.5e5, log=True), latency=(0, 2), noise=SENSOR_NOISE),
}
RANDOMIZATION_PRESETS["wide_slip"] = dataclasses.replace(RANDOMIZATION_PRESETS["wide"],
                                                         odometry_scale=Draw(1.0, 1.25))
RANDOMIZATION_PRESETS["wide_slip_gain"] = dataclasses.replace(RANDOMIZATION_PRESETS["wide"],
                                                              odometry_slip_gain=Draw(0.0, 1.5))
"""Named presets. ``none``: the nominal rover, perfect sensors, no delay (training as before). ``mild``: a
rover like ours on ordinary ground. ``wide``: the evaluation's test distribution (mu 0.2-1.0, payload
0-25 kg, motors +-20 %, latency 0-2 steps, the ROS node's sensor noise). ``wide_slip``: ``wide``, and wheel odometry
that over-reads by up to a quarter (:attr:`RandomizationConfig.odometry_scale`; a study of the deployable policy's
training, docs/tasks.md). ``wide_slip_gain``: ``wide``, and wheel odometry whose error grows with the encoders' slip,
by up to 1.5 times that slip again (:attr:`RandomizationConfig.odometry_slip_gain`; a study, docs/tasks.md). Every
draw happens on reset."""


def scale_preset(config: RandomizationConfig, rover: RoverConfig) -> RandomizationConfig:
    """A preset (written for the ATRV-Jr, :data:`RANDOMIZATION_PRESETS`) for ``rover``'s robot: its payload in
    proportion to the robot's mass, its payload offset to its footprint, its motors' no-load speed and its wheel
    radius to the robot's own; the ATRV-Jr's preset as it is. The other draws (friction, torque scale, stiffness,
    latency, noise, odometry) are relative or the ground's already."""
    from atrv_warp.core.robot import DEFAULT_ROBOT, load_robot

    if rover.robot_spec == load_robot(DEFAULT_ROBOT):
        return config
    from atrv_warp.sim.urdf import load_rover
    from atrv_warp.task.scaling import REFERENCE_FOOTPRINT, footprint_radius

    reference = RoverConfig(robot=DEFAULT_ROBOT)
    ratios = {"payload_mass": load_rover(rover).total_mass / load_rover(reference).total_mass,
              "payload_offset": footprint_radius(load_rover(rover), rover) / REFERENCE_FOOTPRINT,
              "speed_limit": rover.wheel_speed_limit / reference.wheel_speed_limit,
              "wheel_radius": rover.wheel_radius / reference.wheel_radius}
    changes = {name: dataclasses.replace(getattr(config, name), low=getattr(config, name).low * ratio,
                                         high=getattr(config, name).high * ratio)
               for name, ratio in ratios.items() if getattr(config, name) is not None}
    return dataclasses.replace(config, **changes)


@dataclass(frozen=True)
class AroundConfig:
    """A randomization centred on a simulator-config file, e.g. the rover ``atrv-calibrate`` fitted: each drawn
    parameter is uniform in the file's value +- a spread, the larger of the fit's interval and a stated fraction.

    :func:`resolve_around` turns it, against a file, into a :class:`RandomizationConfig` of absolute ranges; the
    parameters it does not draw keep the file's values in every world.
    """

    parameters: tuple[str, ...] = ("friction", "payload_mass", "torque_scale", "wheel_radius")
    """The physical parameters drawn around the file's values (:data:`PHYSICS_DRAWS` but ``payload_offset``, which
    one range cannot centre in x and y at once). The file must set each. Default: those ``atrv-calibrate`` fits
    by default (Coulomb mu, payload, motor torque scale, wheel radius)."""
    standard_errors: float = 2.0
    """Half-width of each range in the fit's standard errors, as the file records them
    (``[calibration.standard_error]``): 2 is the fit's 95 % interval."""
    fraction: float = 0.1
    """... and at least this fraction of the value on each side; where the file records no standard error (a file
    written by hand, a ``nan``), the half-width is this alone. A fit's standard error counts the recording's noise,
    not the simulator's differences from the rover, nor one day's ground from the next (docs/calibration.md), and
    can be under 1 % of the value."""
    mode: str = "reset"
    """When each parameter is drawn (:data:`DRAW_MODES`)."""
    every: int = 0
    """``interval`` mode: steps between draws within an episode."""
    latency: tuple[int, int] = (0, 0)
    """Action latency [steps] (:attr:`RandomizationConfig.latency`): not a fitted value, so an absolute range."""
    noise: SensorNoise | None = None
    """Sensor noise (:attr:`RandomizationConfig.noise`)."""

    def __post_init__(self):
        for name in self.parameters:
            if name not in PHYSICS_DRAWS:
                raise ValueError(f"randomization around: unknown physical parameter {name!r}; known: "
                                 f"{list(PHYSICS_DRAWS)}")
            if name == "payload_offset":
                raise ValueError("randomization around: payload_offset cannot be drawn around a value (one range "
                                 "draws both x and y); draw it with RandomizationConfig(payload_offset=Draw(...))")
        for name in ("standard_errors", "fraction"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"randomization around: {name} must be a finite number >= 0, got {value!r}")
        Draw(0.0, 0.0, mode=self.mode, every=self.every).check("randomization around")


_POSITIVE_FLOOR = 0.1
"""A parameter that must stay above zero (friction, stiffness, wheel radius, speed limit) is drawn no lower than this
fraction of its centre, however wide the spread; one that may be zero (payload, torque scale) no lower than zero."""


def resolve_around(around: AroundConfig, sim_config: str | Path, *, rover: RoverConfig | None = None,
                   contact: ContactConfig | None = None) -> RandomizationConfig:
    """``around`` centred on the simulator-config file ``sim_config``: a :class:`RandomizationConfig` of absolute
    ranges, ``centre +- max(standard_errors x the fit's standard error, fraction x |centre|)``, clipped to each
    parameter's valid values.

    Args:
        around: What to draw, and how wide.
        sim_config: The simulator-config TOML file (``atrv-calibrate``'s output, or one written by hand).
        rover: The rover the file applies to (default: the realistic variant), as
            :class:`~atrv_warp.task.env.RoverEnv` builds it.
        contact: The contact law the file applies to (default: :class:`~atrv_warp.sim.config.ContactConfig`).

    Raises:
        ValueError: One line naming the file: one it cannot read (:func:`~atrv_warp.sim.config_file.read_sim_config`), or
            a parameter ``around`` draws that the file does not set.
    """
    read = read_sim_config(sim_config, rover, contact)
    centre = parameter_values(read.rover, read.contact)
    draws = {}
    for name in around.parameters:
        table, key = PARAMETER_KEYS[name]
        if not read.sets(table, key):
            raise ValueError(f"randomization around sim config {read.path}: it does not set {name} ([{table}] {key}), "
                             "which the randomization draws around the file's value")
        c = float(centre[name])
        se = read.standard_error.get(name, math.nan)
        half = max(around.fraction * abs(c), around.standard_errors * se if math.isfinite(se) else 0.0)
        try:
            check_parameter(name, 0.0)
            floor = 0.0
        except ValueError:  # must stay above zero
            floor = _POSITIVE_FLOOR * c
        draws[name] = Draw(max(c - half, floor), c + half, mode=around.mode, every=around.every)
    return RandomizationConfig(**draws, latency=around.latency, noise=around.noise)


_MILD = RANDOMIZATION_PRESETS["mild"]

AROUND_PRESETS: dict[str, AroundConfig] = {
    "around": AroundConfig(latency=_MILD.latency, noise=_MILD.noise),
}
"""Named randomizations centred on a simulator config (``randomization=around`` with ``--sim-config FILE``).
``around``: mu, payload, torque scale and wheel radius drawn on every reset within the larger of the fit's 95 %
interval and +-10 % of each value; ``mild``'s latency (0-1 steps) and the ROS node's sensor noise."""


def randomization_names() -> list[str]:
    """Every randomization's name: the presets of absolute ranges, then those centred on a simulator config."""
    return [*RANDOMIZATION_PRESETS, *AROUND_PRESETS]


def get_randomization(value: RandomizationConfig | AroundConfig | str | None, *, sim_config: str | Path | None = None,
                      rover: RoverConfig | None = None, contact: ContactConfig | None = None) -> RandomizationConfig:
    """The randomization ``value`` names or is (``None``: ``none``), as absolute ranges: one centred on a simulator
    config (:data:`AROUND_PRESETS`, an :class:`AroundConfig`) resolved against ``sim_config`` on ``rover`` and
    ``contact`` (:func:`resolve_around`); a preset of :data:`RANDOMIZATION_PRESETS` fitted to ``rover``'s robot
    (:func:`scale_preset`).

    Raises:
        ValueError: One line: an unknown name; one centred on a simulator config without ``sim_config``; what
            :func:`resolve_around` raises.
    """
    if value is None:
        return RANDOMIZATION_PRESETS["none"]
    if isinstance(value, RandomizationConfig):
        return value
    around = AROUND_PRESETS.get(value) if isinstance(value, str) else value
    if isinstance(around, AroundConfig):
        if not sim_config:
            label = f"randomization {value!r}" if isinstance(value, str) else "a randomization around a config"
            raise ValueError(f"{label} is centred on a simulator config: give one (sim_config=FILE, "
                             "--sim-config FILE)")
        return resolve_around(around, sim_config, rover=rover, contact=contact)
    try:
        preset = RANDOMIZATION_PRESETS[value]
    except KeyError:
        raise ValueError(f"unknown randomization preset {value!r}; known: {sorted(randomization_names())}") from None
    return scale_preset(preset, rover) if rover is not None else preset
