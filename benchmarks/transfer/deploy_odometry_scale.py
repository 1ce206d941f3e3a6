"""Deployable nav policies on a base whose wheel odometry over-reads: success against the odometry's scale.

Run: ``python -m benchmarks.transfer.deploy_odometry_scale [--policy nav_deploy] [--policy before=OLD.pt] [--episodes 1000]``

Wheels that creep or slip turn further than the rover moves, so a base's encoders over-read the distance driven
(``benchmarks/transfer/mujoco_odometry.py`` measures it in our simulator and in the MuJoCo twin). A policy that sees its goal
from odometry then believes it has arrived short of the goal. Each policy runs one deterministic episode in each of
``--episodes`` worlds of the test set (``EVAL_SEED``) on the nominal rover, its odometry reading
``RandomizationConfig.odometry_scale`` times the distance driven (fixed per run: 1.0, 1.1, 1.2, 1.3), and under
``wide`` with the same scales. The episodes are the same in every run.

Prints the table and writes ``benchmarks/results/deploy_odometry_scale.json`` with each policy's sha256.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from benchmarks._common import labelled, load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
SCALES = (1.0, 1.1, 1.2, 1.3)
"""The odometry's distance per distance driven in each run [-]."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", action="append", metavar="[LABEL=]POLICY",
                        help="a deployable policy (shipped name or file), repeatable (default: nav_deploy)")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--out", default=str(RESULTS / "deploy_odometry_scale.json"))
    args = parser.parse_args()
    policies = [labelled(p) for p in (args.policy or ["nav_deploy"])]

    import torch

    torch.set_num_threads(1)
    from atrv_warp.policy import load_policy, policy_path
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_result, run_episodes
    from atrv_warp.task.randomization import RANDOMIZATION_PRESETS, Draw

    result = {"benchmark": "deploy_odometry_scale", "episodes": args.episodes, "seed": EVAL_SEED,
              "scales": list(SCALES), "policies": {}}
    paths = []
    for label, name in policies:
        policy = load_policy(name, task="nav_deploy")
        path = policy_path(name)
        paths.append(str(path))
        rows = result["policies"][label] = {"runs": []}  # the file and its sha256: the provenance's policies
        print(f"{label} ({path}): {args.episodes} test episodes", flush=True)
        for preset in ("none", "wide"):
            for scale in SCALES:
                t0 = time.perf_counter()
                shift = dataclasses.replace(RANDOMIZATION_PRESETS[preset], odometry_scale=Draw(scale, scale))
                env = ATRVjrEnv(args.episodes, task="nav_deploy", randomization=shift)
                summary = run_episodes(policy, env, seed=EVAL_SEED).summary()
                rows["runs"].append({"randomization": preset, "odometry_scale": scale, **summary.as_dict(),
                                     "seconds": round(time.perf_counter() - t0, 1)})
                print(format_result(f"  {preset:>4}, odometry x {scale:.1f}", summary), flush=True)
    out = write_results(args.out, result, version=VERSION, task=True, policies=tuple(paths), driver=True)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def deploy_odometry_scale(name: str = "deploy_odometry_scale.json") -> str:
    """``deploy_odometry_scale.json``: deployable policies' success (and timeouts) against how many times the distance
    driven their odometry reads, on the nominal rover and under ``wide``."""
    d = load_results(name)
    presets = {"none": "nominal", "wide": "`wide`"}
    columns = [(label, preset) for label in d["policies"] for preset in presets]
    rows = []
    for scale in d["scales"]:
        cells = []
        for label, preset in columns:
            r = next(r for r in d["policies"][label]["runs"]
                     if r["randomization"] == preset and r["odometry_scale"] == scale)
            cells.append(f"**{100 * r['success_rate']:.1f} %** ({100 * r['timeout_rate']:.1f} %)")
        rows.append([f"{scale:.1f}", *cells])
    return markdown_table(["odometry / distance driven", *[f"{label}, {presets[p]}: success (timeout)" for label, p in columns]],
                          ["---:"] * (1 + len(columns)), rows)


TABLES = {
    "deploy_odometry_scale": deploy_odometry_scale,
}


if __name__ == "__main__":
    sys.exit(main())
