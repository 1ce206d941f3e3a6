"""The simulator: many ATRV-Jr rovers on Newton's Featherstone solver, with our contact kernel.

- :mod:`.config`: rover (and variants), contact law, arena, integrator settings.
- :mod:`.urdf` / :mod:`.model`: the checked URDF description and the Newton model of N worlds.
- :mod:`.simulator`: :class:`RoverSim`, its public contract (:class:`SimBuffers`) and driving modes.
- :mod:`.contact`: :class:`ContactModel`; :mod:`.kernels`: contact and rover Warp kernels.
- :mod:`.diff`: :class:`DiffRollout`, gradients through the simulator.
- :mod:`.checks`: the reference drive protocol shared by the physics report and tests.
"""

from atrv_warp.sim.config import (
    VARIANTS,
    ArenaConfig,
    ContactConfig,
    InertialOverride,
    RoverConfig,
    SimConfig,
    get_variant,
)
from atrv_warp.sim.contact import ContactModel
from atrv_warp.sim.simulator import DRIVE_MODE_TORQUES, DriveMode, RoverSim, SimBuffers
from atrv_warp.sim.urdf import URDFError, load_rover

__all__ = [
    "DRIVE_MODE_TORQUES",
    "VARIANTS",
    "ArenaConfig",
    "ContactConfig",
    "ContactModel",
    "DriveMode",
    "InertialOverride",
    "RoverConfig",
    "RoverSim",
    "SimBuffers",
    "SimConfig",
    "URDFError",
    "get_variant",
    "load_rover",
]
