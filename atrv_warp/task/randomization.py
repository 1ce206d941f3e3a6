"""Domain randomization: each world's physics, its sensors' noise and its action latency, drawn per world.

What robot-learning users know from Isaac Lab's event terms and MuJoCo Playground's ``domain_randomize``,
on the device next to the state: every draw happens in a Warp kernel, from a stream of its own per
(world, episode) (and step, for the ``interval`` mode) under the environment's seed, so the same seed
gives the same draws. The drawn physics lands in :attr:`atrv_warp.sim.RoverSim.params`, which the
simulator's kernels read every substep.

- :class:`Draw`: one parameter's range (uniform or log-uniform) and when it is drawn.
- :class:`RandomizationConfig`: what is randomized, with :class:`~atrv_warp.sim.config.SensorNoise`.
- :data:`RANDOMIZATION_PRESETS`: ``none``, ``mild`` and ``wide``; :func:`get_randomization`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from atrv_warp.sim.config import SENSOR_NOISE, SensorNoise
from atrv_warp.sim.params import PARAMETERS, check_parameter

__all__ = [
    "DRAW_MODES",
    "MAX_LATENCY",
    "PHYSICS_DRAWS",
    "RANDOMIZATION_PRESETS",
    "Draw",
    "RandomizationConfig",
    "get_randomization",
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

    def __post_init__(self):
        for name in (*PHYSICS_DRAWS, "motor_lag"):
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
        return bool(self.physics) or self.delays_actions or self.noise is not None

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
"""Named presets. ``none``: the nominal rover, perfect sensors, no delay (training as before). ``mild``: a
rover like ours on ordinary ground. ``wide``: the evaluation's test distribution (mu 0.2-1.0, payload
0-25 kg, motors +-20 %, latency 0-2 steps, the ROS node's sensor noise). Every draw happens on reset."""


def get_randomization(value: RandomizationConfig | str | None) -> RandomizationConfig:
    """The preset called ``value`` (``None``: ``none``), or ``value`` itself."""
    if value is None:
        return RANDOMIZATION_PRESETS["none"]
    if isinstance(value, RandomizationConfig):
        return value
    try:
        return RANDOMIZATION_PRESETS[value]
    except KeyError:
        raise ValueError(f"unknown randomization preset {value!r}; known: {sorted(RANDOMIZATION_PRESETS)}") from None
