"""The reference ROS tutorial's fixed-torque driving modes (``/command``'s ``coast``, ``forward`` …): what each
commands of the motors. Apart from the simulator so that a command's parameters are checked without building one
(the ROS node refuses a bad ``mode`` before it imports Newton)."""

from __future__ import annotations

from enum import Enum

__all__ = ["DRIVE_MODE_REFERENCE_TORQUE", "DRIVE_MODE_TORQUES", "DriveMode"]


class DriveMode(str, Enum):
    """The reference ROS tutorial's fixed-torque driving modes."""

    COAST = "coast"
    FORWARD = "forward"
    BACKWARD = "backward"
    ROTATE_RIGHT = "rotate_right"
    ROTATE_LEFT = "rotate_left"


DRIVE_MODE_TORQUES: dict[DriveMode, tuple[float, float]] = {
    DriveMode.COAST: (0.0, 0.0),
    DriveMode.FORWARD: (4.0, 4.0),
    DriveMode.BACKWARD: (-4.0, -4.0),
    DriveMode.ROTATE_RIGHT: (5.0, -5.0),
    DriveMode.ROTATE_LEFT: (-5.0, 5.0),
}
"""(left, right) wheel torque [N·m] of each mode, on the ATRV-Jr (the reference tutorial's): another robot's are the same
share of its motors' torque limit (:data:`DRIVE_MODE_REFERENCE_TORQUE` is the ATRV-Jr's)."""
DRIVE_MODE_REFERENCE_TORQUE = 20.0
"""[N·m] The ATRV-Jr's torque limit, which :data:`DRIVE_MODE_TORQUES` are shares of."""
