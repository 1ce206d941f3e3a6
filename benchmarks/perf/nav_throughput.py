"""Throughput of the navigation task against the flat reference task, measured in one run.

Run: ``python -m benchmarks.perf.nav_throughput [--sizes 64 1024] [--seconds 3] [--rounds 3] [--device cuda:0]``

For each N, in this process (pinned to one core on the CPU) with one torch thread: env-steps/s of
``ATRVjrEnv`` stepping random actions (with resets) for the ``reach`` task (flat, no obstacles,
no scanner) and the ``nav`` task (terrain, six obstacles, 64-beam scan), measured alternately,
best of ``--rounds`` each; then where nav's extra time goes: the simulator step on the flat arena
and on terrain with obstacles, and one scan (and the scan's two kernel layouts, for all worlds and
for 5 % of them as after a reset). Kernel compilation (the first build and step of each
task) is timed separately and excluded. Target (issue 13): nav >= 50 % of reach at N = 1024.
Figures are printed and written to ``benchmarks/results/nav_throughput.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, random_step, rate, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"



def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 1024])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--device", default="cpu", help="simulation device, e.g. cuda:0")
    parser.add_argument("--out", default=str(RESULTS / "nav_throughput.json"))
    args = parser.parse_args()

    if args.device == "cpu":
        pin_to_one_core()
    import torch
    import warp as wp

    torch.set_num_threads(1)
    from atrv_warp.task.env import ATRVjrEnv

    compile_s = {}
    for task in ("reach", "nav"):  # first build + step compiles (or loads) every kernel the task uses
        t0 = time.perf_counter()
        env = ATRVjrEnv(2, task=task, device=args.device)
        env.rollout(2)
        compile_s[task] = time.perf_counter() - t0
    print(f"first build and step (kernel compilation or cache load): {compile_s}")

    rows = []
    for n in args.sizes:
        envs = {task: ATRVjrEnv(n, task=task, seed=0, device=args.device) for task in ("reach", "nav")}
        gen = torch.Generator().manual_seed(0)
        steppers = {task: random_step(env, gen) for task, env in envs.items()}

        best = {"reach": 0.0, "nav": 0.0}
        for _ in range(args.rounds):  # interleaved: both tasks see the same machine load
            for task, so_far in best.items():
                best[task] = max(so_far, rate(steppers[task], n, args.seconds, sync=wp.synchronize))
        sims = {task: env.sim for task, env in envs.items()}
        sim_rate = {task: rate(sim.step, n, args.seconds, sync=wp.synchronize) for task, sim in sims.items()}
        scanner = envs["nav"].scanner
        scan_rate = rate(scanner.scan, n, args.seconds, sync=wp.synchronize)
        # The scan's two kernel layouts (a thread per beam, the GPU's; a thread per world, the CPU's
        # default), for every world and for a reset's rescan of 5 % of them, alternately.
        few = wp.array(torch.rand(n, generator=gen).numpy() < 0.05, dtype=bool, device=args.device)
        layouts = {}
        for _ in range(args.rounds):
            for layout in ("beam", "world"):
                for name, mask in (("all", None), ("reset_5pct", few)):
                    ms = 1e3 * n / rate(lambda m=mask, lay=layout, sc=scanner: sc.scan(m, layout=lay), n, args.seconds / 4,
                                         sync=wp.synchronize)
                    key = f"{layout}_{name}_ms"
                    layouts[key] = min(layouts.get(key, ms), ms)
        row = {"num_envs": n, "reach_env_steps_per_s": best["reach"], "nav_env_steps_per_s": best["nav"],
               "nav_over_reach": best["nav"] / best["reach"],
               "sim_step_flat_per_s": sim_rate["reach"], "sim_step_terrain_obstacles_per_s": sim_rate["nav"],
               "scan_64_beams_per_s": scan_rate, "scan_layouts": layouts,
               "us_per_world_step": {"env_reach": 1e6 / best["reach"], "env_nav": 1e6 / best["nav"],
                                     "sim_flat": 1e6 / sim_rate["reach"], "sim_nav": 1e6 / sim_rate["nav"],
                                     "scan": 1e6 / scan_rate}}
        rows.append(row)
        us = row["us_per_world_step"]
        print(f"N={n:5d}: reach {best['reach']:8.0f}  nav {best['nav']:8.0f} env-steps/s  -> nav/reach "
              f"{row['nav_over_reach']:.2f} | per world-step [us]: sim flat {us['sim_flat']:.1f}, sim terrain+obstacles "
              f"{us['sim_nav']:.1f}, scan {us['scan']:.1f}", flush=True)
        print(f"         scan per call [ms], thread per beam / per world: all worlds {layouts['beam_all_ms']:.2f} / "
              f"{layouts['world_all_ms']:.2f}; 5 % of them (a reset) {layouts['beam_reset_5pct_ms']:.2f} / "
              f"{layouts['world_reset_5pct_ms']:.2f}", flush=True)
    result = {"benchmark": "nav_throughput", "target": "nav >= 0.5 x reach at N = 1024", "device": args.device,
              "compile_s": compile_s,
              "rows": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S"), "python": sys.version.split()[0]}
    out = write_results(args.out, result, version=VERSION, task=True)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def nav_throughput(name: str = "nav_throughput.json") -> str:
    """``nav_throughput.json``: the nav task's env-steps/s against the reach task's."""
    rows = []
    for r in load_results(name)["rows"]:
        us = r["us_per_world_step"]
        rows.append([str(r["num_envs"]), f"{r['reach_env_steps_per_s']:,.0f}", f"{r['nav_env_steps_per_s']:,.0f}",
                     f"{r['nav_over_reach']:.2f}", f"{us['sim_flat']:.1f} / {us['sim_nav']:.1f} / {us['scan']:.1f} µs"])
    return markdown_table(["N", "reach env-steps/s", "nav env-steps/s", "nav / reach",
                   "per world-step: sim flat / sim terrain + obstacles / scan"], ["---:"] * 4 + ["---"], rows)


def nav_throughput_cuda() -> str:
    """``nav_throughput_cuda.json``: the same on one GPU."""
    return nav_throughput("nav_throughput_cuda.json")


TABLES = {
    "nav_throughput": nav_throughput,
    "nav_throughput_cuda": nav_throughput_cuda,
}


if __name__ == "__main__":
    sys.exit(main())
