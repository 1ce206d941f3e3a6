"""A global planner in kernels, shaped like Nav2's: each world's path over its map's costmap, from a start to a goal.

The costmap (:class:`PlanMaps`) holds, per planning cell, NavFn's traversal cost (``nav2_navfn_planner/navfn.cpp``,
``NavFn::setCostmap``): ``COST_NEUTRAL + COST_FACTOR * c`` (50 + 0.8 c) for a Nav2 cost ``c`` below the inscribed
obstacle's 253, the unknown cell's 253 where unknown space may be planned through, and none (-1) for a lethal or
inscribed cell. :func:`goal_fields` runs Dijkstra from each world's goal over its map, one thread a world (NavFn
computes its potential from the robot and walks it down from the goal; rooted at the goal instead, the field serves
every later pose of the robot): 8-connected (a diagonal step only where both cells beside it are passable), each
step's cost its length in cells times the cost of the cell it enters; it keeps, for every cell, the next cell toward
the goal. :func:`follow_fields` then reads a world's path from any start in a few microseconds: a
replan with the same goal and costmap (what Nav2's behaviour tree asks for about once a second) is a walk down the
field. The search's scratch (costs so far, the open set as a binary heap with each cell's place in it) is one row
per slot.
"""

from __future__ import annotations

import warp as wp

from atrv_warp.sim.kernels.obstacles import OBSTACLE_NONE, ObstacleSet, surface_distance

__all__ = ["COST_NEUTRAL", "PlanMaps", "PlanMarks", "follow_fields", "goal_fields", "mark_seen"]

COST_NEUTRAL = wp.constant(50.0)
"""NavFn's cost of a free cell (``COST_NEUTRAL``): the least a step can cost."""
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


@wp.struct
class PlanMarks:
    """The unmapped obstacles each world's global costmap has marked (Nav2's obstacle layer), inflated as the map's
    walls are; read only where ``active``."""

    active: int  # 0: no obstacle layer
    seen: wp.array2d(dtype=wp.int32)  # (N, slots) 1: the obstacle in that slot is marked
    marked: wp.array(dtype=wp.int32)  # (N,) how many are (0: the map's costs alone)
    obstacles: ObstacleSet
    inscribed: float  # [m]
    inflation_radius: float  # [m]
    cost_scaling_factor: float  # [1/m]


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
def plan_cell(maps: PlanMaps, m: int, p: wp.vec2):
    """The (row, col) of map ``m``'s planning cell that holds ``p`` [m] (off the grid: out of range)."""
    res = maps.resolution[m]
    o = maps.origin[m]
    return int(wp.floor((p[1] - o[1]) / res)), int(wp.floor((p[0] - o[0]) / res))


@wp.func
def cell_centre(maps: PlanMaps, m: int, k: int) -> wp.vec2:
    """The centre [m] of map ``m``'s planning cell ``k`` (row-major)."""
    cols = maps.cols[m]
    res = maps.resolution[m]
    return maps.origin[m] + wp.vec2((float(k % cols) + 0.5) * res, (float(k / cols) + 0.5) * res)


@wp.func
def passable(maps: PlanMaps, m: int, row: int, col: int) -> bool:
    if row < 0 or col < 0 or row >= maps.rows[m] or col >= maps.cols[m]:
        return False
    return maps.cost[maps.start[m] + row * maps.cols[m] + col] >= 0.0


@wp.func
def cell_cost(maps: PlanMaps, m: int, k: int, marks: PlanMarks, w: int) -> float:
    """Planning cell ``k``'s traversal cost in world ``w`` (-1: closed): its map's, and where the world's costmap has
    marked obstacles, theirs as Nav2's inflation layer costs a cell at their surfaces' distance (NavFn's weight of
    the higher; closed within the inscribed radius)."""
    c = maps.cost[maps.start[m] + k]
    if marks.active == 0 or c < 0.0 or marks.marked[w] == 0:
        return c
    centre = cell_centre(maps, m, k)
    obstacles = marks.obstacles
    for o in range(obstacles.count):
        kind = obstacles.kind[w, o]
        if marks.seen[w, o] != 0 and kind != OBSTACLE_NONE:
            d = surface_distance(kind, obstacles.pose[w, o], obstacles.size[w, o], centre)
            if d <= marks.inscribed:
                return -1.0
            if d <= marks.inflation_radius:
                inflated = wp.floor(252.0 * wp.exp(-marks.cost_scaling_factor * (d - marks.inscribed)))
                c = wp.max(c, COST_NEUTRAL + 0.8 * inflated)
    return c


@wp.kernel
def mark_seen(poses: wp.array(dtype=wp.transform), bodies_per_world: int, chassis: int, reach: float,
              half_fov: float, marks: PlanMarks, stale: wp.array(dtype=wp.int32)):
    """Each world's costmap marks the unmapped obstacles its laser now sees: within ``reach`` [m] of the chassis
    origin (Nav2's ``obstacle_max_range``) and inside the laser's field of view, ``half_fov`` [rad] either side of the
    heading (occlusion not modelled); a world that marks a new one is ``stale`` (its field is searched again)."""
    w = wp.tid()
    pose = poses[w * bodies_per_world + chassis]
    p = wp.transform_get_translation(pose)
    q = wp.vec2(p[0], p[1])
    heading = wp.quat_rotate(wp.transform_get_rotation(pose), wp.vec3(1.0, 0.0, 0.0))
    yaw = wp.atan2(heading[1], heading[0])
    obstacles = marks.obstacles
    for o in range(obstacles.count):
        kind = obstacles.kind[w, o]
        if kind != OBSTACLE_NONE and marks.seen[w, o] == 0:
            c = obstacles.pose[w, o]
            bearing = wp.atan2(c[1] - q[1], c[0] - q[0]) - yaw
            bearing = wp.atan2(wp.sin(bearing), wp.cos(bearing))
            if surface_distance(kind, c, obstacles.size[w, o], q) <= reach and wp.abs(bearing) <= half_fov:
                marks.seen[w, o] = 1
                marks.marked[w] = marks.marked[w] + 1
                stale[w] = 1


@wp.kernel
def goal_fields(
    maps: PlanMaps,
    world_map: wp.array(dtype=wp.int32),
    worlds: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.vec2),
    goals: wp.array(dtype=wp.vec2),
    reach: float,
    marks: PlanMarks,
    g: wp.array2d(dtype=float),
    place: wp.array2d(dtype=wp.int32),
    heap_f: wp.array2d(dtype=float),
    heap_cell: wp.array2d(dtype=wp.int32),
    toward: wp.array2d(dtype=wp.int32),
):
    """Slot ``s`` computes world ``worlds[s]``'s field toward ``goals[w]`` [m] (Dijkstra from the goal, where NavFn's
    potential spreads from the robot): ``toward[w, k]``, for every cell ``k``, the next cell of the cheapest walk from
    ``k`` to the goal (the goal's own: itself; -1: no walk). A closed cell next to an open one gets its way out too
    (a robot that has strayed into a wall's inscribed band is led out of it, as NavFn clears the start), but no
    walk passes through one.

    The search stops once it has reached every cell up to ``reach`` times the cost of the walk from ``starts[w]``
    (0: the whole map): far enough for the replans of a robot that keeps near its way; a cell beyond is left at -1,
    and a replan from there searches again."""
    s = wp.tid()
    w = worlds[s]
    m = world_map[w]
    if m < 0:
        return
    rows = maps.rows[m]
    cols = maps.cols[m]
    cells = rows * cols
    for k in range(cells):
        toward[w, k] = -1
        g[s, k] = UNREACHED
        place[s, k] = OPEN_NONE
    gr, gc = plan_cell(maps, m, goals[w])
    if not passable(maps, m, gr, gc):
        return
    goal_cell = gr * cols + gc
    sr, sc = plan_cell(maps, m, starts[w])
    start_cell = int(-1)
    if sr >= 0 and sc >= 0 and sr < rows and sc < cols:
        start_cell = sr * cols + sc
    bound = float(UNREACHED)
    toward[w, goal_cell] = goal_cell
    g[s, goal_cell] = 0.0
    heap_f[s, 0] = 0.0
    heap_cell[s, 0] = goal_cell
    place[s, goal_cell] = 0
    size = int(1)
    while size > 0:
        current = heap_cell[s, 0]
        size = size - 1
        if size > 0:  # the last entry to the top, then down to its place
            heap_f[s, 0] = heap_f[s, size]
            heap_cell[s, 0] = heap_cell[s, size]
            place[s, heap_cell[s, 0]] = 0
            sift_down(heap_f, heap_cell, place, s, size)
        place[s, current] = CLOSED
        if g[s, current] > bound:
            break
        if reach > 0.0 and start_cell >= 0 and g[s, start_cell] < UNREACHED and bound == UNREACHED:
            bound = reach * g[s, start_cell]  # the start's walk is known: search on to ``reach`` times it
        r = current / cols
        c = current - r * cols
        entering = cell_cost(maps, m, current, marks, w)  # what a step into ``current`` costs, per cell of its length
        here = g[s, current]
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                nr = r + dr
                nc = c + dc
                # a walk from the neighbour steps into ``current``: the step seen from the neighbour's side
                if nr < 0 or nc < 0 or nr >= rows or nc >= cols or (dr == 0 and dc == 0):
                    continue
                n = nr * cols + nc
                if place[s, n] == CLOSED:
                    continue
                step = float(1.0)
                if dr != 0 and dc != 0:  # no corner cutting: both cells beside the step open
                    if cell_cost(maps, m, nr * cols + c, marks, w) < 0.0 or cell_cost(maps, m, r * cols + nc, marks,
                                                                                       w) < 0.0:
                        continue
                    step = 1.41421356
                candidate = here + step * entering
                if candidate < g[s, n]:
                    g[s, n] = candidate
                    toward[w, n] = current
                    if cell_cost(maps, m, n, marks, w) >= 0.0:  # a closed cell is left, never walked through
                        i = place[s, n]
                        if i == OPEN_NONE:
                            i = size
                            size = size + 1
                        heap_f[s, i] = candidate
                        heap_cell[s, i] = n
                        place[s, n] = i
                        sift_up(heap_f, heap_cell, place, s, i)


@wp.kernel
def follow_fields(
    maps: PlanMaps,
    world_map: wp.array(dtype=wp.int32),
    worlds: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.vec2),
    goals: wp.array(dtype=wp.vec2),
    toward: wp.array2d(dtype=wp.int32),
    marks: PlanMarks,
    path: wp.array2d(dtype=wp.vec2),
    path_length: wp.array(dtype=wp.int32),
    path_cost: wp.array(dtype=float),
):
    """World ``worlds[i]``'s path from ``starts[w]`` [m] down its field (:func:`goal_fields`) to ``goals[w]``:
    ``path[w]`` (the start, the centres of the cells between, the goal), ``path_length[w]`` points (0 where there is
    no walk, or one longer than ``path`` holds) and its cost ``path_cost[w]`` (NavFn's units: 50 a free cell)."""
    i = wp.tid()
    w = worlds[i]
    path_length[w] = 0
    path_cost[w] = UNREACHED
    m = world_map[w]
    if m < 0:
        return
    rows = maps.rows[m]
    cols = maps.cols[m]
    sr, sc = plan_cell(maps, m, starts[w])
    if sr < 0 or sc < 0 or sr >= rows or sc >= cols:
        return
    k = sr * cols + sc
    if toward[w, k] < 0:
        return
    capacity = path.shape[1]
    count = int(1)
    cost = float(0.0)
    path[w, 0] = starts[w]
    while toward[w, k] != k:
        n = toward[w, k]
        step = float(1.0)
        if n / cols != k / cols and n % cols != k % cols:
            step = 1.41421356
        cost = cost + step * cell_cost(maps, m, n, marks, w)
        k = n
        if count >= capacity:
            return
        path[w, count] = cell_centre(maps, m, k)
        count = count + 1
    if count == 1:  # the start's cell is the goal's
        path[w, 1] = goals[w]
        count = 2
    path[w, count - 1] = goals[w]
    path_length[w] = count
    path_cost[w] = cost
