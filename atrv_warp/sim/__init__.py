"""The simulator: many ATRV-Jr rovers on Newton's Featherstone solver, with our contact kernel.

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
  turning responses), shared by benchmarks and tests; :mod:`.checks`: the fingerprints results files record.
- :mod:`.sysid`: system identification, the simulator's parameters fitted to a drive recorded on a rover.
- :mod:`.robot_check`: a robot file's figures measured in the simulator.

Importing this package configures Warp (:func:`atrv_warp.runtime.configure`: a quiet console) before any of
its modules imports Newton, whose import initialises Warp.
"""

from atrv_warp import runtime

runtime.configure()

from atrv_warp.sim.config import (
    FAST_SIM_DT,
    REFERENCE_SIM_DT,
    VARIANTS,
    ArenaConfig,
    ContactConfig,
    InertialOverride,
    ObstacleConfig,
    RoverConfig,
    SimConfig,
    get_variant,
)
from atrv_warp.sim.contact import ContactModel, Obstacles, Terrain
from atrv_warp.sim.params import PARAMETERS, WorldParams
from atrv_warp.sim.scanner import LaserScanner, ScannerConfig
from atrv_warp.sim.simulator import DRIVE_MODE_TORQUES, DriveMode, RoverSim, SimBuffers
from atrv_warp.sim.terrain import TERRAIN_PRESETS, HeightGrid, TerrainConfig
from atrv_warp.sim.urdf import URDFError, load_rover

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
