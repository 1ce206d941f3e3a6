"""Measurement protocols on the simulator, shared by the benchmarks (which print and record them) and the tests (which
assert on them): the reference tutorial's drop–settle–drive run, rovers driven into the walls at top speed, the slip
ratio, a rover parked on a slope, the motor driver's step and turning responses, and the analytic figures they are held
to (rolling without slip, a rigid rover's twist under pure Coulomb friction).

The simulator's fingerprints, hashes of fixed rollouts that results files record, are in :mod:`atrv_warp.sim.fingerprints`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from atrv_warp.sim.config import ContactConfig, RoverConfig, SimConfig
from atrv_warp.sim.simulator import DriveMode, RoverSim

__all__ = [
    "STEP_COMMANDS",
    "STEP_FRICTIONS",
    "ReferenceDrive",
    "WallImpacts",
    "coulomb_twist",
    "full_torque_acceleration",
    "parked_on_slope",
    "reference_drive",
    "rolling_acceleration",
    "settle_time",
    "slip_ratio",
    "step_response",
    "turning_response",
    "wall_impacts",
    "wheel_contact_xy",
]


def rolling_acceleration(sim: RoverSim, torque: float) -> float:
    """F / (M + sum I_axle / r^2) [m/s^2]: ``torque`` [N·m] on every wheel, no slip, from the model's masses."""
    desc = sim.description
    r = sim.rover_cfg.wheel_radius
    spin = sum(float(w.axis @ w.inertial.inertia @ w.axis) for w in desc.wheels)
    return len(desc.wheels) * torque / r / (desc.total_mass + spin / r**2)


@dataclass
class ReferenceDrive:
    """What :func:`reference_drive` recorded, one entry per env step (0.05 s)."""

    sim: RoverSim
    settle_z: np.ndarray  # (settle_steps,) chassis height while settling [m]
    track: np.ndarray  # (drive_steps, 3) chassis x, y relative to the start of the drive, and z [m]
    forward_speed: np.ndarray  # (drive_steps,) chassis world-frame vx [m/s]


def reference_drive(settle_steps: int = 20, drive_steps: int = 98) -> ReferenceDrive:
    """The reference variant dropped 2 cm above its rest height, settled for ``settle_steps``
    (1 s), then driven forward (+4 N·m on every wheel) for ``drive_steps`` (4.9 s): the
    reference tutorial's straight-line run."""
    sim = RoverSim(1, variant="reference")
    sim.reset(height=sim.rest_height + 0.02)
    settle_z = []
    for _ in range(settle_steps):
        sim.step()
        settle_z.append(sim.root_pose[0, 2].item())
    start = np.array([sim.root_pose[0, 0].item(), sim.root_pose[0, 1].item(), 0.0])
    sim.set_mode(DriveMode.FORWARD)
    track, speed = [], []
    for _ in range(drive_steps):
        sim.step()
        track.append(sim.root_pose[0, :3].tolist())
        speed.append(sim.lin_vel[0, 0].item())
    return ReferenceDrive(sim, np.array(settle_z), np.array(track) - start, np.array(speed))


@dataclass
class WallImpacts:
    """What :func:`wall_impacts` measured over its worlds."""

    top_speed: float  # the motor's top speed at the rim [m/s]
    max_speed: float  # fastest chassis speed any finite world reached [m/s]
    overspeed_worlds: int  # worlds that ever exceeded 1.2 x top_speed
    nonfinite_worlds: int


def wall_impacts(worlds: int = 256, steps: int = 200, *, sim: SimConfig | None = None,
                 contact: ContactConfig | None = None) -> WallImpacts:
    """Rovers driven into the walls at top speed: ``worlds`` start at x = 9 m with headings spread
    over the full circle, half of them driving forward and half backward at ±20 N·m on every wheel,
    held for ``steps`` (200 = 10 s, enough to reach a wall at top speed and slide or bounce along it).

    Nothing but the contact can push a rover faster than the motor's top speed, so a world that
    ever exceeds it has had energy put in by a wall impact: the integration step is too long for
    the impact it resolves."""
    rovers = RoverSim(worlds, sim=sim, contact=contact)
    half = worlds // 2
    k = torch.arange(worlds)
    yaw = (k % half).float() / half * (2 * math.pi)
    sign = torch.where(k < half, 1.0, -1.0)
    rovers.reset(poses=torch.stack([torch.full((worlds,), 9.0), torch.zeros(worlds), yaw], 1))
    rovers.commands.copy_(torch.stack([sign, sign], 1) * 20.0)
    top = rovers.rover_cfg.wheel_speed_limit * rovers.rover_cfg.wheel_radius
    bad = torch.zeros(worlds, dtype=torch.bool)
    fastest = torch.zeros(worlds)
    for _ in range(steps):
        rovers.step()
        bad |= rovers.nonfinite.bool()
        fastest = torch.maximum(fastest, torch.where(bad, 0.0, rovers.lin_vel.norm(dim=-1)))
    return WallImpacts(top, float(fastest.max()), int((fastest > 1.2 * top).sum()), int(bad.sum()))


def wheel_contact_xy(sim: RoverSim) -> np.ndarray:
    """(W, 2) each wheel's ground contact point in the chassis frame [m] (the axle's end, plus the
    wheel's offset along it)."""
    out = []
    for w in sim.description.wheels:
        axle = w.origin[:3, :3] @ np.asarray(w.axis, dtype=np.float64)
        side = 1.0 if w.origin[1, 3] > 0 else -1.0
        outward = axle * np.sign(axle[1] * side)  # the axle direction that points away from the chassis
        out.append((w.origin[:3, 3] + sim.rover_cfg.wheel_offset * outward)[:2])
    return np.array(out)


def coulomb_twist(contacts: np.ndarray, rim_speeds: np.ndarray, iterations: int = 200) -> np.ndarray:
    """Steady planar twist (vx [m/s], vy [m/s], yaw rate [rad/s]) of a rigid rover on equally loaded
    wheels under pure Coulomb friction, its wheels' rims moving forward at ``rim_speeds`` (W,) [m/s]
    at ``contacts`` (W, 2) [m] in the body frame.

    Each wheel's force is ``mu N`` against its slip ``s_i = v + w x r_i - (rim_i, 0)``; force and moment
    balance is the stationary point of the convex sum ``sum_i |s_i|``, which this minimises by
    iteratively reweighted least squares. Only the slip directions matter, so mu and N drop out.
    """
    x, y = contacts[:, 0], contacts[:, 1]
    # s_i = A_i @ (vx, vy, w) - b_i, two rows per wheel
    a = np.zeros((2 * len(x), 3))
    a[0::2, 0], a[0::2, 2] = 1.0, -y
    a[1::2, 1], a[1::2, 2] = 1.0, x
    b = np.zeros(2 * len(x))
    b[0::2] = rim_speeds
    twist = np.linalg.lstsq(a, b, rcond=None)[0]
    for _ in range(iterations):
        slip = (a @ twist - b).reshape(-1, 2)
        weight = 1.0 / np.maximum(np.linalg.norm(slip, axis=1), 1e-9)
        wa = a * np.repeat(weight, 2)[:, None]
        twist = np.linalg.solve(a.T @ wa, wa.T @ b)
    return twist


def slip_ratio(torque: float, *, contact: ContactConfig | None = None, seconds: float = 2.0) -> float:
    """Longitudinal slip ratio ``(r w - v) / (r w)`` [-] of a rover driven from rest by ``torque``
    [N·m] on every wheel, averaged over the last half of ``seconds``."""
    sim = RoverSim(1, contact=contact)
    sim.set_commands([torque, torque])
    r = sim.rover_cfg.wheel_radius
    ratios = []
    steps = round(seconds / sim.sim_cfg.step_dt)
    for i in range(steps):
        sim.step()
        if i >= steps // 2:
            rim = r * float(sim.wheel_speed[0].mean())
            ratios.append((rim - float(sim.lin_vel[0, 0])) / rim)
    return float(np.mean(ratios))


def parked_on_slope(degrees: tuple[float, ...], *, contact: ContactConfig | None = None, seconds: float = 5.0,
                    brake: float = 0.5) -> np.ndarray:
    """How far [m] a rover parked across a slope of each angle [deg] (axles downhill) moves in
    ``seconds`` after settling for 1 s; one simulator per slope.

    Parked: no drive command, its motors braking each side's wheels with ``brake`` [N·m per rad/s]
    of its wheel speed, as a DC motor with shorted windings does. Free wheels would not do: with
    Coulomb friction and no rolling resistance, the smallest heading offset from the settling lets a
    rover on free wheels roll down, as a real one with its motors declutched would."""
    from atrv_warp.sim.terrain import TerrainConfig

    moved = []
    for deg in degrees:
        sim = RoverSim(1, contact=contact, terrain=TerrainConfig(amplitude=0.0, roughness=0.0,
                                                                 incline=math.radians(deg), tiles=1))
        sim.reset(poses=[[0.0, 0.0, math.pi / 2]])
        side = torch.tensor([w.side for w in sim.description.wheels])
        start = None
        for i in range(20 + round(seconds / sim.sim_cfg.step_dt)):
            if i == 20:
                start = sim.root_pose[0, :3].clone()
            ws = sim.wheel_speed[0]
            sim.step(-brake * torch.stack([ws[side == 0].mean(), ws[side == 1].mean()]))
        finite = bool(torch.isfinite(sim.root_pose).all())
        moved.append(float((sim.root_pose[0, :3] - start).norm()) if finite else math.inf)
    return np.array(moved)


def full_torque_acceleration(contact: ContactConfig | None = None) -> float:
    """Mean acceleration [m/s²] of a rover at full torque (20 N·m on every wheel) from rest, its tyres
    sliding: from 0.2 s (past the chassis' first squat) over 1 s or until 4 m/s, whichever is first
    (before the rover nears its wheels' top speed). Coulomb friction bounds the drive force by mu times
    the normal load, which averages M g; over so short a window the chassis' pitching under the load
    transfer moves the figure by some percent either way."""
    sim = RoverSim(1, contact=contact)
    sim.set_commands([20.0, 20.0])
    for _ in range(4):
        sim.step()
    v0, t0 = sim.lin_vel[0, 0].item(), sim.sim_time
    for _ in range(20):
        sim.step()
        if sim.lin_vel[0, 0].item() > 4.0:
            break
    return (sim.lin_vel[0, 0].item() - v0) / (sim.sim_time - t0)


STEP_COMMANDS: tuple[tuple[float, float], ...] = ((0.0, 0.5), (0.5, 0.5), (1.0, 0.2))
"""(linear [m/s], angular [rad/s]) ``/cmd_vel`` steps of the driver's step response: in place and on two arcs."""
STEP_FRICTIONS: tuple[float, ...] = (0.2, 0.3, 0.8, 1.0)
"""Coulomb µ of the step response: ice-like to dry asphalt."""


def settle_time(ratio, dt: float, band: float = 0.1) -> float:
    """The time [s] after which ``ratio`` (a trace over its target, sampled every ``dt`` [s] from ``dt`` on) stays
    within ``band`` of 1: 0 where it never leaves the band, ``inf`` where its last sample is outside it."""
    outside = np.flatnonzero(np.abs(np.asarray(ratio, dtype=np.float64) - 1.0) > band)
    if not len(outside):
        return 0.0
    return math.inf if outside[-1] + 1 == len(ratio) else float(dt * (outside[-1] + 1))


def step_response(commands=STEP_COMMANDS, frictions=STEP_FRICTIONS, *, seconds: float = 5.0, band: float = 0.1,
                  driver=None, sim: SimConfig | None = None, rover: RoverConfig | None = None) -> list[dict]:
    """The motor driver's answer to ``/cmd_vel`` steps: one world per (command, µ), from rest, the command
    re-sent every step (a 20 Hz controller), for ``seconds``, on ``rover`` (default: the ATRV-Jr).

    Per world: ``settle`` the time [s] after which the yaw rate stays within ``band`` of the commanded one,
    ``overshoot`` the yaw rate's peak over the command minus 1, ``steady`` the mean yaw rate over the last second
    over the command, ``ripple`` its standard deviation over the last second over the command (a sustained
    oscillation shows there), ``speed`` the mean forward speed over the last second over the command (arcs), and
    the traces ``time``, ``yaw_rate`` and ``speed_trace``."""
    cases = [(v, w, mu) for mu in frictions for v, w in commands]
    rovers = RoverSim(len(cases), sim=sim, driver=driver, rover=rover)
    rovers.set_params(friction=[mu for _, _, mu in cases])
    # each rover starts on the circle it will drive, centred on the arena's centre (effective track ratio ~1.6)
    rovers.reset(poses=[[0.0, -v / w if w else 0.0, 0.0] for v, w, _ in cases])
    twist = torch.tensor([[v, w] for v, w, _ in cases])
    dt = rovers.sim_cfg.step_dt
    steps = round(seconds / dt)
    rates, speeds = [], []
    for _ in range(steps):
        rovers.set_twist(twist)
        rovers.step()
        yaw = rovers.rpy[:, 2]
        rates.append(rovers.ang_vel[:, 2].clone())
        speeds.append(rovers.lin_vel[:, 0] * torch.cos(yaw) + rovers.lin_vel[:, 1] * torch.sin(yaw))
    rate, speed = torch.stack(rates).double(), torch.stack(speeds).double()  # (T, worlds)
    time = dt * torch.arange(1, steps + 1, dtype=torch.float64)
    last = round(1.0 / dt)
    out = []
    for i, (v, w, mu) in enumerate(cases):
        r = rate[:, i] / w
        out.append({"linear": v, "angular": w, "friction": mu, "settle": settle_time(r.numpy(), dt, band),
                    "overshoot": float(r.max() - 1.0), "steady": float(r[-last:].mean()),
                    "ripple": float(r[-last:].std()),
                    "speed": float(speed[-last:, i].mean() / v) if v else math.nan,
                    "time": time.tolist(), "yaw_rate": rate[:, i].tolist(), "speed_trace": speed[:, i].tolist()})
    return out


def turning_response(commands, *, driver=None, contact: ContactConfig | None = None, seconds: float = 8.0,
                     average: float = 3.0, sim: SimConfig | None = None, rover: RoverConfig | None = None
                     ) -> list[dict]:
    """Drive one world per ``commands[i]`` = (linear [m/s], angular [rad/s]) through the motor driver
    (``driver``: a :class:`~atrv_warp.sim.driver.DriverConfig`) for ``seconds``, the command re-sent every step, and
    return per command the mean left and right wheel speeds [rad/s], yaw rate [rad/s] and speed [m/s] over the last
    ``average`` seconds: what a skid-steer calibration measures.

    Each rover starts facing +x where the circle it will drive (for an effective track ratio near 1.6) is centred
    on the arena's centre, so that it meets no wall; worlds never interact."""
    from atrv_warp.core.kinematics import side_speeds

    rovers = RoverSim(len(commands), contact=contact, sim=sim, driver=driver, rover=rover)
    rovers.reset(poses=[[0.0, -1.6 * v / w if w else 0.0, 0.0] for v, w in commands])
    side = torch.tensor([w.side for w in rovers.description.wheels])
    twist = torch.tensor(commands, dtype=torch.float32)
    dt = rovers.sim_cfg.step_dt
    steps, kept = round(seconds / dt), round(average / dt)
    sums = torch.zeros(len(commands), 4, dtype=torch.float64)
    for k in range(steps):
        rovers.set_twist(twist)
        rovers.step()
        if k >= steps - kept:
            speeds = side_speeds(rovers.wheel_speed, side)
            sums += torch.cat([speeds, rovers.ang_vel[:, 2:3], rovers.lin_vel[:, :2].norm(dim=-1, keepdim=True)], -1)
    mean = (sums / kept).tolist()
    return [{"linear": v, "angular": w, "wheel_left": m[0], "wheel_right": m[1], "yaw_rate": m[2], "speed": m[3]}
            for (v, w), m in zip(commands, mean)]
