"""Skid-steer kinematics, in torch: a twist to each side's wheel speed and back, and the rover's track.

A skid-steer rover's wheels slide sideways when it turns, so it turns slower than a differential drive
with the same track: ``yaw rate = r (w_right - w_left) / (factor x track)``. :class:`SkidSteer` holds
``r``, the track and that factor; the base driver (``integrations/ros/base.py``), the calibration's replay
and the odometry all go through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from atrv_warp.core.robot import DEFAULT_ROBOT, load_robot

__all__ = ["EFFECTIVE_TRACK_FACTOR", "SkidSteer", "side_speeds", "track_width"]

EFFECTIVE_TRACK_FACTOR = load_robot(DEFAULT_ROBOT).effective_track_factor
"""Effective track / wheel track of the default robot, the ATRV-Jr, on our physics [-], from its robot file
(``atrv_warp/robots/atrvjr.toml``: the median over turning commands measured by ``benchmarks/physics/skid_calibration.py``).
Coulomb friction predicts 1.58 for this geometry, and Mandow et al. (IROS 2007) measured about 1.5 on a Pioneer
3-AT. Every robot's own is its file's :attr:`~atrv_warp.core.robot.Robot.effective_track_factor`."""


@dataclass(frozen=True)
class SkidSteer:
    """A skid-steer base's kinematics."""

    wheel_radius: float
    """Wheel rolling radius [m]."""
    track_width: float
    """Distance between the left and right wheel centres [m] (:func:`track_width` of a URDF)."""
    effective_track_factor: float = EFFECTIVE_TRACK_FACTOR
    """Effective track / wheel track [-] (:data:`EFFECTIVE_TRACK_FACTOR`)."""

    def __post_init__(self):
        for name in ("wheel_radius", "track_width", "effective_track_factor"):
            value = getattr(self, name)
            try:
                ok = math.isfinite(float(value)) and float(value) > 0
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")

    @property
    def effective_track(self) -> float:
        """The track a turn sees [m]: ``effective_track_factor x track_width``."""
        return self.effective_track_factor * self.track_width

    def wheel_speeds(self, linear, angular) -> torch.Tensor:
        """(..., 2) (left, right) wheel speeds [rad/s] that drive ``linear`` [m/s] and ``angular`` [rad/s]."""
        linear, angular = _as_tensor(linear), _as_tensor(angular)
        half = 0.5 * angular * self.effective_track
        return torch.stack([linear - half, linear + half], -1) / self.wheel_radius

    def twist(self, speeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(linear [m/s], angular [rad/s]) that (..., 2) (left, right) wheel speeds [rad/s] drive."""
        left, right = _as_tensor(speeds).unbind(-1)
        r = self.wheel_radius
        return r * (left + right) / 2, r * (right - left) / self.effective_track


def _as_tensor(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(x, dtype=torch.float64)


def track_width(description, rover) -> float:
    """Wheel track [m] of a rover: the distance between its outermost wheels' contact centres.

    ``description`` is the URDF's :class:`~atrv_warp.sim.urdf.RoverDescription` (its ``wheels``, each with a
    4x4 ``origin``, left to right or right to left) and ``rover`` its :class:`~atrv_warp.sim.config.RoverConfig`
    (``wheel_offset`` [m], the contact's lateral offset from the wheel joint)."""
    wheels = description.wheels
    return abs(float(wheels[0].origin[1, 3]) - float(wheels[-1].origin[1, 3])) + 2 * rover.wheel_offset


def side_speeds(wheel_speed: torch.Tensor, side: torch.Tensor) -> torch.Tensor:
    """(N, 2) mean (left, right) wheel speeds [rad/s] from (N, W) ``wheel_speed`` and each wheel's side (W,)
    (0 left, 1 right)."""
    return torch.stack([wheel_speed[:, side == 0].mean(-1), wheel_speed[:, side == 1].mean(-1)], -1)
