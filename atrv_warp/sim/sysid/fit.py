"""Fit the simulator's physical parameters to a recorded drive: Levenberg-Marquardt on the replays' residuals.

The log is cut into segments of a few seconds. Every segment starts from its recorded state (pose, body
velocity, wheel speeds, and the wheel-speed controller's integral) and is replayed in its own world with
its recorded commands: the velocity commands through the base's own motor driver inside the rollout
(:mod:`atrv_warp.sim.driver`, the simulator's kernel, with the radius and track the robot's driver is configured
with: :attr:`CalibrationConfig.driver_wheel_radius`, by default the nominal rover's), or the recorded wheel efforts.
The physical wheel radius is fitted apart from the configured one: a worn tyre is a smaller physical radius under
the same driver. The residuals are the simulated against the recorded path, wheel speeds and efforts. The
parameters are few, so the fit is Gauss-Newton's: each iteration replays every training segment at the current
point and one step along each parameter, all in one batch of worlds (forward differences, no tape), and solves
for a damped step. Two starting points run at once, each in its own worlds, and must end at the same point;
every ``held_out_every``-th segment is kept out of the fit and only measured.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from atrv_warp.core.geometry import quat_to_yaw, wrap_angle
from atrv_warp.core.kinematics import track_width
from atrv_warp.core.robot import DEFAULT_ROBOT, RobotFileError, load_robot
from atrv_warp.sim.config import ContactConfig, RoverConfig, nominal_rover_config
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.kernels.rover import MOTOR_TAPER_START
from atrv_warp.sim.sysid.log import DriveLog

__all__ = ["COMMAND_SOURCES", "CONFOUNDED", "DEFAULT_FIT", "FIT_FIDELITY", "FIT_PARAMETERS", "MISFIT_FLOOR", "MOTOR_PARAMETERS", "CalibrationConfig",
           "CalibrationError", "CalibrationResult", "Segments", "calibrate", "integral_from_effort", "make_segments",
           "recording_noise", "replay_errors", "sim_config_tables"]


@dataclass(frozen=True)
class FitParameter:
    table: str
    """The simulator-config table (``rover`` or ``contact``) ..."""
    key: str
    """... and key the fitted value is written to."""
    low: float
    high: float
    unit: str


FIT_PARAMETERS: dict[str, FitParameter] = {
    "friction": FitParameter("contact", "friction", 0.05, 1.5, "-"),
    "torque_scale": FitParameter("rover", "torque_scale", 0.3, 1.5, "-"),
    "payload_mass": FitParameter("rover", "payload_mass", 0.0, 60.0, "kg"),
    "speed_limit": FitParameter("rover", "wheel_speed_limit", 10.0, 120.0, "rad/s"),
    "wheel_radius": FitParameter("rover", "wheel_radius", 0.10, 0.16, "m"),
    "friction_rise": FitParameter("contact", "friction_rise", 0.0, 1.0, "s/m"),
}
"""What the fit can adjust, with its bounds: Coulomb mu, motor torque scale, payload at the chassis' centre of
mass, motor no-load speed, wheel rolling radius, and the sliding friction's rise with slip speed
(:attr:`~atrv_warp.sim.config.ContactConfig.friction_rise`: not in :data:`DEFAULT_FIT`; for a rover whose brisk
turns the model check flags, ``docs/calibration.md``)."""
DEFAULT_FIT = ("friction", "torque_scale", "payload_mass", "wheel_radius")
COMMAND_SOURCES = ("auto", "cmd_vel", "effort")
"""``cmd_vel``: replay the velocity commands through the base's PI controller (and match the recorded wheel
efforts, where the joint states carry them); ``effort``: replay the recorded wheel efforts as the motors'
torques; ``auto``: ``cmd_vel`` where the bag has commands, else ``effort``."""
MOTOR_PARAMETERS = ("torque_scale", "speed_limit")
"""The motor's parameters: they turn a commanded torque into the applied one, which an effort replay
applies as recorded, so only a ``cmd_vel`` replay can fit them."""

_POSITION_SCALE = 0.05  # [m]: position error that costs 1
_HEADING_ARM = 0.5  # [m]: a heading error costs as the position error at this distance
_WHEEL_SCALE = 0.5  # [rad/s]: wheel-speed error that costs 1
_EFFORT_SCALE = 1.0  # [N·m]: wheel-effort error that costs 1
_NO_TAPER = 1.0e4  # [rad/s]: an effort replay's motor no-load speed (the recorded torques already taper)
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


@dataclass
class Segments:
    """The log cut into ``S`` replayable segments of ``L`` steps (positions relative to each start)."""

    t0: np.ndarray  # (S,) start [s]
    yaw0: np.ndarray  # (S,) heading at the start [rad]
    velocity: np.ndarray  # (S, 2) forward, leftward chassis speed at the start [m/s]
    yaw_rate: np.ndarray  # (S,)
    wheel: np.ndarray  # (S, 2) side wheel speeds at the start [rad/s]
    integral: np.ndarray  # (S, 2) the driver's PI integral at the start [rad]
    inputs: np.ndarray  # (S, L, 2) (linear [m/s], angular [rad/s]) commands (cmd_vel) or torques [N·m] (effort)
    ref_pose: np.ndarray  # (S, L + 1, 3) recorded x, y [m] from the start, yaw [rad]
    ref_wheel: np.ndarray  # (S, L + 1, 2) recorded side wheel speeds [rad/s]
    ref_effort: np.ndarray | None  # (S, L, 2) recorded side efforts at each step's end [N·m] (cmd_vel replay)
    held_out: np.ndarray  # (S,) bool
    command: str
    latency: float = 0.0
    """The commands' latency [s] the inputs were cut with (a ``cmd_vel`` replay)."""
    tilt: np.ndarray | None = None  # (S, 2) roll, pitch at the start [rad]
    tilt_rate: np.ndarray | None = None  # (S, 2) angular velocity about the chassis' x and y at the start [rad/s]
    wheel_each: np.ndarray | None = None  # (S, W) each wheel's forward speed at the start, the rover's order [rad/s]
    wheel_joints: tuple[str, ...] = ()
    """The joints of ``wheel_each``'s columns."""
    start_effort: np.ndarray | None = None  # (S, 2) side efforts at the start [N·m] (a cmd_vel replay with efforts)
    start_target: np.ndarray | None = None  # (S, 2) the driver's wheel-speed targets at the start [rad/s]

    def __len__(self) -> int:
        return len(self.t0)


@dataclass
class CalibrationResult:
    """What :func:`calibrate` found (``to_dict`` is the report's JSON)."""

    values: dict[str, float]
    """Fitted value of each parameter, in its unit."""
    nominal: dict[str, float]
    """The rover's value before the fit."""
    spread: dict[str, float]
    """Standard deviation over the starts' end points; nan with one start."""
    standard_error: dict[str, float]
    """Each value's standard error: :attr:`statistical_error` and the replay's fidelity (:data:`FIT_FIDELITY`) in
    quadrature; 1.96 of them either side is the 95 % interval the console, the report and the written config give."""
    starts: list[dict]
    """Each start's end: its values, mean training loss, replays (``evaluations``), the share of a range its last
    undamped step would move (``settled``) and its loss after each iteration (``losses``)."""
    errors: dict[str, dict[str, list[float]]]
    """Mean position error [m] per segment: ``{"train"|"held_out": {"before": [...], "after": [...]}}``."""
    converged: bool
    reason: str
    segments: Segments
    seconds: float
    compile_seconds: float
    paths: dict[str, np.ndarray] = field(default_factory=dict)
    """Held-out segments' recorded, nominal and calibrated paths (for the plot)."""
    driver: dict[str, float] | None = None
    """The driver a ``cmd_vel`` replay ran the commands through: its configured ``wheel_radius`` [m] and
    ``track_width`` [m], ``effective_track_factor`` [-], ``kp`` and ``ki``; ``None`` for an effort replay."""
    misfit: dict | None = None
    """The model check: ``noise`` (each channel's noise in the recording, from its sample-to-sample second
    differences), ``ratio`` (each channel's median held-out error after the fit over the larger of its noise and its
    :data:`MISFIT_FLOOR`), ``threshold`` (:attr:`CalibrationConfig.misfit_ratio`), ``flagged`` and its one ``line``."""
    latency: dict | None = None
    """The commands' latency (a ``cmd_vel`` replay): ``seconds``, whether it was ``fitted`` and, if so, the training
    loss at the first fit's values for each latency tried (``loss_by_latency``); ``None`` for an effort replay."""
    statistical_error: dict[str, float] = field(default_factory=dict)
    """The part from the recording's noise: the sandwich estimate from every training segment's loss gradient and the
    Gauss-Newton Hessian of the total, both from the fit's last Jacobian (segments taken as independent); nan where
    the Hessian is singular."""
    correlation: list[tuple[str, str, float]] = field(default_factory=list)
    """Each pair of fitted parameters' correlation in the sandwich estimate (nan where the Hessian is singular)."""

    @property
    def confounded(self) -> list[tuple[str, str, float]]:
        """The pairs the drive does not tell apart: correlation beyond :data:`CONFOUNDED` (it fixes a combination of
        them, not each)."""
        return [(a, b, r) for a, b, r in self.correlation if abs(r) > CONFOUNDED]

    def error_summary(self) -> dict[str, dict[str, float]]:
        """Median of the per-segment errors, and the ratio before / after."""
        out = {}
        for split, e in self.errors.items():
            before, after = float(np.median(e["before"])), float(np.median(e["after"]))
            out[split] = {"before_m": before, "after_m": after, "reduction": before / max(after, 1e-9)}
        return out

    def to_dict(self) -> dict:
        return {"values": self.values, "nominal": self.nominal, "standard_error": self.standard_error,
                "statistical_error": self.statistical_error,
                "correlation": [{"pair": [a, b], "correlation": r} for a, b, r in self.correlation],
                "confounded": [[a, b] for a, b, _ in self.confounded],
                "spread": self.spread, "starts": self.starts,
                "errors": self.errors, "error_summary": self.error_summary(), "converged": self.converged,
                "reason": self.reason, "segments": {"train": int((~self.segments.held_out).sum()),
                                                    "held_out": int(self.segments.held_out.sum()),
                                                    "seconds": self.segments.inputs.shape[1] * 0.05,
                                                    "command": self.segments.command},
                "driver": self.driver, "latency": self.latency, "misfit": self.misfit, "fit_seconds": self.seconds,
                "compile_seconds": self.compile_seconds}


def _controller(log: DriveLog, driver: DriverConfig, grid: np.ndarray, wheel: np.ndarray, dt: float,
                substeps: int, latency: float = 0.0):
    """The base's motor driver replayed along the log on the recorded wheel speeds
    (:func:`atrv_warp.sim.driver.replay`): each step's command (zero once the timeout has stopped the base), and
    the driver's PI integral before the step, and its wheel-speed targets there (left, right [rad/s]).
    ``latency`` [s]: a command reaches the driver this long after its stamp."""
    from atrv_warp.sim.driver import replay

    arrived = grid - latency
    received = np.searchsorted(log.cmd_time, arrived + 1e-6, side="right")  # commands received by each step
    last = np.maximum(received - 1, 0)
    fresh = (received > 0) & (arrived - log.cmd_time[last] <= driver.cmd_vel_timeout + 1e-9)
    twist = np.where(fresh[:, None], log.cmd[last, :2], 0.0)
    kinematics = driver.kinematics(None, None)
    state = replay(driver, kinematics, twist[None], fresh[None],
                   np.concatenate([wheel, wheel[-1:]])[None], step_dt=dt, substeps=substeps)
    targets = kinematics.wheel_speeds(state["reference"][0, :-1, 0].double(), state["reference"][0, :-1, 1].double())
    return twist, state["integral"][0, :-1].double().numpy(), targets.numpy().reshape(-1, 2)


def integral_from_effort(effort, target, speed, driver: DriverConfig, *, torque_scale=1.0,
                         speed_limit=math.inf) -> torch.Tensor:
    """The base driver's PI integral [rad] from what a bag records at a step's end, (..., 2) each side's: the
    ``effort`` [N·m] (the torque of the driver's last loop times the motor's ``torque_scale``, tapered near its
    no-load ``speed_limit`` [rad/s] as the simulator's motor is), the driver's wheel-speed ``target`` and the wheels'
    ``speed`` [rad/s]. The torque the driver asked for, less its proportional term, over its integral gain. NaN where
    the effort cannot tell it: a saturated motor (the integral is held there), one tapering past half its torque, a
    zero torque scale or integral gain.

    It holds the integral to a few thousandths of a radian, where the driver replayed along 20 Hz wheel speeds is
    several hundredths off (``benchmarks/calibration/calibration_start_state.py``)."""
    effort, target, speed = (torch.as_tensor(x, dtype=torch.float32) for x in (effort, target, speed))
    scale = torch.as_tensor(torque_scale, dtype=torch.float32)
    limit = torch.as_tensor(speed_limit, dtype=torch.float32)
    taper = ((1.0 - speed.abs() / limit) / (1.0 - float(MOTOR_TAPER_START))).clamp(0.0, 1.0)
    taper = torch.where(effort * speed <= 0.0, torch.ones_like(taper), taper)  # braking: the full torque
    asked = effort / (scale * taper).clamp(min=1e-6)
    integral = (asked - driver.kp * (target - speed)) / max(driver.ki, 1e-12)
    usable = (taper > 0.5) & (asked.abs() < 0.999 * driver.torque_limit) & (scale > 1e-3) & (driver.ki > 0)
    return torch.where(usable, integral, torch.full_like(integral, math.nan))


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average of ``window`` samples (made odd) along axis 0; the ends repeat the first and last."""
    half = max(0, window) // 2
    if half == 0:
        return x
    padded = np.concatenate([np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)])
    kernel = np.full(2 * half + 1, 1.0 / (2 * half + 1))
    return np.stack([np.convolve(padded[:, i], kernel, mode="valid") for i in range(x.shape[1])], -1)


MAX_GAP_S = 1.0
"""A pause longer than this [s] between two poses or two joint states splits a drive: segments are cut within the
spans between pauses, and a pause's time is never put on the step grid. So the memory a fit takes grows with the
recorded drive, not with the time a bag spans (a bag with a day-long gap costs what its data costs)."""


def drive_spans(log: DriveLog, start: float, end: float) -> list[tuple[float, float]]:
    """The spans of [``start``, ``end``] [s] in which neither the poses nor the joint states pause longer than
    :data:`MAX_GAP_S`, in order."""
    pauses = sorted((float(t[k]), float(t[k + 1])) for t in (log.pose_time, log.joint_time)
                    for k in np.nonzero(np.diff(t) > MAX_GAP_S)[0])
    spans, lo = [], start
    for a, b in pauses:
        if a > lo:
            spans.append((lo, min(a, end)))
        lo = max(lo, b)
        if lo >= end:
            break
    if lo < end:
        spans.append((lo, end))
    return [(a, b) for a, b in spans if b > a] or [(start, end)]


def _along(log: DriveLog, cfg: CalibrationConfig, driver: DriverConfig, grid: np.ndarray, dt: float, substeps: int,
           latency: float, command: str) -> dict:
    """What the fit reads of ``log`` on one span's step ``grid``: the wheels, the smoothed pose and its velocity, the
    tilt, each wheel, the efforts, and the replayed driver's inputs, integral and targets."""
    wheel = np.stack([np.interp(grid, log.joint_time, log.wheel_speed[:, s]) for s in (0, 1)], -1)
    pose = _smooth(np.stack([np.interp(grid, log.pose_time, log.pose[:, i]) for i in range(3)], -1),
                   round(cfg.pose_smoothing / dt))
    if log.twist:
        vel = np.stack([np.interp(grid, log.pose_time, log.body_velocity[:, i]) for i in range(3)], -1)
    else:  # the velocity from the smoothed poses, in the chassis frame
        vx, vy = np.gradient(pose[:, 0], dt), np.gradient(pose[:, 1], dt)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        vel = np.stack([c * vx + s * vy, -s * vx + c * vy, np.gradient(pose[:, 2], dt)], -1)
    # the start state's tilt, its rate and each wheel's speed (a pitching rover restarted level rocks back)
    tilt = None if log.tilt is None else np.stack([np.interp(grid, log.pose_time, log.tilt[:, i]) for i in (0, 1)], -1)
    tilt_rate = (None if log.tilt_rate is None else
                 np.stack([np.interp(grid, log.pose_time, log.tilt_rate[:, i]) for i in (0, 1)], -1))
    each = (None if log.wheel_each is None else
            np.stack([np.interp(grid, log.joint_time, log.wheel_each[:, j]) for j in range(log.wheel_each.shape[1])], -1))
    # the effort stamped at a step's end is what the motors held over it
    effort = (None if log.effort is None else
              np.stack([np.interp(grid + dt, log.joint_time, log.effort[:, s]) for s in (0, 1)], -1))
    if command == "cmd_vel":
        inputs, integral, targets = _controller(log, driver, grid, wheel, dt, substeps, latency)
    else:
        inputs, integral, targets = effort, np.zeros_like(effort), None
    # the effort stamped at a segment's start: the torque of the driver's last loop before it, which its integral made
    start_effort = (None if command != "cmd_vel" or log.effort is None else
                    np.stack([np.interp(grid, log.joint_time, log.effort[:, s]) for s in (0, 1)], -1))
    return {"grid": grid, "wheel": wheel, "pose": pose, "vel": vel, "tilt": tilt, "tilt_rate": tilt_rate,
            "each": each, "effort": effort, "inputs": inputs, "integral": integral, "targets": targets,
            "start_effort": start_effort}


def make_segments(log: DriveLog, cfg: CalibrationConfig, driver: DriverConfig, dt: float = 0.05,
                  substeps: int = 5, *, latency: float | None = None, like: Segments | None = None) -> Segments:
    """Cut ``log`` into segments of ``cfg.segment_seconds`` on the controller's step grid, leaving out the
    ones where the rover stands still; raises :class:`CalibrationError` if fewer than ``cfg.min_segments`` remain.
    ``driver``: the base's driver with its configured radius and track set (:meth:`CalibrationConfig.driver`);
    ``substeps``: the driver's loop runs this many times per step, as in the simulator; ``latency``: the commands'
    latency [s] (``None``: ``cfg.latency``, or 0 where it is fitted); ``like``: the same segments as these (their
    start times), under another latency. The robot's gains, torque limit and track factor fill what ``driver``
    leaves unset (``cfg.robot``'s)."""
    driver = driver.resolved(cfg.robot)
    command = cfg.command
    if command == "auto":
        command = "cmd_vel" if len(log.cmd_time) else "effort"
    if command == "cmd_vel" and not len(log.cmd_time):
        raise CalibrationError(f"{log.path}: no velocity commands to replay (use --command effort)")
    if command == "effort" and log.effort is None:
        raise CalibrationError(f"{log.path}: the joint states carry no efforts to replay (use --command cmd_vel)")
    if command == "effort" and cfg.params != DEFAULT_FIT and set(cfg.params) & set(MOTOR_PARAMETERS):
        raise CalibrationError(f"{log.path}: an effort replay applies the recorded torques, so it cannot fit "
                               f"{sorted(set(cfg.params) & set(MOTOR_PARAMETERS))} (fit them with --command cmd_vel, "
                               "or leave them out of --params)")
    start = max(log.pose_time[0], log.joint_time[0])
    end = min(log.pose_time[-1], log.joint_time[-1])
    if cfg.duration is not None:
        end = min(end, start + cfg.duration)
    latency = (cfg.latency or 0.0) if latency is None else latency
    steps = round(cfg.segment_seconds / dt)
    spans = [_along(log, cfg, driver, a + dt * np.arange(math.floor((b - a) / dt + 1e-6) + 1), dt, substeps, latency,
                    command) for a, b in drive_spans(log, start, end)]
    spans = [span for span in spans if len(span["grid"]) > steps] or spans[:1]
    # segments are cut within a span: none straddles a gap, whose time is never gridded
    offsets = np.cumsum([0] + [len(span["grid"]) for span in spans])
    starts = np.concatenate([o + np.arange(0, len(span["grid"]) - steps, steps) for o, span in zip(offsets, spans)])
    joined = {k: None if spans[0][k] is None else np.concatenate([span[k] for span in spans]) for k in spans[0]}
    grid, wheel, pose, vel = joined["grid"], joined["wheel"], joined["pose"], joined["vel"]
    tilt, tilt_rate, each, effort = joined["tilt"], joined["tilt_rate"], joined["each"], joined["effort"]
    inputs, integral, targets, start_effort = (joined["inputs"], joined["integral"], joined["targets"],
                                               joined["start_effort"])
    keep = []
    for k in starts:
        window = slice(k, k + steps + 1)
        moved = np.hypot(*(pose[k + steps, :2] - pose[k, :2])) + _HEADING_ARM * abs(pose[k + steps, 2] - pose[k, 2])
        commanded = np.abs(inputs[k:k + steps]).max() > (0.05 if command == "cmd_vel" else 0.5)  # m/s, rad/s; N·m
        if moved > 0.05 or np.abs(wheel[window]).max() > 0.5 or commanded:
            keep.append(k)
    if like is not None:
        keep = list(np.searchsorted(grid, like.t0 - 1e-6))
    if len(keep) < cfg.min_segments:
        gridded = (len(grid) - 1) * dt
        raise CalibrationError(f"{log.path}: too short to fit: {len(keep)} moving segment(s) of "
                               f"{cfg.segment_seconds:g} s in {gridded:.1f} s of log (need {cfg.min_segments})"
                               + (f"; {end - start - gridded:.1f} s of it are pauses longer than {MAX_GAP_S:g} s"
                                  if end - start - gridded > 1.0 else ""))
    keep = np.array(keep)
    idx = keep[:, None] + np.arange(steps + 1)[None, :]
    ref = pose[idx].copy()
    ref[:, :, :2] -= ref[:, :1, :2]
    return Segments(t0=grid[keep], yaw0=pose[keep, 2], velocity=vel[keep, :2], yaw_rate=vel[keep, 2],
                    wheel=wheel[keep], integral=integral[keep], inputs=inputs[idx[:, :-1]], ref_pose=ref,
                    ref_wheel=wheel[idx],
                    ref_effort=effort[idx[:, :-1]] if command == "cmd_vel" and effort is not None else None,
                    held_out=(np.arange(len(keep)) % cfg.held_out_every) == cfg.held_out_every - 1,
                    command=command, latency=latency if command == "cmd_vel" else 0.0,
                    tilt=None if tilt is None else tilt[keep], tilt_rate=None if tilt_rate is None else tilt_rate[keep],
                    wheel_each=None if each is None else each[keep], wheel_joints=log.wheel_joints,
                    start_effort=None if start_effort is None else start_effort[keep],
                    start_target=None if targets is None else targets[keep])


class _Replay:
    """Segments replayed forward in chunks of a :class:`~atrv_warp.sim.diff.DiffRollout`'s worlds, each world with
    its own parameter values; no tape: the fit's derivatives are finite differences, each in worlds of its own."""

    def __init__(self, segments: Segments, worlds: int, rover: RoverConfig, contact: ContactConfig,
                 cfg: CalibrationConfig, driver: DriverConfig):
        from atrv_warp.sim.diff import DiffRollout

        # the mass matrix refreshed once per step, as the simulator steps by default (its dense products are most of
        # a CPU rollout's time)
        self.roll = DiffRollout(worlds, steps=segments.inputs.shape[1], rover=rover, contact=contact,
                                twist=segments.command == "cmd_vel", driver=driver, action_scale=1.0,
                                mass_matrix_interval=None)
        self.segments, self.worlds = segments, worlds
        self.rover, self.driver = rover, driver
        self.warmup = round(cfg.warmup / 0.05) if segments.command == "cmd_vel" else 0
        self.nominal_chassis_mass = self.roll.nominal_chassis_mass
        joints = [w.joint for w in self.roll.sim.description.wheels]
        self.start_wheels = segments.wheel  # (S, 2) each side's speed, or (S, W) each wheel's in the rover's order
        if segments.wheel_each is not None and set(segments.wheel_joints) == set(joints):
            self.start_wheels = segments.wheel_each[:, [segments.wheel_joints.index(j) for j in joints]]

    def start_integral(self, pad: np.ndarray, kwargs: dict) -> torch.Tensor:
        """(W, 2) the driver's PI integral at the segments' starts, for each world's motor
        (:func:`integral_from_effort`, and the replayed driver's where that has none)."""
        seg = self.segments
        replayed = torch.as_tensor(seg.integral[pad], dtype=torch.float32)
        if seg.start_effort is None or seg.start_target is None:
            return replayed
        w = len(pad)
        scale = torch.as_tensor(kwargs.get("torque_scale", self.rover.torque_scale), dtype=torch.float32).expand(w)
        limit = torch.as_tensor(kwargs.get("speed_limit", self.rover.wheel_speed_limit), dtype=torch.float32).expand(w)
        integral = integral_from_effort(seg.start_effort[pad], seg.start_target[pad], seg.wheel[pad], self.driver,
                                        torque_scale=scale[:, None], speed_limit=limit[:, None])
        return torch.where(torch.isfinite(integral), integral, replayed)

    @torch.no_grad()
    def _chunk(self, index: np.ndarray, values: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor,
                                                                               torch.Tensor]:
        seg, n, w = self.segments, len(index), self.worlds
        pad = np.concatenate([index, np.full(w - n, index[0])])
        poses = torch.zeros(w, 3)
        poses[:, 2] = torch.as_tensor(seg.yaw0[pad], dtype=torch.float32)
        kwargs = {} if seg.command == "cmd_vel" else {"torque_scale": 1.0, "speed_limit": _NO_TAPER}
        for name, v in values.items():
            v = torch.as_tensor(np.concatenate([v, np.full(w - n, v[0])]), dtype=torch.float32)
            if name == "payload_mass":
                kwargs["chassis_mass"] = self.nominal_chassis_mass + v
            else:
                kwargs[name] = v
        # each world starts at the rest height of its own wheel radius and payload, as the recorded rover drove
        payload = kwargs["chassis_mass"] - self.nominal_chassis_mass if "chassis_mass" in kwargs else None
        state = self.roll.moving_state(poses, torch.as_tensor(seg.velocity[pad], dtype=torch.float32),
                                       torch.as_tensor(seg.yaw_rate[pad], dtype=torch.float32),
                                       torch.as_tensor(self.start_wheels[pad], dtype=torch.float32),
                                       wheel_radius=kwargs.get("wheel_radius"), payload_mass=payload,
                                       tilt=None if seg.tilt is None else torch.as_tensor(seg.tilt[pad]),
                                       tilt_rate=None if seg.tilt_rate is None else torch.as_tensor(seg.tilt_rate[pad]))
        actions = torch.as_tensor(seg.inputs[pad], dtype=torch.float32).transpose(0, 1).contiguous()
        integral = self.start_integral(pad, kwargs)
        sim_poses, speeds, torques = self.roll(actions, state, integral=integral, wheel_speeds=True,
                                               wheel_torques=True, **kwargs)
        ref = torch.as_tensor(seg.ref_pose[pad], dtype=torch.float32).transpose(0, 1)  # (L + 1, W, 3)
        ref_wheel = torch.as_tensor(seg.ref_wheel[pad], dtype=torch.float32).transpose(0, 1)
        xy = sim_poses[..., :2] - sim_poses[:1, :, :2]
        yaw = quat_to_yaw(sim_poses[..., 3:7])
        dxy = xy - ref[..., :2]
        dyaw = wrap_angle(yaw - ref[..., 2])
        # residuals whose squares sum to the segment's loss: each term's mean over its steps. The motor terms skip
        # the first steps, while the driver's reconstructed integral settles (its error decays within a few of its
        # 0.01 s loops); the path keeps them, it integrates what they do
        settled = slice(self.warmup, None)
        parts = [dxy / (_POSITION_SCALE * math.sqrt(len(dxy))),
                 (_HEADING_ARM * dyaw / (_POSITION_SCALE * math.sqrt(len(dyaw))))[..., None]]
        wheel = (speeds - ref_wheel)[settled]
        parts.append(wheel / (_WHEEL_SCALE * math.sqrt(len(wheel))))
        if seg.ref_effort is not None:
            ref_effort = torch.as_tensor(seg.ref_effort[pad], dtype=torch.float32).transpose(0, 1)
            effort = (torques - ref_effort)[settled]
            parts.append(effort / (_EFFORT_SCALE * math.sqrt(len(effort))))
        residuals = torch.cat([p.transpose(0, 1).reshape(w, -1) for p in parts], -1)  # (W, R)
        path = torch.cat([xy, yaw[..., None]], -1)
        return residuals[:n], dxy.norm(dim=-1).mean(0)[:n], path[:, :n]

    def channels(self, residuals: np.ndarray) -> dict[str, np.ndarray]:
        """Each segment's root-mean-square error per channel, in its unit, from its residuals (S, R) as
        :meth:`residuals` returns them: ``position`` [m], ``heading`` [rad], ``wheel_speed`` [rad/s] (per side) and,
        where the bag has efforts, ``effort`` [N·m] (per side)."""
        steps = self.segments.inputs.shape[1]
        sizes = {"position": 2 * (steps + 1), "heading": steps + 1, "wheel_speed": 2 * (steps + 1 - self.warmup)}
        if self.segments.ref_effort is not None:
            sizes["effort"] = 2 * (steps - self.warmup)
        scale = {"position": _POSITION_SCALE, "heading": _POSITION_SCALE / _HEADING_ARM,
                 "wheel_speed": _WHEEL_SCALE / math.sqrt(2.0), "effort": _EFFORT_SCALE / math.sqrt(2.0)}
        out, at = {}, 0
        for name, size in sizes.items():
            out[name] = scale[name] * np.sqrt((residuals[:, at:at + size] ** 2).sum(-1))
            at += size
        return out

    def residuals(self, index: np.ndarray, values: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Replay segments ``index`` (any number, in chunks of :attr:`worlds`), world i with ``values[p][i]``;
        returns each segment's residuals (S, R) (their squares sum to its loss), its mean position error [m] (S,)
        and the simulated path (L + 1, S, 3)."""
        out = [self._chunk(index[i:i + self.worlds], {p: v[i:i + self.worlds] for p, v in values.items()})
               for i in range(0, len(index), self.worlds)]
        return tuple(np.concatenate([o[j].double().numpy() for o in out], 1 if j == 2 else 0) for j in range(3))


def _driver_record(driver: DriverConfig) -> dict[str, float]:
    """What the report and the written config record of the replayed driver."""
    return {name: getattr(driver, name) for name in ("wheel_radius", "track_width", "effective_track_factor", "kp", "ki")}


def _nominal(rover: RoverConfig, contact: ContactConfig) -> dict[str, float]:
    """Every fit parameter's value in ``rover`` and ``contact``."""
    configs = {"rover": rover, "contact": contact}
    return {name: getattr(configs[p.table], p.key) for name, p in FIT_PARAMETERS.items()}


def sim_config_tables(values: dict[str, float]) -> dict[str, dict[str, float]]:
    """Fit parameters' ``values`` as a simulator config's tables, ``{"rover": {key: value}, "contact": {...}}``: the
    keywords of :class:`~atrv_warp.sim.config.RoverConfig` and :class:`~atrv_warp.sim.config.ContactConfig`
    (:data:`FIT_PARAMETERS`' ``table`` and ``key``)."""
    tables: dict[str, dict[str, float]] = {"rover": {}, "contact": {}}
    for name, value in values.items():
        p = FIT_PARAMETERS[name]
        tables[p.table][p.key] = value
    return tables


@dataclass
class _Start:
    """One start's Levenberg–Marquardt state, in the unit box of the parameters' bounds."""

    unit: np.ndarray  # (P,) the current point, 0..1 of each parameter's range
    residuals: np.ndarray  # (S, R) at it
    jacobian: np.ndarray  # (S, R, P) d residuals / d unit, by forward differences
    damping: float
    robust: float | None
    """:attr:`CalibrationConfig.robust`."""
    evaluations: int = 1
    settled: float = math.inf
    """The undamped Gauss–Newton step from the current point: its largest move as a fraction of a range."""
    history: list = field(default_factory=list)

    @property
    def loss(self) -> float:
        """The mean of the segments' losses."""
        return float((self.residuals**2).sum() / len(self.residuals))

    @property
    def objective(self) -> float:
        """What the fit lowers: the mean of the segments' losses, each through :func:`_cauchy`."""
        return float(_cauchy((self.residuals**2).sum(-1), self.robust).mean())

    def weights(self) -> np.ndarray:
        """(S,) each segment's weight in the Gauss-Newton step (the derivative of :func:`_cauchy` at its loss)."""
        loss = (self.residuals**2).sum(-1)
        return np.ones_like(loss) if self.robust is None else 1.0 / (1.0 + loss / self.robust)

    def step(self, damping: float) -> np.ndarray:
        """The Levenberg-Marquardt step from :attr:`unit` with Marquardt's scaling (a ``damping`` share of the normal
        equations' diagonal; 0: Gauss-Newton's), each segment weighted by :meth:`weights`, in the box: a parameter on
        a bound that the step would push out stays there, and the others are solved for without it."""
        w = self.weights()
        a = np.einsum("s,srp,srq->pq", w, self.jacobian, self.jacobian)
        g = np.einsum("s,srp,sr->p", w, self.jacobian, self.residuals)
        a = a + damping * np.diag(np.diag(a).clip(min=1e-12))
        free = np.ones(len(g), dtype=bool)
        for _ in range(len(g)):
            delta = np.zeros(len(g))
            delta[free] = -np.linalg.lstsq(a[np.ix_(free, free)], g[free], rcond=None)[0]
            out = free & (((self.unit <= 0.0) & (delta < 0)) | ((self.unit >= 1.0) & (delta > 0)))
            if not out.any():
                break
            free &= ~out
        return (self.unit + delta).clip(0.0, 1.0)


def _cauchy(loss: np.ndarray, scale: float | None) -> np.ndarray:
    """Segment losses through Cauchy's ``scale * log(1 + loss / scale)``: as they are where small, growing only
    logarithmically past ``scale`` (``None``: as they are)."""
    return loss if scale is None else scale * np.log1p(loss / scale)


def _levenberg_marquardt(replay: _Replay, train: np.ndarray, names: list[str], low: np.ndarray, span: np.ndarray,
                         units: np.ndarray, cfg: CalibrationConfig, say: Callable[[str], None]) -> list[_Start]:
    """Fit every start in ``units`` (K, P) at once: each iteration replays, for every start still moving, its
    trial point and a forward-difference step along each parameter from it, all in one batch of worlds. A trial that
    lowers the loss is taken, with its Jacobian; one that does not raises the damping and the old Jacobian serves
    again. A start stops once its undamped Gauss–Newton step moves no parameter more than ``cfg.tolerance`` of
    its range: a stationary point of the whole loss, valley or not."""
    count, p, t0 = len(train), len(names), time.perf_counter()

    def replay_points(points: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Residuals and Jacobian at each point: it and its P forward-difference neighbours, every training segment."""
        stencils, steps = [], []
        for u in points:
            h = np.where(u + cfg.difference_step <= 1.0, cfg.difference_step, -cfg.difference_step)  # inward
            stencils.append(np.concatenate([u[None], u[None] + np.diag(h)]))
            steps.append(h)
        grid = low + span * np.concatenate(stencils)  # (K (P + 1), P) parameter values
        per_world = {name: np.repeat(grid[:, j], count) for j, name in enumerate(names)}
        res = replay.residuals(np.tile(train, len(grid)), per_world)[0].reshape(len(points), p + 1, count, -1)
        return [(r[0], ((r[1:] - r[:1]) / h[:, None, None]).transpose(1, 2, 0)) for r, h in zip(res, steps)]

    starts = [_Start(u, r, jac, cfg.damping, cfg.robust) for u, (r, jac) in zip(units, replay_points(list(units)))]
    for s in starts:
        s.history.append(s.objective)
    for it in range(cfg.iterations):
        moving = [s for s in starts if s.settled > cfg.tolerance]
        for s in moving:  # the undamped step's size: settled once it is within the tolerance
            s.settled = float(np.abs(s.step(0.0) - s.unit).max())
        moving = [s for s in moving if s.settled > cfg.tolerance]
        if not moving:
            break
        trials = [s.step(s.damping) for s in moving]
        for s, u, (r, jac) in zip(moving, trials, replay_points(trials)):
            s.evaluations += 1
            if float(_cauchy((r**2).sum(-1), cfg.robust).mean()) < s.objective:
                s.unit, s.residuals, s.jacobian, s.damping = u, r, jac, max(s.damping / 3.0, 1e-6)
            else:
                s.damping *= 4.0
            s.history.append(s.objective)
        say(f"  iteration {it + 1:2d}: " + "; ".join(
            f"loss {s.objective:.4f} " + " ".join(f"{n} {low[j] + span[j] * s.unit[j]:.4g}" for j, n in enumerate(names))
            for s in starts) + f"  ({time.perf_counter() - t0:.0f} s)")
    for s in starts:  # where the loop ran out, each start's last undamped step
        s.settled = float(np.abs(s.step(0.0) - s.unit).max())
    return starts


def _standard_error(start: _Start, names: list[str], span: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
    """Sandwich standard errors at the fit: ``H^-1 (sum_i g_i g_i^T) H^-1`` with ``g_i`` the gradient of training
    segment i's loss and ``H`` the Gauss–Newton Hessian of their sum, both from the fit's last Jacobian (segments
    taken as independent), and the parameters' correlation matrix; nan where ``H`` is singular."""
    jac, res, w = start.jacobian, start.residuals, start.weights()  # (S, R, P), (S, R), (S,)
    g = 2.0 * np.einsum("s,srp,sr->sp", w, jac, res)
    hessian = 2.0 * np.einsum("s,srp,srq->pq", w, jac, jac)
    if not bool((np.linalg.eigvalsh(hessian) > 1e-12 * np.abs(hessian).max()).all()):
        return {p: math.nan for p in names}, np.full((len(names), len(names)), math.nan)
    inverse = np.linalg.inv(hessian)
    cov = inverse @ (g.T @ g) @ inverse
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return {p: float(span[j] * sd[j]) for j, p in enumerate(names)}, cov / np.outer(sd, sd)


def calibrate(log: DriveLog, cfg: CalibrationConfig = CalibrationConfig(), *,
              rover: RoverConfig | None = None, contact: ContactConfig | None = None,
              progress: Callable[[str], None] | None = None) -> CalibrationResult:
    """Fit ``cfg.params`` to ``log``, starting from ``rover`` and ``contact`` (default: ``cfg.robot``'s nominal rover).

    Where ``cfg.latency`` is ``None`` (a ``cmd_vel`` replay), the commands' latency is fitted too: after a fit at
    none, the training segments are replayed at the fitted values with each whole-step latency up to
    ``cfg.max_latency``; one that lowers the loss by more than 5 % is taken and the values fitted again with it,
    in turn until no latency does. The result ends with the model check (:attr:`CalibrationResult.misfit`)."""

    say = progress or (lambda _text: None)
    rover = rover or cfg.nominal_rover()
    contact = contact or ContactConfig()
    driver = cfg.driver()
    seg = make_segments(log, cfg, driver)
    names = [p for p in cfg.params if seg.command == "cmd_vel" or p not in MOTOR_PARAMETERS]
    nominal = _nominal(rover, contact)
    for p in names:
        if not FIT_PARAMETERS[p].low <= nominal[p] <= FIT_PARAMETERS[p].high:
            raise CalibrationError(f"the rover's {p} {nominal[p]:g} is outside the fit's bounds "
                                   f"[{FIT_PARAMETERS[p].low:g}, {FIT_PARAMETERS[p].high:g}]")
    through = (f" through a driver configured with wheel radius {driver.wheel_radius:g} m, track "
               f"{driver.track_width:g} m" if seg.command == "cmd_vel" else "")
    train, held = np.flatnonzero(~seg.held_out), np.flatnonzero(seg.held_out)
    say(f"{len(train)} training and {len(held)} held-out segments of {cfg.segment_seconds:g} s "
        f"({seg.command}{through}); fitting {', '.join(names)} from {cfg.starts} starts")
    t_compile = time.perf_counter()
    # one batch: every start's point and its forward differences on every training segment, in chunks of at most
    # cfg.worlds of about equal size
    total = cfg.starts * (len(names) + 1) * len(train)
    replay = _Replay(seg, -(-total // -(-total // cfg.worlds)), rover, contact, cfg, driver)
    replay.residuals(train[:1], {p: np.array([nominal[p]]) for p in names})  # the first use compiles the kernels
    compile_s = time.perf_counter() - t_compile
    t_fit = time.perf_counter()
    ends = _fit(replay, train, names, nominal, cfg, say)
    latency = None
    if cfg.latency is None and seg.command == "cmd_vel":
        # the latency and the values are fitted in turn: each fit's values replayed at every whole-step latency; a
        # latency that lowers the loss by more than 5 % is taken and the values fitted again (a fit at a latency
        # short of the truth absorbs part of it, so the next scan can see further)
        candidates = [round(0.05 * k, 6) for k in range(round(cfg.max_latency / 0.05) + 1)]
        current, tried = 0.0, {0.0}
        for _ in range(len(candidates)):
            fitted = {**nominal, **_values(ends, names)}
            losses = {}
            for value in candidates:
                replay.segments = make_segments(log, cfg, driver, latency=value, like=seg)
                res = replay.residuals(train, {p: np.full(len(train), fitted[p]) for p in names})[0]
                losses[value] = float(_cauchy((res**2).sum(-1), cfg.robust).mean())
            best = min(losses, key=losses.get)
            latency = {"seconds": current, "fitted": True, "loss_by_latency": losses}
            if best == current or best in tried or losses[best] >= 0.95 * losses[current]:
                break
            say(f"command latency {best:g} s lowers the loss {losses[current]:.4f} -> {losses[best]:.4f}: fitting "
                "again with it")
            current = best
            tried.add(best)
            replay.segments = make_segments(log, cfg, driver, latency=current, like=seg)
            ends = _fit(replay, train, names, nominal, cfg, say)
        latency["seconds"] = current
        seg = replay.segments = make_segments(log, cfg, driver, latency=current, like=seg)
    elif seg.command == "cmd_vel":
        latency = {"seconds": seg.latency, "fitted": False}
    return _result(replay, seg, ends, names, nominal, cfg, noise=recording_noise(log, cfg), latency=latency,
                   seconds=time.perf_counter() - t_fit,
                   compile_seconds=compile_s, driver=_driver_record(driver) if seg.command == "cmd_vel" else None)


def _values(ends: list[_Start], names: list[str]) -> dict[str, float]:
    """The best start's values."""
    best = min(ends, key=lambda s: s.objective)
    return {p: float(FIT_PARAMETERS[p].low + (FIT_PARAMETERS[p].high - FIT_PARAMETERS[p].low) * best.unit[j])
            for j, p in enumerate(names)}


def _fit(replay: _Replay, train: np.ndarray, names: list[str], nominal: dict[str, float], cfg: CalibrationConfig,
         say: Callable[[str], None]) -> list[_Start]:
    """Levenberg-Marquardt from the rover's values and ``cfg.starts - 1`` random points within the bounds."""
    low = np.array([FIT_PARAMETERS[p].low for p in names])
    span = np.array([FIT_PARAMETERS[p].high for p in names]) - low
    rng = np.random.default_rng(cfg.seed)
    start = (np.array([nominal[p] for p in names]) - low) / span
    units = np.concatenate([start[None], rng.uniform(0.1, 0.9, (cfg.starts - 1, len(names)))])
    return _levenberg_marquardt(replay, train, names, low, span, units, cfg, say)


def recording_noise(log: DriveLog, cfg: CalibrationConfig = CalibrationConfig()) -> dict[str, float]:
    """Each channel's noise in the part of ``log`` the fit uses, as a standard deviation: from the second differences
    of consecutive samples (a white noise's have sqrt(6) times its deviation; a smooth signal's are small at 20 Hz),
    robustly (the median absolute deviation): ``position`` [m] (x and y), ``wheel_speed`` [rad/s] and, where the bag
    has them, ``effort`` [N·m]."""
    def deviation(t: np.ndarray, x: np.ndarray) -> float:
        if cfg.duration is not None:
            x = x[t <= t[0] + cfg.duration]
        d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
        return float(np.mean(1.4826 * np.median(np.abs(d2 - np.median(d2, 0)), 0)) / math.sqrt(6.0))

    out = {"position": deviation(log.pose_time, log.pose[:, :2]),
           "wheel_speed": deviation(log.joint_time, log.wheel_speed)}
    if log.effort is not None:
        out["effort"] = deviation(log.joint_time, log.effort)
    return out


def _model_check(errors: dict, noise: dict[str, float], cfg: CalibrationConfig) -> dict:
    """:attr:`CalibrationResult.misfit` from the held-out errors after the fit and the recording's noise."""
    after = errors["held_out"]["rms_after"]
    ratio = {c: after[c] / max(noise[c], MISFIT_FLOOR[c]) for c in noise if c in after}
    over = {c: r for c, r in ratio.items() if r > cfg.misfit_ratio}
    before, after_m = float(np.median(errors["held_out"]["before"])), float(np.median(errors["held_out"]["after"]))
    worse = after_m > 1.05 * before and after_m > MISFIT_FLOOR["position"]
    names = {"position": "position", "wheel_speed": "wheel speed", "effort": "wheel effort"}
    units = {"position": "m", "wheel_speed": "rad/s", "effort": "N·m"}
    shown = ", ".join(f"{names[c]} {ratio[c]:.1f}x" for c in ratio)
    if over or worse:
        what = ", ".join(f"{names[c]} {after[c]:.3g} {units[c]} ({r:.1f}x its noise)" for c, r in over.items())
        line = (f"MISFIT: the model does not explain this drive: after the fit the held-out {what}"
                if over else "MISFIT: the model does not explain this drive")
        line += ("; the fit made the held-out path error worse" if worse else "")
        line += (". Something on this rover is not in the model (motor lag, a slope, an off-centre load, a latency "
                 f"over {cfg.max_latency:g} s ...): the fitted values absorb it, so do not trust them as measurements")
        if "friction_rise" not in cfg.params:
            line += ("; where brisk turns miss, a friction that rises with slip may be it (--params "
                     f"{','.join(cfg.params)},friction_rise)")
    else:
        line = (f"model check: the held-out errors after the fit are {shown} the recording's noise (at most "
                f"{cfg.misfit_ratio:g}x passes): no misfit seen")
    return {"noise": noise, "ratio": ratio, "threshold": cfg.misfit_ratio, "flagged": bool(over or worse),
            "line": line}


def _result(replay: _Replay, seg: Segments, ends: list[_Start], names: list[str], nominal: dict[str, float],
            cfg: CalibrationConfig, *, noise: dict[str, float], **fields) -> CalibrationResult:
    """The fit's result: the best start, the starts' agreement, the standard errors, and every split's errors
    before and after, replayed in one batch."""
    train, held = np.flatnonzero(~seg.held_out), np.flatnonzero(seg.held_out)
    low = np.array([FIT_PARAMETERS[p].low for p in names])
    span = np.array([FIT_PARAMETERS[p].high for p in names]) - low
    starts = [{"values": {p: float(low[j] + span[j] * s.unit[j]) for j, p in enumerate(names)}, "train_loss": s.loss,
               "objective": s.objective,
               "evaluations": s.evaluations, "settled": s.settled, "losses": s.history} for s in ends]
    best = min(range(len(ends)), key=lambda k: ends[k].objective)
    fitted = {**nominal, **starts[best]["values"]}
    units_end = np.stack([s.unit for s in ends])
    # how far apart the starts ended (the largest parameter's distance, as a fraction of its range): where the loss
    # is flat along a valley, as a payload's is under a driver that holds its wheel speeds tightly, two starts that
    # end at the same point have found the valley's floor, not a ledge of it
    agree = float((units_end.max(0) - units_end.min(0)).max())
    spread = {p: float(np.std([s["values"][p] for s in starts], ddof=1)) if len(starts) > 1 else math.nan
              for p in names}
    statistical, correlation = _standard_error(ends[best], names, span)
    # the replay's fidelity, in quadrature: the sandwich estimate describes the recording's noise, not what the replay
    # cannot follow, which on the calibration sweep is most of the error
    standard_error = {p: math.hypot(statistical[p], FIT_FIDELITY[p]) for p in names}
    pairs = [(a, b, float(correlation[i, j])) for i, a in enumerate(names) for j, b in enumerate(names) if i < j]
    # every split before and after, in one batch
    index = np.concatenate([train, held, train, held])
    n = len(train) + len(held)
    res, err, path = replay.residuals(index, {p: np.repeat([nominal[p], fitted[p]], n) for p in names})
    loss = (res**2).sum(-1)
    rms = replay.channels(res)
    errors = {}
    for split, a, b in (("train", 0, len(train)), ("held_out", len(train), n)):
        errors[split] = {"before": err[a:b].tolist(), "after": err[n + a:n + b].tolist(),
                         "loss_before": float(loss[a:b].mean()), "loss_after": float(loss[n + a:n + b].mean()),
                         "rms_before": {c: float(np.median(v[a:b])) for c, v in rms.items()},
                         "rms_after": {c: float(np.median(v[n + a:n + b])) for c, v in rms.items()}}
    paths = {"recorded": seg.ref_pose[held], "nominal": path[:, len(train):n].transpose(1, 0, 2),
             "calibrated": path[:, n + len(train):].transpose(1, 0, 2), "t0": seg.t0[held]}
    # converged: every start settled (its undamped Gauss-Newton step within cfg.tolerance of each range: a stationary
    # point of the whole loss), the starts ended within 2 % of each parameter's range of each other, and the fit
    # beats the rover it started from on the training and the held-out segments
    settled = max(s.settled for s in ends)
    improved = all(errors[split]["loss_after"] < errors[split]["loss_before"] for split in errors)
    converged = improved and settled <= cfg.tolerance and agree < 0.02
    reason = ("converged" if converged else
              "did not converge: the fit is no better than the starting rover on the training or the held-out "
              "segments" if not improved else
              f"did not converge: after {cfg.iterations} iterations a Gauss-Newton step still moved a parameter "
              f"{100 * settled:.1f} % of its range" if settled > cfg.tolerance else
              f"did not converge: the starts ended {100 * agree:.1f} % of a parameter's range apart")
    return CalibrationResult(values={p: fitted[p] for p in names}, nominal={p: nominal[p] for p in names},
                             spread=spread, standard_error=standard_error, statistical_error=statistical,
                             correlation=pairs, starts=starts, errors=errors,
                             converged=converged, reason=reason, segments=seg, paths=paths,
                             misfit=_model_check(errors, noise, cfg), **fields)


def replay_errors(log: DriveLog, values: dict[str, float], cfg: CalibrationConfig = CalibrationConfig(), *,
                  rover: RoverConfig | None = None, contact: ContactConfig | None = None,
                  latency: float | None = None) -> dict[str, np.ndarray]:
    """Each segment's mean position error [m] with the parameters ``values`` (the others ``rover``'s and
    ``contact``'s), replayed as :func:`calibrate` replays ``log``: ``{"train": (S,), "held_out": (H,)}`` (a fit of a
    shorter part of the drive, measured on a longer one's held-out segments). ``latency``: the commands' [s] (a fit's
    ``result.latency["seconds"]``; ``None``: ``cfg``'s)."""
    rover = rover or cfg.nominal_rover()
    contact = contact or ContactConfig()
    driver = cfg.driver()
    seg = make_segments(log, cfg, driver, latency=latency)
    point = {**_nominal(rover, contact), **values}
    names = [p for p in FIT_PARAMETERS if seg.command == "cmd_vel" or p not in MOTOR_PARAMETERS]
    replay = _Replay(seg, min(len(seg), cfg.worlds), rover, contact, cfg, driver)
    index = np.arange(len(seg))
    err = replay.residuals(index, {p: np.full(len(seg), point[p]) for p in names})[1]
    return {"train": err[~seg.held_out], "held_out": err[seg.held_out]}
