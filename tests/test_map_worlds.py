"""Worlds from a Nav2 map (``RoverEnv(maps=...)``, ``--map``): episodes start and end in the map's free space, clear
of the robot's footprint, the target reachable from the start; the clearance term reads the walls; every command
that builds a world takes the map, and a bad map is one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from atrv_warp.sim.maps import CELL_REACH, components, spawn_cells
from atrv_warp.world import MapError, OccupancyMap, load_map, save_map
from atrv_warp.world.nav2_map import FREE, OCCUPIED, UNKNOWN

RESOLUTION, ORIGIN = 0.1, (-12.0, -8.0)


def two_rooms() -> OccupancyMap:
    """24 m x 16 m at 0.1 m: two rooms joined by a 1.2 m doorway, an unknown corner, and a closed 1.7 m closet in the
    left room (room enough for the robot, no way out)."""
    g = np.full((160, 240), FREE, np.int8)
    g[0, :] = g[-1, :] = g[:, 0] = g[:, -1] = OCCUPIED
    g[:, 120] = OCCUPIED
    g[70:82, 120] = FREE  # the doorway
    g[120:, 200:] = UNKNOWN
    g[100:119, 20:40] = OCCUPIED
    g[101:118, 21:39] = FREE  # the closet's inside
    return OccupancyMap(cells=g, resolution=RESOLUTION, origin=ORIGIN, label="rooms")


def flood(mask: np.ndarray) -> np.ndarray:
    """4-connected groups by a breadth-first fill, each named by its smallest flat index (the check of
    :func:`components`)."""
    out = np.full(mask.shape, -1, dtype=np.int64)
    rows, cols = mask.shape
    for start in np.flatnonzero(mask):
        r0, c0 = divmod(int(start), cols)
        if out[r0, c0] >= 0:
            continue
        out[r0, c0], todo = start, [(r0, c0)]
        while todo:
            r, c = todo.pop()
            for rr, cc in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
                if 0 <= rr < rows and 0 <= cc < cols and mask[rr, cc] and out[rr, cc] < 0:
                    out[rr, cc] = start
                    todo.append((rr, cc))
    return out


def test_components_are_the_4_connected_groups():
    rng = np.random.default_rng(0)
    for shape, density in (((40, 60), 0.3), ((25, 25), 0.5), ((1, 30), 0.2), ((30, 1), 0.0), ((50, 50), 0.45)):
        mask = rng.random(shape) >= density
        assert np.array_equal(components(mask), flood(mask)), (shape, density)
    snake = np.zeros((41, 41), bool)  # one corridor back and forth: the longest chain a grid has
    snake[::2, :] = True
    snake[1::4, -1] = snake[3::4, 0] = True
    assert np.array_equal(components(snake), flood(snake)) and len(np.unique(components(snake))) == 2


def test_spawn_cells_keep_the_footprint_clear_and_group_by_where_the_robot_can_drive():
    from atrv_warp.sim.maps import distance_field

    site = two_rooms()
    field = distance_field(site.walls)
    cells, first, count = spawn_cells(field, RESOLUTION, circumscribed=0.41, inscribed=0.26)
    assert ((field.ravel()[cells] - CELL_REACH) * RESOLUTION >= 0.41).all()
    groups = components((field - CELL_REACH) * RESOLUTION >= 0.26).ravel()[cells]
    assert np.array_equal(groups, groups[first]) and np.array_equal(count, np.bincount(first)[first])
    # both rooms are one group through the doorway; the closet is its own
    rows, cols = np.divmod(cells, site.shape[1])
    x, _ = site.centre_of(rows, cols)
    closet = (rows > 100) & (rows < 118) & (cols > 21) & (cols < 39)
    assert closet.any() and len(set(groups[closet])) == 1 and set(groups[closet]).isdisjoint(groups[~closet])
    assert len(set(groups[(x < 0) & ~closet]) | set(groups[x > 0])) == 1
    # a doorway narrower than the robot parts the rooms
    narrow = site.cells.copy()
    narrow[70:82, 120], narrow[74:78, 120] = OCCUPIED, FREE
    field = distance_field(OccupancyMap(cells=narrow, resolution=RESOLUTION, origin=ORIGIN).walls)
    cells, first, _ = spawn_cells(field, RESOLUTION, circumscribed=0.41, inscribed=0.26)
    x, _ = site.centre_of(*np.divmod(cells, site.shape[1]))
    assert set(first[x < 0]).isdisjoint(first[x > 0])


def test_episodes_in_a_map_start_and_end_clear_of_its_walls_and_reachable():
    """256 episodes of nav_deploy on the ATRV-Jr in the two rooms: every start and target clear of the walls by the
    robot's circumscribed radius, the target in the start's group (never in the closet with a start outside), and
    the task's 5-10 m apart; a third of the targets lie in the other room; the same seed draws the same episodes."""
    from atrv_warp.task.env import RoverEnv

    site = two_rooms()
    env = RoverEnv(256, task="nav_deploy", seed=3, maps=[site])
    env.reset()
    starts, targets = env.episode_start[:, :2].numpy(), env.target.numpy()
    inscribed, circumscribed = env.sim.footprint_radii
    field = env.sim.maps.distance[0]
    groups = components((field - CELL_REACH) * RESOLUTION >= inscribed)
    for points in (starts, targets):
        row, col = site.cell_of(points[:, 0], points[:, 1])
        assert ((field[row, col] - CELL_REACH) * RESOLUTION >= circumscribed).all()
    assert np.array_equal(groups[site.cell_of(*starts.T)], groups[site.cell_of(*targets.T)])
    distance = np.linalg.norm(targets - starts, axis=1)
    low, high = env.task_cfg.target_distance
    assert ((distance >= low - 1e-4) & (distance <= high + 1e-4)).all()
    crossing = np.sign(starts[:, 0]) != np.sign(targets[:, 0])
    assert 0.2 < crossing.mean() < 0.6
    # the unmapped obstacles stand on the map
    kind, pose = env.sim.obstacles.kind.numpy(), env.sim.obstacles.pose.numpy()
    xy = pose[kind > 0][:, :2]
    assert len(xy) and (xy >= ORIGIN).all() and (xy <= (12.0, 8.0)).all()
    again = RoverEnv(256, task="nav_deploy", seed=3, maps=[site])
    again.reset()
    assert torch.equal(again.episode_start, env.episode_start) and torch.equal(again.target, env.target)


def test_the_clearance_term_reads_the_nearest_wall():
    """A rover parked at a known spot near the doorway's wall: the clearance term is the radius less its distance to
    the nearest wall cell (the field, less half a cell), where no obstacle slot is nearer."""
    from atrv_warp.task.env import RoverEnv

    site = two_rooms()
    env = RoverEnv(2, task="nav_deploy", seed=0, maps=[site], obstacles=0, obstacles_on_path=0,
                   clearance_weight=1.0)
    td = env.reset()
    spots = torch.tensor([[0.6, -3.0, 0.0], [-6.0, 0.0, 0.0]])  # 0.55 m from the wall at x = 0; the room's middle
    env.sim.reset(poses=spots)
    td = env.step(td.set("action", torch.zeros(2, 2)))["next"]
    p = env.sim.root_pose[:, :2].numpy()
    row, col = site.cell_of(p[:, 0], p[:, 1])
    gap = (env.sim.maps.distance[0][row, col] - 0.5) * RESOLUTION
    radius = env.task_cfg.clearance_radius
    expected = -np.clip(radius - gap, 0.0, None)
    assert expected[0] < 0.0 and expected[1] == 0.0
    assert td["reward_terms", "clearance"].flatten().numpy() == pytest.approx(expected, abs=1e-5)


def test_a_saved_map_reads_back_as_map_server_reads_it(tmp_path):
    site = two_rooms()
    path = save_map(site, tmp_path / "rooms.yaml")
    back = load_map(path)
    assert np.array_equal(back.cells, site.cells) and back.origin == ORIGIN and back.resolution == RESOLUTION
    assert (tmp_path / "rooms.pgm").read_bytes().startswith(b"P5\n240 160\n255\n")
    with pytest.raises(MapError, match="give the YAML's path"):
        save_map(site, tmp_path / "rooms.pgm")


def test_a_map_too_tight_for_the_robot_is_named():
    from atrv_warp.sim import RoverSim

    g = np.full((12, 12), OCCUPIED, np.int8)
    g[4:8, 4:8] = FREE  # 0.4 m of free floor: no ATRV-Jr fits
    with pytest.raises(MapError, match="no free cell is 0.43 m from every wall"):
        RoverSim(1, maps=[OccupancyMap(cells=g, resolution=0.1, origin=(0.0, 0.0))])


def test_evaluate_demo_and_train_take_a_map(tmp_path, capsys):
    """``evaluate --map``: the episodes in the map, its file and sha256 and each episode's map in the JSON, the
    success by map with two; ``demo --map`` starts at the most open spot; ``train --map`` records it, and a bad map
    stops each before any work in one line."""
    from atrv_warp.cli import demo, evaluate
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.run import resolve_run

    rooms = save_map(two_rooms(), tmp_path / "rooms.yaml")
    other = save_map(OccupancyMap(cells=two_rooms().cells[:, ::-1].copy(), resolution=RESOLUTION, origin=ORIGIN),
                     tmp_path / "mirrored.yaml")
    out = tmp_path / "eval.json"
    assert evaluate.main(["nav_deploy", "--map", str(rooms), str(other), "--episodes", "4", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "success by map: rooms:" in printed and "mirrored:" in printed
    figures = json.loads(out.read_text())
    assert [m["name"] for m in figures["maps"]] == ["rooms", "mirrored"]
    assert figures["maps"][0]["sha256"] == load_map(rooms).digest and figures["episode_map"] == [0, 1, 0, 1]
    assert demo.main(["--map", str(rooms), "--seconds", "0.5"]) == 0
    assert f"in {rooms}, from its most open spot" in capsys.readouterr().out
    cfg = load_train_config("smoke", {"env.map": f"[{rooms},{other},building:1@7]"})
    assert cfg.env.map == (str(rooms), str(other), "building:1@7")
    sites = resolve_run(cfg).record()["sites"]  # what the run's policies record of the maps they trained in
    assert sites["entries"] == [str(rooms), str(other), "building:1@7"]
    assert [(m["name"], m["file"]) for m in sites["maps"]] == [("rooms", str(rooms)), ("mirrored", str(other)),
                                                               ("building_7", None)]
    assert sites["maps"][0]["sha256"] == load_map(rooms).digest and len(sites["maps"][2]["sha256"]) == 64
    missing = tmp_path / "gone.yaml"
    assert evaluate.main(["nav_deploy", "--map", str(missing), "--episodes", "2"]) == 2
    assert demo.main(["--map", str(missing)]) == 2
    assert f"map not found: {missing}" in capsys.readouterr().err
    with pytest.raises(ValueError, match=f"train config: env.map: map not found: {missing}"):
        load_train_config("smoke", {"env.map": str(missing)})
    assert evaluate.main(["nav_deploy", "--engine", "mujoco", "--map", str(rooms), "--episodes", "2"]) == 2
    assert "maps are for engine ours" in capsys.readouterr().err


def test_a_map_larger_than_the_arena_holds_the_nav_terrain():
    """A 33.4 m yard: the arena drawn around it is a whole number of 2 m, which the nav task's terrain grid spans."""
    from atrv_warp.sim.maps import arena_around
    from atrv_warp.task.env import RoverEnv

    site = OccupancyMap(cells=np.full((334, 334), FREE, np.int8), resolution=0.1, origin=(-16.7, -16.7))
    assert arena_around([site]).size == 36.0  # 2 x ceil(16.7 + 1)
    env = RoverEnv(2, task="nav_deploy", seed=0, maps=[site])
    env.rollout(3)


def test_the_planner_in_the_loop_plans_each_episode_and_replans_from_the_robot():
    """``planner=PlannerConfig()``: each reset's path runs from the episode's start to its target; every
    ``replan_period`` a world plans again from where its robot is; an episode whose path the planner cannot give
    (here: longer than ``max_points``) is drawn again, at most ``redraws`` times; a restored snapshot plans from the
    restored poses."""
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv

    site = two_rooms()
    env = RoverEnv(32, task="nav_deploy", seed=1, maps=[site], planner=PlannerConfig(replan_period=1.0))
    td = env.reset()
    assert (env.path_length > 2).all()
    first = torch.stack([env.path[w, 0] for w in range(32)])
    last = torch.stack([env.path[w, int(env.path_length[w]) - 1] for w in range(32)])
    assert torch.equal(first, env.episode_start[:, :2]) and torch.equal(last, env.target)
    period = round(1.0 / env.sim.sim_cfg.step_dt)
    for k in range(period):
        td = env.step(td.set("action", torch.full((32, 2), 0.5)))["next"]
        if k == period - 2:
            pose = env.sim.root_pose[:, :2].clone()
    live = td["done"].reshape(-1) == 0
    assert torch.equal(env.path[live, 0], env.sim.root_pose[live, :2]) and not torch.equal(pose[live], first[live])
    snapshot = env.state_dict()
    env.reset()
    env.load_state_dict(snapshot)
    assert torch.equal(env.path[live, 0], env.sim.root_pose[live, :2])
    # paths of at most 70 points (about 7 m at 0.1 m): more than half the 5-10 m episodes are drawn again, and
    # eight redraws find every world one that fits (29 of 64 without)
    short = {redraws: RoverEnv(64, task="nav_deploy", seed=1, maps=[site],
                               planner=PlannerConfig(max_points=70, redraws=redraws)) for redraws in (0, 8)}
    for env in short.values():
        env.reset()
    planned = {redraws: int((env.path_length > 0).sum()) for redraws, env in short.items()}
    assert planned[0] < 40 and planned[8] == 64


def test_worlds_set_to_given_layouts_keep_them_until_released():
    """``set_worlds``: the given start, target, map and obstacles, replayed by every reset (auto-resets too) until
    ``release_worlds``; the other worlds draw as before, bit for bit; a bad layout is one line naming the world and
    changes nothing."""
    from atrv_warp.task.env import RoverEnv

    rooms, mirrored = two_rooms(), OccupancyMap(cells=two_rooms().cells[:, ::-1].copy(), resolution=RESOLUTION,
                                                origin=ORIGIN)
    env = RoverEnv(4, task="nav_deploy", seed=2, maps=[rooms, mirrored])
    plain = RoverEnv(4, task="nav_deploy", seed=2, maps=[rooms, mirrored])
    env.reset()
    plain.reset()
    layout = [("box", -2.0, 1.0, 0.3, 0.4, 0.2), ("cylinder", -3.0, -2.0, 0.25)]
    env.set_worlds([1], starts=[[-6.0, 3.0, 0.5]], targets=[[5.0, -3.0]], target_yaws=[1.0], obstacles=[layout],
                   maps=[0])
    assert env.sim.maps.world_map[1] == 0
    for _ in range(3):  # resets of world 1 replay it; the others keep their own streams
        assert env.episode_start[1].tolist() == pytest.approx([-6.0, 3.0, 0.5])
        assert env.target[1].tolist() == pytest.approx([5.0, -3.0]) and float(env.target_yaw[1]) == pytest.approx(1.0)
        assert env.sim.obstacles.kind[1, :2].tolist() == [1, 2] and (env.sim.obstacles.kind[1, 2:] == 0).all()
        assert env.sim.obstacles.pose[1, 0].tolist() == pytest.approx([-2.0, 1.0, 0.3])
        env.reset()
        plain.reset()
        others = [0, 2, 3]
        assert torch.equal(env.episode_start[others], plain.episode_start[others])
    assert env.pinned.tolist() == [False, True, False, False]
    env.release_worlds([1])
    env.reset()
    assert env.episode_start[1].tolist() != pytest.approx([-6.0, 3.0, 0.5])
    before = env.episode_start.clone()
    for bad, message in (
            ({"starts": [[0.05, -3.0, 0.0]], "targets": [[5.0, -3.0]]}, "world 2's start .* is in a wall of map rooms"),
            ({"starts": [[-6.0, 3.0, 0.0]], "targets": [[50.0, 0.0]]}, "world 2's target .* inside the arena"),
            ({"starts": [[-6.0, 3.0, 0.0]], "targets": [[5.0, -3.0]], "obstacles": [[("cone", 1.0, 1.0)]]},
             "world 2: obstacle 0: .*'cone'"),
            ({"starts": [[-6.0, 3.0, 0.0]], "targets": [[5.0, -3.0]], "maps": [2]}, "maps must index the 2 maps"),
            ({"starts": [[-6.0, 3.0, 0.0]], "targets": [[5.0, -3.0]], "maps": [0, 1]}, "one map index for each of")):
        with pytest.raises(ValueError, match=message):
            env.set_worlds([2], **bad)
    assert torch.equal(env.episode_start, before) and env.pinned.tolist() == [False] * 4
    with pytest.raises(ValueError, match=r"release_worlds: world indices must be in \[0, 4\), got \[7\]"):
        env.release_worlds([7])


def test_the_obstacles_across_the_way_stand_on_the_plan():
    """With the planner, the task's ``obstacles_on_path`` stand on each episode's plan (within ``path_offset`` of it,
    clear of the start and the target, a way round left), where a straight line through the rooms' wall would not
    put them; the planner's path runs through them (it plans on the map alone)."""
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv

    env = RoverEnv(64, task="nav_deploy", seed=4, maps=[two_rooms()], planner=PlannerConfig())
    env.reset()
    cfg = env.task_cfg
    assert cfg.obstacles_on_path == 1
    crossing = doorway = 0
    walls = np.argwhere(two_rooms().walls)[:, ::-1] * RESOLUTION + np.array(ORIGIN) + RESOLUTION / 2
    for w in range(64):
        path = env.path[w, :int(env.path_length[w])].numpy()
        q = env.sim.obstacles.pose[w, 0, :2].numpy()
        ends = (env.episode_start[w, :2].numpy(), env.target[w].numpy())
        radius = env.sim.obstacles.size[w, 0].norm().item() if env.sim.obstacles.kind[w, 0] == 1 else \
            env.sim.obstacles.size[w, 0, 0].item()
        if min(np.linalg.norm(q - e) for e in ends) <= radius + cfg.clearance:  # no place on the plan kept it clear
            continue
        a, b = path[:-1], path[1:]
        t = np.clip(((q - a) * (b - a)).sum(-1) / np.maximum(((b - a) ** 2).sum(-1), 1e-12), 0.0, 1.0)
        if np.linalg.norm(a + t[:, None] * (b - a) - q, axis=1).min() > cfg.path_offset + 1e-4:
            # no place on the plan's middle left the robot a way round (a plan's middle in the doorway): the
            # obstacle stays where the sampler drew it, which does
            middle = path[int(0.35 * len(path)):int(0.65 * len(path)) + 1]
            gap = np.linalg.norm(middle[:, None] - walls[None], axis=-1).min(1)
            assert (gap < radius + cfg.path_offset + 2 * env.sim.footprint_radii[1]).any(), w
            doorway += 1
            continue
        crossing += bool(np.sign(ends[0][0]) != np.sign(ends[1][0]))
    assert crossing >= 10 and doorway <= 16  # plans through the doorway, not along the straight line through the wall


def test_an_obstacle_of_its_own_height_under_the_laser_is_met_not_seen():
    """``set_worlds``' obstacles take a height: a box 0.15 m high, under the ATRV-Jr's laser (0.28 m), is not in the
    scan but stops the rover; the same box at the task's height is seen 1.4 m ahead. A snapshot restores the heights,
    and one without them (from before) restores the task's."""
    from atrv_warp.task.env import RoverEnv

    env = RoverEnv(2, task="nav_deploy", seed=0, obstacles=2, obstacles_on_path=0)
    wall = ("box", 2.0, 0.0, 0.0, 0.3, 1.0)
    env.set_worlds([0, 1], starts=[[0.0, 0.0, 0.0]] * 2, targets=[[8.0, 0.0]] * 2,
                   obstacles=[[wall], [(*wall, 0.15)]])
    ground = env.sim.arena_cfg.ground_top
    assert env.sim.obstacles.height[:, 0].tolist() == pytest.approx([env.sim.obstacles.kernel.top, ground + 0.15])
    ahead = env.scanner.ranges[:, env.scanner.ranges.shape[1] // 2]
    assert ahead[0] == pytest.approx(1.42, abs=0.02) and ahead[1] > 10.0
    snapshot = env.state_dict()
    td = env.reset()
    ends = torch.zeros(2, dtype=torch.long)
    for _ in range(60):
        td = env.step(td.set("action", torch.tensor([[0.5, 0.0]] * 2)))["next"]
        ends = torch.where(ends == 0, td["end_reason"].reshape(-1), ends)
    from atrv_warp.task.spec import END_REASONS

    assert ends.tolist() == [END_REASONS.index("obstacle")] * 2  # both ended on the obstacle
    env.load_state_dict(snapshot)
    assert env.sim.obstacles.height[1, 0] == pytest.approx(ground + 0.15)
    old = {k: v for k, v in snapshot.items() if k != "task.obstacle_height"}
    env.load_state_dict(old)
    assert (env.sim.obstacles.height == env.sim.obstacles.kernel.top).all()
    with pytest.raises(ValueError, match="needs a height above the ground > 0"):
        env.set_worlds([0], starts=[[0.0, 0.0, 0.0]], targets=[[8.0, 0.0]], obstacles=[[(*wall, -1.0)]])


def test_an_arena_without_walls_is_open_ground(tmp_path):
    """``ArenaConfig(walls=False)``: a rover driven at full speed past where the walls stood meets nothing and is
    not flagged, the laser reads no wall, and the recording draws none; with the walls, the same drive is stopped."""
    from atrv_warp.integrations.recorder import RerunRecorder
    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.config import ArenaConfig

    rovers = {walls: RoverSim(1, arena=ArenaConfig(walls=walls)) for walls in (True, False)}
    for walls, sim in rovers.items():
        sim.reset(poses=[[12.0, 0.0, 0.0]])
        hit = False
        for _ in range(160):  # 8 s at the ATRV-Jr's top speed: 4 m, past the wall at 15 m
            sim.set_twist(torch.tensor([[0.5, 0.0]]))
            sim.step()
            hit |= bool(sim.wall_contact.any())
        x = float(sim.root_pose[0, 0])
        assert (hit, x < 15.0) == (walls, walls), (walls, x)
    from atrv_warp.sim.scanner import LaserScanner

    for walls, sim in rovers.items():  # ahead: a wall 15 m from the origin, or nothing within the laser's 20 m
        scanner = LaserScanner(sim)
        ranges = scanner.scan()
        assert bool((ranges < scanner.cfg.max_range).any()) == walls
    assert rovers[False].arena_cfg.boxes()[1:] == ()
    from test_viz import read_rrd

    for walls, sim in rovers.items():
        path = tmp_path / f"walls_{walls}.rrd"
        recorder = RerunRecorder(sim, path=path, worlds=[0])
        recorder.log_step()
        recorder.close()
        assert ("/world_0/arena/walls" in read_rrd(path)) == walls


def test_the_example_map_is_what_its_script_draws_and_every_robot_fits_its_doorways():
    """``atrv_warp/assets/maps/office.yaml`` (shipped as package data) reads back as ``docs/make_example_map.py``
    draws it, cell for cell; each shipped robot can start and end an episode in every room of it (one group of
    spawn cells: every doorway passes its inscribed radius)."""
    import importlib.util
    from pathlib import Path

    from atrv_warp.core.robot import ROBOTS
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.sim.maps import distance_field
    from atrv_warp.sim.urdf import footprint_radii, load_rover

    root = Path(__file__).resolve().parent.parent
    spec = importlib.util.spec_from_file_location("make_example_map", root / "docs" / "make_example_map.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    shipped = load_map(root / "atrv_warp" / "assets" / "maps" / "office.yaml")
    drawn = script.office()
    assert shipped.resolution == drawn.resolution and shipped.origin == drawn.origin
    assert np.array_equal(shipped.cells, drawn.cells)
    field = distance_field(shipped.walls)
    for robot in ROBOTS:
        rover = nominal_rover_config(robot)
        inscribed, circumscribed = footprint_radii(load_rover(rover), rover)
        cells, first, _ = spawn_cells(field, shipped.resolution, circumscribed, inscribed)
        assert len(cells) > 1000 and len(set(first.tolist())) == 1, robot
