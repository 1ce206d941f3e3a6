"""The deployable nav policy beside the torque nav policy: success on the test set, and how each drives.

Run: ``python -m benchmarks.transfer.deploy_policy [--episodes 1000]``

Both shipped nav policies run one deterministic episode in each of 1,000 worlds of the test set
(``EVAL_SEED``), under ``wide`` and on the nominal rover (no randomization): the torque policy
(``nav_policy.pt``: wheel torques from arena coordinates, task ``nav``) and the deployable one
(``nav_deploy_policy.pt``: ``/cmd_vel`` through the base's motor driver from wheel odometry, IMU and scan, task
``nav_deploy``). The two tasks draw the same worlds, starts and goals for a seed, so the episodes are the same.

Per policy and randomization: the success rate and how episodes ended, and how it drives over the steps
before each episode ended: the mean change of forward speed |Δv| [m/s] and of yaw rate |Δω| [rad/s] per 0.05 s
step (the true chassis motion), the mean over episodes of the peak forward speed [m/s], and the closest any
episode came to an obstacle: the chassis origin's distance to the obstacle's bounding circle [m] (the clearance
term's measure; mean over episodes of each episode's minimum, and the 5th percentile).
Prints the table and writes ``benchmarks/results/deploy_policy.json`` with each policy's sha256.
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
POLICIES = (("torque", "nav", "nav"), ("deploy", "nav_deploy", "nav_deploy"))
"""(label, shipped policy name, task) of each row."""


class DrivingStyle:
    """Accumulates, over each world's steps until its episode ends, how the rover moves (an ``on_step`` callback)."""

    def __init__(self, env):
        import torch

        self.torch = torch
        n = env.num_envs
        self.live = torch.ones(n, dtype=torch.bool)
        self.prev = None
        self.dv, self.dw, self.count = torch.zeros(n), torch.zeros(n), torch.zeros(n)
        self.peak = torch.zeros(n)
        self.closest = torch.full((n,), float("inf"))

    def motion(self, sim):
        yaw = sim.rpy[:, 2]
        forward = sim.lin_vel[:, 0] * self.torch.cos(yaw) + sim.lin_vel[:, 1] * self.torch.sin(yaw)
        return forward.clone(), sim.ang_vel[:, 2].clone()

    def clearance(self, sim):
        obstacles = sim.obstacles
        if obstacles.kind.shape[1] == 0:
            return self.torch.full((sim.num_worlds,), float("inf"))
        size = obstacles.size
        radius = self.torch.where(obstacles.kind == 2, size[..., 0], size.norm(dim=-1))  # cylinder; box: corner
        gap = (obstacles.pose[..., :2] - sim.root_pose[:, None, :2]).norm(dim=-1) - radius
        return self.torch.where(obstacles.kind != 0, gap, self.torch.inf).min(-1).values

    def __call__(self, env, td):
        sim = env.sim
        v, w = self.motion(sim)
        live = self.live
        if self.prev is not None:
            self.dv += self.torch.where(live, (v - self.prev[0]).abs(), 0.0)
            self.dw += self.torch.where(live, (w - self.prev[1]).abs(), 0.0)
            self.count += live.float()
        self.peak = self.torch.where(live, self.torch.maximum(self.peak, v), self.peak)
        self.closest = self.torch.where(live, self.torch.minimum(self.closest, self.clearance(sim)), self.closest)
        self.prev = (v, w)
        self.live = live & ~td["next", "done"].reshape(-1).cpu()

    def summary(self) -> dict:
        t = self.torch
        per = self.count.clamp_min(1)
        finite = self.closest[t.isfinite(self.closest)]
        return {"mean_abs_dv": float((self.dv / per).mean()), "mean_abs_dw": float((self.dw / per).mean()),
                "mean_peak_speed": float(self.peak.mean()), "max_peak_speed": float(self.peak.max()),
                "mean_closest_obstacle": float(finite.mean()), "p5_closest_obstacle": float(finite.quantile(0.05))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    from atrv_warp.policy import load_policy, policy_path
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_result, run_episodes

    rows, paths = [], []
    for randomization in ("wide", "none"):
        for label, name, task in POLICIES:
            path = policy_path(name)
            paths.append(path)
            env = ATRVjrEnv(args.episodes, task=task, randomization=randomization)
            style = DrivingStyle(env)
            t0 = time.perf_counter()
            result = run_episodes(load_policy(path, task=task), env, seed=EVAL_SEED, on_step=style).summary()
            row = {"policy": label, "file": Path(path).name, "task": task, "randomization": randomization,
                   **result.as_dict(), **style.summary()}
            rows.append(row)
            print(format_result(f"{label} ({randomization})", result), f"({time.perf_counter() - t0:.0f} s)",
                  flush=True)
    print(f"\n{'policy':>8} {'random.':>7} {'success':>8} {'|dv| m/s':>9} {'|dw| rad/s':>10} {'peak m/s':>9} "
          f"{'closest m':>9} {'p5 m':>6}")
    for r in rows:
        print(f"{r['policy']:>8} {r['randomization']:>7} {100 * r['success_rate']:7.1f}% {r['mean_abs_dv']:9.4f} "
              f"{r['mean_abs_dw']:10.4f} {r['mean_peak_speed']:9.2f} {r['mean_closest_obstacle']:9.2f} "
              f"{r['p5_closest_obstacle']:6.2f}")
    out = write_results(RESULTS / "deploy_policy.json", {"benchmark": "deploy_policy", "seed": EVAL_SEED,
                                                         "episodes": args.episodes, "rows": rows},
                        version=VERSION, task=True, driver=True, policies=tuple(dict.fromkeys(paths)))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def deploy_policy() -> str:
    """``deploy_policy.json``: the deployable and the torque nav policy on the same test episodes, how each ended
    and how each drives."""
    rows = []
    for r in load_results("deploy_policy.json")["rows"]:
        rows.append([f"{r['policy']} (`{r['file']}`)", "`wide`" if r["randomization"] == "wide" else "nominal",
                     f"**{r['success_rate']:.1%}**", f"{r['timeout_rate']:.1%}", f"{r['obstacle_rate']:.1%}",
                     f"{r['mean_abs_dv']:.3f}", f"{r['mean_abs_dw']:.3f}", f"{r['mean_peak_speed']:.2f}",
                     f"{r['mean_closest_obstacle']:.2f} / {r['p5_closest_obstacle']:.2f}"])
    return markdown_table(["policy", "rover", "success", "timeout", "obstacle", "mean abs. Δv per step [m/s]",
                   "mean abs. Δω per step [rad/s]", "peak speed [m/s]", "closest obstacle, mean / 5th pct. [m]"],
                          ["---", "---", "---:", "---:", "---:", "---:", "---:", "---:", "---:"], rows)


TABLES = {
    "deploy_policy": deploy_policy,
}


if __name__ == "__main__":
    sys.exit(main())
