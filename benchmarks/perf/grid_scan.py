"""What a laser beam costs in a map: the grid raycast with the distance field (leaps in open space, cells near walls)
against the same raycast walking every cell (a DDA alone), and today's scan of eight boxes, per world-step.

Run: ``python -m benchmarks.perf.grid_scan [--worlds 1024] [--beams 64] [--repeats 5] [--device cpu]``

The map is a 100 m square building at 0.05 m (2,000 x 2,000 cells, the size issue 72 asks to load and step): outer
walls, rooms of 10 m joined by 1.2 m doorways, and furniture (boxes of 0.3-1.5 m) in each room. ``--worlds`` scanners
stand at seeded free positions at least 0.5 m from any wall, ``--beams`` beams over 360 degrees up to 20 m (the
scanner's default range). Both grid variants run one kernel (:func:`atrv_warp.sim.kernels.grid.ray_grid`); the DDA
alone is that kernel given a distance field of zeros, so it never leaps. Before timing, the two variants' ranges are
checked to agree within 1 mm (a walk over hundreds of cells sums float32 rounding). Each variant is timed ``--repeats`` times, interleaved, and the median kept; the
distance field's build time is reported apart (once per map, at load). The box scan is eight boxes per world
(``nav_deploy``'s most obstacles) through :func:`~atrv_warp.sim.kernels.obstacles.ray_obstacle`, for scale.
Written to ``benchmarks/results/grid_scan.json``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

import numpy as np

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
RESOLUTION, SIDE, ROOM, DOOR, MAX_RANGE = 0.05, 100.0, 10.0, 1.2, 20.0
"""The building: cell [m], side [m], room [m], doorway [m]; the beams' range [m]."""


def building(seed: int = 0) -> np.ndarray:
    """(rows, cols) bool walls of the benchmark's building (see the module's docstring)."""
    rng = np.random.default_rng(seed)
    n, room, door, wall = round(SIDE / RESOLUTION), round(ROOM / RESOLUTION), round(DOOR / RESOLUTION), 3
    walls = np.zeros((n, n), dtype=bool)
    walls[:wall], walls[-wall:], walls[:, :wall], walls[:, -wall:] = True, True, True, True
    for k in range(room, n, room):  # the rooms' walls, a doorway in each wall segment
        walls[k:k + wall], walls[:, k:k + wall] = True, True
        for j in range(0, n, room):
            gap = j + rng.integers(wall + 2, room - door - 2)
            walls[k:k + wall, gap:gap + door] = False
            walls[gap:gap + door, k:k + wall] = False
    for r0 in range(0, n, room):  # furniture: two to four boxes a room
        for c0 in range(0, n, room):
            for _ in range(rng.integers(2, 5)):
                h, w = rng.integers(round(0.3 / RESOLUTION), round(1.5 / RESOLUTION), size=2)
                r, c = r0 + rng.integers(wall + 20, room - h - 20), c0 + rng.integers(wall + 20, room - w - 20)
                walls[r:r + h, c:c + w] = True
    return walls


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=1024)
    parser.add_argument("--beams", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default=str(RESULTS / "grid_scan.json"))
    args = parser.parse_args(argv)

    import warp as wp

    from atrv_warp import runtime
    from atrv_warp.sim.kernels.obstacles import OBSTACLE_BOX, ray_obstacle
    from atrv_warp.sim.maps import GridWorlds, cast_grid_rays
    from atrv_warp.world import OccupancyMap
    from atrv_warp.world.nav2_map import FREE, OCCUPIED

    runtime.configure()

    @wp.kernel
    def cast_boxes(boxes: wp.array2d(dtype=wp.vec4), origins: wp.array(dtype=wp.vec3),
                   directions: wp.array(dtype=wp.vec3), beams: int, t_max: float, ranges: wp.array(dtype=float)):
        i = wp.tid()
        world = i / beams
        t = t_max
        for b in range(boxes.shape[1]):
            box = boxes[world, b]
            t = wp.min(t, ray_obstacle(OBSTACLE_BOX, wp.vec3(box[0], box[1], 0.0), wp.vec2(box[2], box[3]), 2.0,
                                       origins[i], directions[i], t))
        ranges[i] = t

    device = wp.get_device(args.device)
    walls = building()
    site = OccupancyMap(cells=np.where(walls, OCCUPIED, FREE).astype(np.int8), resolution=RESOLUTION,
                        origin=(-SIDE / 2, -SIDE / 2))
    GridWorlds([site], world_map=[0], device=device)  # compile
    t0 = time.perf_counter()
    grids = GridWorlds([site], world_map=[0] * args.worlds, device=device)
    field_s = time.perf_counter() - t0
    walking = GridWorlds([site], world_map=[0] * args.worlds, device=device)
    walking.struct.distance = wp.zeros_like(walking.struct.distance)  # never leaps: a DDA over every cell

    rng = np.random.default_rng(1)
    clear = np.argwhere(grids.distance[0] >= 0.5 / RESOLUTION)
    cells = clear[rng.choice(len(clear), args.worlds, replace=False)]
    x, y = site.centre_of(cells[:, 0], cells[:, 1])
    angles = np.linspace(-math.pi, math.pi, args.beams, endpoint=False)
    origins = np.repeat(np.stack([x, y, np.full_like(x, 0.3)], -1), args.beams, axis=0).astype(np.float32)
    a = np.tile(angles, args.worlds) + rng.uniform(-math.pi, math.pi, args.worlds).repeat(args.beams)
    directions = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1).astype(np.float32)
    boxes = np.stack([rng.uniform(-8, 8, (args.worlds, 8)) + x[:, None], rng.uniform(-8, 8, (args.worlds, 8)) + y[:, None],
                      rng.uniform(0.15, 0.75, (args.worlds, 8)), rng.uniform(0.15, 0.75, (args.worlds, 8))], -1)
    o, d = wp.array(origins, dtype=wp.vec3, device=device), wp.array(directions, dtype=wp.vec3, device=device)
    b = wp.array(boxes.astype(np.float32), dtype=wp.vec4, device=device)
    ranges = wp.empty(len(origins), dtype=float, device=device)

    def run(variant: str):
        if variant == "boxes":
            wp.launch(cast_boxes, dim=len(origins), inputs=[b, o, d, args.beams, MAX_RANGE], outputs=[ranges],
                      device=device)
        else:
            s = (grids if variant == "field" else walking).struct
            wp.launch(cast_grid_rays, dim=len(origins), inputs=[s, 0, o, d, MAX_RANGE], outputs=[ranges], device=device)
        wp.synchronize_device(device)
        return ranges.numpy().copy()

    first = {v: run(v) for v in ("field", "walk", "boxes")}  # compiled and checked before timing
    gap = float(np.abs(first["field"] - first["walk"]).max())
    assert gap <= 1e-3, f"the two grid variants disagree by {gap} m"  # a walk of 400 cells sums its rounding
    seconds = {v: [] for v in first}
    for _ in range(args.repeats):
        for v, times in seconds.items():
            t0 = time.perf_counter()
            run(v)
            times.append(time.perf_counter() - t0)
    per_world_step = {v: statistics.median(s) / args.worlds * 1e6 for v, s in seconds.items()}
    hits = first["field"] < MAX_RANGE
    result = {"device": device.alias, "worlds": args.worlds, "beams": args.beams, "max_range_m": MAX_RANGE,
              "map_cells": list(walls.shape), "resolution_m": RESOLUTION, "repeats": args.repeats,
              "distance_field_s": field_s, "grid_variants_gap_m": gap,
              "mean_range_m": float(first["field"].mean()), "hit_fraction": float(hits.mean()),
              "us_per_world_step": per_world_step,
              "walk_over_field": per_world_step["walk"] / per_world_step["field"],
              "field_over_boxes": per_world_step["field"] / per_world_step["boxes"], "seconds": seconds}
    for v, us in per_world_step.items():
        print(f"{v:<6} {us:8.1f} us per world-step ({args.beams} beams)")
    print(f"distance field of {walls.shape[0]} x {walls.shape[1]} cells: {field_s:.2f} s; the walk costs "
          f"{result['walk_over_field']:.1f}x the field's raycast; the field's is {result['field_over_boxes']:.1f}x "
          "eight boxes'")
    print(f"written to {write_results(args.out, result, version=VERSION, dynamics=False)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
