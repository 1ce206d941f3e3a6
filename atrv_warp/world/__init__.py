"""The places rovers drive in, as a robot's stack already has them: a Nav2 ``map_server`` map
(:func:`load_map`)."""

from atrv_warp.world.nav2_map import MapError, OccupancyMap, load_map

__all__ = ["MapError", "OccupancyMap", "load_map"]
