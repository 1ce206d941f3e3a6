"""What a calibration fits and how: the fitted parameters and their bounds, the fit's settings and its errors.

:mod:`.segments` cuts a drive into replayable segments under these settings, :mod:`.replay` replays them in the
simulator, :mod:`.solver` moves the parameters and :mod:`.fit` runs the whole calibration and reports it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from atrv_warp.core.kinematics import track_width
from atrv_warp.core.robot import DEFAULT_ROBOT, RobotFileError, load_robot
from atrv_warp.sim.config import RoverConfig, nominal_rover_config
from atrv_warp.sim.driver import DriverConfig

__all__ = ["COMMAND_SOURCES", "CONFOUNDED", "DEFAULT_FIT", "FIT_FIDELITY", "FIT_PARAMETERS", "HEADING_ARM",
           "MISFIT_FLOOR", "MOTOR_PARAMETERS", "CalibrationConfig", "CalibrationError", "FitParameter",
           "sim_config_tables"]


@dataclass(frozen=True)
class FitParameter:
    table: str
    """The simulator-config table (``rover`` or ``contact``) ..."""
    key: str
    """... and key the fitted value is written to."""
    low: float
    """The least value the fit tries, on the reference robot (the ATRV-Jr); :meth:`bounds` gives another robot's."""
    high: float
    unit: str
    scale: str = ""
    """What the bounds grow with from robot to robot: the nominal rover's ``wheel_radius`` or ``wheel_speed_limit``,
    or ``mass`` (its URDF's total); ``""``: the same on every robot (a friction, a share of the motor's torque)."""

    def bounds(self, robot: str = DEFAULT_ROBOT) -> tuple[float, float]:
        """``(low, high)`` on ``robot`` (a shipped robot's name or a robot file): the reference's, times the robot's
        :attr:`scale` over the reference's (on the reference itself, exactly :attr:`low` and :attr:`high`)."""
        if not self.scale:
            return self.low, self.high
        ratio = robot_scale(robot, self.scale) / robot_scale(DEFAULT_ROBOT, self.scale)
        return self.low * ratio, self.high * ratio


@functools.lru_cache(maxsize=16)
def robot_scale(robot: str, scale: str) -> float:
    """The size of ``robot`` that a :attr:`FitParameter.scale` names: its nominal rover's wheel radius [m] or motor
    no-load speed [rad/s], or its total mass [kg]."""
    rover = nominal_rover_config(robot)
    if scale == "mass":
        from atrv_warp.sim.urdf import load_rover

        return float(load_rover(rover).total_mass)
    return float(getattr(rover, scale))


FIT_PARAMETERS: dict[str, FitParameter] = {
    "friction": FitParameter("contact", "friction", 0.05, 1.5, "-"),
    "torque_scale": FitParameter("rover", "torque_scale", 0.3, 1.5, "-"),
    "payload_mass": FitParameter("rover", "payload_mass", 0.0, 60.0, "kg", scale="mass"),
    "speed_limit": FitParameter("rover", "wheel_speed_limit", 10.0, 120.0, "rad/s", scale="wheel_speed_limit"),
    "wheel_radius": FitParameter("rover", "wheel_radius", 0.10, 0.16, "m", scale="wheel_radius"),
    "friction_rise": FitParameter("contact", "friction_rise", 0.0, 1.0, "s/m"),
}
"""What the fit can adjust, with its bounds on the ATRV-Jr: Coulomb mu, motor torque scale, payload at the chassis'
centre of mass, motor no-load speed, wheel rolling radius, and the sliding friction's rise with slip speed
(:attr:`~atrv_warp.sim.config.ContactConfig.friction_rise`: not in :data:`DEFAULT_FIT`; for a rover whose brisk
turns the model check flags, ``docs/calibration.md``). On another robot the payload's, the no-load speed's and the
radius's bounds scale with its mass, no-load speed and radius (:meth:`FitParameter.bounds`)."""
DEFAULT_FIT = ("friction", "torque_scale", "payload_mass", "wheel_radius")
COMMAND_SOURCES = ("auto", "cmd_vel", "effort")
"""``cmd_vel``: replay the velocity commands through the base's PI controller (and match the recorded wheel
efforts, where the joint states carry them); ``effort``: replay the recorded wheel efforts as the motors'
torques; ``auto``: ``cmd_vel`` where the bag has commands, else ``effort``."""
MOTOR_PARAMETERS = ("torque_scale", "speed_limit")
"""The motor's parameters: they turn a commanded torque into the applied one, which an effort replay
applies as recorded, so only a ``cmd_vel`` replay can fit them."""

HEADING_ARM = 0.5
"""[m]: a heading error costs as the position error at this distance (the replay's loss), and a segment moved as
much (:func:`~atrv_warp.sim.sysid.segments.make_segments` keeps the moving ones)."""
FIT_FIDELITY = {"friction": 0.003, "torque_scale": 0.0065, "payload_mass": 0.6, "speed_limit": 1.0,
                "wheel_radius": 0.0009, "friction_rise": 0.05}
"""How well the replay pins each parameter beyond the recording's noise [its unit]: the root-mean-square error of
the calibration sweep's converged fits of rovers it modelled exactly (``benchmarks/calibration/calibration_sweep.py --seed 0``;
the speed limit and the friction's rise, never fitted there, estimates), added in quadrature to the statistical
standard error. It is the replay's own limit: its start is rebuilt from 20 Hz samples, and a slipping wheel
amplifies any difference. Measured
before each segment's start took the recorded tilt, each wheel's speed and the driver's integral from the effort
(``git show 6c7c636:benchmarks/results/calibration_sweep_before_start_state.json``), which brought the fits closer: the intervals are now wider than
the replay needs."""
CONFOUNDED = 0.95
"""The correlation beyond which two fitted values are reported as confounded: the drive fixes a combination of them,
not each."""
MISFIT_FLOOR = {"position": 0.01, "wheel_speed": 0.05, "effort": 0.1}
"""The least error [m, rad/s, N·m] the model check calls noise, whatever the recording's own (a reference or encoder
far finer than this would otherwise flag what no training needs)."""


class CalibrationError(ValueError):
    """A log or a setting the fit cannot use (one line saying why)."""


@dataclass(frozen=True)
class CalibrationConfig:
    """How to fit (``python -m atrv_warp.calibrate --help`` lists them as options)."""

    params: tuple[str, ...] = DEFAULT_FIT
    """Parameters to fit (:data:`FIT_PARAMETERS`); the others keep the rover's values."""
    command: str = "auto"
    """Command source (:data:`COMMAND_SOURCES`)."""
    segment_seconds: float = 2.0
    """Length of each replayed segment [s]."""
    duration: float | None = None
    """Seconds of the drive to use, from its start [s] (``None``: all of it)."""
    pose_smoothing: float = 0.25
    """Window of the centred moving average over the reference poses [s] (0: none). It takes the reference's
    noise out of each segment's start and of the error (a 1 cm noise is about the error left after a fit),
    and changes a path that bends at 1 rad/s by well under a millimetre."""
    warmup: float = 0.25
    """Each segment's first seconds [s] left out of the wheel-speed and effort terms (a ``cmd_vel`` replay): the
    driver's integral at a segment's start is reconstructed (from the recorded efforts, or from 20 Hz wheel speeds
    where the bag has none), and its error decays there."""
    held_out_every: int = 5
    """Every k-th segment is held out of the fit, and only measured."""
    starts: int = 2
    """Starting points, fitted at once: the rover's values, then random points within the bounds. Under a driver that
    holds its wheel speeds tightly the loss is flat along friction x mass; two starts that end at the same point have
    found the valley's floor, and the fit converges only where they do."""
    iterations: int = 15
    """Levenberg-Marquardt iterations at most, on every training segment."""
    tolerance: float = 0.005
    """A start has settled once its undamped Gauss-Newton step moves no parameter more than this share of its
    range."""
    difference_step: float = 0.005
    """The forward differences' step, as a share of each parameter's range."""
    damping: float = 0.01
    """Levenberg-Marquardt's first damping (a share of the normal equations' diagonal)."""
    robust: float | None = 1.0
    """Each segment's loss counts through Cauchy's ``robust * log(1 + loss / robust)`` (``None``: as it is). A segment
    the replay cannot follow (a wheel that spins up in a turn and runs away, a chaotic stretch in any model) can
    cost hundreds where a followed one costs well under 1, and a few such would pull every parameter to them."""
    worlds: int = 512
    """Worlds per rollout at most: an iteration's segments run in chunks of about equal size up to this."""
    seed: int = 0
    min_segments: int = 5
    """A log with fewer moving segments is too short to fit."""
    robot: str = DEFAULT_ROBOT
    """The robot the bag was recorded on (a shipped robot's name or a robot file's path): its nominal rover, and its
    driver's gains, torque limit and track factor where the fields below leave them ``None``."""
    kp: float | None = None
    """The base's wheel-speed PI, as the robot's driver runs it (:class:`~atrv_warp.sim.driver.DriverConfig`);
    ``None``: the robot's."""
    ki: float | None = None
    effective_track_factor: float | None = None
    cmd_vel_timeout: float = DriverConfig.cmd_vel_timeout
    torque_limit: float | None = None
    driver_wheel_radius: float | None = None
    """The wheel radius the robot's driver is configured with [m]: it turns ``/cmd_vel`` into wheel-speed targets
    and wheel speeds into odometry. ``None``: the nominal rover's (the realistic variant's 0.125 m, as an unconfigured
    :class:`~atrv_warp.sim.driver.DriverConfig` has; not a ``sim_config``'s). The physical radius, worn or not, is a
    fitted parameter (``wheel_radius``)."""
    driver_track_width: float | None = None
    """The wheel track the robot's driver is configured with [m]. ``None``: the nominal rover's (its URDF's, 0.5 m)."""
    latency: float | None = None
    """How long after its stamp a ``/cmd_vel`` reaches the driver [s] (a command path's delay, which the bag's
    stamps do not show). ``None``: fitted, in whole steps of 0.05 s up to :attr:`max_latency`."""
    max_latency: float = 0.2
    """The longest latency a fit of it tries [s]."""
    misfit_ratio: float = 2.0
    """The model check (:attr:`CalibrationResult.misfit`): a misfit is flagged where, after the fit, a channel's
    median held-out error is more than this many times the recording's own noise in it (or its
    :data:`MISFIT_FLOOR`, where that is larger). A model that explains the drive leaves about the noise: 0.9-1.7x on
    the calibration sweep's and the misfit benchmark's well-modelled rovers."""

    def driver(self) -> DriverConfig:
        """The base's motor driver as the replay runs it: these gains and limits, and the configured radius and track
        (a real driver knows its configured values, not the wheel's wear), ``None`` resolved to the nominal rover's."""
        from atrv_warp.sim.urdf import load_rover

        nominal = self.nominal_rover()
        radius = nominal.wheel_radius if self.driver_wheel_radius is None else self.driver_wheel_radius
        track = track_width(load_rover(nominal), nominal) if self.driver_track_width is None else self.driver_track_width
        return DriverConfig(wheel_radius=radius, track_width=track,
                            effective_track_factor=self.effective_track_factor, kp=self.kp, ki=self.ki,
                            torque_limit=self.torque_limit, cmd_vel_timeout=self.cmd_vel_timeout
                            ).resolved(nominal.robot_spec)

    def nominal_rover(self) -> RoverConfig:
        """The robot's nominal rover (the ATRV-Jr's realistic variant by default)."""
        return nominal_rover_config(self.robot)

    def __post_init__(self):
        unknown = sorted(set(self.params) - set(FIT_PARAMETERS))
        twice = sorted({p for p in self.params if self.params.count(p) > 1})
        if twice:
            raise CalibrationError(f"parameter(s) {twice} named more than once in the parameters to fit "
                                   f"{list(self.params)}")
        if unknown or not self.params:
            raise CalibrationError(f"unknown or no parameter(s) to fit {unknown or list(self.params)}; "
                                   f"known: {list(FIT_PARAMETERS)}")
        if self.command not in COMMAND_SOURCES:
            raise CalibrationError(f"command must be one of {COMMAND_SOURCES}, got {self.command!r}")
        if not 0.0 <= self.pose_smoothing <= 0.5 * self.segment_seconds:
            raise CalibrationError(f"pose_smoothing must be within [0, segment_seconds / 2], got {self.pose_smoothing}")
        for name in ("segment_seconds", "kp", "effective_track_factor", "cmd_vel_timeout", "torque_limit"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise CalibrationError(f"{name} must be > 0, got {getattr(self, name)}")
        try:
            load_robot(self.robot)
        except RobotFileError as err:
            raise CalibrationError(f"robot: {err}") from None
        if self.robust is not None and not self.robust > 0:
            raise CalibrationError(f"robust must be > 0 or None, got {self.robust}")
        if self.duration is not None and not self.duration > 0:
            raise CalibrationError(f"duration must be > 0 [s] or None, got {self.duration}")
        if self.latency is not None and not (math.isfinite(self.latency) and self.latency >= 0):
            raise CalibrationError(f"latency must be a finite number >= 0 [s] or None, got {self.latency!r}")
        if not (math.isfinite(self.misfit_ratio) and self.misfit_ratio > 0):
            raise CalibrationError(f"misfit_ratio must be a finite number > 0, got {self.misfit_ratio!r}")
        if not (math.isfinite(self.max_latency) and self.max_latency >= 0):
            raise CalibrationError(f"max_latency must be a finite number >= 0 [s], got {self.max_latency!r}")
        for name in ("driver_wheel_radius", "driver_track_width"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise CalibrationError(f"{name} must be a finite number > 0 [m], got {value!r}")
        for name in ("tolerance", "difference_step", "damping"):
            if not 0 < getattr(self, name) < 1:
                raise CalibrationError(f"{name} must be within (0, 1), got {getattr(self, name)}")
        for name in ("held_out_every", "starts", "iterations", "min_segments", "worlds"):
            if getattr(self, name) < 1:
                raise CalibrationError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.held_out_every < 2:
            raise CalibrationError("held_out_every must be >= 2 (1 would hold every segment out)")



def sim_config_tables(values: dict[str, float]) -> dict[str, dict[str, float]]:
    """Fit parameters' ``values`` as a simulator config's tables, ``{"rover": {key: value}, "contact": {...}}``: the
    keywords of :class:`~atrv_warp.sim.config.RoverConfig` and :class:`~atrv_warp.sim.config.ContactConfig`
    (:data:`FIT_PARAMETERS`' ``table`` and ``key``)."""
    tables: dict[str, dict[str, float]] = {"rover": {}, "contact": {}}
    for name, value in values.items():
        p = FIT_PARAMETERS[name]
        tables[p.table][p.key] = value
    return tables

