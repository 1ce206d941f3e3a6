"""Fit the simulator's physical parameters to a recorded drive, through the simulator's own gradients.

The log is cut into segments of a few seconds. Every segment starts from its recorded state (pose, body
velocity, wheel speeds, and the wheel-speed controller's integral) and is replayed in its own world with
its recorded commands: the velocity commands through the base's own motor driver inside the rollout
(:mod:`atrv_warp.sim.driver`, the simulator's kernel, with the radius and track the robot's driver is configured
with: :attr:`CalibrationConfig.driver_wheel_radius`, by default the nominal rover's), or the recorded wheel efforts.
The physical wheel radius is fitted apart from the configured one: a worn tyre is a smaller physical radius under
the same driver. The loss is the error of the
simulated against the recorded path and wheel speeds. Several starting points run at once, each in its own
worlds; every ``held_out_every``-th segment is kept out of the fit and only measured.
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
from atrv_warp.integrations.calibration.log import DriveLog
from atrv_warp.sim.config import ContactConfig, RoverConfig, get_variant
from atrv_warp.sim.driver import DriverConfig

__all__ = ["COMMAND_SOURCES", "DEFAULT_FIT", "FIT_PARAMETERS", "MOTOR_PARAMETERS", "CalibrationConfig",
           "CalibrationError", "CalibrationResult", "Segments", "calibrate", "make_segments"]


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
}
"""What the fit can adjust, with its bounds: Coulomb mu, motor torque scale, payload at the chassis' centre of
mass, motor no-load speed, wheel rolling radius."""
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
    pose_smoothing: float = 0.25
    """Window of the centred moving average over the reference poses [s] (0: none). It takes the reference's
    noise out of each segment's start and of the error (a 1 cm noise is about the error left after a fit),
    and changes a path that bends at 1 rad/s by well under a millimetre."""
    warmup: float = 0.25
    """Each segment's first seconds [s] left out of the wheel-speed and effort terms (a ``cmd_vel`` replay): the
    driver's integral at a segment's start is reconstructed from 20 Hz wheel speeds, and its error decays there."""
    held_out_every: int = 5
    """Every k-th segment is held out of the fit, and only measured."""
    starts: int = 4
    """Starting points, fitted at once: the rover's values, then random points within the bounds."""
    batch: int = 16
    """Training segments per start in each gradient step."""
    iterations: int = 30
    """Adam steps on minibatches, every start at once."""
    lr: float = 0.2
    """Adam's step in the bounded parameters' logit space, decaying to a tenth."""
    polish: int = 20
    """Then L-BFGS iterations on every training segment (0: none) ... Under a driver that holds its wheel speeds
    tightly the loss is flat along friction x mass, and the polish walks that valley: 6 iterations stopped 8 kg short
    of a 12 kg payload, 20 reached it within 2 kg (``atrv-calibrate`` on the bag of
    ``tests/test_calibration.py``'s recovery test)."""
    polish_starts: int = 2
    """... from each of this many best starts; the one that ends lowest is the fit."""
    seed: int = 0
    min_segments: int = 5
    """A log with fewer moving segments is too short to fit."""
    kp: float = DriverConfig.kp
    """The base's wheel-speed PI, as the robot's driver runs it (:class:`~atrv_warp.sim.driver.DriverConfig`)."""
    ki: float = DriverConfig.ki
    effective_track_factor: float = DriverConfig.effective_track_factor
    cmd_vel_timeout: float = DriverConfig.cmd_vel_timeout
    torque_limit: float = DriverConfig.torque_limit
    driver_wheel_radius: float | None = None
    """The wheel radius the robot's driver is configured with [m]: it turns ``/cmd_vel`` into wheel-speed targets
    and wheel speeds into odometry. ``None``: the nominal rover's (the realistic variant's 0.125 m, as an unconfigured
    :class:`~atrv_warp.sim.driver.DriverConfig` has; not a ``sim_config``'s). The physical radius, worn or not, is a
    fitted parameter (``wheel_radius``)."""
    driver_track_width: float | None = None
    """The wheel track the robot's driver is configured with [m]. ``None``: the nominal rover's (its URDF's, 0.5 m)."""

    def driver(self) -> DriverConfig:
        """The base's motor driver as the replay runs it: these gains and limits, and the configured radius and track
        (a real driver knows its configured values, not the wheel's wear), ``None`` resolved to the nominal rover's."""
        from atrv_warp.sim.urdf import load_rover

        nominal = get_variant("realistic")
        radius = nominal.wheel_radius if self.driver_wheel_radius is None else self.driver_wheel_radius
        track = track_width(load_rover(nominal), nominal) if self.driver_track_width is None else self.driver_track_width
        return DriverConfig(wheel_radius=radius, track_width=track,
                            effective_track_factor=self.effective_track_factor, kp=self.kp, ki=self.ki,
                            torque_limit=self.torque_limit, cmd_vel_timeout=self.cmd_vel_timeout)

    def __post_init__(self):
        unknown = sorted(set(self.params) - set(FIT_PARAMETERS))
        if unknown or not self.params:
            raise CalibrationError(f"unknown or no parameter(s) to fit {unknown or list(self.params)}; "
                                   f"known: {list(FIT_PARAMETERS)}")
        if self.command not in COMMAND_SOURCES:
            raise CalibrationError(f"command must be one of {COMMAND_SOURCES}, got {self.command!r}")
        if not 0.0 <= self.pose_smoothing <= 0.5 * self.segment_seconds:
            raise CalibrationError(f"pose_smoothing must be within [0, segment_seconds / 2], got {self.pose_smoothing}")
        for name in ("segment_seconds", "lr", "kp", "effective_track_factor", "cmd_vel_timeout", "torque_limit"):
            if not getattr(self, name) > 0:
                raise CalibrationError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("driver_wheel_radius", "driver_track_width"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise CalibrationError(f"{name} must be a finite number > 0 [m], got {value!r}")
        if self.polish < 0:
            raise CalibrationError(f"polish must be >= 0, got {self.polish}")
        if not 1 <= self.polish_starts <= self.starts:
            raise CalibrationError(f"polish_starts must be within [1, starts], got {self.polish_starts}")
        for name in ("held_out_every", "starts", "batch", "iterations", "min_segments"):
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
    """Standard deviation over the converged starts (each with its own start and draws of segments); nan with one."""
    standard_error: dict[str, float]
    """Each value's standard error: the sandwich estimate from every training segment's loss gradient and a
    finite-difference Hessian of the total at the fitted values (segments taken as independent); nan where
    the Hessian is not positive definite."""
    starts: list[dict]
    """Each start's values and loss, both the means over its last quarter of minibatch steps."""
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

    def error_summary(self) -> dict[str, dict[str, float]]:
        """Median of the per-segment errors, and the ratio before / after."""
        out = {}
        for split, e in self.errors.items():
            before, after = float(np.median(e["before"])), float(np.median(e["after"]))
            out[split] = {"before_m": before, "after_m": after, "reduction": before / max(after, 1e-9)}
        return out

    def to_dict(self) -> dict:
        return {"values": self.values, "nominal": self.nominal, "standard_error": self.standard_error,
                "spread": self.spread, "starts": self.starts,
                "errors": self.errors, "error_summary": self.error_summary(), "converged": self.converged,
                "reason": self.reason, "segments": {"train": int((~self.segments.held_out).sum()),
                                                    "held_out": int(self.segments.held_out.sum()),
                                                    "seconds": self.segments.inputs.shape[1] * 0.05,
                                                    "command": self.segments.command},
                "driver": self.driver, "fit_seconds": self.seconds, "compile_seconds": self.compile_seconds}


def _controller(log: DriveLog, driver: DriverConfig, grid: np.ndarray, wheel: np.ndarray, dt: float,
                substeps: int):
    """The base's motor driver replayed along the log on the recorded wheel speeds
    (:func:`atrv_warp.sim.driver.replay`): each step's command (zero once the timeout has stopped the base), and
    the driver's PI integral before the step."""
    from atrv_warp.sim.driver import replay

    received = np.searchsorted(log.cmd_time, grid + 1e-6, side="right")  # commands received by each step
    last = np.maximum(received - 1, 0)
    fresh = (received > 0) & (grid - log.cmd_time[last] <= driver.cmd_vel_timeout + 1e-9)
    twist = np.where(fresh[:, None], log.cmd[last, :2], 0.0)
    state = replay(driver, driver.kinematics(None, None), twist[None], fresh[None],
                   np.concatenate([wheel, wheel[-1:]])[None], step_dt=dt, substeps=substeps)
    return twist, state["integral"][0, :-1].double().numpy()


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average of ``window`` samples (made odd) along axis 0; the ends repeat the first and last."""
    half = max(0, window) // 2
    if half == 0:
        return x
    padded = np.concatenate([np.repeat(x[:1], half, 0), x, np.repeat(x[-1:], half, 0)])
    kernel = np.full(2 * half + 1, 1.0 / (2 * half + 1))
    return np.stack([np.convolve(padded[:, i], kernel, mode="valid") for i in range(x.shape[1])], -1)


def make_segments(log: DriveLog, cfg: CalibrationConfig, driver: DriverConfig, dt: float = 0.05,
                  substeps: int = 5) -> Segments:
    """Cut ``log`` into segments of ``cfg.segment_seconds`` on the controller's step grid, leaving out the
    ones where the rover stands still; raises :class:`CalibrationError` if fewer than ``cfg.min_segments`` remain.
    ``driver``: the base's driver with its configured radius and track set (:meth:`CalibrationConfig.driver`);
    ``substeps``: the driver's loop runs this many times per step, as in the simulator."""
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
    grid = start + dt * np.arange(math.floor((end - start) / dt + 1e-6) + 1)
    wheel = np.stack([np.interp(grid, log.joint_time, log.wheel_speed[:, s]) for s in (0, 1)], -1)
    pose = _smooth(np.stack([np.interp(grid, log.pose_time, log.pose[:, i]) for i in range(3)], -1),
                   round(cfg.pose_smoothing / dt))
    if log.twist:
        vel = np.stack([np.interp(grid, log.pose_time, log.body_velocity[:, i]) for i in range(3)], -1)
    else:  # the velocity from the smoothed poses, in the chassis frame
        vx, vy = np.gradient(pose[:, 0], dt), np.gradient(pose[:, 1], dt)
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        vel = np.stack([c * vx + s * vy, -s * vx + c * vy, np.gradient(pose[:, 2], dt)], -1)
    # the effort stamped at a step's end is what the motors held over it
    effort = (None if log.effort is None else
              np.stack([np.interp(grid + dt, log.joint_time, log.effort[:, s]) for s in (0, 1)], -1))
    if command == "cmd_vel":
        inputs, integral = _controller(log, driver, grid, wheel, dt, substeps)
    else:
        inputs, integral = effort, np.zeros_like(effort)
    steps = round(cfg.segment_seconds / dt)
    starts = np.arange(0, len(grid) - steps, steps)
    keep = []
    for k in starts:
        window = slice(k, k + steps + 1)
        moved = np.hypot(*(pose[k + steps, :2] - pose[k, :2])) + _HEADING_ARM * abs(pose[k + steps, 2] - pose[k, 2])
        commanded = np.abs(inputs[k:k + steps]).max() > (0.05 if command == "cmd_vel" else 0.5)  # m/s, rad/s; N·m
        if moved > 0.05 or np.abs(wheel[window]).max() > 0.5 or commanded:
            keep.append(k)
    if len(keep) < cfg.min_segments:
        raise CalibrationError(f"{log.path}: too short to fit: {len(keep)} moving segment(s) of "
                               f"{cfg.segment_seconds:g} s in {end - start:.1f} s of log (need {cfg.min_segments})")
    keep = np.array(keep)
    idx = keep[:, None] + np.arange(steps + 1)[None, :]
    ref = pose[idx].copy()
    ref[:, :, :2] -= ref[:, :1, :2]
    return Segments(t0=grid[keep], yaw0=pose[keep, 2], velocity=vel[keep, :2], yaw_rate=vel[keep, 2],
                    wheel=wheel[keep], integral=integral[keep], inputs=inputs[idx[:, :-1]], ref_pose=ref,
                    ref_wheel=wheel[idx],
                    ref_effort=effort[idx[:, :-1]] if command == "cmd_vel" and effort is not None else None,
                    held_out=(np.arange(len(keep)) % cfg.held_out_every) == cfg.held_out_every - 1,
                    command=command)


class _Replay:
    """Segments replayed in chunks of a :class:`~atrv_warp.sim.diff.DiffRollout`'s worlds."""

    def __init__(self, segments: Segments, worlds: int, rover: RoverConfig, contact: ContactConfig,
                 cfg: CalibrationConfig, driver: DriverConfig):
        from atrv_warp.sim.diff import DiffRollout

        self.roll = DiffRollout(worlds, steps=segments.inputs.shape[1], rover=rover, contact=contact,
                                twist=segments.command == "cmd_vel", driver=driver, action_scale=1.0)
        self.segments, self.worlds = segments, worlds
        self.warmup = round(cfg.warmup / 0.05) if segments.command == "cmd_vel" else 0
        self.nominal = {"chassis_mass": self.roll.nominal_chassis_mass}

    def run(self, index: np.ndarray, values: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Replay segments ``index`` (at most ``worlds``) with per-segment parameter ``values``; returns the
        per-segment loss, the mean position error [m] and the simulated (L + 1, S, 3) path."""
        seg, n, w = self.segments, len(index), self.worlds
        pad = np.concatenate([index, np.full(w - n, index[0])])
        poses = torch.zeros(w, 3)
        poses[:, 2] = torch.as_tensor(seg.yaw0[pad], dtype=torch.float32)
        state = self.roll.moving_state(poses, torch.as_tensor(seg.velocity[pad], dtype=torch.float32),
                                       torch.as_tensor(seg.yaw_rate[pad], dtype=torch.float32),
                                       torch.as_tensor(seg.wheel[pad], dtype=torch.float32))
        kwargs = {} if seg.command == "cmd_vel" else {"torque_scale": 1.0, "speed_limit": _NO_TAPER}
        for name, v in values.items():
            v = v.reshape(-1).expand(n) if v.numel() == 1 else v
            v = torch.cat([v, v[:1].detach().expand(w - n)])
            if name == "payload_mass":
                kwargs["chassis_mass"] = self.nominal["chassis_mass"] + v
            else:
                kwargs[name] = v
        actions = torch.as_tensor(seg.inputs[pad], dtype=torch.float32).transpose(0, 1).contiguous()
        integral = torch.as_tensor(seg.integral[pad], dtype=torch.float32)
        sim_poses, speeds, torques = self.roll(actions, state, integral=integral, wheel_speeds=True,
                                               wheel_torques=True, **kwargs)
        ref = torch.as_tensor(seg.ref_pose[pad], dtype=torch.float32).transpose(0, 1)  # (L + 1, W, 3)
        ref_wheel = torch.as_tensor(seg.ref_wheel[pad], dtype=torch.float32).transpose(0, 1)
        xy = sim_poses[..., :2] - sim_poses[:1, :, :2]
        yaw = quat_to_yaw(sim_poses[..., 3:7])
        dyaw = wrap_angle(yaw - ref[..., 2])
        dpos = (xy - ref[..., :2]).square().sum(-1)
        # the motor terms skip the first steps, while the driver's reconstructed integral settles (its error decays
        # within a few of its 0.01 s loops); the path keeps them, it integrates what they do
        settled = slice(self.warmup, None)
        loss = (dpos / _POSITION_SCALE**2 + (_HEADING_ARM * dyaw / _POSITION_SCALE).square()).mean(0)
        loss = loss + ((speeds - ref_wheel)[settled].square().sum(-1) / _WHEEL_SCALE**2).mean(0)
        if seg.ref_effort is not None:
            ref_effort = torch.as_tensor(seg.ref_effort[pad], dtype=torch.float32).transpose(0, 1)
            loss = loss + ((torques - ref_effort)[settled].square().sum(-1) / _EFFORT_SCALE**2).mean(0)
        path = torch.cat([xy, yaw[..., None]], -1)
        return loss[:n], dpos.sqrt().mean(0)[:n].detach(), path[:, :n].detach()

    @torch.no_grad()
    def evaluate(self, index: np.ndarray, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Loss, mean position error and path of every segment in ``index`` with one set of ``values``."""
        losses, errors, paths = [], [], []
        for i in range(0, len(index), self.worlds):
            chunk = index[i:i + self.worlds]
            loss, err, path = self.run(chunk, {k: torch.tensor(float(v)) for k, v in values.items()})
            losses.append(loss.numpy())
            errors.append(err.numpy())
            paths.append(path.numpy())
        return np.concatenate(losses), np.concatenate(errors), np.concatenate(paths, 1)


def _driver_record(driver: DriverConfig) -> dict[str, float]:
    """What the report and the written config record of the replayed driver."""
    return {name: getattr(driver, name) for name in ("wheel_radius", "track_width", "effective_track_factor", "kp", "ki")}


def _nominal(rover: RoverConfig, contact: ContactConfig) -> dict[str, float]:
    return {"friction": contact.friction, "torque_scale": rover.torque_scale, "payload_mass": rover.payload_mass,
            "speed_limit": rover.wheel_speed_limit, "wheel_radius": rover.wheel_radius}


def _polish(replay: _Replay, train: np.ndarray, names: list[str], start: torch.Tensor, lo: torch.Tensor,
            span: torch.Tensor, iterations: int, say: Callable[[str], None]) -> tuple[torch.Tensor, float, float]:
    """L-BFGS on the mean loss of every training segment (deterministic, unlike the minibatch steps), in the
    same logit space, from ``start``; returns the values where the loss was lowest, that loss, and how far its last
    three evaluations lay apart (the largest parameter's spread, as a fraction of its range: small once it has
    settled)."""
    if iterations == 0:
        return start, math.inf, math.inf
    t0 = time.perf_counter()
    unit = ((start - lo) / span).clamp(1e-4, 1 - 1e-4)
    logits = torch.logit(unit).detach().requires_grad_(True)
    opt = torch.optim.LBFGS([logits], lr=1.0, max_iter=iterations, history_size=10, line_search_fn="strong_wolfe")
    chunks = [train[i:i + replay.worlds] for i in range(0, len(train), replay.worlds)]
    calls = []

    def closure():
        opt.zero_grad()
        total = 0.0
        for chunk in chunks:
            values = lo + span * torch.sigmoid(logits)
            loss, _, _ = replay.run(chunk, {p: values[j] for j, p in enumerate(names)})
            part = loss.sum() / len(train)
            part.backward()
            total += part.item()
        calls.append((total, (lo + span * torch.sigmoid(logits)).detach().clone()))
        return torch.tensor(total)

    opt.step(closure)
    loss, values = min(calls, key=lambda c: c[0])
    last = torch.stack([v for _, v in calls[-3:]])
    settled = float(((last.max(0).values - last.min(0).values) / span).max())
    say(f"  polish: {len(calls)} full-batch evaluations, loss {calls[0][0]:.3f} -> {loss:.3f}  "
        + "  ".join(f"{p} {float(values[j]):.4g}" for j, p in enumerate(names)) + f"  ({time.perf_counter() - t0:.0f} s)")
    return values, loss, settled


def _standard_error(replay: _Replay, train: np.ndarray, names: list[str], values: torch.Tensor, low: torch.Tensor,
                    high: torch.Tensor) -> dict[str, float]:
    """Sandwich standard errors at ``values``: ``H^-1 (sum_i g_i g_i^T) H^-1`` with ``g_i`` the gradient of
    training segment i's loss (each segment is its own world, so one backward pass gives them all) and ``H``
    the Hessian of their sum by forward differences of 1 % of each parameter's range."""

    def gradients(v: torch.Tensor) -> torch.Tensor:  # (S, P)
        rows = []
        for i in range(0, len(train), replay.worlds):
            chunk = train[i:i + replay.worlds]
            leaves = {p: v[j].float().expand(len(chunk)).clone().requires_grad_(True) for j, p in enumerate(names)}
            loss, _, _ = replay.run(chunk, leaves)
            loss.sum().backward()
            rows.append(torch.stack([leaves[p].grad for p in names], -1))
        return torch.cat(rows).double()

    g = gradients(values.double())
    hessian = torch.zeros(len(names), len(names), dtype=torch.float64)
    for j in range(len(names)):
        h = 0.01 * float(high[j] - low[j])
        if values[j] + h > high[j]:
            h = -h
        step = values.double().clone()
        step[j] += h
        hessian[:, j] = (gradients(step).sum(0) - g.sum(0)) / h
    hessian = 0.5 * (hessian + hessian.T)
    if not bool((torch.linalg.eigvalsh(hessian) > 0).all()):
        return {p: math.nan for p in names}
    inverse = torch.linalg.inv(hessian)
    cov = inverse @ (g.T @ g) @ inverse
    return {p: float(cov[j, j].clamp_min(0).sqrt()) for j, p in enumerate(names)}


def calibrate(log: DriveLog, cfg: CalibrationConfig = CalibrationConfig(), *,
              rover: RoverConfig | None = None, contact: ContactConfig | None = None,
              progress: Callable[[str], None] | None = None) -> CalibrationResult:
    """Fit ``cfg.params`` to ``log``, starting from ``rover`` and ``contact`` (default: the realistic rover)."""

    say = progress or (lambda _text: None)
    rover = rover or get_variant("realistic")
    contact = contact or ContactConfig()
    driver = cfg.driver()
    seg = make_segments(log, cfg, driver)
    train, held = np.flatnonzero(~seg.held_out), np.flatnonzero(seg.held_out)
    batch = min(cfg.batch, len(train))
    nominal = _nominal(rover, contact)
    names = [p for p in cfg.params if seg.command == "cmd_vel" or p not in MOTOR_PARAMETERS]
    low = torch.tensor([FIT_PARAMETERS[p].low for p in names], dtype=torch.float64)
    high = torch.tensor([FIT_PARAMETERS[p].high for p in names], dtype=torch.float64)
    for p in names:
        if not FIT_PARAMETERS[p].low <= nominal[p] <= FIT_PARAMETERS[p].high:
            raise CalibrationError(f"the rover's {p} {nominal[p]:g} is outside the fit's bounds "
                                   f"[{FIT_PARAMETERS[p].low:g}, {FIT_PARAMETERS[p].high:g}]")
    gen = torch.Generator().manual_seed(cfg.seed)
    start = torch.tensor([nominal[p] for p in names], dtype=torch.float64)
    unit = torch.cat([((start - low) / (high - low)).clamp(0.02, 0.98)[None], 0.1 + 0.8 * torch.rand(cfg.starts - 1, len(names),
                                                                                    generator=gen, dtype=torch.float64)])
    logits = torch.logit(unit).float().requires_grad_(True)  # (K, P)
    lo, span = low.float(), (high - low).float()
    through = (f" through a driver configured with wheel radius {driver.wheel_radius:g} m, track "
               f"{driver.track_width:g} m" if seg.command == "cmd_vel" else "")
    say(f"{len(train)} training and {len(held)} held-out segments of {cfg.segment_seconds:g} s "
        f"({seg.command}{through}); fitting {', '.join(names)} from {cfg.starts} starts")
    t_compile = time.perf_counter()
    replay = _Replay(seg, cfg.starts * batch, rover, contact, cfg, driver)
    replay.evaluate(train[:1], nominal)  # first use compiles the rollout's kernels (cached afterwards)
    compile_s = time.perf_counter() - t_compile
    t_fit = time.perf_counter()
    opt = torch.optim.Adam([logits], lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.iterations, eta_min=0.1 * cfg.lr)
    history, losses = [], []
    for it in range(cfg.iterations):
        picks = np.concatenate([train[torch.randperm(len(train), generator=gen)[:batch].numpy()]
                                for _ in range(cfg.starts)])
        values = lo + span * torch.sigmoid(logits)  # (K, P)
        per_world = {p: values[:, j].repeat_interleave(batch) for j, p in enumerate(names)}
        loss, _, _ = replay.run(picks, per_world)
        total = loss.view(cfg.starts, batch).mean(1)
        opt.zero_grad()
        total.sum().backward()
        opt.step()
        sched.step()
        history.append(values.detach().clone())
        losses.append(total.detach().clone())
        if it % 10 == 0 or it == cfg.iterations - 1:
            best = int(total.argmin())
            say(f"  step {it + 1:3d}/{cfg.iterations}: loss {total.detach().min().item():9.3f}  "
                + "  ".join(f"{p} {float(values[best, j]):.4g}" for j, p in enumerate(names))
                + f"  ({time.perf_counter() - t_fit:.0f} s)")
    # each start's value and loss: the means over its last quarter of steps (they average out the draws of
    # segments; the loss over that many draws is about the loss over every training segment)
    quarter = max(2, cfg.iterations // 4)
    tail = torch.stack(history[-quarter:])  # (T, K, P)
    final = tail.mean(0)
    tail_loss = torch.stack(losses[-quarter:]).mean(0)
    starts = [{"values": {p: float(final[k, j]) for j, p in enumerate(names)}, "train_loss": float(tail_loss[k])}
              for k in range(cfg.starts)]
    ranked = sorted(range(cfg.starts), key=lambda k: starts[k]["train_loss"])
    good = [s for s in starts if s["train_loss"] <= 1.5 * starts[ranked[0]]["train_loss"]]
    spread = {p: float(np.std([s["values"][p] for s in good], ddof=1)) if len(good) > 1 else math.nan for p in names}
    # the minibatch steps leave the best starts close in loss but not always in the same valley: polish a few
    polished = {k: _polish(replay, train, names, final[k], lo, span, cfg.polish, say)
                for k in ranked[:cfg.polish_starts]}
    best = min(polished, key=lambda k: polished[k][1]) if cfg.polish else ranked[0]
    # where the polished starts ended apart from each other (the largest parameter's distance, as a fraction of its
    # range): 0 with one; two starts that walk to the same point have found the valley's floor, not a ledge of it
    ends = torch.stack([v for v, _, _ in polished.values()]) if cfg.polish else final[best][None]
    agree = float(((ends.max(0).values - ends.min(0).values) / span).max())
    polished, settled = (polished[best][0], polished[best][2]) if cfg.polish else (final[best], math.inf)
    fitted = {**nominal, **{p: float(polished[j]) for j, p in enumerate(names)}}
    t_se = time.perf_counter()
    standard_error = _standard_error(replay, train, names, polished, low, high)
    say(f"  standard errors from {len(train)} segments' gradients and a finite-difference Hessian "
        f"({time.perf_counter() - t_se:.0f} s)")
    errors, paths = {}, {}
    for split, index in (("train", train), ("held_out", held)):
        loss0, err0, path0 = replay.evaluate(index, nominal)
        loss1, err1, path1 = replay.evaluate(index, fitted)
        errors[split] = {"before": err0.tolist(), "after": err1.tolist(),
                         "loss_before": float(loss0.mean()), "loss_after": float(loss1.mean())}
        if split == "held_out":
            paths = {"recorded": seg.ref_pose[index], "nominal": path0.transpose(1, 0, 2),
                     "calibrated": path1.transpose(1, 0, 2), "t0": seg.t0[index]}
    # converged: the fit settled, and fits the training and the held-out segments better than the rover it started
    # from. Settled: the full-batch polish's last evaluations lie within 1 % of each parameter's range (a stationary
    # point of the whole loss), and either the polished starts ended within 2 % of each other (where the loss is flat
    # along a valley, as a payload's is under a driver that holds its wheel speeds tightly, the polish walks it after
    # the minibatch steps, from each start to the same floor) or the best start had stopped moving over the last
    # quarter of the minibatch steps (within 2 %). Without a polish, that last alone.
    tail = tail[:, best]
    drift = ((tail.max(0).values - tail.min(0).values) / span).max().item()
    improved = all(errors[split]["loss_after"] < errors[split]["loss_before"] for split in errors)
    polish_ok = settled < 0.01 and (cfg.polish_starts > 1 and agree < 0.02 or drift < 0.02)
    converged = improved and (polish_ok if cfg.polish else drift < 0.02)
    reason = ("converged" if converged else
              "did not converge: the fit is no better than the starting rover on the training or the held-out "
              "segments" if not improved else
              f"did not converge: the last full-batch steps still moved a parameter {100 * settled:.1f} % of its range"
              if cfg.polish and settled >= 0.01 else
              f"did not converge: the polished starts ended {100 * agree:.1f} % of a parameter's range apart, and the "
              f"minibatch steps still moved {100 * drift:.1f} % over their last {len(tail)}" if cfg.polish else
              f"did not converge: the parameters still moved {100 * drift:.1f} % of their range over the last "
              f"{len(tail)} steps")
    return CalibrationResult(values={p: fitted[p] for p in names}, nominal={p: nominal[p] for p in names},
                             spread=spread, standard_error=standard_error, starts=starts, errors=errors, converged=converged, reason=reason,
                             segments=seg, seconds=time.perf_counter() - t_fit, compile_seconds=compile_s,
                             paths=paths, driver=_driver_record(driver) if seg.command == "cmd_vel" else None)
