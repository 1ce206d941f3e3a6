"""Ray collection against local multi-process collection, on this machine.

Run: ``flock /tmp/atrv_bench.lock python -m benchmarks.perf.ray_collection [--worlds 512] [--steps 8] [--rounds 3]``
(needs the ``ray`` extra).

Frames/s of the training path's :class:`RayCollector` (:func:`make_ray_collector`: asynchronous, the
learner's weights sent to a collector after each of its batches) with 1 and 2 collectors, against
TorchRL's :class:`MultiSyncCollector` with 1 and 2 worker processes (weights updated after each batch,
as the trainer does for its local worker), the same worlds per worker and steps per batch, the same
policy (the default actor), no learning. Like for like: the local workers are not pinned to cores
(Ray's actors are not), and Ray's workers run at niceness 0 like the local ones (Ray's default is 15,
which on a machine shared with other work hands them less CPU; ``--ray-niceness`` sets it). All four are built first and measured in turn, ``--rounds`` times
(interleaved, so the machine's drift hits each alike); the best round of each is kept.

Before each window the collector is drained: a Ray collector's actors have a batch in flight when
the previous window ends (first ready, first served), so the window skips as many batches as there
are collectors, after waiting for those actors to be idle.

Target (issue #15): Ray within 20 % of the local multi-process collectors at 512 worlds per worker.
Figures are printed and written to ``benchmarks/results/ray_collection.json``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _window(collector, it, *, skip: int, batches: int, after_batch) -> tuple[float, int]:
    """(frames/s, frames) over ``batches`` batches of ``it`` after ``skip`` batches."""
    for _ in range(skip):
        next(it)
        after_batch(collector)
    frames, t0 = 0, time.perf_counter()
    for _ in range(batches):
        frames += next(it).numel()
        after_batch(collector)
    return frames / (time.perf_counter() - t0), frames


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=512, help="worlds per worker / collector")
    parser.add_argument("--steps", type=int, default=8, help="steps per world in one batch (training default 8)")
    parser.add_argument("--batches", type=int, default=20, help="timed batches per worker per window")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ray-niceness", type=int, default=0, help="niceness of Ray's worker processes (Ray: 15)")
    parser.add_argument("--out", default=str(RESULTS / "ray_collection.json"))
    args = parser.parse_args()

    import ray
    import torch
    from tensordict import TensorDict
    from torchrl.collectors import MultiSyncCollector

    from atrv_warp.policy import make_actor
    from atrv_warp.rl.collectors import OBJECT_STORE_BYTES, make_ray_collector, placements
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.task.env import EnvFactory

    torch.set_num_threads(1)
    cores = sorted(os.sched_getaffinity(0))
    actor = make_actor()  # the default network (width 128, depth 2); its weights are what gets sent
    fpb = args.worlds * args.steps
    os.environ["RAY_worker_niceness"] = str(args.ray_niceness)  # read by the raylet ray.init starts
    # 3 logical CPUs: the 1- and the 2-collector RayCollector both live through the run (one collects at a time)
    ray.init(num_cpus=3, object_store_memory=OBJECT_STORE_BYTES, include_dashboard=False, logging_level="warning")

    def ray_after(collector):  # the RayCollector itself sends the weights (update_after_each_batch)
        return None

    def local_after(collector):  # as the trainer does for its local worker process
        collector.update_policy_weights_(TensorDict.from_module(actor))

    def drain_ray(collector):
        placements(collector)  # queued behind each actor's batch in flight: returns once all are idle

    contenders = {}
    for k in (1, 2):
        local = MultiSyncCollector([EnvFactory(args.worlds, seed=100 + i) for i in range(k)], actor,
                                   frames_per_batch=fpb * k, total_frames=-1)
        # (collector, yields per window of `--batches` per worker, batches in flight to skip, after each, drain)
        contenders[f"MultiSyncCollector x{k}"] = (local, args.batches, 0, local_after, lambda c: None)
        cfg = load_train_config("default", {"collector": "ray", "num_collectors": str(k),
                                            "envs_per_collector": str(args.worlds), "steps_per_batch": str(args.steps)})
        remote = make_ray_collector(cfg, actor, total_frames=10**12, init_random_frames=0, env_seed=100)
        contenders[f"RayCollector x{k}"] = (remote, args.batches * k, k, ray_after, drain_ray)
    iterators = {name: iter(c[0]) for name, c in contenders.items()}
    for name, (collector, _, in_flight, after, drain) in contenders.items():  # warm-up: first batches
        _window(collector, iterators[name], skip=0, batches=2 * max(in_flight, 1), after_batch=after)
        drain(collector)

    rounds: dict[str, list[float]] = {name: [] for name in contenders}
    for r in range(args.rounds):
        for name, (collector, yields, in_flight, after, drain) in contenders.items():
            fps, frames = _window(collector, iterators[name], skip=in_flight, batches=yields, after_batch=after)
            drain(collector)
            rounds[name].append(fps)
            print(f"round {r + 1}  {name:22s} {fps:10,.0f} frames/s  ({frames:,} frames)", flush=True)

    for collector, *_ in contenders.values():
        collector.shutdown()
    ray.shutdown()

    best = {name: max(v) for name, v in rounds.items()}
    ratios = {k: best[f"RayCollector x{k}"] / best[f"MultiSyncCollector x{k}"] for k in (1, 2)}
    result = {"benchmark": "ray_collection", "cores": len(cores), "worlds_per_worker": args.worlds,
              "steps_per_batch": args.steps, "ray_worker_niceness": args.ray_niceness, "local_workers_pinned": False, "frames_per_worker_batch": fpb, "timed_batches_per_worker": args.batches,
              "rounds": rounds, "best_fps": best, "ray_over_local": {str(k): v for k, v in ratios.items()},
              "target": "Ray >= 0.8 x local multi-process (overhead within 20 %)",
              "met": all(v >= 0.8 for v in ratios.values()),
              "load_avg_1min_at_end": os.getloadavg()[0], "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    out = write_results(args.out, result, version=VERSION, task=True)
    print(f"\n| workers x {args.worlds} worlds, {args.steps} steps/batch | MultiSyncCollector frames/s | "
          "RayCollector frames/s | Ray / local |\n|---:|---:|---:|---:|")
    for k in (1, 2):
        print(f"| {k} | {best[f'MultiSyncCollector x{k}']:,.0f} | {best[f'RayCollector x{k}']:,.0f} | {ratios[k]:.2f} |")
    print(f"\ntarget (Ray within 20 %): {'met' if result['met'] else 'MISSED'}; load average "
          f"{result['load_avg_1min_at_end']:.2f} on {len(cores)} cores; written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def ray_collection() -> str:
    """``ray_collection.json``: TorchRL's ``RayCollector`` against ``MultiSyncCollector``."""
    d = load_results("ray_collection.json")
    fps, ratio = d["best_fps"], d["ray_over_local"]
    return markdown_table([f"workers x {d['worlds_per_worker']} worlds", "MultiSyncCollector frames/s", "RayCollector frames/s",
                   "Ray / local"], ["---:"] * 4,
                          [[k, f"{fps[f'MultiSyncCollector x{k}']:,.0f}", f"{fps[f'RayCollector x{k}']:,.0f}", f"{ratio[k]:.2f}"]
                   for k in sorted(ratio)])


TABLES = {
    "ray_collection": ray_collection,
}


if __name__ == "__main__":
    sys.exit(main())
