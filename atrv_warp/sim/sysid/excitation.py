"""The scripted drive a calibration bag records, apart from any transport: :class:`Excitation` draws seeded random
velocity commands (runs, arcs, turns in place, stops; half of them steps, half ramps) and steers back toward the
start when the rover strays. :class:`~atrv_warp.integrations.ros.drive.ExcitationDriver` sends them over ROS 2 to
the simulator node (or a robot); :func:`~atrv_warp.integrations.mujoco.record.record_twin_bag` gives them to the
MuJoCo twin. Plain Python and numpy.
"""

from __future__ import annotations

import math

import numpy as np

from atrv_warp.core.geometry import wrap_angle

__all__ = ["Excitation"]


class Excitation:
    """Random velocity commands, each held 0.8-2.5 s and re-sent every ``resend`` seconds (a base's watchdog wants
    them), drawn from ``seed``; beyond ``radius`` [m] from the start it drives back.

    Half the changes are steps, which saturate the motors (the motor's strength, and the friction where the tyres
    slide); the other half are ramps at 0.5-2 m/s² (and as many rad/s² per m/s of the limits' ratio), as a
    joystick or a base's acceleration limit gives: a driver that tracks its wheel speeds tightly then needs the
    torque that the rover's mass takes, which the wheel efforts record."""

    def __init__(self, seed: int = 0, radius: float = 8.0, max_linear: float = 1.2, max_angular: float = 1.2,
                 resend: float = 0.1):
        self.rng = np.random.default_rng(seed)
        self.radius, self.max_linear, self.max_angular, self.resend = radius, max_linear, max_angular, resend
        self.command = (0.0, 0.0)
        self.target = (0.0, 0.0)
        self.rate = math.inf
        """The ramp's rate toward ``target`` [m/s²] (``inf``: a step)."""
        self.last = 0.0
        self.next_change = 0.0
        self.next_send = 0.0

    def draw(self, pose: tuple[float, float, float]) -> tuple[float, float]:
        """The next target (linear [m/s], angular [rad/s]) from the rover's ``pose`` (x, y, yaw)."""
        x, y, yaw = pose
        if math.hypot(x, y) > self.radius:  # head home: turn toward the start while rolling
            error = float(wrap_angle(math.atan2(-y, -x) - yaw))
            return (0.3 if abs(error) > 1.0 else 0.8), max(-1.0, min(1.0, 1.5 * error))
        kind = self.rng.random()
        if kind < 0.12:
            return 0.0, 0.0
        if kind < 0.32:
            return 0.0, float(self.rng.choice([-1, 1]) * self.rng.uniform(0.4, self.max_angular))
        return (float(self.rng.uniform(-0.5 * self.max_linear, self.max_linear)),
                float(self.rng.uniform(-self.max_angular, self.max_angular)))

    def update(self, now: float, pose: tuple[float, float, float]) -> tuple[float, float] | None:
        """The command to send at time ``now`` [s] with the rover at ``pose`` (x [m], y [m], yaw [rad] from the
        start), or ``None`` until the next re-send."""
        if now >= self.next_change:
            self.target = self.draw(pose)
            self.rate = math.inf if self.rng.random() < 0.5 else float(self.rng.uniform(0.5, 2.0))
            self.next_change = now + float(self.rng.uniform(0.8, 2.5))
            self.next_send = now
        dt, self.last = max(now - self.last, 0.0), now
        if math.isinf(self.rate):
            self.command = self.target
        else:
            step = (self.rate * dt, self.rate * dt * self.max_angular / self.max_linear)
            self.command = tuple(c + max(-d, min(d, t - c)) for c, t, d in zip(self.command, self.target, step))
        if now < self.next_send - 1e-9:
            return None
        self.next_send = now + self.resend
        return self.command
