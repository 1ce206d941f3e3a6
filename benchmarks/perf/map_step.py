"""The environment's step in map worlds against today's ``nav_deploy`` step, same worlds and beams, in one run.

Run: ``python -m benchmarks.perf.map_step [--worlds 1024] [--seconds 3] [--rounds 3] [--device cuda:0]``

In this process (pinned to one core on the CPU, one torch thread): env-steps/s of ``nav_deploy`` on the ATRV-Jr
stepping random actions with resets, in the task's arena (terrain, obstacle slots, the 64-beam scan against boxes)
and in map worlds (the same task, its terrain and obstacles, the scan and the chassis against the map's grid too):
procedural buildings and yards (``building:16``, ``yard:16``, the worlds round-robin) and one 100 m x 100 m map at
0.05 m (4 M cells, a large site); then the buildings and the yards with Nav2's planner in the loop
(``PlannerConfig()``: a plan at every reset, a replan every second). Measured alternately, best of ``--rounds``
each; kernel compilation excluded. Targets (issue 72): a map world's step at most 1.5x the arena's (part 9); the
planner's resets and replans at most 20 % on the same worlds' step (part 5). Written to
``benchmarks/results/map_step.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import pin_to_one_core, random_step, rate, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
TARGET = 1.5
"""The most a map world's step may cost, as a multiple of the arena's (issue 72, part 9)."""
PLANNER_TARGET = 1.2
"""The most the planner in the loop may cost, as a multiple of the same worlds' step without it (part 5)."""


def large_site():
    """A 100 m square at 0.05 m: walls every 10 m with doorways, as a large building's floor."""
    import numpy as np

    from atrv_warp.world import OccupancyMap
    from atrv_warp.world.nav2_map import FREE, OCCUPIED

    cells = np.full((2000, 2000), FREE, dtype=np.int8)
    cells[[0, -1], :] = cells[:, [0, -1]] = OCCUPIED
    for k in range(200, 2000, 200):
        cells[k:k + 3, :] = OCCUPIED
        cells[:, k:k + 3] = OCCUPIED
        cells[k:k + 3, k // 2 + 40:k // 2 + 70] = FREE  # a 1.5 m doorway in each wall
        cells[k // 2 + 40:k // 2 + 70, k:k + 3] = FREE
    return OccupancyMap(cells=cells, resolution=0.05, origin=(-50.0, -50.0), label="floor_100m")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=1024)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--device", default="cpu", help="simulation device, e.g. cuda:0")
    parser.add_argument("--out", default=str(RESULTS / "map_step.json"))
    args = parser.parse_args()
    if args.device == "cpu":
        pin_to_one_core()
    import torch
    import warp as wp

    torch.set_num_threads(1)
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv

    worlds = {"arena": ((), None), "building:16": (("building:16",), None), "yard:16": (("yard:16",), None),
              "floor_100m": ((large_site(),), None), "building:16 + planner": (("building:16",), PlannerConfig()),
              "yard:16 + planner": (("yard:16",), PlannerConfig())}
    t0 = time.perf_counter()
    envs = {name: RoverEnv(args.worlds, task="nav_deploy", seed=0, device=args.device, maps=maps, planner=planner)
            for name, (maps, planner) in worlds.items()}
    build_s = time.perf_counter() - t0
    gen = torch.Generator().manual_seed(0)
    steppers = {name: random_step(env, gen) for name, env in envs.items()}
    for step in steppers.values():  # the first steps compile (or load) every kernel
        for _ in range(3):
            step()
    best = dict.fromkeys(envs, 0.0)
    for _ in range(args.rounds):  # interleaved: every world kind sees the same machine load
        for name in envs:
            best[name] = max(best[name], rate(steppers[name], args.worlds, args.seconds, sync=wp.synchronize))
    rows = [{"worlds": name, "env_steps_per_s": best[name], "us_per_world_step": 1e6 / best[name],
             "over_arena": best["arena"] / best[name]} for name in envs]
    for row in rows:
        print(f"{row['worlds']:>12}: {row['env_steps_per_s']:8.0f} env-steps/s, {row['us_per_world_step']:6.1f} us per "
              f"world-step, {row['over_arena']:.2f}x the arena's", flush=True)
    worst = max(row["over_arena"] for row in rows if "planner" not in row["worlds"])
    planner = {kind: best[kind] / best[f"{kind} + planner"] for kind in ("building:16", "yard:16")}
    for kind, ratio in planner.items():
        print(f"the planner in the loop on {kind}: {ratio:.2f}x the step without it", flush=True)
    result = {"benchmark": "map_step", "target": f"a map world's step <= {TARGET}x the arena's; the planner's resets "
              f"and replans <= {PLANNER_TARGET}x", "device": args.device,
              "num_worlds": args.worlds, "build_s": build_s, "rows": rows, "worst_over_arena": worst,
              "planner_over_plain": planner, "meets_target": worst <= TARGET,
              "planner_meets_target": max(planner.values()) <= PLANNER_TARGET,
              "time": time.strftime("%Y-%m-%d %H:%M:%S"), "python": sys.version.split()[0]}
    out = write_results(args.out, result, version=VERSION, task=True)
    print(f"worst map world {worst:.2f}x the arena's (target <= {TARGET}x); planner at most "
          f"{max(planner.values()):.2f}x (target <= {PLANNER_TARGET}x); written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
