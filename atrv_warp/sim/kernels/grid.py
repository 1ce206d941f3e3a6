"""Walls from an occupancy grid in kernels: each map's distance field, and a laser beam cast against the grid.

A map (:class:`atrv_warp.world.OccupancyMap`) is a grid of square cells, each a wall or free; walls stand from the
ground to ``GridMaps.top``. A beam is cast by :func:`ray_grid`: far from every wall it leaps ahead by the distance
field (sphere tracing: the nearest wall is at least that far, so nothing is skipped), near one it walks cell by cell
(Amanatides and Woo's DDA), so the range it returns is where the ray enters the first wall cell, exact to rounding,
at the cost of a few cells per beam instead of one per cell along its whole length.

The distance field (:func:`distance_field`) is the exact Euclidean distance transform of the wall cells (Felzenszwalb
and Huttenlocher's lower envelope of parabolas, a row pass and then a column pass, one thread per line), in cells from
each cell's centre to the nearest wall cell's centre, the space outside the map counting as wall.
"""

from __future__ import annotations

import warp as wp

ENVELOPE_BOUND = wp.constant(wp.float64(1.0e12))
"""Beyond every boundary between the column pass's parabolas (their squares reach 4096^2 cells^2)."""
SKIP_MARGIN = wp.constant(1.5)
"""Cells kept back from a distance field's leap: a point anywhere in a cell is at most half a diagonal (0.71 cells)
from the centre the field measures from, and the wall cell's side is at most another 0.71 cells nearer than its centre
(1.5 > 1.42)."""
MIN_LEAP = wp.constant(2.0)
"""Cells of guaranteed free space below which a beam walks cell by cell instead of leaping."""
WALK_CELLS = wp.constant(4)
"""Cells a beam walks before it asks the distance field again."""


@wp.struct
class GridMaps:
    """Every map the worlds use, packed one after another, and each world's map (see the module's docstring)."""

    count: int  # maps (0: no map in any world)
    wall: wp.array(dtype=wp.uint8)  # every map's cells, row-major, row 0 at the map's origin: 1 wall, 0 free
    distance: wp.array(dtype=float)  # beside ``wall``: each cell's distance field [cells]
    start: wp.array(dtype=wp.int32)  # (M,) index of each map's first cell
    rows: wp.array(dtype=wp.int32)  # (M,)
    cols: wp.array(dtype=wp.int32)  # (M,)
    resolution: wp.array(dtype=float)  # (M,) [m per cell]
    origin: wp.array(dtype=wp.vec2)  # (M,) the lower-left cell's outer corner (x, y) [m]
    world_map: wp.array(dtype=wp.int32)  # (N,) each world's map, or -1 for none
    top: float  # height of every wall's top [m], absolute
    # where an episode may start or end: every map's cells clear of the robot at any heading, map by map and, within a
    # map, in groups the robot can drive between (``atrv_warp.sim.maps.spawn_cells``)
    spawn: wp.array(dtype=wp.int32)  # each such cell's index within its map (row * cols + col)
    spawn_start: wp.array(dtype=wp.int32)  # (M,) each map's first entry in ``spawn``
    spawn_count: wp.array(dtype=wp.int32)  # (M,) each map's entries
    spawn_group: wp.array(dtype=wp.int32)  # beside ``spawn``: the first entry of the cell's group
    spawn_group_count: wp.array(dtype=wp.int32)  # beside ``spawn``: the entries of the cell's group


@wp.func
def is_wall(grids: GridMaps, m: int, row: int, col: int) -> bool:
    """A wall cell, or a cell outside the map (what lies beyond a map is unknown, and unknown is a wall)."""
    if row < 0 or col < 0 or row >= grids.rows[m] or col >= grids.cols[m]:
        return True
    return grids.wall[grids.start[m] + row * grids.cols[m] + col] != wp.uint8(0)


@wp.func
def cell_at(grids: GridMaps, m: int, p: wp.vec2):
    """The (row, col) of map ``m``'s cell that holds ``p`` [m] (off the map: out of range)."""
    res = grids.resolution[m]
    o2 = grids.origin[m]
    return int(wp.floor((p[1] - o2[1]) / res)), int(wp.floor((p[0] - o2[0]) / res))


@wp.func
def wall_distance(grids: GridMaps, m: int, p: wp.vec2) -> float:
    """How far ``p`` [m] is from the nearest wall cell of map ``m`` [m], to within a cell: the distance field at
    ``p``'s cell less half a cell (centre to centre, less the wall cell's half width); 0 in a wall or off the map."""
    row, col = cell_at(grids, m, p)
    if is_wall(grids, m, row, col):
        return 0.0
    return (grids.distance[grids.start[m] + row * grids.cols[m] + col] - 0.5) * grids.resolution[m]


@wp.func
def spawn_point(grids: GridMaps, m: int, entry: int) -> wp.vec2:
    """The centre [m] of map ``m``'s cell at ``entry`` of ``grids.spawn``."""
    cell = grids.spawn[entry]
    cols = grids.cols[m]
    res = grids.resolution[m]
    return grids.origin[m] + wp.vec2((float(cell % cols) + 0.5) * res, (float(cell / cols) + 0.5) * res)


@wp.func
def first_crossing(t: float, position: float, cell: int, d: float, res: float):
    """Along one axis of a ray at ``t`` [m], at ``position`` [cells] in cell ``cell``, moving ``d`` [m per m along
    the ray]: (the cell step, -1 or 1; the t of the next cell boundary; the t between boundaries), the t never for
    an axis the ray does not move along."""
    if d > 0.0:
        return 1, t + (float(cell + 1) - position) * res / d, res / d
    if d < 0.0:
        return -1, t + (float(cell) - position) * res / d, -res / d
    return 1, float(1.0e30), float(1.0e30)


@wp.func
def ray_grid(grids: GridMaps, m: int, origin: wp.vec3, direction: wp.vec3, t_max: float) -> float:
    """Distance [m] along a unit ray from ``origin`` to the first wall cell of map ``m`` it enters, or ``t_max``;
    0 from inside a wall; a hit above the walls' top misses."""
    res = grids.resolution[m]
    o2 = grids.origin[m]
    dx = direction[0]
    dy = direction[1]
    planar = wp.sqrt(dx * dx + dy * dy)  # horizontal metres per metre along the ray
    t = float(0.0)
    hit = float(-1.0)
    # each pass either leaps (the field's free space is at least MIN_LEAP cells) or walks WALK_CELLS cells: a bound
    # on the passes that no beam within t_max reaches keeps a malformed field from looping
    passes = int(t_max * planar / res) + 8
    for _pass in range(passes):
        if t >= t_max or hit >= 0.0:
            break
        u = (origin[0] + t * dx - o2[0]) / res  # the ray's point in cells
        v = (origin[1] + t * dy - o2[1]) / res
        col = int(wp.floor(u))
        row = int(wp.floor(v))
        if is_wall(grids, m, row, col):
            hit = t
            break
        if planar < 1.0e-9:  # straight up or down: it meets no wall
            break
        free = grids.distance[grids.start[m] + row * grids.cols[m] + col] - SKIP_MARGIN
        if free >= MIN_LEAP:
            t = t + free * res / planar
            continue
        # walk: the t at which the ray crosses the next column's and the next row's boundary, and their spacing
        step_c, next_c, delta_c = first_crossing(t, u, col, dx, res)
        step_r, next_r, delta_r = first_crossing(t, v, row, dy, res)
        for _cell in range(WALK_CELLS):
            if next_c < next_r:
                col = col + step_c
                t = next_c
                next_c = next_c + delta_c
            else:
                row = row + step_r
                t = next_r
                next_r = next_r + delta_r
            if t >= t_max:
                break
            if is_wall(grids, m, row, col):
                hit = t
                break
    if hit < 0.0 or hit >= t_max:
        return t_max
    if origin[2] + hit * direction[2] > grids.top:
        return t_max
    return hit


@wp.kernel
def distance_rows(wall: wp.array2d(dtype=wp.uint8), across: wp.array2d(dtype=float)):
    """One thread per row: each cell's distance [cells] to the nearest wall in its row, the space beyond the row's
    ends counting as wall."""
    row = wp.tid()
    cols = wall.shape[1]
    last = int(-1)  # the nearest wall on the left (the border at -1)
    for col in range(cols):
        if wall[row, col] != wp.uint8(0):
            last = col
        across[row, col] = float(col - last)
    last = cols  # on the right (the border at cols)
    for k in range(cols):
        col = cols - 1 - k
        if wall[row, col] != wp.uint8(0):
            last = col
        across[row, col] = wp.min(across[row, col], float(last - col))


@wp.kernel
def distance_columns(across: wp.array2d(dtype=float), apex: wp.array2d(dtype=wp.int32),
                     bound: wp.array2d(dtype=wp.float64), distance: wp.array2d(dtype=float)):
    """One thread per column: the exact Euclidean distance [cells] to the nearest wall, from the row pass's distances
    (the lower envelope of the parabolas ``(r - q)^2 + across[q]^2``, in float64 so that the envelope's boundaries
    are exact; ``apex`` and ``bound`` are this column's scratch: the envelope's parabolas and where each begins), the
    space beyond the column's ends counting as wall."""
    col = wp.tid()
    rows = across.shape[0]
    k = int(0)
    apex[col, 0] = 0
    bound[col, 0] = -ENVELOPE_BOUND
    bound[col, 1] = ENVELOPE_BOUND
    for q in range(1, rows):
        fq = wp.float64(across[q, col]) * wp.float64(across[q, col]) + wp.float64(q * q)
        p = apex[col, k]
        fp = wp.float64(across[p, col]) * wp.float64(across[p, col]) + wp.float64(p * p)
        s = (fq - fp) / wp.float64(2 * (q - p))
        while s <= bound[col, k]:  # bound[col, 0] is below every s: k stays >= 0
            k = k - 1
            p = apex[col, k]
            fp = wp.float64(across[p, col]) * wp.float64(across[p, col]) + wp.float64(p * p)
            s = (fq - fp) / wp.float64(2 * (q - p))
        k = k + 1
        apex[col, k] = q
        bound[col, k] = s
        bound[col, k + 1] = ENVELOPE_BOUND
    k = int(0)
    for r in range(rows):
        while bound[col, k + 1] < wp.float64(r):
            k = k + 1
        p = apex[col, k]
        d = wp.sqrt(float((r - p) * (r - p)) + across[p, col] * across[p, col])
        distance[r, col] = wp.min(d, float(wp.min(r + 1, rows - r)))  # the border beyond the column's ends
