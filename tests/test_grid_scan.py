"""The laser against a map's grid (``atrv_warp.sim.kernels.grid``): the distance field is the exact Euclidean
distance transform, and a beam cast through the grid reads what today's box scan reads where both describe the same
world (boxes on cell boundaries drawn into a grid), within half a cell."""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from atrv_warp.sim.kernels.obstacles import OBSTACLE_BOX, ray_obstacle
from atrv_warp.sim.maps import GridWorlds, distance_field
from atrv_warp.world import OccupancyMap
from atrv_warp.world.nav2_map import FREE, OCCUPIED, UNKNOWN


def brute_distance(walls: np.ndarray) -> np.ndarray:
    """Each cell's distance [cells] to the nearest wall cell or the border beyond the grid, by trying every one."""
    rows, cols = walls.shape
    padded = np.ones((rows + 2, cols + 2), dtype=bool)
    padded[1:-1, 1:-1] = walls
    wr, wc = np.nonzero(padded)
    r, c = np.mgrid[1:rows + 1, 1:cols + 1]
    d2 = (r[..., None] - wr) ** 2 + (c[..., None] - wc) ** 2
    return np.sqrt(d2.min(-1))


def test_the_distance_field_is_the_exact_euclidean_transform():
    rng = np.random.default_rng(0)
    for shape, density in (((37, 23), 0.05), ((16, 61), 0.01), ((40, 40), 0.0), ((9, 9), 0.5)):
        walls = rng.random(shape) < density
        assert np.allclose(distance_field(walls), brute_distance(walls), atol=1e-5), (shape, density)


def boxes_world(rng, count: int, resolution: float, cells: int):
    """``count`` axis-aligned boxes whose sides lie on cell boundaries, in a square map of ``cells`` cells a side
    centred on the origin: (the map, the boxes as (cx, cy, hx, hy) [m])."""
    grid = np.full((cells, cells), FREE, dtype=np.int8)
    boxes = []
    for _ in range(count):
        r0, c0 = rng.integers(0, cells - 12, size=2)
        h, w = rng.integers(1, 12, size=2)
        grid[r0:r0 + h, c0:c0 + w] = OCCUPIED if rng.random() < 0.5 else UNKNOWN  # both are walls
        x0, y0 = -cells * resolution / 2 + c0 * resolution, -cells * resolution / 2 + r0 * resolution
        boxes.append((x0 + w * resolution / 2, y0 + h * resolution / 2, w * resolution / 2, h * resolution / 2))
    site = OccupancyMap(cells=grid, resolution=resolution, origin=(-cells * resolution / 2, -cells * resolution / 2))
    return site, np.array(boxes, dtype=np.float32)


@wp.kernel
def cast_boxes(boxes: wp.array(dtype=wp.vec4), origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
               t_max: float, top: float, ranges: wp.array(dtype=float)):
    i = wp.tid()
    t = t_max
    for b in range(boxes.shape[0]):
        box = boxes[b]
        t = wp.min(t, ray_obstacle(OBSTACLE_BOX, wp.vec3(box[0], box[1], 0.0), wp.vec2(box[2], box[3]), top,
                                   origins[i], directions[i], t))
    ranges[i] = t


def test_a_beam_through_the_grid_reads_what_the_box_scan_reads():
    """200 origins in free space, 90 beams each, in a 30 m map at 0.1 m holding 150 boxes (occupied or unknown):
    every range within half a cell of the box scan's (the map's border lies beyond the 8 m range)."""
    rng = np.random.default_rng(1)
    resolution, cells, max_range = 0.1, 300, 8.0
    site, boxes = boxes_world(rng, 150, resolution, cells)
    grids = GridWorlds([site], world_map=[0])
    free_cells = np.argwhere(site.cells[100:200, 100:200] == FREE) + 100  # within 5 m of the centre
    picks = free_cells[rng.choice(len(free_cells), 200, replace=False)]
    x, y = site.centre_of(picks[:, 0], picks[:, 1])
    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    origins = np.repeat(np.stack([x, y, np.full_like(x, 0.3)], -1), len(angles), axis=0)
    origins[:, :2] += rng.uniform(-0.5, 0.5, (len(origins), 2)) * resolution * 0.9  # anywhere in the cell
    a = np.tile(angles, len(picks)) + rng.uniform(-0.01, 0.01, len(origins))
    directions = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1)
    grid_ranges = grids.cast(0, origins, directions, max_range)
    box_ranges = wp.empty(len(origins), dtype=float)
    wp.launch(cast_boxes, dim=len(origins), inputs=[wp.array(boxes, dtype=wp.vec4),
                                                    wp.array(origins.astype(np.float32), dtype=wp.vec3),
                                                    wp.array(directions.astype(np.float32), dtype=wp.vec3),
                                                    max_range, 2.0], outputs=[box_ranges])
    box_ranges = box_ranges.numpy()
    inside = np.array([any(abs(o[0] - b[0]) <= b[2] and abs(o[1] - b[1]) <= b[3] for b in boxes) for o in origins])
    assert not inside.any()  # every origin is in free space, as a rover's scanner is
    hits = box_ranges < max_range
    assert 0.3 < hits.mean() < 0.95  # the boxes are in sight of most beams, and not all
    assert np.abs(grid_ranges - box_ranges).max() <= resolution / 2, np.abs(grid_ranges - box_ranges).max()


def test_a_beam_over_the_walls_or_from_inside_one():
    grid = np.zeros((50, 50), dtype=np.int8)
    grid[:, 30] = OCCUPIED  # a wall along y at x = 3.0-3.1 m
    grids = GridWorlds([OccupancyMap(cells=grid, resolution=0.1, origin=(0.0, 0.0))], world_map=[0], wall_top=1.0)
    rising = np.array([math.cos(0.5), 0.0, math.sin(0.5)])  # 29 degrees up: 1.3 m high at the wall
    level = np.array([1.0, 0.0, 0.0])
    ranges = grids.cast(0, [[1.0, 2.5, 0.2], [1.0, 2.5, 0.2], [3.05, 2.5, 0.2], [1.0, 2.5, 0.2]],
                        [level, rising, level, -level], 10.0)
    assert ranges[0] == pytest.approx(2.0, abs=1e-5)  # enters the wall's first cell at x = 3.0
    assert ranges[1] == 10.0  # passes over the 1 m wall
    assert ranges[2] == 0.0  # from inside a wall
    assert ranges[3] == pytest.approx(1.0, abs=1e-5)  # the map's edge at x = 0: what lies beyond is unknown


def test_a_rover_in_a_map_sees_its_walls_and_is_stopped_by_them():
    """``RoverSim(maps=[...])``: the laser reads the map's wall (and, beyond the map's edge, the unknown), worlds take
    the maps in turn, and a rover driven into a wall is held by it and flagged as touching an obstacle, while a rover
    in a world without that wall drives on."""
    import torch

    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.kernels.contact import FLAG_OBSTACLE
    from atrv_warp.sim.scanner import LaserScanner, ScannerConfig

    walled = np.zeros((200, 200), dtype=np.int8)  # 10 m square at 0.05 m about the origin
    walled[:, 160] = OCCUPIED  # a wall across x = 3.0 ... 3.05 m
    open_site = OccupancyMap(cells=np.zeros((200, 200), dtype=np.int8), resolution=0.05, origin=(-5.0, -5.0))
    sim = RoverSim(3, maps=[OccupancyMap(cells=walled, resolution=0.05, origin=(-5.0, -5.0)), open_site])
    assert sim.maps.world_map.tolist() == [0, 1, 0]
    scanner = LaserScanner(sim, ScannerConfig(beams=1, fov=0.1))
    sim.reset(poses=torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, math.pi]]))
    sim.step()
    scanner.scan()
    ranges = scanner.ranges[:, 0].tolist()
    assert ranges[0] == pytest.approx(ranges[1] - 2.0, abs=0.01)  # the wall 2 m before the open map's edge
    assert ranges[2] == pytest.approx(ranges[1], abs=0.01)  # facing the walled map's edge at x = -5: as far
    touched, furthest = torch.zeros(3, dtype=torch.int32), -math.inf
    for _ in range(round(4.0 / sim.sim_cfg.step_dt)):  # 4 s at 1 m/s: 3 m to the wall, 5 to the open map's edge
        sim.set_twist(torch.tensor([[1.0, 0.0], [1.0, 0.0], [0.0, 0.0]]))
        sim.step()
        touched |= sim.contact_flags.cpu() & int(FLAG_OBSTACLE)
        furthest = max(furthest, float(sim.root_pose[0, 0]))
    front = 3.0 - furthest  # the wall's face from the chassis' centre, nearest: the chassis' front half, no less
    assert 0.2 < front < 0.8, furthest
    assert touched.tolist() == [int(FLAG_OBSTACLE), 0, 0]
    assert float(sim.root_pose[1, 0]) > 3.0  # no wall in the open map


def test_a_100_m_map_at_5_cm_loads_from_its_files_and_steps(tmp_path):
    """The size issue 72 names (2,000 x 2,000 cells), given to the simulator as a YAML's path: it loads, its rover
    steps, and its laser reads the building's outer wall."""
    import torch
    from PIL import Image

    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.scanner import LaserScanner, ScannerConfig

    pixels = np.full((2000, 2000), 254, dtype=np.uint8)
    pixels[:20], pixels[-20:], pixels[:, :20], pixels[:, -20:] = 0, 0, 0, 0  # 1 m outer walls
    Image.fromarray(pixels, mode="L").save(tmp_path / "hall.pgm")
    (tmp_path / "hall.yaml").write_text("image: hall.pgm\nresolution: 0.05\norigin: [-50.0, -50.0, 0.0]\nnegate: 0\n"
                                        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    sim = RoverSim(1, maps=[tmp_path / "hall.yaml"])
    assert sim.maps.maps[0].shape == (2000, 2000) and sim.maps.maps[0].name == "hall"
    scanner = LaserScanner(sim, ScannerConfig(beams=1, fov=0.1, max_range=60.0))
    sim.reset(poses=torch.tensor([[10.0, 0.0, 0.0]]))
    sim.step()
    scanner.scan()
    assert 38.0 < float(scanner.ranges[0, 0]) < 39.0  # the outer wall's face at x = 49 m, from a laser ahead of 10 m
