"""The simulated world as ``visualization_msgs/MarkerArray``, for RViz and Foxglove: the arena's walls,
each rover's obstacles, its goal and, on terrain, a coarse height-coloured mesh of its tile.

:func:`scene_of` snapshots what a rover's world holds (plain numpy); :func:`world_markers` turns the
snapshots into one message in the world frame. A rover whose snapshot holds a non-finite number is
left out of the message and named, so that the node logs it: no marker is ever published with a
non-finite pose. Imported only by :mod:`.node` (it needs ``visualization_msgs``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from atrv_warp.integrations.topdown import OBSTACLE_BOX, OBSTACLE_CYLINDER, terrain_colors

__all__ = ["TERRAIN_MAX_SIDE", "RoverScene", "scene_of", "world_markers"]

TERRAIN_MAX_SIDE = 41
"""A terrain tile is drawn from at most this many samples per side (a 0.75 m mesh on a 30 m tile)."""
_WALL = (0.47, 0.47, 0.51, 1.0)
_OBSTACLE = (0.78, 0.55, 0.16, 1.0)
_GOAL = (0.16, 0.35, 0.9, 0.6)


@dataclass(frozen=True)
class RoverScene:
    """What one rover's world holds, in the world frame [m]."""

    ns: str
    """Marker namespace prefix: ``""`` for a single rover, ``rover_<k>/`` for several."""
    kind: np.ndarray
    """(slots,) obstacle kinds (``topdown.OBSTACLE_BOX``, ``OBSTACLE_CYLINDER``; 0 empty)."""
    pose: np.ndarray
    """(slots, 3) obstacle x, y [m], yaw [rad]."""
    size: np.ndarray
    """(slots, 2) box half extents or cylinder (radius, -) [m]."""
    obstacle_z: tuple[float, float]
    """Obstacles' bottom and top [m]."""
    heights: np.ndarray | None
    """(n, n) terrain heights [m] over the tile, or ``None`` on flat ground."""
    terrain_half: float
    """Half side of the terrain tile [m]."""
    terrain_base: float
    """Height of the tile's zero [m]."""
    goal: tuple[float, float] | None
    goal_radius: float
    """Radius of the goal disc [m] (the node's ``reach_radius``)."""
    ground_top: float

    def ground_at(self, x: float, y: float) -> float:
        """Height of the ground [m] at (x, y): the nearest terrain sample, or the flat ground's top."""
        if self.heights is None:
            return self.ground_top
        n = self.heights.shape[0]
        i, j = (int(np.clip(round((v + self.terrain_half) / (2 * self.terrain_half) * (n - 1)), 0, n - 1)) for v in (x, y))
        return self.terrain_base + float(self.heights[i, j])

    def finite(self) -> bool:
        """Every number that places a marker is finite."""
        parts = [self.pose, self.size, np.asarray(self.obstacle_z)]
        if self.heights is not None:
            parts.append(self.heights)
        if self.goal is not None:
            parts.append(np.asarray(self.goal))
        return all(bool(np.isfinite(p).all()) for p in parts)


def scene_of(sim, k: int, *, ns: str, goal: tuple[float, float] | None, goal_radius: float) -> RoverScene:
    """World ``k`` of a :class:`~atrv_warp.sim.RoverSim` as a :class:`RoverScene`."""
    obstacles, terrain = sim.obstacles, sim.terrain
    if obstacles.slots:
        kind, pose, size = (t[k].detach().cpu().numpy().copy() for t in (obstacles.kind, obstacles.pose,
                                                                          obstacles.size))
        z = (terrain.base - 0.5, float(obstacles.kernel.top))
    else:
        kind, pose, size, z = np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 2)), (0.0, 0.0)
    heights = terrain.grid.heights[int(terrain.tile[k])] if terrain.enabled else None
    return RoverScene(ns, kind, pose, size, z, heights, terrain.grid.half_size if terrain.enabled else 0.0,
                      terrain.base, goal, goal_radius, sim.arena_cfg.ground_top)


def _marker(ns: str, mid: int, kind: int, frame: str, stamp, color, *, xyz=(0.0, 0.0, 0.0), yaw: float = 0.0,
            scale=(1.0, 1.0, 1.0)) -> Marker:
    m = Marker()
    m.header.frame_id, m.header.stamp = frame, stamp
    m.ns, m.id, m.type, m.action = ns, mid, kind, Marker.ADD
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in xyz)
    m.pose.orientation.z, m.pose.orientation.w = math.sin(0.5 * yaw), math.cos(0.5 * yaw)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
    m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    return m


def _terrain(scene: RoverScene, frame: str, stamp) -> Marker:
    """The tile as a TRIANGLE_LIST, each vertex coloured by its height (the Rerun recorder's colours)."""
    n0 = scene.heights.shape[0]
    step = max(1, math.ceil((n0 - 1) / (TERRAIN_MAX_SIDE - 1)))
    h = scene.heights[::step, ::step]
    n = h.shape[0]
    axis = np.linspace(-scene.terrain_half, scene.terrain_half, n0)[::step]
    x, y = np.meshgrid(axis, axis, indexing="ij")
    vertices = np.stack([x, y, scene.terrain_base + h], -1).reshape(-1, 3)
    colors = terrain_colors(h).reshape(-1, 3) / 255.0
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).reshape(-1)
    tris = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)]).reshape(-1)
    m = _marker(f"{scene.ns}terrain", 0, Marker.TRIANGLE_LIST, frame, stamp, (1.0, 1.0, 1.0, 1.0))
    m.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in vertices[tris]]
    m.colors = [ColorRGBA(r=float(c[0]), g=float(c[1]), b=float(c[2]), a=1.0) for c in colors[tris]]
    return m


def world_markers(arena, scenes: list[RoverScene], frame: str, stamp) -> tuple[MarkerArray, list[str]]:
    """Walls (namespace ``arena``), then per rover its obstacles (``<ns>obstacles``), goal (``<ns>goal``)
    and terrain (``<ns>terrain``), all in ``frame``; the message starts with a DELETEALL, so that a
    latched array replaces the last one whole. Returns the message and the namespaces of the rovers
    left out because their snapshot holds a non-finite number."""
    out = MarkerArray()
    clear = Marker()
    clear.header.frame_id, clear.header.stamp, clear.action = frame, stamp, Marker.DELETEALL
    out.markers.append(clear)
    for i, (_, centre, half) in enumerate(arena.boxes()[1:]):
        out.markers.append(_marker("arena", i, Marker.CUBE, frame, stamp, _WALL, xyz=centre,
                                   scale=[2 * v for v in half]))
    skipped = []
    for scene in scenes:
        if not scene.finite():
            skipped.append(scene.ns or "rover")
            continue
        bottom, top = scene.obstacle_z
        zc, height = 0.5 * (bottom + top), top - bottom
        for i, (kind, (x, y, yaw), (a, b)) in enumerate(zip(scene.kind, scene.pose, scene.size)):
            if kind == OBSTACLE_BOX:
                out.markers.append(_marker(f"{scene.ns}obstacles", i, Marker.CUBE, frame, stamp, _OBSTACLE,
                                           xyz=(x, y, zc), yaw=float(yaw), scale=(2 * a, 2 * b, height)))
            elif kind == OBSTACLE_CYLINDER:
                out.markers.append(_marker(f"{scene.ns}obstacles", i, Marker.CYLINDER, frame, stamp, _OBSTACLE,
                                           xyz=(x, y, zc), scale=(2 * a, 2 * a, height)))
        if scene.goal is not None:
            d = 2 * scene.goal_radius
            out.markers.append(_marker(f"{scene.ns}goal", 0, Marker.CYLINDER, frame, stamp, _GOAL,
                                       xyz=(*scene.goal, scene.ground_at(*scene.goal) + 0.02), scale=(d, d, 0.04)))
        if scene.heights is not None:
            out.markers.append(_terrain(scene, frame, stamp))
    return out, skipped
