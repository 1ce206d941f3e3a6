"""The light core: the rover's geometry and kinematics in plain torch, for code that runs without the simulator.

Nothing here imports Warp, Newton or TorchRL, so a program on a robot's computer (a policy node, an
observation builder) can use it with torch alone. The simulator's Warp kernels keep one ``@wp.func`` of
each conversion, and the tests hold each to its torch twin here.

- :mod:`.geometry`: quaternions (x, y, z, w), rotation matrices, yaw, angle wrapping;
- :mod:`.kinematics`: skid-steer kinematics (:class:`~.kinematics.SkidSteer`), the wheel track, side speeds;
- :mod:`.scan`: a laser scan's sectors (:class:`~.scan.ScanSectors`), declared by their angular edges,
  and REP 117's reading of a ``LaserScan``'s ranges;
- :mod:`.observation`: the robot observation built from a robot's messages (:class:`~.observation.RobotObservation`,
  from an exported policy's contract);
- :mod:`.inputs`: an input file read only from a regular file of bounded size (the standard library alone).
"""

from atrv_warp.core.lazy import lazy_names

_EXPORTS = {
    **dict.fromkeys(("matrix_to_quat", "quat_to_matrix", "quat_to_rpy", "quat_to_yaw", "rpy_to_quat", "wrap_angle",
                     "yaw_to_quat"), "geometry"),
    **dict.fromkeys(("EFFECTIVE_TRACK_FACTOR", "SkidSteer", "side_speeds", "track_width"), "kinematics"),
    **dict.fromkeys(("RobotObservation", "Scan"), "observation"),
    **dict.fromkeys(("ScanSectors", "remount", "sector_readings"), "scan"),
}
"""Each name this package gives, and its module: imported on first use, so that the standard-library modules here
(:mod:`.robot`, :mod:`.inputs`) load without torch (the robot-side install reads robot files before torch)."""

__all__ = [
    "EFFECTIVE_TRACK_FACTOR",
    "RobotObservation",
    "Scan",
    "ScanSectors",
    "SkidSteer",
    "matrix_to_quat",
    "quat_to_matrix",
    "quat_to_rpy",
    "quat_to_yaw",
    "remount",
    "rpy_to_quat",
    "sector_readings",
    "side_speeds",
    "track_width",
    "wrap_angle",
    "yaw_to_quat",
]

__getattr__, __dir__ = lazy_names(__name__, _EXPORTS, __all__)
