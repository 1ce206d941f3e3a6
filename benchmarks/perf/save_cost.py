"""What a training save costs: seconds and disk per million transitions, and its share of a run's time.

Run: ``python -m benchmarks.perf.save_cost [--transitions 1000000] [--repeats 3]``

A save (:class:`atrv_warp.rl.checkpoint.Checkpoint`) writes the replay buffer, the networks and optimisers, and
the best policy, each flushed to the disk, then commits with one rename. Here a ``nav_deploy`` run's parts (its
networks, a SAC learner, a replay buffer full of ``--transitions`` random rows of the task's replay keys) are saved
``--repeats`` times into a temporary folder, and restored once (reading, checksums and filling a new buffer). The
share of training time divides a save by the time between two saves of the ``nav_deploy`` preset at the frame rate
its time-to-90 % benchmark measured (``train_to_success_nav_deploy.json``). Written to
``benchmarks/results/save_cost.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transitions", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(RESULTS / "save_cost.json"))
    args = parser.parse_args(argv)

    import torch
    from tensordict import TensorDict

    from atrv_warp.rl.checkpoint import Checkpoint, RunState, load_checkpoint
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.learner import make_buffer, make_learner, make_run_actor

    n = args.transitions
    cfg = load_train_config("nav_deploy", {"buffer_size": str(n)})
    actor, normalize = make_run_actor(cfg)
    dim = normalize.loc.numel()
    normalize.set_stats(torch.zeros(dim), torch.ones(dim))
    learner = make_learner(cfg, actor, normalize)
    buffer = make_buffer(cfg)
    g = torch.Generator().manual_seed(0)
    buffer.extend(TensorDict({"observation": torch.randn(n, dim, generator=g), "action": torch.rand(n, 2, generator=g),
                              ("next", "observation"): torch.randn(n, dim, generator=g),
                              ("next", "reward"): torch.randn(n, 1, generator=g),
                              ("next", "done"): torch.zeros(n, 1, dtype=torch.bool),
                              ("next", "terminated"): torch.zeros(n, 1, dtype=torch.bool),
                              ("next", "truncated"): torch.zeros(n, 1, dtype=torch.bool)}, [n]))
    state = RunState(frames=n, stats_ready=True)
    save_s = []
    with tempfile.TemporaryDirectory() as tmp:
        checkpoint = Checkpoint(Path(tmp))
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            checkpoint.save(cfg, state, actor, learner, buffer)
            save_s.append(time.perf_counter() - t0)
        disk = sum(p.stat().st_size for p in Path(tmp).rglob("*") if p.is_file())
        fresh_actor, fresh_normalize = make_run_actor(cfg)
        fresh = make_buffer(cfg)
        t0 = time.perf_counter()
        restoring = Checkpoint(Path(tmp))
        restoring.restore(load_checkpoint(restoring.path), cfg, fresh_actor, fresh_normalize, fresh)
        restore_s = time.perf_counter() - t0
        assert len(fresh) == n
    measured = json.loads((RESULTS / "train_to_success_nav_deploy.json").read_text())["median"]["frames_per_s"]
    between_s = cfg.logging.eval_every_frames / measured
    per_million = 1e6 / n
    result = {"benchmark": "save_cost", "task": cfg.env.task, "transitions": n, "repeats": args.repeats,
              "save_s": save_s, "save_s_median": statistics.median(save_s), "restore_s": restore_s,
              "disk_bytes": disk, "save_s_per_million": statistics.median(save_s) * per_million,
              "disk_gb_per_million": disk / 1e9 * per_million,
              "eval_every_frames": cfg.logging.eval_every_frames, "training_frames_per_s": measured,
              "seconds_between_saves": between_s,
              "share_of_training": statistics.median(save_s) / (between_s + statistics.median(save_s))}
    out = write_results(args.out, result, version=VERSION, dynamics=False)
    print(f"save of {n:,} transitions: {result['save_s_median']:.2f} s (median of {args.repeats}), restore "
          f"{restore_s:.2f} s, {disk / 1e9:.3f} GB on disk; a save every {between_s:.0f} s of nav_deploy training "
          f"takes {100 * result['share_of_training']:.1f} % of it -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
