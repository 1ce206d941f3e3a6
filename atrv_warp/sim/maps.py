"""Maps on the device: each map's walls and distance field packed for the kernels (:class:`GridWorlds`), shared by
every world that drives in it.

    from atrv_warp.world import load_map
    from atrv_warp.sim.maps import GridWorlds
    grids = GridWorlds([load_map("mymap.yaml")], world_map=[0] * num_worlds, device="cpu")
    grids.struct                        # the kernels' GridMaps (atrv_warp.sim.kernels.grid)
    grids.cast(0, origins, directions, max_range)    # ranges [m] of rays in map 0 (a test's and a benchmark's probe)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from atrv_warp.sim.config import ArenaConfig
from atrv_warp.sim.kernels.grid import GridMaps, distance_columns, distance_rows, ray_grid
from atrv_warp.world import MapError, OccupancyMap

__all__ = ["ARENA_MARGIN", "CELL_REACH", "DEFAULT_WALL_TOP", "GridWorlds", "arena_around", "components",
           "distance_field", "round_robin", "spawn_cells"]

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


CELL_REACH = 0.5 * 2.0**0.5
"""Cells by which a wall cell's nearest point may lie nearer than its centre (half its diagonal): a cell's distance
field less this is how far its centre is from every wall cell."""


def components(passable: np.ndarray) -> np.ndarray:
    """(rows, cols) int64: each ``passable`` cell's 4-connected group, named by the group's smallest flat index, and
    -1 elsewhere (union by hooking each edge's larger root under its smaller one, then pointer jumping, in NumPy: a
    2,000 × 2,000 map in seconds)."""
    passable = np.asarray(passable, dtype=bool)
    index = np.arange(passable.size).reshape(passable.shape)
    across = passable[:, :-1] & passable[:, 1:]
    along = passable[:-1, :] & passable[1:, :]
    u = np.concatenate([index[:, :-1][across], index[:-1, :][along]])
    v = np.concatenate([index[:, 1:][across], index[1:, :][along]])
    parent = np.arange(passable.size)
    while u.size:
        ru, rv = parent[u], parent[v]  # roots: every parent is one after the jumping below
        apart = ru != rv
        u, v, ru, rv = u[apart], v[apart], ru[apart], rv[apart]
        np.minimum.at(parent, np.maximum(ru, rv), np.minimum(ru, rv))
        while True:
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
    return np.where(passable.ravel(), parent, -1).reshape(passable.shape)


def spawn_cells(distance: np.ndarray, resolution: float, circumscribed: float,
                inscribed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a robot may start or end an episode in a map whose distance field is ``distance`` [cells]: the cells
    whose centre is at least ``circumscribed`` [m] from every wall cell (the robot fits at any heading), grouped by
    the cells at least ``inscribed`` [m] from every wall, 4-connected (where the robot can drive, as Nav2's planner
    plans: lethal inside the inscribed radius).

    Returns:
        (cells, group_first, group_count): each such cell's flat index, group by group; the index in ``cells`` of
        its group's first; its group's size. Empty if none.
    """
    clear = (distance - CELL_REACH) * resolution
    labels = components(clear >= inscribed).ravel()
    cells = np.flatnonzero(clear.ravel() >= circumscribed)
    order = np.argsort(labels[cells], kind="stable")
    cells, groups = cells[order], labels[cells[order]]
    names, first, count = np.unique(groups, return_index=True, return_counts=True)
    slot = np.searchsorted(names, groups)
    return cells.astype(np.int32), first[slot].astype(np.int32), count[slot].astype(np.int32)


ARENA_MARGIN = 1.0
"""Ground beyond the farthest map's edge [m] in :func:`arena_around`'s arena."""


def arena_around(maps: Sequence[OccupancyMap]) -> ArenaConfig:
    """The reference arena, or, with ``maps``, a square arena centred on the origin whose walls stand
    :data:`ARENA_MARGIN` beyond every map's edge (its side rounded up to a whole number of 2 m): a map bounds its world
    (what lies beyond its edge is a wall), so the arena's walls are never met and its ground lies under every map."""
    if not maps:
        return ArenaConfig()
    reach = max(max(abs(m.origin[0]), abs(m.origin[1]), abs(m.origin[0] + m.size[0]), abs(m.origin[1] + m.size[1]))
                for m in maps)
    # a whole number of 2 m: the terrain's height grid spans it at any of its resolutions
    return ArenaConfig(size=max(ArenaConfig().size, 2.0 * math.ceil(reach + ARENA_MARGIN)))


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
    ``maps``, or -1 for a world without one); :attr:`struct` is what the kernels read. No maps: no world has one.

    ``footprint`` (inscribed, circumscribed radius [m]) is the robot's, for where its episodes may start and end
    (:func:`spawn_cells`); a map with no such cell is a :class:`~atrv_warp.world.MapError` naming it."""

    def __init__(self, maps: Sequence[OccupancyMap], world_map: Sequence[int], device=None, *,
                 wall_top: float = DEFAULT_WALL_TOP, footprint: tuple[float, float] = (0.0, 0.0)):
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
        self._pack_spawn(s, fields, footprint)
        self.struct = s
        self.distance = fields[:len(self.maps)]  # each map's field [cells], on the host
        self.world_map = world_map  # (N,) each world's map, or -1

    def open_spot(self, m: int) -> tuple[float, float]:
        """The centre (x, y) [m] of map ``m``'s cell farthest from every wall (the first such cell, row by row)."""
        site = self.maps[m]
        row, col = np.unravel_index(int(np.argmax(self.distance[m])), self.distance[m].shape)
        x, y = site.centre_of(row, col)
        return float(x), float(y)

    def _pack_spawn(self, s: GridMaps, fields: list[np.ndarray], footprint: tuple[float, float]) -> None:
        """Each map's :func:`spawn_cells` for ``footprint``, packed one map after another into ``s``."""
        inscribed, circumscribed = footprint
        cells, first, count, starts = [], [], [], []
        for m, field in zip(self.maps, fields, strict=False):
            c, f, n = spawn_cells(field, m.resolution, circumscribed, inscribed)
            if not c.size:
                raise MapError(f"{m.source or m.name}: no free cell is {circumscribed:.2f} m from every wall (the "
                               "robot's footprint at any heading): no episode can start in this map")
            starts.append(sum(len(x) for x in cells))
            cells.append(c)
            first.append(f + starts[-1])
            count.append(n)

        def packed(parts):
            return wp.array(np.concatenate(parts) if parts else np.zeros(1, np.int32), dtype=wp.int32,
                            device=self.device)
        s.spawn, s.spawn_group, s.spawn_group_count = packed(cells), packed(first), packed(count)
        s.spawn_start = packed([np.asarray(starts, np.int32)])
        s.spawn_count = packed([np.asarray([len(c) for c in cells], np.int32)])

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
