"""The global planner (``atrv_warp.sim.planner``): Nav2's costmap (inflation as ``computeCost``), NavFn's weights, and
a field from the goal in a kernel whose walks are the cheapest paths, checked against a plain Dijkstra."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest
import torch

from atrv_warp.sim.maps import GridWorlds
from atrv_warp.sim.planner import INSCRIBED, LETHAL, NO_INFORMATION, Planner, PlannerConfig, costmap, navfn_costs
from atrv_warp.world import OccupancyMap
from atrv_warp.world.nav2_map import FREE, OCCUPIED, UNKNOWN


def dijkstra(cost: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """The cheapest 8-connected walk's cost (each step its length times the entered cell's cost, no corner cutting,
    -1 closed), by Dijkstra over every cell: the planner's rules, searched the plain way."""
    rows, cols = cost.shape
    best = {start: 0.0}
    todo = [(0.0, start)]
    while todo:
        d, (r, c) = heapq.heappop(todo)
        if (r, c) == goal:
            return d
        if d > best[(r, c)]:
            continue
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                nr, nc = r + dr, c + dc
                if (dr, dc) == (0, 0) or not (0 <= nr < rows and 0 <= nc < cols) or cost[nr, nc] < 0:
                    continue
                if dr and dc and (cost[r, nc] < 0 or cost[nr, c] < 0):
                    continue
                nd = d + (math.sqrt(2.0) if dr and dc else 1.0) * float(cost[nr, nc])
                if nd < best.get((nr, nc), math.inf):
                    best[(nr, nc)] = nd
                    heapq.heappush(todo, (nd, (nr, nc)))
    return math.inf


def site_of(cells: np.ndarray, resolution: float = 0.1) -> OccupancyMap:
    return OccupancyMap(cells=cells, resolution=resolution, origin=(0.0, 0.0))


def test_the_costmap_inflates_as_nav2_and_navfn_weighs_it():
    """One occupied cell in a free row: lethal on it, inscribed within the radius, 252 exp(-k (d - r)) out to the
    inflation radius, 0 beyond; an unknown cell is unknown and inflates nothing; NavFn's weights follow."""
    cells = np.full((1, 30), FREE, np.int8)
    cells[0, 0], cells[0, 29] = OCCUPIED, UNKNOWN
    field = np.arange(30, dtype=np.float32)[None]  # cells from the occupied one
    cfg = PlannerConfig(inflation_radius=1.0, cost_scaling_factor=3.0)
    cost = costmap(cells, field, 0.1, 0.25, cfg)[0]
    d = np.arange(30) * 0.1
    assert cost[0] == LETHAL and (cost[1:3] == INSCRIBED).all() and cost[29] == NO_INFORMATION
    expected = (252.0 * np.exp(-3.0 * (d[3:11] - 0.25))).astype(np.uint8)
    assert np.array_equal(cost[3:11], expected) and (cost[11:29] == 0).all()
    weights = navfn_costs(cost[None], allow_unknown=True)[0]
    assert weights[0] == weights[1] == -1.0 and weights[29] == 253.0 and weights[20] == 50.0
    assert weights[5] == pytest.approx(50.0 + 0.8 * cost[5])
    assert navfn_costs(cost[None], allow_unknown=False)[0][29] == -1.0


def test_the_planner_finds_the_cheapest_path_as_dijkstra_does():
    """60 plans on random maps with walls and unknown patches: each path (the walk down the goal's field) costs what
    a plain Dijkstra's walk from the start costs (to float rounding), there is none exactly where Dijkstra finds none,
    and each path steps cell to cell from the start to the goal through passable cells; 60 replans from other starts
    down the same fields cost what Dijkstra's walks from there cost (fields of the whole map), or find a way where
    Dijkstra does (fields searched to twice the start's cost, searched again from a start beyond)."""
    rng = np.random.default_rng(0)
    found = 0
    for trial in range(6):
        cells = np.full((30, 40), FREE, np.int8)
        for _ in range(12):
            r, c = rng.integers(0, 28), rng.integers(0, 38)
            cells[r:r + rng.integers(1, 12), c:c + rng.integers(1, 3)] = OCCUPIED if rng.random() < 0.8 else UNKNOWN
        site = site_of(cells)
        worlds = 10
        grids = GridWorlds([site], [0] * worlds, "cpu")
        planner = Planner(grids, (0.12, 0.2), PlannerConfig(allow_unknown=bool(trial % 2), slots=4,
                                                            field_reach=0.0 if trial < 3 else 2.0))
        weights = navfn_costs(planner.costmaps[0], planner.cfg.allow_unknown)
        open_cells = np.argwhere(weights >= 0)
        picks = open_cells[rng.choice(len(open_cells), 2 * worlds, replace=False)]
        xy = torch.tensor(np.stack(site.centre_of(picks[:, 0], picks[:, 1]), -1), dtype=torch.float32)
        starts, goals = xy[:worlds], xy[worlds:]
        planner.plan(range(worlds), starts, goals)
        for w in range(worlds):
            want = dijkstra(weights, tuple(picks[w]), tuple(picks[worlds + w]))
            got = float(planner.path_cost[w]) if planner.path_length[w] > 0 else math.inf
            assert got == pytest.approx(want, rel=1e-5), (trial, w)
            points = planner.points(w)
            found += bool(len(points))
            if len(points):
                assert np.allclose(points[0], starts[w]) and np.allclose(points[-1], goals[w])
                steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
                assert (steps <= 0.1 * math.sqrt(2.0) + 1e-5).all()
                r, c = site.cell_of(points[:, 0], points[:, 1])
                assert (weights[r, c] >= 0).all()
        # a replan from elsewhere walks the same field: the cheapest path from there, no new search
        elsewhere = open_cells[rng.choice(len(open_cells), worlds, replace=False)]
        planner.replan(range(worlds), torch.tensor(np.stack(site.centre_of(elsewhere[:, 0], elsewhere[:, 1]), -1),
                                                   dtype=torch.float32))
        for w in range(worlds):  # the whole map's field: the cheapest; a field to twice the start's: a way there
            want = dijkstra(weights, tuple(elsewhere[w]), tuple(picks[worlds + w]))
            got = float(planner.path_cost[w]) if planner.path_length[w] > 0 else math.inf
            if planner.cfg.field_reach == 0 or math.isinf(want):
                assert got == pytest.approx(want, rel=1e-5), (trial, w, "replan")
            else:
                assert want * (1 - 1e-5) <= got < math.inf, (trial, w, "replan")
    assert found >= 40  # most pairs are joined: the comparison is of paths, not of failures


def test_a_doorway_half_again_the_robots_width_stays_open_and_the_path_keeps_to_its_middle():
    """Two rooms whose wall has a doorway: 1.5 times the robot's width (inscribed radius 0.26 m) is planned
    through, down its middle; 0.9 times is not (only the inscribed band closes it, not the footprint)."""
    width = 2 * 0.26
    for factor, open_ in ((1.5, True), (0.9, False)):
        cells = np.full((100, 100), FREE, np.int8)
        cells[:, 50] = OCCUPIED
        door = round(factor * width / 0.05)
        cells[50 - door // 2:50 - door // 2 + door, 50] = FREE
        site = site_of(cells, 0.05)
        planner = Planner(GridWorlds([site], [0], "cpu"), (0.26, 0.4))
        planner.plan([0], torch.tensor([[1.0, 1.0]]), torch.tensor([[4.0, 4.0]]))
        assert (planner.path_length[0] > 0) == open_, factor
        if open_:
            points = planner.points(0)
            crossing = points[np.argmin(np.abs(points[:, 0] - 2.525))]
            assert abs(crossing[1] - 2.5) <= 0.1  # the doorway's middle, within a planning cell


def test_a_bad_planner_setting_is_named():
    with pytest.raises(ValueError, match="inflation_radius must be a finite number > 0"):
        PlannerConfig(inflation_radius=float("nan"))
    with pytest.raises(ValueError, match="slots must be >= 2"):
        PlannerConfig(slots=0)


def test_a_robot_in_a_walls_inscribed_band_is_led_out_and_too_many_fields_are_refused():
    """A start inside the closed band beside a wall (a robot that strayed there) gets a path out of it, stepping
    straight into open cells; fields that would not fit in memory are refused, naming the worlds and cells."""
    cells = np.full((40, 40), FREE, np.int8)
    cells[:, 20] = OCCUPIED
    site = site_of(cells)
    planner = Planner(GridWorlds([site], [0], "cpu"), (0.25, 0.4))
    planner.plan([0], torch.tensor([[1.85, 1.0]]), torch.tensor([[0.5, 3.5]]))  # 0.2 m from the wall's face
    points = planner.points(0)
    assert len(points) > 2 and points[1][0] < 1.85 and np.allclose(points[-1], [0.5, 3.5])
    large = site_of(np.full((400, 400), FREE, np.int8))
    with pytest.raises(ValueError, match=r"fields would take 6.0 GiB \(10000 worlds x 160,000 planning cells"):
        Planner(GridWorlds([large], [0] * 10_000, "cpu"), (0.25, 0.4), PlannerConfig(resolution=0.1))
