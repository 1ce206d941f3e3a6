"""The places rovers drive in, as a robot's stack already has them: a Nav2 ``map_server`` map
(:func:`load_map`; :func:`save_map` writes one as ``map_saver_cli`` does)."""

from atrv_warp.world.nav2_map import MapError, OccupancyMap, load_map, save_map

__all__ = ["MapError", "OccupancyMap", "load_map", "save_map"]
