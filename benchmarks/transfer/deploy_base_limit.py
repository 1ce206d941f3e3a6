"""What the deployable task's base acceleration limit does: the deployable nav policy with and without it.

Run: ``python -m benchmarks.transfer.deploy_base_limit [--policy nav_deploy] [--episodes 1000]``

The policy runs one deterministic episode in each of ``--episodes`` worlds of the test set (``EVAL_SEED``), on the
nominal rover (``none``) and under ``wide``, twice: through a base without acceleration limits (the
``diff_drive_controller`` default), and through ``nav_deploy``'s (``TaskConfig.linear_max_acceleration``, 1 m/s²,
the Husky A200's). The episodes are the same in all four. Per run: success and how episodes ended, and how far
the goal the policy sees is from the true one: each step's |observed goal distance (fused odometry) - true
distance| [m], its maximum over each episode, as the median and 90th percentile over episodes (under ``wide`` it
includes the odometry noise's drift). A launch on flat ground at the nominal µ (a full-speed ``/cmd_vel`` from rest
for 2 s) gives the fused odometry's distance over the true one, with and without the limit.

Prints the table and writes ``benchmarks/results/deploy_base_limit.json`` with the policy's sha256.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def odometry_error(policy, env, seed: int) -> tuple:
    """(EpisodeRecord, per-episode max |observed - true goal distance| [m]) of one deterministic run."""
    import torch

    from atrv_warp.task.evaluation import run_episodes

    worst = torch.zeros(env.num_envs)
    live = torch.ones(env.num_envs, dtype=torch.bool)

    def on_step(env_, td):
        # the step's next observation and the true distance after it, while the episode runs
        err = (td["next", "observation"][:, 0] - env_.target_distance).abs().cpu()
        worst.copy_(torch.where(live, torch.maximum(worst, err), worst))
        live.logical_and_(~td["next", "done"].reshape(-1).cpu())

    record = run_episodes(policy, env, seed=seed, on_step=on_step)
    return record, worst


def launch_ratio(limit: float | None) -> float:
    """Fused odometry's distance / the true distance after 2 s of a full-speed /cmd_vel from rest (flat, µ 0.3)."""
    import torch

    from atrv_warp.task.config import TaskConfig
    from atrv_warp.task.env import ATRVjrEnv

    env = ATRVjrEnv(1, seed=0, task=TaskConfig(action="twist", observation="robot", linear_max_acceleration=limit))
    td = env.reset()
    start = env.sim.root_pose[0, :2].clone()
    for _ in range(40):
        td = env.step(td.set("action", torch.tensor([[1.0, 0.0]])))["next"]
    return env.sim.driver.fused[0, 0].item() / (env.sim.root_pose[0, :2] - start).norm().item()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="nav_deploy", help="a deployable policy (name or file)")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--out", default=str(RESULTS / "deploy_base_limit.json"))
    args = parser.parse_args()

    import torch

    torch.set_num_threads(1)
    from atrv_warp.policy import load_policy, policy_path
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_result
    from atrv_warp.task.registry import get_task

    task = get_task("nav_deploy")
    policy = load_policy(args.policy, task="nav_deploy")
    path = policy_path(args.policy)
    bases = {"unlimited": None, "limited": task.linear_max_acceleration}  # the base without and with the task's limit
    result = {"benchmark": "deploy_base_limit", "policy": str(path), "episodes": args.episodes, "seed": EVAL_SEED,
              "limit": {"linear_max_acceleration": task.linear_max_acceleration, "unit": "m/s²"}, "runs": []}
    print(f"{path}: {args.episodes} test episodes; the base without limits (unlimited) and with "
          f"linear.x.max_acceleration {task.linear_max_acceleration:g} m/s²", flush=True)
    for randomization in ("none", "wide"):
        for base, limit in bases.items():
            t0 = time.perf_counter()
            env = ATRVjrEnv(args.episodes, task=dataclasses.replace(task, linear_max_acceleration=limit),
                            randomization=randomization)
            record, worst = odometry_error(policy, env, EVAL_SEED)
            summary = record.summary()
            row = {"randomization": randomization, "base": base, **summary.as_dict(),
                   "odometry_error_median": float(worst.median()), "odometry_error_p90": float(worst.quantile(0.9)),
                   "seconds": round(time.perf_counter() - t0, 1)}
            result["runs"].append(row)
            print(format_result(f"{randomization:>4}, base {base}", summary), flush=True)
            print(f"      goal seen from odometry off the true one by up to {row['odometry_error_median']:.2f} m "
                  f"(median episode), {row['odometry_error_p90']:.2f} m (90th percentile)", flush=True)
    result["launch_odometry_ratio"] = {base: launch_ratio(limit) for base, limit in bases.items()}
    print("a 2 s full-speed launch at µ 0.3, fused odometry / true distance: "
          + ", ".join(f"{k} {v:.3f}" for k, v in result["launch_odometry_ratio"].items()))
    out = write_results(args.out, result, version=VERSION, task=True, policies=(str(path),), driver=True)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def deploy_base_limit(name: str = "deploy_base_limit.json") -> str:
    """``deploy_base_limit.json``: the deployable policy through a base without and with the task's acceleration
    limit, success and how far the goal it sees from odometry is from the true one."""
    d = load_results(name)
    rows = []
    for r in d["runs"]:
        base = "none" if r["base"] == "unlimited" else f"{d['limit']['linear_max_acceleration']:g} m/s²"
        rows.append(["`wide`" if r["randomization"] == "wide" else "nominal", base, f"**{r['success_rate']:.1%}**",
                     f"{r['timeout_rate']:.1%}", f"{r['obstacle_rate']:.1%}", f"{r['mean_steps']:.0f}",
                     f"{r['odometry_error_median']:.2f} / {r['odometry_error_p90']:.2f}"])
    return markdown_table(["rover", "base's acceleration limit", "success", "timeout", "obstacle", "mean steps",
                   "goal seen from odometry, off by up to [m] (median / 90th pct. episode)"],
                          ["---", "---", "---:", "---:", "---:", "---:", "---:"], rows)


TABLES = {
    "deploy_base_limit": deploy_base_limit,
}


if __name__ == "__main__":
    sys.exit(main())
