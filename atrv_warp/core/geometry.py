"""Quaternions, rotation matrices and angles, written once, in torch.

Quaternions are (x, y, z, w), as ROS messages, Newton's ``body_q`` and Warp's ``wp.quat`` order them;
every function takes a batch (``...`` leading dimensions) and keeps the input's dtype and device. The Warp
kernels' ``@wp.func`` twins (``sim/kernels/rover.py``'s ``quat_to_rpy``, Warp's ``quat_to_matrix``) are held
to these by ``tests/test_core.py``.
"""

from __future__ import annotations

import torch

__all__ = ["matrix_to_quat", "quat_to_matrix", "quat_to_rpy", "quat_to_yaw", "rpy_to_quat", "wrap_angle", "yaw_to_quat"]


def _as_tensor(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(x, dtype=torch.float64)


def quat_to_yaw(q) -> torch.Tensor:
    """Yaw [rad] in (-pi, pi] (the Z of intrinsic Z-Y-X) of unit quaternions (..., 4) (x, y, z, w)."""
    x, y, z, w = _as_tensor(q).unbind(-1)
    return torch.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_to_rpy(q) -> torch.Tensor:
    """Roll, pitch, yaw [rad] (..., 3), intrinsic Z-Y-X, of unit quaternions (..., 4) (x, y, z, w)."""
    x, y, z, w = _as_tensor(q).unbind(-1)
    roll = torch.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = torch.asin((2.0 * (w * y - z * x)).clamp(-1.0, 1.0))
    yaw = torch.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return torch.stack([roll, pitch, yaw], -1)


def quat_to_matrix(q) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) (parent from child) of unit quaternions (..., 4) (x, y, z, w)."""
    x, y, z, w = _as_tensor(q).unbind(-1)
    rows = (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))
    return torch.stack(rows, -1).unflatten(-1, (3, 3))


def matrix_to_quat(m) -> torch.Tensor:
    """Unit quaternions (..., 4) (x, y, z, w, with w >= 0) of rotation matrices (..., 3, 3)."""
    m = _as_tensor(m)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    w = (1.0 + m00 + m11 + m22).clamp(min=0.0).sqrt() / 2
    x = torch.copysign((1.0 + m00 - m11 - m22).clamp(min=0.0).sqrt() / 2, m[..., 2, 1] - m[..., 1, 2])
    y = torch.copysign((1.0 - m00 + m11 - m22).clamp(min=0.0).sqrt() / 2, m[..., 0, 2] - m[..., 2, 0])
    z = torch.copysign((1.0 - m00 - m11 + m22).clamp(min=0.0).sqrt() / 2, m[..., 1, 0] - m[..., 0, 1])
    return torch.stack([x, y, z, w], -1)


def rpy_to_quat(rpy) -> torch.Tensor:
    """Unit quaternions (..., 4) (x, y, z, w) of roll, pitch, yaw [rad] (..., 3), intrinsic Z-Y-X (the inverse of
    :func:`quat_to_rpy`)."""
    half = _as_tensor(rpy) / 2
    cr, cp, cy = half.cos().unbind(-1)
    sr, sp, sy = half.sin().unbind(-1)
    return torch.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                        cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], -1)


def yaw_to_quat(yaw) -> torch.Tensor:
    """Quaternions (..., 4) (x, y, z, w) of rotations by ``yaw`` [rad] about z."""
    half = _as_tensor(yaw) / 2
    zero = torch.zeros_like(half)
    return torch.stack([zero, zero, half.sin(), half.cos()], -1)


def wrap_angle(a) -> torch.Tensor:
    """Angles [rad] wrapped to (-pi, pi]."""
    a = _as_tensor(a)
    return torch.atan2(torch.sin(a), torch.cos(a))
