"""Physics checks shared by ``benchmarks/physics_report.py`` (which prints them) and
``tests/test_physics.py`` (which asserts on them): the reference tutorial's drop–settle–drive
protocol and the analytic acceleration of a rover rolling without slip."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
