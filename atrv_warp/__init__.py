"""atrv_warp: many skid-steer rovers at once (the ATRV-Jr, a Jackal, a Husky, or yours from its URDF), on Newton
physics and Warp kernels.

Layout: :mod:`atrv_warp.sim` (the simulator), :mod:`atrv_warp.task` (the drive-to-target task
and its TorchRL environment), :mod:`atrv_warp.rl` (SAC training), :mod:`atrv_warp.integrations`
(Rerun, ROS 2, Gymnasium), :mod:`atrv_warp.policy` (saved policies); the command-line tools are thin modules in
:mod:`atrv_warp.cli` (``python -m atrv_warp.train``, ``evaluate``, ``demo``, ``model``, ``ros``, ``export``,
``calibrate``, ``robot``), and :mod:`atrv_warp.deploy` runs an exported policy on a robot.

Public names are imported lazily so that ``python -m atrv_warp.<tool>`` loads only what
the tool needs: importing the package loads neither Warp, Newton nor TorchRL, and :mod:`atrv_warp.core`
(the rover's geometry and kinematics in torch) runs with torch alone.
"""

from atrv_warp.core.lazy import lazy_names

from . import runtime as _runtime

__version__ = "0.2.0"
"""This package's version (``pyproject.toml``'s; ``CHANGELOG.md`` says what changed)."""

_runtime.configure_logging()  # TorchRL's console level; Warp is configured when the simulator is imported

_EXPORTS = {
    "ArenaConfig": "sim.config",
    "ContactConfig": "sim.config",
    "InertialOverride": "sim.config",
    "RoverConfig": "sim.config",
    "SimConfig": "sim.config",
    "VARIANTS": "sim.config",
    "get_variant": "sim.config",
    "TaskConfig": "task.config",
    "TrainConfig": "rl.config",
    "ATRVjrEnv": "task.env",
    "RoverEnv": "task.env",
    "EnvFactory": "task.env",
    "END_REASONS": "task.spec",
    "EndReason": "task.spec",
    "DRIVE_MODE_TORQUES": "sim.modes",
    "DriveMode": "sim.modes",
    "RoverSim": "sim.simulator",
    "SimBuffers": "sim.simulator",
    "DiffRollout": "sim.diff",
    "URDFError": "sim.urdf",
    "load_rover": "sim.urdf",
    "load_policy": "policy",
}

__all__ = [
    "DRIVE_MODE_TORQUES",
    "END_REASONS",
    "VARIANTS",
    "ATRVjrEnv",
    "ArenaConfig",
    "ContactConfig",
    "DiffRollout",
    "DriveMode",
    "EndReason",
    "EnvFactory",
    "InertialOverride",
    "RoverConfig",
    "RoverEnv",
    "RoverSim",
    "SimBuffers",
    "SimConfig",
    "TaskConfig",
    "TrainConfig",
    "URDFError",
    "get_variant",
    "load_policy",
    "load_rover",
]

__getattr__, __dir__ = lazy_names(__name__, _EXPORTS, __all__)
