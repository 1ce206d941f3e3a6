"""Physics checks shared by ``benchmarks/physics_report.py`` (which prints them) and
``tests/test_physics.py`` (which asserts on them): the reference tutorial's drop–settle–drive
protocol, the analytic acceleration of a rover rolling without slip, and rovers driven into the
walls at top speed."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from atrv_warp.sim.config import ContactConfig, SimConfig
from atrv_warp.sim.simulator import DriveMode, RoverSim


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
