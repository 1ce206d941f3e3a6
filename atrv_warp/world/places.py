"""Procedural places to train in, as Nav2 maps: buildings (rooms, corridors, doorways, furniture) and yards (trees,
fences with gates, sheds), each drawn from a seed and sized for a robot.

    from atrv_warp.world.places import building, yard
    site = building(seed=3, robot_width=0.6)         # an OccupancyMap, as load_map would give it
    save_map(site, "building_3.yaml")                # what map_saver_cli would have written of it

Sizes follow the robot: a doorway or a gate is 1.5 to 3 times ``robot_width`` wide (the robot issue's rule: what
the robot can just pass and what it passes easily), a room at least :data:`MIN_ROOM` and four robot widths a side, a
corridor 2.5 to 4 robot widths. A building is walled all round with every room reached through doorways (a split
wall gets one, so the rooms hang on one tree); furniture keeps clear of doorways. Outside the building, and beyond a
yard's fence line, lies unknown space, as a saved map has it. Same seed, same place.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from atrv_warp.world.nav2_map import FREE, OCCUPIED, UNKNOWN, MapError, OccupancyMap, load_map

__all__ = ["DOOR_WIDTHS", "MIN_ROOM", "PLACES", "WALL", "Door", "building", "draw_building", "draw_yard", "place",
           "place_entry", "read_map_files", "resolve_sites", "yard"]

MIN_ROOM = 3.0
"""The least side of a building's room [m] (or four robot widths, whichever is more)."""
DOOR_WIDTHS = (1.5, 3.0)
"""A doorway's or a gate's width, in robot widths."""
WALL = 0.15
"""A building's walls and a yard's fences: their thickness [m]."""


@dataclass(frozen=True)
class Door:
    """A doorway or a gate: its centre (x, y) [m], its width [m], and whether its wall runs along x."""

    x: float
    y: float
    width: float
    along_x: bool


class _Canvas:
    """A grid drawn in metres (origin at the lower-left corner), as OccupancyGrid values."""

    def __init__(self, width: float, height: float, resolution: float, fill: int):
        self.res = resolution
        self.cells = np.full((round(height / resolution), round(width / resolution)), fill, dtype=np.int8)

    def box(self, x0: float, y0: float, x1: float, y1: float, value: int) -> None:
        r = self.res
        rows, cols = self.cells.shape
        c0, c1 = max(0, round(min(x0, x1) / r)), min(cols, max(round(max(x0, x1) / r), round(min(x0, x1) / r) + 1))
        r0, r1 = max(0, round(min(y0, y1) / r)), min(rows, max(round(max(y0, y1) / r), round(min(y0, y1) / r) + 1))
        self.cells[r0:r1, c0:c1] = value

    def disc(self, x: float, y: float, radius: float, value: int) -> None:
        rows, cols = self.cells.shape
        yy, xx = np.mgrid[0:rows, 0:cols]
        inside = ((xx + 0.5) * self.res - x) ** 2 + ((yy + 0.5) * self.res - y) ** 2 <= radius ** 2
        self.cells[inside] = value

    def site(self, origin: tuple[float, float], label: str) -> OccupancyMap:
        digest = hashlib.sha256(self.cells.tobytes() + repr((self.cells.shape, self.res, origin)).encode()).hexdigest()
        return OccupancyMap(cells=self.cells, resolution=self.res, origin=origin, digest=digest, label=label)


def _door_width(rng: np.random.Generator, robot_width: float) -> float:
    return float(rng.uniform(*DOOR_WIDTHS)) * robot_width


def _split(rng, canvas: _Canvas, room: tuple, robot_width: float, min_room: float, doors: list, rooms: list,
           depth: int = 0) -> None:
    """Split ``room`` (x0, y0, x1, y1) [m] by a wall with one doorway (or two walls and a corridor between, each with
    a doorway), then each part, until a part is too small to split; the leaves go to ``rooms``."""
    x0, y0, x1, y1 = room
    along_x = (y1 - y0) > (x1 - x0)  # split the longer side: the new wall runs along x
    span = (y1 - y0) if along_x else (x1 - x0)
    corridor = float(rng.uniform(2.5, 4.0)) * robot_width if rng.random() < 0.3 and depth < 2 else 0.0
    if span < 2 * min_room + corridor or depth >= 5:
        rooms.append(room)
        return
    low = y0 if along_x else x0
    for _ in range(16):  # a cut whose walls meet no doorway in the room's own walls
        at = float(rng.uniform(min_room, span - min_room - corridor))
        cuts = [at, at + corridor] if corridor else [at]
        if not any(_blocks(d, room, along_x, low + cut, robot_width) for d in doors for cut in cuts):
            break
    else:
        rooms.append(room)
        return
    length = (x1 - x0) if along_x else (y1 - y0)
    for cut in cuts:
        width = min(_door_width(rng, robot_width), length - 4 * WALL)
        centre = float(rng.uniform(width / 2 + 2 * WALL, length - width / 2 - 2 * WALL))
        if along_x:
            y = y0 + cut
            canvas.box(x0, y - WALL / 2, x1, y + WALL / 2, OCCUPIED)
            canvas.box(x0 + centre - width / 2, y - WALL, x0 + centre + width / 2, y + WALL, FREE)
            doors.append(Door(x0 + centre, y, width, True))
        else:
            x = x0 + cut
            canvas.box(x - WALL / 2, y0, x + WALL / 2, y1, OCCUPIED)
            canvas.box(x - WALL, y0 + centre - width / 2, x + WALL, y0 + centre + width / 2, FREE)
            doors.append(Door(x, y0 + centre, width, False))
    first = (x0, y0, x1, low + at) if along_x else (x0, y0, low + at, y1)
    last = (x0, low + cuts[-1], x1, y1) if along_x else (low + cuts[-1], y0, x1, y1)
    _split(rng, canvas, first, robot_width, min_room, doors, rooms, depth + 1)
    if corridor:
        rooms.append((x0, low + at, x1, low + cuts[-1]) if along_x else (low + at, y0, low + cuts[-1], y1))
    _split(rng, canvas, last, robot_width, min_room, doors, rooms, depth + 1)


def _blocks(door: Door, room: tuple, along_x: bool, at: float, robot_width: float) -> bool:
    """Whether a wall across ``room`` at ``at`` (a y where it runs along x, else an x) would meet ``door`` in one of
    the room's side walls, or come within a robot width of it."""
    x0, y0, x1, y1 = room
    if door.along_x == along_x:
        return False
    side, position = (door.x, door.y) if along_x else (door.y, door.x)
    ends = (x0, x1) if along_x else (y0, y1)
    on_side = min(abs(side - e) for e in ends) <= WALL
    return on_side and abs(position - at) <= door.width / 2 + robot_width + WALL


def _clear_of(doors: list[Door], x: float, y: float, radius: float) -> bool:
    return all(np.hypot(d.x - x, d.y - y) > radius + d.width for d in doors)


def building(seed: int, robot_width: float, **settings) -> OccupancyMap:
    """:func:`draw_building`'s map."""
    return draw_building(seed, robot_width, **settings)[0]


def yard(seed: int, robot_width: float, **settings) -> OccupancyMap:
    """:func:`draw_yard`'s map."""
    return draw_yard(seed, robot_width, **settings)[0]


def draw_building(seed: int, robot_width: float, *, size: tuple[float, float] | None = None,
                  resolution: float = 0.1, furniture: int = 3) -> tuple[OccupancyMap, list[Door]]:
    """A building drawn from ``seed`` for a robot ``robot_width`` [m] wide: outer walls, rooms split off by walls
    with doorways (some by a corridor), up to ``furniture`` pieces in each room (tables and shelves, clear of the
    doorways), unknown space 1 m around; ``size`` (width, height) [m], default drawn from 14 to 24 m a side. The map's
    origin is placed so that its middle is at (0, 0). Returns the map and its doorways (in the map's frame)."""
    rng = np.random.default_rng([int(seed), 0xB1D])
    width, height = size or (float(rng.uniform(14.0, 24.0)), float(rng.uniform(14.0, 24.0)))
    margin = 1.0
    canvas = _Canvas(width + 2 * margin, height + 2 * margin, resolution, UNKNOWN)
    canvas.box(margin, margin, margin + width, margin + height, FREE)
    for x0, y0, x1, y1 in ((0, 0, width, 0), (0, height, width, height), (0, 0, 0, height), (width, 0, width, height)):
        canvas.box(margin + x0 - WALL / 2, margin + y0 - WALL / 2, margin + x1 + WALL / 2, margin + y1 + WALL / 2,
                   OCCUPIED)
    doors: list[Door] = []
    rooms: list[tuple] = []
    _split(rng, canvas, (margin, margin, margin + width, margin + height), robot_width,
           max(MIN_ROOM, 4 * robot_width), doors, rooms)
    for x0, y0, x1, y1 in rooms:
        for _ in range(int(rng.integers(0, furniture + 1))):
            w, d = float(rng.uniform(0.4, 1.6)), float(rng.uniform(0.4, 1.0))
            if rng.random() < 0.5:
                w, d = d, w
            if x1 - x0 < w + 2 * robot_width or y1 - y0 < d + 2 * robot_width:
                continue
            cx, cy = float(rng.uniform(x0 + w / 2 + WALL, x1 - w / 2 - WALL)), float(
                rng.uniform(y0 + d / 2 + WALL, y1 - d / 2 - WALL))
            if _clear_of(doors, cx, cy, max(w, d) / 2 + 1.5 * robot_width):
                canvas.box(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2, OCCUPIED)
    return _placed(canvas, doors, f"building_{seed}")


def draw_yard(seed: int, robot_width: float, *, size: tuple[float, float] | None = None, resolution: float = 0.1,
              trees: int = 12, sheds: int = 2) -> tuple[OccupancyMap, list[Door]]:
    """A yard drawn from ``seed`` for a robot ``robot_width`` [m] wide: a fence all round and one across it, each with
    gates; ``sheds`` sheds (walled, a door each) and ``trees`` trees (trunks 0.15 to 0.4 m in radius) clear of the
    gates; unknown space 1 m beyond the fence; ``size`` default drawn from 18 to 30 m a side. Origin as
    :func:`draw_building`'s. Returns the map and its gates and shed doors."""
    rng = np.random.default_rng([int(seed), 0x7A4D])
    width, height = size or (float(rng.uniform(18.0, 30.0)), float(rng.uniform(18.0, 30.0)))
    margin = 1.0
    canvas = _Canvas(width + 2 * margin, height + 2 * margin, resolution, UNKNOWN)
    canvas.box(margin, margin, margin + width, margin + height, FREE)
    gates: list[Door] = []
    fences = [((0, 0), (width, 0)), ((0, height), (width, height)), ((0, 0), (0, height)),
              ((width, 0), (width, height))]
    across = float(rng.uniform(0.35, 0.65))
    fences.append(((across * width, 0), (across * width, height)))  # one fence across, with two gates
    for k, ((ax, ay), (bx, by)) in enumerate(fences):
        canvas.box(margin + ax - WALL / 2, margin + ay - WALL / 2, margin + bx + WALL / 2, margin + by + WALL / 2,
                   OCCUPIED)
        if k < 4:
            continue  # the outer fence stays shut: the yard is the site
        along_x = ay == by
        length = (bx - ax) if along_x else (by - ay)
        for part in (0.25, 0.75):
            gate = _door_width(rng, robot_width)
            centre = float(rng.uniform(part - 0.15, part + 0.15)) * length
            x, y = (margin + ax + centre, margin + ay) if along_x else (margin + ax, margin + ay + centre)
            if along_x:
                canvas.box(x - gate / 2, y - WALL, x + gate / 2, y + WALL, FREE)
            else:
                canvas.box(x - WALL, y - gate / 2, x + WALL, y + gate / 2, FREE)
            gates.append(Door(x, y, gate, along_x))
    for _ in range(sheds):
        w, d = float(rng.uniform(2.0, 4.0)), float(rng.uniform(2.0, 4.0))
        cx = float(rng.uniform(margin + w / 2 + 1.0, margin + width - w / 2 - 1.0))
        cy = float(rng.uniform(margin + d / 2 + 1.0, margin + height - d / 2 - 1.0))
        if not _clear_of(gates, cx, cy, max(w, d) / 2 + 2 * robot_width):
            continue
        canvas.box(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2, OCCUPIED)
        canvas.box(cx - w / 2 + WALL, cy - d / 2 + WALL, cx + w / 2 - WALL, cy + d / 2 - WALL, FREE)
        door = min(_door_width(rng, robot_width), w - 4 * WALL)
        canvas.box(cx - door / 2, cy - d / 2 - WALL, cx + door / 2, cy - d / 2 + 2 * WALL, FREE)
        gates.append(Door(cx, cy - d / 2 + WALL / 2, door, True))  # the middle of its wall
    for _ in range(trees):
        r = float(rng.uniform(0.15, 0.4))
        x = float(rng.uniform(margin + 1.0, margin + width - 1.0))
        y = float(rng.uniform(margin + 1.0, margin + height - 1.0))
        if _clear_of(gates, x, y, r + 1.5 * robot_width):
            canvas.disc(x, y, r, OCCUPIED)
    return _placed(canvas, gates, f"yard_{seed}")


def _placed(canvas: _Canvas, doors: list[Door], label: str) -> tuple[OccupancyMap, list[Door]]:
    """The canvas as a map centred on (0, 0), and its doors moved with it."""
    rows, cols = canvas.cells.shape
    ox, oy = -cols * canvas.res / 2, -rows * canvas.res / 2
    return canvas.site((ox, oy), label), [Door(d.x + ox, d.y + oy, d.width, d.along_x) for d in doors]


PLACES = {"building": building, "yard": yard}
"""The procedural places by name."""


def place(kind: str, seed: int, robot_width: float, **settings) -> OccupancyMap:
    """:data:`PLACES`'s ``kind`` drawn from ``seed`` (``ValueError`` naming the known kinds for another)."""
    if kind not in PLACES:
        raise ValueError(f"unknown place {kind!r}; known: {', '.join(PLACES)}")
    return PLACES[kind](seed, robot_width, **settings)


SPEC = re.compile(r"^(?P<kind>[a-z_]+):(?P<count>\d+)(@(?P<seed>\d+))?$")
"""A procedural entry in a list of sites: ``KIND:COUNT`` (seeds 0 to COUNT - 1) or ``KIND:COUNT@FIRST`` (seeds FIRST
on: places never trained on, for an evaluation)."""


def place_entry(entry: OccupancyMap | str | Path) -> re.Match | None:
    """The procedural entry ``entry`` is (:data:`SPEC`'s match), or ``None`` for a map: an
    :class:`~atrv_warp.world.OccupancyMap`, or a file (a file named like a place is read as the file)."""
    if isinstance(entry, OccupancyMap):
        return None
    spec = SPEC.match(str(entry))
    return None if spec is None or Path(entry).exists() else spec


def read_map_files(entries: Sequence[OccupancyMap | str | Path]) -> list:
    """Each entry that is a map's file read now (a bad one a :class:`~atrv_warp.world.MapError` naming it), the
    others kept: what a command checks before it builds a simulator, which draws the places for its robot."""
    return [entry if isinstance(entry, OccupancyMap) or place_entry(entry) is not None else load_map(entry)
            for entry in entries]


def resolve_sites(entries: Sequence[OccupancyMap | str | Path], robot_width: float) -> list[OccupancyMap]:
    """Each entry as maps: a map as it is, a ``map_server`` YAML read (:func:`~atrv_warp.world.load_map`), a
    procedural entry (:data:`SPEC`: ``building:64``, ``yard:10@1000``) drawn for a robot ``robot_width`` [m] wide.

    Raises:
        MapError: A map that does not read, or an entry that is neither a file nor a procedural one (named).
    """
    sites: list[OccupancyMap] = []
    for entry in entries:
        spec = place_entry(entry)
        if spec is None:
            sites.append(entry if isinstance(entry, OccupancyMap) else load_map(entry))
            continue
        if spec["kind"] not in PLACES:
            raise MapError(f"map {entry}: unknown place {spec['kind']!r} (known: {', '.join(PLACES)}) and no such file")
        first, count = int(spec["seed"] or 0), int(spec["count"])
        if count < 1:
            raise MapError(f"map {entry}: at least one place, got {count}")
        sites += [place(spec["kind"], seed, robot_width) for seed in range(first, first + count)]
    return sites
