"""Nav2's global planner in the simulator: each world's path over its map, as ``planner_server`` hands a controller a
``nav_msgs/Path``.

    from atrv_warp.sim.planner import Planner, PlannerConfig
    planner = Planner(sim.maps, footprint=sim.footprint_radii)          # the maps' costmaps, built once
    planner.plan(worlds, starts, goals)                                  # (K,) world indices, (N, 2) [m] each
    planner.path[w, :planner.path_length[w]]                             # world w's points [m], start to goal
    planner.replan(worlds, poses)                                        # from where the robots are now: cheap

The costmap is Nav2's global costmap over the map (``static_layer`` and ``inflation_layer``, with
``track_unknown_space``): a cell on an occupied map cell is lethal (254), one within the robot's inscribed radius of it
inscribed (253), one farther ``252 exp(-cost_scaling_factor (d - inscribed))`` out to ``inflation_radius`` and 0 beyond
(``nav2_costmap_2d/inflation_layer.hpp``, ``computeCost``; ``d`` centre to centre), an unknown cell unknown (255,
neither inflated nor inflating). The planner weighs it as NavFn does (:mod:`atrv_warp.sim.kernels.planner`): lethal
and inscribed cells closed, unknown ones passable at 253 where :attr:`PlannerConfig.allow_unknown` (Nav2's default),
and every other cell ``50 + 0.8 c``: the cheapest path keeps to the middle of a doorway and away from walls, and a
doorway 1.5 times the robot's width stays open (only the inscribed radius closes, not the whole footprint).

A plan is the cheapest path over NavFn's weights, found the other way round: NavFn spreads its potential from the
robot and walks it down from the goal; here a field spreads from the goal (:meth:`Planner.set_goals`, Dijkstra in a
kernel, 8-connected where NavFn interpolates across cells, searched as far as :attr:`PlannerConfig.field_reach` times
the start's path cost) and is walked down from the robot (:meth:`Planner.replan`), so that a replan to the same goal
(Nav2's behaviour tree asks about once a second) costs microseconds; a robot that strays beyond the field is
searched for again from where it is. NavFn's intermediate poses carry no heading (its last is the goal's), so a path
here is points. The planning grid may be coarser than the map (:attr:`PlannerConfig.resolution`; never coarser than
the inscribed radius, so that a wall's closed band is at least two cells wide and no diagonal step crosses it). Each
planning cell reads the map cell under its centre. Fields are computed :attr:`PlannerConfig.slots` worlds at a time,
on the maps' device; each world keeps its field (four bytes a planning cell).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from atrv_warp.sim.kernels.obstacles import ObstacleSet
from atrv_warp.sim.kernels.planner import PlanMaps, PlanMarks, follow_fields, goal_fields, mark_seen
from atrv_warp.sim.maps import GridWorlds, distance_field
from atrv_warp.world.nav2_map import OCCUPIED, UNKNOWN

__all__ = ["FIELD_MEMORY", "INSCRIBED", "LETHAL", "NO_INFORMATION", "Planner", "PlannerConfig", "costmap",
           "navfn_costs"]

LETHAL, INSCRIBED, NO_INFORMATION = 254, 253, 255
"""Nav2's costmap values (``nav2_costmap_2d/cost_values.hpp``): ``LETHAL_OBSTACLE``, ``INSCRIBED_INFLATED_OBSTACLE``,
``NO_INFORMATION``."""
FIELD_MEMORY = 4 << 30
"""The most the worlds' fields may take [bytes]: more is refused, naming the worlds and cells it would take."""


@dataclass(frozen=True)
class PlannerConfig:
    """The global costmap's inflation and the planner's settings, named as Nav2's params file names them."""

    inflation_radius: float = 0.7
    """How far from a wall the inflation reaches [m] (``inflation_layer.inflation_radius``)."""
    cost_scaling_factor: float = 3.0
    """How fast the inflated cost decays with distance [1/m] (``inflation_layer.cost_scaling_factor``)."""
    allow_unknown: bool = True
    """Plan through unknown cells, at the highest passable cost (``GridBased.allow_unknown``; Nav2's default)."""
    resolution: float = 0.1
    """The planning grid's cell [m]; the map's where it is finer, the inscribed radius where that is smaller."""
    max_points: int = 2048
    """The most points a path may have; a longer one is no path."""
    slots: int = 64
    """Worlds whose fields are computed at a time (each holds scratch for its map's planning grid)."""
    replan_period: float = 1.0
    """How often each world's path is planned again from where its robot is [s] (Nav2's default behaviour tree
    replans at 1 Hz: ``RateController hz="1.0"``); 0: only at a reset."""
    redraws: int = 8
    """Times a reset draws a world's episode again while its start and goal have no path between them."""
    field_reach: float = 1.5
    """How far a goal's field is searched, as a multiple of the cost of the start's path (0: the whole map): the
    replans of a robot that keeps near its way read it; one that strays beyond is searched again from there."""
    obstacle_layer: bool = False
    """The global costmap's obstacle layer: each world's unmapped obstacles are marked once its laser sees them
    (within :attr:`obstacle_range` and the laser's field of view; occlusion is not modelled) and inflated as the
    map's walls, and its next replan goes around them. Off: the plan is over the map alone."""
    obstacle_range: float = 2.5
    """How far the obstacle layer marks what the laser sees [m] (Nav2's ``obstacle_max_range``)."""

    def __post_init__(self):
        for name in ("inflation_radius", "cost_scaling_factor", "resolution", "obstacle_range"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"PlannerConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("max_points", "slots"):
            if getattr(self, name) < 2:
                raise ValueError(f"PlannerConfig.{name} must be >= 2, got {getattr(self, name)!r}")
        if not (math.isfinite(self.replan_period) and self.replan_period >= 0):
            raise ValueError(f"PlannerConfig.replan_period must be a finite number >= 0, got {self.replan_period!r}")
        if self.redraws < 0:
            raise ValueError(f"PlannerConfig.redraws must be >= 0, got {self.redraws!r}")
        if not (math.isfinite(self.field_reach) and (self.field_reach == 0 or self.field_reach >= 1)):
            raise ValueError(f"PlannerConfig.field_reach must be 0 (the whole map) or a finite number >= 1, got "
                             f"{self.field_reach!r}")


def costmap(cells: np.ndarray, occupied_distance: np.ndarray, resolution: float, inscribed: float,
            cfg: PlannerConfig) -> np.ndarray:
    """(rows, cols) uint8: Nav2's global costmap of map cells ``cells`` (OccupancyGrid values) whose distance to the
    nearest occupied cell is ``occupied_distance`` [cells, centre to centre] (see the module's docstring)."""
    d = occupied_distance * resolution
    cost = np.zeros(cells.shape, dtype=np.uint8)
    near = (d > inscribed) & (d <= cfg.inflation_radius)
    cost[near] = (252.0 * np.exp(-cfg.cost_scaling_factor * (d[near] - inscribed))).astype(np.uint8)
    cost[d <= inscribed] = INSCRIBED
    cost[cells == OCCUPIED] = LETHAL
    cost[cells == UNKNOWN] = NO_INFORMATION
    return cost


def navfn_costs(cost: np.ndarray, allow_unknown: bool) -> np.ndarray:
    """NavFn's traversal cost of each costmap cell (``NavFn::setCostmap``): ``50 + 0.8 c`` below 253, 253 for an
    unknown cell where allowed, -1 (closed) otherwise."""
    out = np.where(cost < INSCRIBED, 50.0 + 0.8 * cost.astype(np.float32), -1.0).astype(np.float32)
    if allow_unknown:
        out[cost == NO_INFORMATION] = 253.0
    return out


def _indices(worlds) -> torch.Tensor:
    return torch.as_tensor(worlds, dtype=torch.int32).reshape(-1).cpu()


class Planner:
    """Every world's global planner over its map (``grids``: the simulator's :class:`~atrv_warp.sim.maps.GridWorlds`)
    for a robot of ``footprint`` (inscribed, circumscribed radius [m]); :meth:`plan` plans some worlds, :attr:`path`,
    :attr:`path_length` and :attr:`path_cost` hold every world's last plan."""

    def __init__(self, grids: GridWorlds, footprint: tuple[float, float], cfg: PlannerConfig | None = None,
                 obstacles: ObstacleSet | None = None):
        self.cfg = cfg = cfg or PlannerConfig()
        self.grids, self.device = grids, grids.device
        inscribed = footprint[0]
        self.costmaps: list[np.ndarray] = []
        """Each map's costmap on its planning grid (Nav2's values: :func:`costmap`)."""
        self.resolutions: list[float] = []
        """Each map's planning cell [m]."""
        for site in grids.maps:
            res = max(site.resolution, min(cfg.resolution, inscribed))
            rows, cols = (max(1, round(n * site.resolution / res)) for n in site.shape)
            y, x = np.meshgrid(site.origin[1] + (np.arange(rows) + 0.5) * res,
                               site.origin[0] + (np.arange(cols) + 0.5) * res, indexing="ij")
            r, c = site.cell_of(x, y)
            r, c = np.clip(r, 0, site.shape[0] - 1), np.clip(c, 0, site.shape[1] - 1)
            # unknown cells do not inflate, nor does the map's edge (padded with free cells beyond the inflation)
            pad = math.ceil(cfg.inflation_radius / site.resolution) + 1
            occupied = distance_field(np.pad(site.cells == OCCUPIED, pad), self.device)[pad:-pad, pad:-pad]
            self.costmaps.append(costmap(site.cells[r, c], occupied[r, c], site.resolution, inscribed, cfg))
            self.resolutions.append(res)
        self.struct = self._pack()
        n, cells = max(len(grids.world_map), 1), max([c.size for c in self.costmaps] or [1])
        if 4 * n * cells > FIELD_MEMORY:
            raise ValueError(f"the planner's fields would take {4 * n * cells / 2**30:.1f} GiB ({n} worlds x "
                             f"{cells:,} planning cells of the largest map): plan on a coarser grid "
                             f"(PlannerConfig.resolution, now {cfg.resolution} m) or in fewer worlds")
        slots = min(cfg.slots, n)
        self.g = wp.empty((slots, cells), dtype=float, device=self.device)
        self.place = wp.empty((slots, cells), dtype=wp.int32, device=self.device)
        self.heap_f = wp.empty((slots, cells), dtype=float, device=self.device)
        self.heap_cell = wp.empty((slots, cells), dtype=wp.int32, device=self.device)
        self.toward = wp.full((n, cells), -1, dtype=wp.int32, device=self.device)
        """(N, cells) each world's field: the next planning cell toward its goal (-1: none)."""
        self._goals = wp.zeros(n, dtype=wp.vec2, device=self.device)
        self._path = wp.zeros((n, cfg.max_points), dtype=wp.vec2, device=self.device)
        self._length = wp.zeros(n, dtype=wp.int32, device=self.device)
        self._cost = wp.zeros(n, dtype=float, device=self.device)
        self._world_map = grids.struct.world_map
        self.marks = self._marks(n, inscribed, obstacles)
        self.seen = wp.to_torch(self.marks.seen)
        """(N, slots) 1 where a world's costmap has marked the obstacle in that slot (the obstacle layer)."""
        self._stale = wp.zeros(n, dtype=wp.int32, device=self.device)
        self.goals = wp.to_torch(self._goals).view(n, 2)
        """(N, 2) each world's goal [m], as :meth:`set_goals` last set it."""
        self.path = wp.to_torch(self._path).view(n, cfg.max_points, 2)
        """(N, max_points, 2) each world's last path [m], start to goal, in its first :attr:`path_length` rows."""
        self.path_length = wp.to_torch(self._length)
        """(N,) points in each world's last path; 0: none was found."""
        self.path_cost = wp.to_torch(self._cost)
        """(N,) each last path's cost (NavFn's units: 50 for each free cell crossed)."""

    def _marks(self, n: int, inscribed: float, obstacles: ObstacleSet | None) -> PlanMarks:
        marks = PlanMarks()
        slots = obstacles.count if obstacles is not None else 0
        marks.active = int(self.cfg.obstacle_layer and slots > 0)
        marks.seen = wp.zeros((n, max(slots, 1)), dtype=wp.int32, device=self.device)
        marks.marked = wp.zeros(n, dtype=wp.int32, device=self.device)
        if obstacles is None:  # worlds without obstacle slots, as the simulator holds them
            from atrv_warp.sim.config import ArenaConfig
            from atrv_warp.sim.contact import Obstacles

            obstacles = Obstacles(None, n, ArenaConfig(), self.device).kernel
        marks.obstacles = obstacles
        marks.inscribed, marks.inflation_radius = inscribed, self.cfg.inflation_radius
        marks.cost_scaling_factor = self.cfg.cost_scaling_factor
        return marks

    def observe(self, body_q: wp.array, bodies_per_world: int, chassis: int, fov: float) -> None:
        """The obstacle layer marks what each world's laser (field of view ``fov`` [rad] about the chassis' heading)
        now sees, from the chassis poses in ``body_q``; nothing without the layer."""
        if self.marks.active:
            wp.launch(mark_seen, dim=self._length.shape[0], inputs=[body_q, bodies_per_world, chassis,
                                                                    float(self.cfg.obstacle_range), 0.5 * fov,
                                                                    self.marks, self._stale], device=self.device)

    def forget(self, worlds: torch.Tensor) -> None:
        """Clear the obstacle layer's marks of ``worlds`` ((N,) bool: a new episode's costmap has seen nothing)."""
        if self.marks.active:
            mask = worlds.to(self.seen.device).reshape(-1)
            self.seen[mask] = 0
            wp.to_torch(self.marks.marked)[mask] = 0
            wp.to_torch(self._stale)[mask] = 0

    def _pack(self) -> PlanMaps:
        s = PlanMaps()
        costs = [navfn_costs(c, self.cfg.allow_unknown) for c in self.costmaps] or [np.full((1, 1), -1.0, np.float32)]
        starts = np.concatenate([[0], np.cumsum([c.size for c in costs])[:-1]]).astype(np.int32)
        device = self.device
        s.cost = wp.array(np.concatenate([c.ravel() for c in costs]), dtype=float, device=device)
        s.start = wp.array(starts, dtype=wp.int32, device=device)
        s.rows = wp.array([c.shape[0] for c in costs], dtype=wp.int32, device=device)
        s.cols = wp.array([c.shape[1] for c in costs], dtype=wp.int32, device=device)
        s.resolution = wp.array(self.resolutions or [1.0], dtype=float, device=device)
        s.origin = wp.array([m.origin for m in self.grids.maps] or [(0.0, 0.0)], dtype=wp.vec2, device=device)
        return s

    def set_goals(self, worlds: Sequence[int] | torch.Tensor, goals: torch.Tensor, starts: torch.Tensor) -> None:
        """Compute the fields of ``worlds`` (indices) toward ``goals`` ((N, 2) [m], every world's; those of ``worlds``
        are read and kept in :attr:`goals`), each searched to :attr:`PlannerConfig.field_reach` times the cost of
        the path from its world's ``starts`` (N, 2), :attr:`PlannerConfig.slots` worlds at a time."""
        worlds = _indices(worlds)
        if not len(worlds):
            return
        index = worlds.long().to(self.goals.device)
        self.goals[index] = goals.detach().to(self.goals)[index]
        starts = self._points(starts)
        slots = self.g.shape[0]
        for first in range(0, len(worlds), slots):
            chunk = wp.array(worlds[first:first + slots].numpy(), dtype=wp.int32, device=self.device)
            wp.launch(goal_fields, dim=len(chunk), inputs=[self.struct, self._world_map, chunk, starts, self._goals,
                                                           float(self.cfg.field_reach), self.marks, self.g,
                                                           self.place, self.heap_f, self.heap_cell],
                      outputs=[self.toward], device=self.device)

    def replan(self, worlds: Sequence[int] | torch.Tensor, starts: torch.Tensor) -> None:
        """Each of ``worlds``' path from ``starts`` ((N, 2) [m], every world's) down its field to its goal; a world
        whose field does not reach its start is searched again from there."""
        worlds = _indices(worlds)
        if self.marks.active:  # a costmap that marked an obstacle since its field was searched: search it again
            stale = wp.to_torch(self._stale)
            index = worlds.long().to(stale.device)
            marked = worlds[stale[index].cpu() != 0]
            if len(marked):
                stale[marked.long().to(stale.device)] = 0
                self.set_goals(marked, self.goals, starts)
        self._follow(worlds, starts)
        lost = worlds[self.path_length[worlds.long().to(self.path_length.device)].cpu() == 0]
        if len(lost):  # strayed beyond its field's reach (or no path at all: searched again to say so)
            self.set_goals(lost, self.goals, starts)
            self._follow(lost, starts)

    def plan(self, worlds: Sequence[int] | torch.Tensor, starts: torch.Tensor, goals: torch.Tensor) -> None:
        """:meth:`set_goals`, then :meth:`replan` from ``starts``: each of ``worlds``' path; the others' are kept."""
        worlds = _indices(worlds)
        self.set_goals(worlds, goals, starts)
        self._follow(worlds, starts)

    def _points(self, xy: torch.Tensor) -> wp.array:
        return wp.from_torch(xy.detach().to(device=self.goals.device, dtype=torch.float32).contiguous(), dtype=wp.vec2)

    def _follow(self, worlds: torch.Tensor, starts: torch.Tensor) -> None:
        if not len(worlds):
            return
        chunk = wp.array(worlds.numpy(), dtype=wp.int32, device=self.device)
        wp.launch(follow_fields, dim=len(chunk), inputs=[self.struct, self._world_map, chunk, self._points(starts),
                                                         self._goals, self.toward, self.marks],
                  outputs=[self._path, self._length, self._cost], device=self.device)

    def points(self, world: int) -> np.ndarray:
        """(L, 2) world ``world``'s last path [m] (empty where none was found)."""
        return self.path[world, :int(self.path_length[world])].cpu().numpy()
