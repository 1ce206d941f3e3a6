"""The simulator: many skid-steer rovers (a robot file each: the ATRV-Jr, a Jackal, a Husky, yours) on Newton's
Featherstone solver, with our contact kernel.

- :mod:`.config`: rover (and variants), contact law, arena, integrator settings.
- :mod:`.urdf` / :mod:`.model`: the checked URDF description and the Newton model of N worlds.
- :mod:`.simulator`: :class:`RoverSim`, its public contract (:class:`SimBuffers`) and driving modes.
- :mod:`.contact`: :class:`ContactModel`, each world's :class:`Terrain` and :class:`Obstacles`;
  :mod:`.kernels`: contact, terrain, obstacle, scan and rover Warp kernels.
- :mod:`.params`: :class:`WorldParams`, each world's physical parameters (friction, payload, motors, wheels).
- :mod:`.terrain`: seeded heightfields (:class:`TerrainConfig`, presets, :class:`HeightGrid`).
- :mod:`.scanner`: :class:`LaserScanner`, the 2-D laser range finder.
- :mod:`.diff`: :class:`DiffRollout`, gradients through the simulator.
- :mod:`.protocols`: measurement protocols (the reference drive, wall impacts, slip, slopes, the driver's step and
  turning responses), shared by benchmarks and tests; :mod:`.fingerprints`: the hashes results files record.
- :mod:`.sysid`: system identification, the simulator's parameters fitted to a drive recorded on a rover.
- :mod:`.robot_check`: a robot file's figures measured in the simulator.

Importing this package configures Warp (:func:`atrv_warp.runtime.configure`: a quiet console) before any of
its modules imports Newton, whose import initialises Warp. Its names (``RoverSim``, ``SimConfig`` …) are imported on
first use, so that ``atrv_warp.sim.config`` or ``.modes`` load without Newton.
"""

from atrv_warp import runtime
from atrv_warp.core.lazy import lazy_names

runtime.configure()

_EXPORTS = {
    "FAST_SIM_DT": "config",
    "REFERENCE_SIM_DT": "config",
    "VARIANTS": "config",
    "ArenaConfig": "config",
    "ContactConfig": "config",
    "InertialOverride": "config",
    "ObstacleConfig": "config",
    "RoverConfig": "config",
    "SimConfig": "config",
    "get_variant": "config",
    "ContactModel": "contact",
    "Obstacles": "contact",
    "Terrain": "contact",
    "DRIVE_MODE_TORQUES": "modes",
    "DriveMode": "modes",
    "PARAMETERS": "params",
    "WorldParams": "params",
    "LaserScanner": "scanner",
    "ScannerConfig": "scanner",
    "RoverSim": "simulator",
    "SimBuffers": "simulator",
    "TERRAIN_PRESETS": "terrain",
    "HeightGrid": "terrain",
    "TerrainConfig": "terrain",
    "URDFError": "urdf",
    "load_rover": "urdf",
}
"""Each public name and the module it is imported from on first use (as the top-level package does): a command
that needs the configs or the driving modes (the ROS node's parameter checks) does not import Newton."""



__all__ = [
    "DRIVE_MODE_TORQUES",
    "FAST_SIM_DT",
    "PARAMETERS",
    "REFERENCE_SIM_DT",
    "TERRAIN_PRESETS",
    "VARIANTS",
    "ArenaConfig",
    "ContactConfig",
    "ContactModel",
    "DriveMode",
    "HeightGrid",
    "InertialOverride",
    "LaserScanner",
    "ObstacleConfig",
    "Obstacles",
    "RoverConfig",
    "RoverSim",
    "ScannerConfig",
    "SimBuffers",
    "SimConfig",
    "Terrain",
    "TerrainConfig",
    "URDFError",
    "WorldParams",
    "get_variant",
    "load_rover",
]

__getattr__, __dir__ = lazy_names(__name__, _EXPORTS, __all__)
