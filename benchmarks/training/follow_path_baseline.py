"""Nav2's Regulated Pure Pursuit on the ``follow_path`` task, for each shipped robot: the baseline a learned path
follower is measured against, and what the floor under the places does to it.

Run: ``python -m benchmarks.training.follow_path_baseline [--episodes 128]`` (about ten minutes on 2 cores). For each
shipped robot, ``atrv_warp.task.pursuit`` drives one deterministic episode in each of ``--episodes`` worlds of
``follow_path`` fitted to it, seeded with the test set's seed, as ``python -m atrv_warp.evaluate --baseline --task
follow_path --map building:16@1000 yard:16@1000`` does: procedural places of seeds the training preset never draws,
on the task's flat floors and on the nav terrain's rolling hills, with the task's unmapped obstacles (one on the
plan) and without them. The plan is over the map alone, so the obstacle on it is met, except in the rows with Nav2's
obstacle layer (``PlannerConfig(obstacle_layer=True)``: an obstacle the laser sees is marked in the costmap and the
next replan goes round it): the replanning baseline. Written to ``benchmarks/results/follow_path_baseline.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
ROBOTS = ("atrvjr", "husky", "jackal")
PLACES = ("building:16@1000", "yard:16@1000")
"""Test places: seeds from 1000 on (the training preset draws 0-31)."""
CASES = (("flat", True, False), ("flat", True, True), ("flat", False, False), ("rolling", True, True),
         ("rolling", False, False))
"""(terrain, unmapped obstacles, the obstacle layer) of each row: the task's own first."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=128)
    parser.add_argument("--robots", nargs="+", default=list(ROBOTS))
    parser.add_argument("--out", default=str(RESULTS / "follow_path_baseline.json"))
    args = parser.parse_args()
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_result, run_episodes
    from atrv_warp.task.pursuit import pursuit_policy

    rows = []
    for robot in args.robots:
        for terrain, obstacles, layer in CASES:
            scene = {} if obstacles else {"obstacles": 0, "obstacles_on_path": 0}
            env = RoverEnv(args.episodes, task="follow_path", robot=robot, maps=PLACES, terrain=terrain,
                           planner=PlannerConfig(obstacle_layer=layer), **scene)
            t0 = time.perf_counter()
            record = run_episodes(pursuit_policy(env.task_cfg, env.robot), env, seed=EVAL_SEED)
            result = record.summary()
            label = f"{robot}, {terrain}, {_obstacles(obstacles, layer)}"
            print(format_result(label, result), f"({time.perf_counter() - t0:.0f} s)", flush=True)
            success = record.success
            rows.append({"robot": robot, "terrain": terrain, "unmapped_obstacles": obstacles, "obstacle_layer": layer,
                         **result.as_dict(),
                         "success_median_path_ratio": float(record.path_ratio[success].median()) if success.any()
                         else None})
    out = write_results(args.out, {"benchmark": "follow_path_baseline", "seed": EVAL_SEED, "episodes": args.episodes,
                                   "places": list(PLACES), "rows": rows}, version=VERSION, task=True, driver=True,
                        robots=tuple(args.robots), tasks=tuple(("follow_path", r) for r in args.robots))
    print(f"written to {out}")
    return 0


def _obstacles(obstacles: bool, layer: bool) -> str:
    if not obstacles:
        return "none"
    return "on the plan, replanned round once seen" if layer else "on the plan"


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def follow_path_baseline() -> str:
    """``follow_path_baseline.json``: Regulated Pure Pursuit on ``follow_path`` per robot, floor, obstacles and
    the obstacle layer."""
    rows = []
    for r in load_results("follow_path_baseline.json")["rows"]:
        ratio = r["success_median_path_ratio"]
        rows.append([r["robot"], r["terrain"], _obstacles(r["unmapped_obstacles"], r["obstacle_layer"]),
                     f"**{100 * r['success_rate']:.1f} %**", f"{100 * (r['obstacle_rate'] + r['wall_rate']):.1f} %",
                     f"{100 * r['no_progress_rate']:.1f} %", f"{100 * r['timeout_rate']:.1f} %",
                     "-" if ratio is None else f"{ratio:.2f}"])
    return markdown_table(["robot", "floor", "unmapped obstacle", "success", "collision", "no progress", "timeout",
                           "driven / plan"], ["---"] * 3 + ["---:"] * 5, rows)


TABLES = {
    "follow_path_baseline": follow_path_baseline,
}


if __name__ == "__main__":
    sys.exit(main())
