"""What a real mobile-base driver does, without ROS types: a wheel-speed PI controller over the light
core's skid-steer kinematics (:mod:`atrv_warp.core.kinematics`), a command watchdog, wheel odometry and an
IMU reading. :mod:`.node` publishes these.

All of it is per rover and plain torch/math, so it is tested without a ROS graph too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from atrv_warp.core.geometry import matrix_to_quat, wrap_angle
from atrv_warp.core.kinematics import SkidSteer, side_speeds

__all__ = ["BaseParams", "VelocityController", "WheelOdometry", "imu_reading", "turning_response"]


@dataclass(frozen=True)
class BaseParams(SkidSteer):
    """Skid-steer base figures (ROS parameters of the node): the kinematics (:class:`~atrv_warp.core.kinematics.SkidSteer`:
    wheel radius, track, effective track factor) and the driver's wheel-speed loop."""

    kp: float = 0.6
    """PI proportional gain [N·m per rad/s]. The controller runs once per 0.05 s step, and a
    slipping wheel's own inertia (0.02 kg·m²) bounds it: above ~0.8 it oscillates."""
    ki: float = 3.0
    """PI integral gain [N·m per rad]."""
    torque_limit: float = 20.0
    """Motor limit [N·m] (the task's action scale)."""
    timeout: float = 0.5
    """Watchdog: with no /cmd_vel for this long [s of sim time], the targets drop to zero."""


@dataclass
class VelocityController:
    """Twist (linear.x [m/s], angular.z [rad/s]) -> per-side wheel-speed targets -> PI torques."""

    params: BaseParams
    target: tuple[float, float] = (0.0, 0.0)
    """Commanded (linear.x, angular.z)."""
    last_command: float = -math.inf
    """Sim time of the newest command [s]."""
    integral: torch.Tensor = field(default_factory=lambda: torch.zeros(2))
    stopped_by_watchdog: bool = False

    def command(self, linear: float, angular: float, now: float) -> None:
        self.target, self.last_command, self.stopped_by_watchdog = (linear, angular), now, False

    def wheel_targets(self, now: float) -> torch.Tensor:
        """(left, right) wheel-speed targets [rad/s]; zero once the watchdog has fired."""
        if now - self.last_command > self.params.timeout:
            self.stopped_by_watchdog = True
            return torch.zeros(2)
        return self.params.wheel_speeds(*self.target).float()

    def torques(self, side_speeds: torch.Tensor, now: float, dt: float) -> torch.Tensor:
        """(left, right) torques [N·m] toward the targets, within the motor limit (anti-windup:
        the integral stops growing while the output saturates)."""
        p = self.params
        error = self.wheel_targets(now) - side_speeds
        candidate = self.integral + error * dt
        out = p.kp * error + p.ki * candidate
        saturated = out.abs() > p.torque_limit
        self.integral = torch.where(saturated, self.integral, candidate)
        return (p.kp * error + p.ki * self.integral).clamp(-p.torque_limit, p.torque_limit)

    def reset(self) -> None:
        self.integral.zero_()


@dataclass
class WheelOdometry:
    """Pose integrated from the wheel speeds alone, as a real base reports it (skid error included)."""

    params: BaseParams
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    linear: float = 0.0
    angular: float = 0.0

    def update(self, side_speeds: torch.Tensor, dt: float) -> None:
        """Advance by ``dt`` [s] with the mean (left, right) wheel speeds [rad/s] (midpoint rule)."""
        linear, angular = self.params.twist(side_speeds.to(torch.float64))
        self.linear, self.angular = float(linear), float(angular)
        mid = self.yaw + 0.5 * self.angular * dt
        self.x += self.linear * math.cos(mid) * dt
        self.y += self.linear * math.sin(mid) * dt
        self.yaw = float(wrap_angle(self.yaw + self.angular * dt))


def imu_reading(frame_pose: torch.Tensor, ang_vel: torch.Tensor, accel: torch.Tensor, gravity: float,
                noise: tuple[float, float], gen: torch.Generator) -> dict:
    """Orientation, angular velocity and specific force of an IMU at ``frame_pose`` (4x4, world).

    ``ang_vel`` and ``accel`` [m/s²] are world-frame chassis quantities; the IMU measures
    ``accel - g`` (so +9.81 m/s² up at rest) and the angular velocity, both in its own frame,
    plus Gaussian noise of standard deviation ``noise`` = (accel [m/s²], gyro [rad/s]).
    """
    rot = frame_pose[:3, :3].to(torch.float64)
    specific = accel.to(torch.float64) - torch.tensor([0.0, 0.0, gravity], dtype=torch.float64)
    a = rot.T @ specific + noise[0] * torch.randn(3, generator=gen, dtype=torch.float64)
    w = rot.T @ ang_vel.to(torch.float64) + noise[1] * torch.randn(3, generator=gen, dtype=torch.float64)
    return {"orientation": tuple(matrix_to_quat(rot).tolist()), "angular_velocity": w.tolist(),
            "linear_acceleration": a.tolist()}


def turning_response(sim, commands: list[tuple[float, float]], params: BaseParams, *, seconds: float = 8.0,
                     average: float = 3.0) -> list[dict]:
    """Drive world ``i`` of ``sim`` (at least ``len(commands)`` worlds, placed apart) with a
    :class:`VelocityController` toward ``commands[i]`` = (linear [m/s], angular [rad/s]) for
    ``seconds``, and return per command the mean left and right wheel speeds [rad/s], yaw rate
    [rad/s] and speed [m/s] over the last ``average`` seconds: what a skid-steer calibration measures.

    Each rover starts facing +x where the circle it will drive (for an effective track ratio near
    1.6) is centred on the arena's centre, so that it meets no wall; worlds never interact."""
    n = len(commands)
    start = [[0.0, -1.6 * v / w if w else 0.0, 0.0] for v, w in commands]
    sim.reset(poses=start + [[0.0, 0.0, 0.0]] * (sim.num_worlds - n))
    side = torch.tensor([w.side for w in sim.description.wheels])
    controllers = [VelocityController(params) for _ in commands]
    for c, (v, w) in zip(controllers, commands):
        c.command(v, w, now=0.0)
    dt = sim.sim_cfg.step_dt
    steps, kept = round(seconds / dt), round(average / dt)
    sums = torch.zeros(n, 4, dtype=torch.float64)
    torques = torch.zeros(sim.num_worlds, 2)
    for k in range(steps):
        speeds = side_speeds(sim.wheel_speed, side)
        for i, c in enumerate(controllers):
            torques[i] = c.torques(speeds[i], now=0.0, dt=dt)
        sim.step(torques)
        if k >= steps - kept:
            speeds = side_speeds(sim.wheel_speed, side)[:n]
            sums += torch.cat([speeds, sim.ang_vel[:n, 2:3], sim.lin_vel[:n, :2].norm(dim=-1, keepdim=True)], -1)
    mean = (sums / kept).tolist()
    return [{"linear": v, "angular": w, "wheel_left": m[0], "wheel_right": m[1], "yaw_rate": m[2], "speed": m[3]}
            for (v, w), m in zip(commands, mean)]

