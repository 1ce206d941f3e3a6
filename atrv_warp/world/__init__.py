"""The places rovers drive in, as a robot's stack already has them: a Nav2 ``map_server`` map
(:func:`load_map`; :func:`save_map` writes one as ``map_saver_cli`` does), or a procedural building or yard
(:mod:`atrv_warp.world.places`); :func:`resolve_sites` takes a list of either."""

from atrv_warp.world.nav2_map import MapError, OccupancyMap, load_map, save_map
from atrv_warp.world.places import resolve_sites

__all__ = ["MapError", "OccupancyMap", "load_map", "resolve_sites", "save_map"]
