"""A recorded drive cut into segments the simulator can replay, each with its recorded start state (pose, body
velocity, tilt, wheel speeds and the base driver's integral) and its recorded commands or efforts."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.kernels.rover import MOTOR_TAPER_START
from atrv_warp.sim.sysid.config import DEFAULT_FIT, HEADING_ARM, MOTOR_PARAMETERS, CalibrationConfig, CalibrationError
from atrv_warp.sim.sysid.log import DriveLog

__all__ = ["MAX_GAP_S", "Segments", "drive_spans", "integral_from_effort", "make_segments"]


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
    the effort cannot tell it: a saturated motor (the integral stops where the output meets the limit), one tapering past half its torque, a
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
        moved = np.hypot(*(pose[k + steps, :2] - pose[k, :2])) + HEADING_ARM * abs(pose[k + steps, 2] - pose[k, 2])
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
