"""A global planner in kernels, shaped like Nav2's: each world's path over its map's costmap, from a start to a goal.

The costmap (:class:`PlanMaps`) holds, per planning cell, NavFn's traversal cost (``nav2_navfn_planner/navfn.cpp``,
``NavFn::setCostmap``): ``COST_NEUTRAL + COST_FACTOR * c`` (50 + 0.8 c) for a Nav2 cost ``c`` below the inscribed
obstacle's 253, the unknown cell's 253 where unknown space may be planned through, and none (-1) for a lethal or
inscribed cell. :func:`plan_paths` runs A* over it, one thread a world: 8-connected (a diagonal step only where both
cells beside it are passable), each step's cost its length in cells times the cost of the cell it enters, guided by
the octile distance times the cheapest cell's cost (so the path is the cheapest, not only one found first). Its
scratch (costs so far, parents, the open set as a binary heap with each cell's place in it) is one row per slot.
"""

from __future__ import annotations

import warp as wp

__all__ = ["COST_NEUTRAL", "PlanMaps", "plan_paths"]

COST_NEUTRAL = wp.constant(50.0)
"""NavFn's cost of a free cell (``COST_NEUTRAL``): the least a step can cost, what the heuristic counts."""
UNREACHED = wp.constant(1.0e30)
OPEN_NONE = wp.constant(-1)
CLOSED = wp.constant(-2)


@wp.struct
class PlanMaps:
    """Every map's planning grid, packed one after another (as :class:`~atrv_warp.sim.kernels.grid.GridMaps`)."""

    cost: wp.array(dtype=float)  # each planning cell's traversal cost, or -1 where none may pass
    start: wp.array(dtype=wp.int32)  # (M,) index of each map's first planning cell
    rows: wp.array(dtype=wp.int32)  # (M,)
    cols: wp.array(dtype=wp.int32)  # (M,)
    resolution: wp.array(dtype=float)  # (M,) [m per planning cell]
    origin: wp.array(dtype=wp.vec2)  # (M,) the lower-left planning cell's outer corner (x, y) [m]


@wp.func
def heap_less(f: wp.array2d(dtype=float), cell: wp.array2d(dtype=wp.int32), s: int, a: int, b: int) -> bool:
    """Whether heap entry ``a`` of slot ``s`` comes before entry ``b`` (the lower f; ties by the lower cell, so that
    the search is the same on every device)."""
    fa = f[s, a]
    fb = f[s, b]
    return fa < fb or (fa == fb and cell[s, a] < cell[s, b])


@wp.func
def heap_swap(f: wp.array2d(dtype=float), cell: wp.array2d(dtype=wp.int32), place: wp.array2d(dtype=wp.int32),
              s: int, a: int, b: int):
    fa = f[s, a]
    ca = cell[s, a]
    f[s, a] = f[s, b]
    cell[s, a] = cell[s, b]
    f[s, b] = fa
    cell[s, b] = ca
    place[s, cell[s, a]] = a
    place[s, cell[s, b]] = b


@wp.func
def sift_up(f: wp.array2d(dtype=float), cell: wp.array2d(dtype=wp.int32), place: wp.array2d(dtype=wp.int32),
            s: int, i: int):
    k = i
    while k > 0:
        parent = (k - 1) / 2
        if not heap_less(f, cell, s, k, parent):
            break
        heap_swap(f, cell, place, s, k, parent)
        k = parent


@wp.func
def sift_down(f: wp.array2d(dtype=float), cell: wp.array2d(dtype=wp.int32), place: wp.array2d(dtype=wp.int32),
              s: int, size: int):
    k = int(0)
    while True:
        low = k
        left = 2 * k + 1
        right = left + 1
        if left < size and heap_less(f, cell, s, left, low):
            low = left
        if right < size and heap_less(f, cell, s, right, low):
            low = right
        if low == k:
            break
        heap_swap(f, cell, place, s, k, low)
        k = low


@wp.func
def octile(r0: int, c0: int, r1: int, c1: int) -> float:
    """The length [cells] of the shortest 8-connected walk between two cells on an empty grid."""
    dr = float(wp.abs(r1 - r0))
    dc = float(wp.abs(c1 - c0))
    return dr + dc + (1.41421356 - 2.0) * wp.min(dr, dc)


@wp.func
def passable(maps: PlanMaps, m: int, row: int, col: int) -> bool:
    if row < 0 or col < 0 or row >= maps.rows[m] or col >= maps.cols[m]:
        return False
    return maps.cost[maps.start[m] + row * maps.cols[m] + col] >= 0.0


@wp.kernel
def plan_paths(
    maps: PlanMaps,
    world_map: wp.array(dtype=wp.int32),
    worlds: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.vec2),
    goals: wp.array(dtype=wp.vec2),
    g: wp.array2d(dtype=float),
    parent: wp.array2d(dtype=wp.int32),
    place: wp.array2d(dtype=wp.int32),
    heap_f: wp.array2d(dtype=float),
    heap_cell: wp.array2d(dtype=wp.int32),
    path: wp.array2d(dtype=wp.vec2),
    path_length: wp.array(dtype=wp.int32),
    path_cost: wp.array(dtype=float),
):
    """Slot ``s`` plans world ``worlds[s]``: its path from ``starts[w]`` to ``goals[w]`` [m] over its map, written to
    ``path[w]`` (the start, the centres of the cells between, the goal) with ``path_length[w]`` points and its cost
    ``path_cost[w]`` (NavFn's units: 50 a free cell); ``path_length[w]`` 0 where there is none (a start or goal off
    the map or in a lethal cell, no way between, or a path longer than ``path`` holds)."""
    s = wp.tid()
    w = worlds[s]
    path_length[w] = 0
    path_cost[w] = UNREACHED
    m = world_map[w]
    if m < 0:
        return
    rows = maps.rows[m]
    cols = maps.cols[m]
    res = maps.resolution[m]
    o = maps.origin[m]
    base = maps.start[m]
    sr = int(wp.floor((starts[w][1] - o[1]) / res))
    sc = int(wp.floor((starts[w][0] - o[0]) / res))
    gr = int(wp.floor((goals[w][1] - o[1]) / res))
    gc = int(wp.floor((goals[w][0] - o[0]) / res))
    if sr < 0 or sc < 0 or sr >= rows or sc >= cols or not passable(maps, m, gr, gc):
        return
    for k in range(rows * cols):
        g[s, k] = UNREACHED
        place[s, k] = OPEN_NONE
    start_cell = sr * cols + sc
    goal_cell = gr * cols + gc
    g[s, start_cell] = 0.0
    parent[s, start_cell] = -1
    heap_f[s, 0] = octile(sr, sc, gr, gc) * COST_NEUTRAL
    heap_cell[s, 0] = start_cell
    place[s, start_cell] = 0
    size = int(1)
    found = int(0)
    while size > 0:
        current = heap_cell[s, 0]
        size = size - 1
        if size > 0:  # the last entry to the top, then down to its place
            heap_f[s, 0] = heap_f[s, size]
            heap_cell[s, 0] = heap_cell[s, size]
            place[s, heap_cell[s, 0]] = 0
            sift_down(heap_f, heap_cell, place, s, size)
        place[s, current] = CLOSED
        if current == goal_cell:
            found = 1
            break
        r = current / cols
        c = current - r * cols
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                nr = r + dr
                nc = c + dc
                if (dr == 0 and dc == 0) or not passable(maps, m, nr, nc):
                    continue
                step = float(1.0)
                if dr != 0 and dc != 0:  # no corner cutting
                    if not passable(maps, m, r, nc) or not passable(maps, m, nr, c):
                        continue
                    step = 1.41421356
                n = nr * cols + nc
                if place[s, n] == CLOSED:
                    continue
                tentative = g[s, current] + step * maps.cost[base + n]
                if tentative < g[s, n]:
                    g[s, n] = tentative
                    parent[s, n] = current
                    f = tentative + octile(nr, nc, gr, gc) * COST_NEUTRAL
                    i = place[s, n]
                    if i == OPEN_NONE:
                        i = size
                        size = size + 1
                    heap_f[s, i] = f
                    heap_cell[s, i] = n
                    place[s, n] = i
                    sift_up(heap_f, heap_cell, place, s, i)
    if found == 0:
        return
    count = int(1)  # the cells from the goal back to the start
    k = goal_cell
    while parent[s, k] >= 0:
        k = parent[s, k]
        count = count + 1
    if count > path.shape[1]:
        return
    k = goal_cell
    for i in range(count):
        r = k / cols
        c = k - r * cols
        path[w, count - 1 - i] = o + wp.vec2((float(c) + 0.5) * res, (float(r) + 0.5) * res)
        k = parent[s, k]
    path[w, 0] = starts[w]
    path[w, count - 1] = goals[w]
    path_length[w] = count
    path_cost[w] = g[s, goal_cell]
