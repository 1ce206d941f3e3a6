"""A training run's wall time against an earlier revision's, measured in one run, interleaved.

    python -m benchmarks.training.training_speed --old c56dbf4 [--config nav_deploy] [--frames 300000] [--rounds 3]

Checks ``--old`` out into a temporary git worktree and trains the same preset in both trees alternately (old,
new, old, new, ...), each a fresh ``python -m atrv_warp.train`` process on the machine's cores, for ``--frames``
frames with the validation ``benchmarks/training/train_to_success.py`` runs (1,000 episodes every 100,000 frames) and a
short final evaluation (``--final-episodes``). Per tree it reports the median wall time of the whole command and
the training's own clock (``train_minutes``: from the first frame to the budget's end, validations included),
frames/s and updates/s, and the ratios old / new. Kernels are compiled and cached by a warm-up run of each tree
first, not counted. Prints the table and writes ``benchmarks/results/training_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"


def _train(tree: Path, out_dir: Path, args, frames: int) -> dict:
    """One training run in ``tree``; its wall time and what its ``final_eval.json`` says."""
    run = out_dir / "run"
    shutil.rmtree(run, ignore_errors=True)
    command = [sys.executable, "-m", "atrv_warp.train", "--config", args.config, f"out_dir={out_dir}", "name=run",
               f"total_frames={frames}", "max_minutes=0", "eval_every_frames=100000", "eval_episodes=1000",
               f"final_eval_episodes={args.final_episodes}", "progress=false"]
    t0 = time.perf_counter()
    subprocess.run(command, cwd=tree, env=_env(tree), check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    final = json.loads((run / "final_eval.json").read_text())
    seconds = final["train_minutes"] * 60
    return {"wall_s": wall, "train_s": seconds, "frames": final["frames"], "updates": final["updates"],
            "frames_per_s": final["frames"] / seconds, "updates_per_s": final["updates"] / seconds}


def _env(tree: Path) -> dict:
    """This environment for a run in ``tree``: its package first, and a fresh run's cores."""
    env = {k: v for k, v in os.environ.items() if k != "ATRV_WARP_CORES"}
    env["PYTHONPATH"] = str(tree)
    return env


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", required=True, help="the earlier revision (a commit, tag or branch)")
    parser.add_argument("--config", default="nav_deploy", help="training preset run in both trees")
    parser.add_argument("--frames", type=int, default=300_000, help="frames per training run")
    parser.add_argument("--rounds", type=int, default=3, help="runs per tree, interleaved")
    parser.add_argument("--final-episodes", type=int, default=100, help="episodes of each run's final evaluation")
    parser.add_argument("--out", default=str(RESULTS / "training_speed.json"))
    args = parser.parse_args()

    old_rev = subprocess.run(["git", "rev-parse", "--short", args.old], cwd=ROOT, check=True, capture_output=True,
                             text=True).stdout.strip()
    scratch = Path(tempfile.mkdtemp(prefix="training_speed_"))
    old_tree = scratch / "old"
    subprocess.run(["git", "worktree", "add", "--detach", "-q", str(old_tree), old_rev], cwd=ROOT, check=True)
    trees = {"old": old_tree, "new": ROOT}
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    try:
        for name, tree in trees.items():  # compile and cache both trees' kernels; not counted
            _train(tree, scratch / name, args, 20_480)
        for k in range(args.rounds):
            for name, tree in trees.items():
                r = _train(tree, scratch / name, args, args.frames)
                runs[name].append(r)
                print(f"round {k + 1} {name}: {r['wall_s']:.0f} s wall, {r['train_s']:.0f} s training, "
                      f"{r['frames_per_s']:,.0f} frames/s, {r['updates_per_s']:.1f} updates/s", flush=True)
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(old_tree)], cwd=ROOT, check=False)
        shutil.rmtree(scratch, ignore_errors=True)

    def median(name: str, key: str) -> float:
        return statistics.median(r[key] for r in runs[name])

    keys = ("wall_s", "train_s", "frames_per_s", "updates_per_s")
    summary = {name: {key: median(name, key) for key in keys} for name in runs}
    # pair by pair (old k, new k), so a drift of the machine's speed during the call cancels
    pairs = [o["train_s"] / n["train_s"] for o, n in zip(runs["old"], runs["new"], strict=True)]
    result = {"benchmark": "training_speed", "old": old_rev, "config": args.config, "frames": args.frames,
              "rounds": args.rounds, "eval_every_frames": 100_000, "eval_episodes": 1000, "runs": runs,
              "median": summary, "train_s_old_over_new_pairs": pairs,
              "train_s_old_over_new": statistics.median(pairs)}
    print("\n| tree | wall [s] | training [s] | frames/s | updates/s |\n|---|---:|---:|---:|---:|")
    for name in runs:
        s = summary[name]
        print(f"| {name} ({old_rev if name == 'old' else 'this tree'}) | {s['wall_s']:.0f} | {s['train_s']:.0f} | "
              f"{s['frames_per_s']:,.0f} | {s['updates_per_s']:.1f} |")
    print(f"training time old / new, median of the pairs: {result['train_s_old_over_new']:.2f}")
    write_results(args.out, result, version=VERSION, task=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
