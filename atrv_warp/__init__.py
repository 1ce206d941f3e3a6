"""atrv_warp: many ATRV-Jr skid-steer rovers at once, on Newton physics and Warp kernels.

Public names are imported lazily so that ``python -m atrv_warp.<tool>`` loads only what
the tool needs.
"""

from importlib import import_module

from . import runtime as _runtime

_runtime.configure()  # quiet Warp/TorchRL console before Newton's import initialises Warp (ATRV_WARP_VERBOSE=1: all)

_EXPORTS = {
    "ArenaConfig": "config",
    "ContactConfig": "config",
    "InertialOverride": "config",
    "RoverConfig": "config",
    "SimConfig": "config",
    "VARIANTS": "config",
    "get_variant": "config",
    "TaskConfig": "config",
    "ATRVjrEnv": "env",
    "EnvFactory": "env",
    "END_REASONS": "env",
    "DRIVE_MODE_TORQUES": "sim",
    "DriveMode": "sim",
    "RoverSim": "sim",
    "URDFError": "urdf",
    "load_rover": "urdf",
}

__all__ = [
    "DRIVE_MODE_TORQUES",
    "END_REASONS",
    "VARIANTS",
    "ATRVjrEnv",
    "ArenaConfig",
    "ContactConfig",
    "DriveMode",
    "EnvFactory",
    "InertialOverride",
    "RoverConfig",
    "RoverSim",
    "SimConfig",
    "TaskConfig",
    "URDFError",
    "get_variant",
    "load_rover",
]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
