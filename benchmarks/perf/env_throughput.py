"""TorchRL overhead and multi-process scaling of ATRVjrEnv.

Run: ``python -m benchmarks.perf.env_throughput [--sizes 64 256 1024] [--seconds 3]``

For each N: frames/s of the raw simulator (``RoverSim.step`` with random commands) and of
``env.rollout`` (random actions from the action spec), measured alternately, best of three each, and of a single-process ``Collector``,
all in this process pinned to one core. Then a ``MultiSyncCollector`` with one worker
against two workers, and the same for ``MultiAsyncCollector`` (each worker pinned to its
own core, ``--worker-envs`` worlds each, 50 steps per worker batch).
Targets: TorchRL overhead <= 15 % of raw sim at N = 1024; two workers >= 1.8x one.
Figures are printed and written to ``benchmarks/results/env_throughput.json``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, rate, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"



def _collector_rate(collector, skip: int, measure: int) -> float:
    it = iter(collector)
    for _ in range(skip):
        next(it)
    frames, t0 = 0, time.perf_counter()
    for _ in range(measure):
        frames += next(it).numel()
    per_s = frames / (time.perf_counter() - t0)
    collector.shutdown()
    return per_s


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 1024])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--worker-envs", type=int, default=512, help="worlds per collector worker")
    parser.add_argument("--out", default=str(RESULTS / "env_throughput.json"))
    args = parser.parse_args()

    cores = sorted(os.sched_getaffinity(0))
    import torch
    torch.set_num_threads(1)
    from torchrl.collectors import Collector, MultiSyncCollector

    from atrv_warp import ATRVjrEnv, EnvFactory, RoverSim

    os.sched_setaffinity(0, {cores[0]})
    rows = []
    for n in args.sizes:
        gen = torch.Generator().manual_seed(0)
        sim = RoverSim(n)
        sim.reset(poses=(torch.rand(n, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14159]))

        def raw_step(sim=sim, n=n):
            sim.commands.uniform_(-20.0, 20.0)
            sim.step()

        env = ATRVjrEnv(n, seed=0)
        horizon = 50
        rollout_fn = lambda env=env, h=horizon: env.rollout(h, break_when_any_done=False)
        # Alternate the two windows and keep the best of three: the machine's speed drifts more
        # between back-to-back runs than the overhead being measured.
        raw, rollout = 0.0, 0.0
        for _ in range(3):
            raw = max(raw, rate(raw_step, n, args.seconds / 3))
            rollout = max(rollout, rate(rollout_fn, n * horizon, args.seconds / 3))
        del sim
        fpb = n * 20
        coll = Collector(env, None, frames_per_batch=fpb, total_frames=-1)
        collector = _collector_rate(coll, skip=2, measure=max(3, int(args.seconds * raw / fpb)))
        row = {"num_envs": n, "raw_sim_fps": raw, "rollout_fps": rollout, "collector_fps": collector,
               "rollout_overhead": 1.0 - rollout / raw, "collector_overhead": 1.0 - collector / raw}
        rows.append(row)
        print(f"N={n:5d}  raw {raw:10,.0f}  rollout {rollout:10,.0f} ({100 * row['rollout_overhead']:5.1f}% overhead)"
              f"  collector {collector:10,.0f} ({100 * row['collector_overhead']:5.1f}% overhead)  frames/s",
              flush=True)

    # Process scaling: one worker against two, each on its own core, 50 steps per worker batch.
    os.sched_setaffinity(0, set(cores))
    from torchrl.collectors import MultiAsyncCollector

    n = args.worker_envs
    fpb_worker = n * 50
    scaling: dict[str, dict[int, float]] = {}
    for cls in (MultiSyncCollector, MultiAsyncCollector):
        scaling[cls.__name__] = {}
        for workers in (1, 2):
            factories = [EnvFactory(n, seed=100 + i, core=i) for i in range(workers)]
            sync = cls is MultiSyncCollector
            coll = cls(factories, None, frames_per_batch=fpb_worker * (workers if sync else 1), total_frames=-1)
            fps = _collector_rate(coll, skip=2 * workers, measure=6 if sync else 6 * workers)
            scaling[cls.__name__][workers] = fps
            print(f"{cls.__name__}, {workers} worker(s) x {n} worlds: {fps:10,.0f} frames/s", flush=True)
        s = scaling[cls.__name__]
        print(f"{cls.__name__}: two workers / one = {s[2] / s[1]:.2f}x (cores available: {len(cores)})")

    result = {"benchmark": "env_throughput", "cores": len(cores), "rows": rows,
              "worker_envs": n, "steps_per_worker_batch": 50,
              "scaling": {k: {"1_worker_fps": v[1], "2_workers_fps": v[2], "speedup": v[2] / v[1]}
                          for k, v in scaling.items()},
              "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    out = write_results(args.out, result, version=VERSION, task=True)
    print("\n| N | raw sim frames/s | env.rollout | overhead | Collector | overhead |\n|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['num_envs']} | {r['raw_sim_fps']:,.0f} | {r['rollout_fps']:,.0f} | "
              f"{100 * r['rollout_overhead']:.1f}% | {r['collector_fps']:,.0f} | {100 * r['collector_overhead']:.1f}% |")
    print("\n| collector | 1 worker frames/s | 2 workers frames/s | speed-up |\n|---|---:|---:|---:|")
    for k, v in scaling.items():
        print(f"| {k} | {v[1]:,.0f} | {v[2]:,.0f} | {v[2] / v[1]:.2f}x |")
    print(f"\nwritten to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def env_throughput() -> str:
    """``env_throughput.json``: raw simulator, ``env.rollout`` and ``Collector`` frames/s."""
    return markdown_table(["N", "raw sim frames/s", "env.rollout", "overhead", "Collector", "overhead"], ["---:"] * 6,
                          [[str(r["num_envs"]), f"{r['raw_sim_fps']:,.0f}", f"{r['rollout_fps']:,.0f}",
                    f"{100 * r['rollout_overhead']:.1f} %", f"{r['collector_fps']:,.0f}",
                    f"{100 * r['collector_overhead']:.1f} %"] for r in load_results("env_throughput.json")["rows"]])


def env_scaling() -> str:
    """``env_throughput.json``: one and two collector workers."""
    d = load_results("env_throughput.json")
    return markdown_table([f"collector ({d['worker_envs']} worlds per worker, {d['steps_per_worker_batch']} steps per worker batch)",
                   "1 worker frames/s", "2 workers frames/s", "speed-up"], ["---", "---:", "---:", "---:"],
                          [[f"`{name}`", f"{r['1_worker_fps']:,.0f}", f"{r['2_workers_fps']:,.0f}", f"{r['speedup']:.2f}×"]
                   for name, r in d["scaling"].items()])


TABLES = {
    "env_throughput": env_throughput,
    "env_scaling": env_scaling,
}


if __name__ == "__main__":
    sys.exit(main())
