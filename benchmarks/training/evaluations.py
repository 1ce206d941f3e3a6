"""The shipped policies and the scripted drivers on the test set: the evaluations table of the docs' tasks page.

Run: ``python -m benchmarks.training.evaluations`` (about a minute once the kernels are compiled). Each driver runs one
deterministic episode in each of 1,000 worlds of its task, seeded with the test set's seed (``EVAL_SEED``),
exactly as ``python -m atrv_warp.evaluate [--task nav] [--baseline]`` does, and the figures go to
``benchmarks/results/evaluations.json`` with the sha256 of each policy file.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
DRIVERS = (("reach", "policy", "shipped reach policy, SAC"), ("reach", "baseline", "scripted driver, reach"),
           ("nav", "policy", "shipped nav policy, SAC trained under `wide`"), ("nav", "baseline", "scripted driver, nav"),
           ("nav_deploy", "policy", ("shipped deployable nav policy (/cmd_vel from odometry, IMU and scan), SAC "
                                     "trained under `wide`")))
"""(task, driver, label) of each row, in the table's order."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--out", default=str(RESULTS / "evaluations.json"))
    args = parser.parse_args()
    from atrv_warp.policy import load_policy, pretrained_policy_path, shipped_policy_path
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_result, run_episodes

    rows, policies = [], []
    for task, driver, label in DRIVERS:
        if driver == "policy":
            path = shipped_policy_path(task) if task != "reach" else pretrained_policy_path()
            policy, name = load_policy(path, task=task), str(Path(path).relative_to(Path(__file__).resolve().parents[2]))
            policies.append(path)
        else:
            policy, name = scripted_policy(), f"scripted baseline ({task})"
        t0 = time.perf_counter()
        result = run_episodes(policy, ATRVjrEnv(args.episodes, task=task), seed=EVAL_SEED).summary()
        print(format_result(name, result), f"({time.perf_counter() - t0:.1f} s)", flush=True)
        rows.append({"task": task, "driver": driver, "label": label, "policy": name, **result.as_dict()})
    out = write_results(args.out, {"benchmark": "evaluations", "seed": EVAL_SEED, "episodes": args.episodes,
                                   "rows": rows}, version=VERSION, task=True, policies=tuple(policies))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def evaluations() -> str:
    """``evaluations.json``: the shipped policies and the scripted drivers on the 1,000 test episodes."""
    rows = []
    for e in load_results("evaluations.json")["rows"]:
        rows.append([e["label"], f"**{100 * e['success_rate']:.1f} %**", f"{100 * e['wall_rate']:.1f} %",
                     f"{100 * e.get('obstacle_rate', 0.0):.1f} %", f"{100 * e['flip_rate']:.1f} %",
                     f"{100 * e['timeout_rate']:.1f} %", f"{e['mean_return']:.2f}", f"{e['mean_steps']:.1f}"])
    return markdown_table(["policy", "success", "wall", "obstacle", "flip", "timeout", "mean return", "mean steps"],
                          ["---"] + ["---:"] * 7, rows)


TABLES = {
    "evaluations": evaluations,
}


if __name__ == "__main__":
    sys.exit(main())
