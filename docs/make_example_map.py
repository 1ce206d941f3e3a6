"""The docs' example map, an office floor as ``map_saver_cli`` writes one: ``python docs/make_example_map.py``.

Writes ``atrv_warp/assets/maps/office.yaml`` and its ``office.pgm`` (trinary, 0.05 m a cell, Nav2's thresholds;
:func:`atrv_warp.world.save_map`). The floor is laid out by hand here, not by the procedural places a run trains in
(:mod:`atrv_warp.world.places`), so that a policy evaluated on it has never seen it: a 24 m x 16 m floor, a corridor
2 m wide along it, four offices north of it behind doorways 1.2 to 1.6 m wide, an open-plan area south with desks and
two pillars, a meeting room and a store room, unknown space around the walls. Same output for the same script: the
map's sha256 is in every results file that drives in it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "atrv_warp" / "assets" / "maps" / "office.yaml"
RESOLUTION = 0.05
SIZE = (24.0, 16.0)  # the floor inside its outer walls [m]
MARGIN = 1.0  # unknown space around it [m]
WALL = 0.15  # wall thickness [m]


def office() -> object:
    """The floor as an :class:`~atrv_warp.world.OccupancyMap`, its middle at (0, 0)."""
    from atrv_warp.world import OccupancyMap
    from atrv_warp.world.nav2_map import FREE, OCCUPIED, UNKNOWN

    width, height = SIZE
    cols, rows = round((width + 2 * MARGIN) / RESOLUTION), round((height + 2 * MARGIN) / RESOLUTION)
    cells = np.full((rows, cols), UNKNOWN, dtype=np.int8)

    def box(x0, y0, x1, y1, value):  # floor coordinates [m], (0, 0) the inner corner of the outer walls
        c0, c1 = round((x0 + MARGIN) / RESOLUTION), round((x1 + MARGIN) / RESOLUTION)
        r0, r1 = round((y0 + MARGIN) / RESOLUTION), round((y1 + MARGIN) / RESOLUTION)
        cells[max(r0, 0):r1, max(c0, 0):c1] = value

    def wall_x(y, x0, x1, doors=()):  # a wall along x at y, doorways (centre, width) left open
        box(x0, y - WALL / 2, x1, y + WALL / 2, OCCUPIED)
        for centre, w in doors:
            box(centre - w / 2, y - WALL / 2, centre + w / 2, y + WALL / 2, FREE)

    def wall_y(x, y0, y1, doors=()):
        box(x - WALL / 2, y0, x + WALL / 2, y1, OCCUPIED)
        for centre, w in doors:
            box(x - WALL / 2, centre - w / 2, x + WALL / 2, centre + w / 2, FREE)

    box(0.0, 0.0, width, height, FREE)
    for y in (0.0, height):
        wall_x(y, -WALL, width + WALL)
    for x in (0.0, width):
        wall_y(x, -WALL, height + WALL)
    # the corridor y in [7, 9]; offices north of it, doorways into it
    wall_x(9.0, 0.0, width, doors=((2.0, 1.2), (9.5, 1.4), (14.5, 1.2), (21.0, 1.6)))
    for x in (6.0, 12.0, 17.5):
        wall_y(x, 9.0, height)
    # south: the open-plan area (x < 14) through a wide opening, a meeting room and a store room
    wall_x(7.0, 0.0, width, doors=((4.0, 3.0), (11.0, 2.0), (16.0, 1.4), (21.5, 1.2)))
    wall_y(14.0, 0.0, 7.0)
    wall_y(19.0, 0.0, 7.0)
    # furniture: desks in the offices, rows of desks and pillars in the open plan, a table, shelves
    for x0, y0, x1, y1 in ((0.4, 14.6, 2.4, 15.6), (3.6, 10.0, 5.6, 11.0),  # office 1
                           (6.4, 14.4, 8.4, 15.6), (10.6, 12.0, 11.6, 14.0),  # office 2
                           (12.4, 14.8, 15.0, 15.6), (15.8, 10.2, 17.1, 11.4),  # office 3
                           (17.9, 13.6, 19.9, 15.6), (22.0, 11.0, 23.6, 12.0),  # office 4
                           (1.5, 1.5, 4.5, 2.3), (1.5, 4.0, 4.5, 4.8), (7.0, 1.5, 10.0, 2.3), (7.0, 4.0, 10.0, 4.8),
                           (12.3, 0.3, 13.6, 3.0),  # open plan: desks, a cabinet
                           (15.5, 2.6, 17.5, 4.2),  # the meeting room's table
                           (19.3, 0.3, 23.7, 0.9), (23.1, 2.0, 23.7, 5.5)):  # the store room's shelves
        box(x0, y0, x1, y1, OCCUPIED)
    for x, y in ((6.0, 3.2), (11.0, 3.2)):  # pillars, 0.4 m square
        box(x - 0.2, y - 0.2, x + 0.2, y + 0.2, OCCUPIED)
    origin = (-width / 2 - MARGIN, -height / 2 - MARGIN)
    return OccupancyMap(cells=cells, resolution=RESOLUTION, origin=origin)


def main() -> int:
    from atrv_warp.world import load_map, save_map

    OUT.parent.mkdir(parents=True, exist_ok=True)
    save_map(office(), OUT)
    site = load_map(OUT)
    print(f"wrote {OUT} ({site.shape[1]} x {site.shape[0]} cells at {site.resolution} m, sha256 {site.digest[:16]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
