"""Maps on the device: each map's walls and distance field packed for the kernels (:class:`GridWorlds`), shared by
every world that drives in it.

    from atrv_warp.world import load_map
    from atrv_warp.sim.maps import GridWorlds
    grids = GridWorlds([load_map("mymap.yaml")], world_map=[0] * num_worlds, device="cpu")
    grids.struct                        # the kernels' GridMaps (atrv_warp.sim.kernels.grid)
    grids.cast(0, origins, directions, max_range)    # ranges [m] of rays in map 0 (a test's and a benchmark's probe)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import warp as wp

from atrv_warp.sim.config import ArenaConfig
from atrv_warp.sim.kernels.grid import GridMaps, distance_columns, distance_rows, ray_grid
from atrv_warp.world import OccupancyMap

__all__ = ["ARENA_MARGIN", "DEFAULT_WALL_TOP", "GridWorlds", "arena_around", "distance_field", "round_robin"]

DEFAULT_WALL_TOP = 2.0
"""Height of a map's walls [m]: above every shipped robot's laser and chassis (a building's walls, a yard's fences)."""


def distance_field(walls: np.ndarray, device: str | wp.context.Device | None = None) -> np.ndarray:
    """(rows, cols) float32: each cell's exact Euclidean distance [cells] from its centre to the nearest wall cell's
    centre (``walls`` a (rows, cols) bool grid; the space outside it counts as wall), computed on ``device``."""
    walls = np.ascontiguousarray(walls, dtype=np.uint8)
    rows, cols = walls.shape
    device = wp.get_device(device)
    wall = wp.array(walls, dtype=wp.uint8, device=device)
    across = wp.empty((rows, cols), dtype=float, device=device)
    wp.launch(distance_rows, dim=rows, inputs=[wall], outputs=[across], device=device)
    apex = wp.empty((cols, rows), dtype=wp.int32, device=device)
    bound = wp.empty((cols, rows + 1), dtype=wp.float64, device=device)
    distance = wp.empty((rows, cols), dtype=float, device=device)
    wp.launch(distance_columns, dim=cols, inputs=[across, apex, bound], outputs=[distance], device=device)
    return distance.numpy()


ARENA_MARGIN = 1.0
"""Ground beyond the farthest map's edge [m] in :func:`arena_around`'s arena."""


def arena_around(maps: Sequence[OccupancyMap]) -> ArenaConfig:
    """The reference arena, or, with ``maps``, a square arena centred on the origin whose walls stand
    :data:`ARENA_MARGIN` beyond every map's edge: a map bounds its world (what lies beyond its edge is a wall), so the
    arena's walls are never met and its ground lies under every map."""
    if not maps:
        return ArenaConfig()
    reach = max(max(abs(m.origin[0]), abs(m.origin[1]), abs(m.origin[0] + m.size[0]), abs(m.origin[1] + m.size[1]))
                for m in maps)
    return ArenaConfig(size=max(ArenaConfig().size, 2.0 * (reach + ARENA_MARGIN)))


def round_robin(num_worlds: int, num_maps: int) -> list[int]:
    """World ``w``'s map: ``w % num_maps`` (each map in turn), or -1 for every world where there are no maps."""
    return [w % num_maps if num_maps else -1 for w in range(num_worlds)]


@wp.kernel
def cast_grid_rays(grids: GridMaps, m: int, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                   t_max: float, ranges: wp.array(dtype=float)):
    """One thread per ray: its range [m] in map ``m`` (unit ``directions``)."""
    i = wp.tid()
    ranges[i] = ray_grid(grids, m, origins[i], directions[i], t_max)


class GridWorlds:
    """``maps`` on ``device``, each held once, and which map each world drives in (``world_map[w]``: an index into
    ``maps``, or -1 for a world without one); :attr:`struct` is what the kernels read. No maps: no world has one."""

    def __init__(self, maps: Sequence[OccupancyMap], world_map: Sequence[int], device=None, *,
                 wall_top: float = DEFAULT_WALL_TOP):
        self.maps = list(maps)
        self.device = wp.get_device(device)
        world_map = np.asarray(world_map, dtype=np.int32)
        if world_map.size and (world_map.min() < -1 or world_map.max() >= len(self.maps)):
            raise ValueError(f"world_map holds {sorted(set(world_map.tolist()))}, but there are {len(self.maps)} maps")
        walls = [m.walls for m in self.maps]
        fields = [distance_field(w, self.device) for w in walls]
        if not walls:  # no map: one placeholder cell, which no world reads (count 0)
            walls, fields = [np.ones((1, 1), dtype=bool)], [np.zeros((1, 1), dtype=np.float32)]
        start = np.concatenate([[0], np.cumsum([w.size for w in walls])[:-1]]).astype(np.int32)
        s = GridMaps()
        s.count = len(self.maps)
        s.wall = wp.array(np.concatenate([w.ravel() for w in walls]).astype(np.uint8), dtype=wp.uint8,
                          device=self.device)
        s.distance = wp.array(np.concatenate([f.ravel() for f in fields]), dtype=float, device=self.device)
        s.start = wp.array(start, dtype=wp.int32, device=self.device)
        s.rows = wp.array([w.shape[0] for w in walls], dtype=wp.int32, device=self.device)
        s.cols = wp.array([w.shape[1] for w in walls], dtype=wp.int32, device=self.device)
        s.resolution = wp.array([m.resolution for m in self.maps] or [1.0], dtype=float, device=self.device)
        s.origin = wp.array([m.origin for m in self.maps] or [(0.0, 0.0)], dtype=wp.vec2, device=self.device)
        s.world_map = wp.array(world_map if world_map.size else np.full(1, -1, np.int32), dtype=wp.int32,
                               device=self.device)
        s.top = float(wall_top)
        self.struct = s
        self.distance = fields[:len(self.maps)]  # each map's field [cells], on the host
        self.world_map = world_map  # (N,) each world's map, or -1

    def cast(self, m: int, origins, directions, max_range: float) -> np.ndarray:
        """Ranges [m] of rays from ``origins`` (R, 3) along unit ``directions`` (R, 3) in map ``m``: the beam the
        simulator's scanner casts, for tests and benchmarks."""
        origins = wp.array(np.asarray(origins, dtype=np.float32), dtype=wp.vec3, device=self.device)
        directions = wp.array(np.asarray(directions, dtype=np.float32), dtype=wp.vec3, device=self.device)
        ranges = wp.empty(origins.shape[0], dtype=float, device=self.device)
        wp.launch(cast_grid_rays, dim=origins.shape[0], inputs=[self.struct, int(m), origins, directions,
                                                                 float(max_range)], outputs=[ranges],
                  device=self.device)
        return ranges.numpy()
