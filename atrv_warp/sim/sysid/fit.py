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

from atrv_warp.sim.config import ContactConfig, RoverConfig
from atrv_warp.sim.driver import DriverConfig

# The names this module held before its split (issue 69) import from here as they did, until 0.3.0; their homes are
# .config and .segments. (DEFAULT_FIT, COMMAND_SOURCES, integral_from_effort and sim_config_tables are kept for that.)
from atrv_warp.sim.sysid.config import (  # noqa: F401
    COMMAND_SOURCES,
    CONFOUNDED,
    DEFAULT_FIT,
    FIT_FIDELITY,
    FIT_PARAMETERS,
    MISFIT_FLOOR,
    MOTOR_PARAMETERS,
    CalibrationConfig,
    CalibrationError,
    sim_config_tables,
)
from atrv_warp.sim.sysid.log import DriveLog
from atrv_warp.sim.sysid.replay import Replay
from atrv_warp.sim.sysid.segments import (
    Segments,
    integral_from_effort,  # noqa: F401
    make_segments,
)
from atrv_warp.sim.sysid.solver import Start, cauchy, levenberg_marquardt, sandwich_error

__all__ = ["CalibrationResult", "calibrate", "recording_noise", "replay_errors"]


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



def _driver_record(driver: DriverConfig) -> dict[str, float]:
    """What the report and the written config record of the replayed driver."""
    return {name: getattr(driver, name) for name in ("wheel_radius", "track_width", "effective_track_factor", "kp", "ki")}


def _nominal(rover: RoverConfig, contact: ContactConfig) -> dict[str, float]:
    """Every fit parameter's value in ``rover`` and ``contact``."""
    configs = {"rover": rover, "contact": contact}
    return {name: getattr(configs[p.table], p.key) for name, p in FIT_PARAMETERS.items()}


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
        low, high = FIT_PARAMETERS[p].bounds(cfg.robot)
        if not low <= nominal[p] <= high:
            raise CalibrationError(f"the rover's {p} {nominal[p]:g} is outside the fit's bounds [{low:g}, {high:g}] "
                                   f"on robot {cfg.robot} (its nominal rover's, scaled: FIT_PARAMETERS)")
    through = (f" through a driver configured with wheel radius {driver.wheel_radius:g} m, track "
               f"{driver.track_width:g} m" if seg.command == "cmd_vel" else "")
    train, held = np.flatnonzero(~seg.held_out), np.flatnonzero(seg.held_out)
    say(f"{len(train)} training and {len(held)} held-out segments of {cfg.segment_seconds:g} s "
        f"({seg.command}{through}); fitting {', '.join(names)} from {cfg.starts} starts")
    t_compile = time.perf_counter()
    # one batch: every start's point and its forward differences on every training segment, in chunks of at most
    # cfg.worlds of about equal size
    total = cfg.starts * (len(names) + 1) * len(train)
    replay = Replay(seg, -(-total // -(-total // cfg.worlds)), rover, contact, cfg, driver)
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
            fitted = {**nominal, **_values(ends, names, cfg)}
            losses = {}
            for value in candidates:
                replay.segments = make_segments(log, cfg, driver, latency=value, like=seg)
                res = replay.residuals(train, {p: np.full(len(train), fitted[p]) for p in names})[0]
                losses[value] = float(cauchy((res**2).sum(-1), cfg.robust).mean())
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


def _box(names: list[str], cfg: CalibrationConfig) -> tuple[np.ndarray, np.ndarray]:
    """Each parameter's least value and range on ``cfg.robot`` (:meth:`~.config.FitParameter.bounds`): the unit box's
    corner and sides."""
    bounds = [FIT_PARAMETERS[p].bounds(cfg.robot) for p in names]
    low = np.array([lo for lo, _ in bounds])
    return low, np.array([hi for _, hi in bounds]) - low


def _values(ends: list[Start], names: list[str], cfg: CalibrationConfig) -> dict[str, float]:
    """The best start's values."""
    best = min(ends, key=lambda s: s.objective)
    low, span = _box(names, cfg)
    return {p: float(low[j] + span[j] * best.unit[j]) for j, p in enumerate(names)}


def _fit(replay: Replay, train: np.ndarray, names: list[str], nominal: dict[str, float], cfg: CalibrationConfig,
         say: Callable[[str], None]) -> list[Start]:
    """Levenberg-Marquardt from the rover's values and ``cfg.starts - 1`` random points within the bounds."""
    low, span = _box(names, cfg)
    rng = np.random.default_rng(cfg.seed)
    start = (np.array([nominal[p] for p in names]) - low) / span
    units = np.concatenate([start[None], rng.uniform(0.1, 0.9, (cfg.starts - 1, len(names)))])
    return levenberg_marquardt(replay, train, names, low, span, units, cfg, say)


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


def _result(replay: Replay, seg: Segments, ends: list[Start], names: list[str], nominal: dict[str, float],
            cfg: CalibrationConfig, *, noise: dict[str, float], **fields) -> CalibrationResult:
    """The fit's result: the best start, the starts' agreement, the standard errors, and every split's errors
    before and after, replayed in one batch."""
    train, held = np.flatnonzero(~seg.held_out), np.flatnonzero(seg.held_out)
    low, span = _box(names, cfg)
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
    statistical, correlation = sandwich_error(ends[best], names, span)
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
    replay = Replay(seg, min(len(seg), cfg.worlds), rover, contact, cfg, driver)
    index = np.arange(len(seg))
    err = replay.residuals(index, {p: np.full(len(seg), point[p]) for p in names})[1]
    return {"train": err[~seg.held_out], "held_out": err[seg.held_out]}
