"""What a real base's IMU reads, without ROS types (:mod:`.node` publishes it). The base's motor driver and its
wheel odometry run inside the simulator (:mod:`atrv_warp.sim.driver`).

Plain torch/math, so it is tested without a ROS graph too.
"""

from __future__ import annotations

import torch

from atrv_warp.core.geometry import matrix_to_quat

__all__ = ["imu_reading"]


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
