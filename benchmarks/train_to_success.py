"""Wall time and environment steps until SAC's evaluation success first reaches 90 %.

Run: ``python benchmarks/train_to_success.py [--config default|nav] [--minutes 10] [--threshold 0.9] [key=value ...]``

Trains with a preset (``configs/default.toml`` by default, ``--config nav`` for the navigation
task; overrides as in ``python -m atrv_warp.train``), evaluating every 100k frames on the
1,000-episode seeded evaluation set, and reports when the success rate first reached the
threshold (wall time since the start of training, evaluations included) and the final rate of
the best policy. Figures are printed and written to ``benchmarks/results/train_to_success.json``
(``train_to_success_<config>.json`` for another preset); the run folder is kept under
``runs/bench_train_to_success[_<config>]``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"


def _series(path: Path) -> list[tuple[int, float]]:
    if not path.is_file():
        return []
    return [(int(a), float(b)) for a, b in (line.split(",") for line in path.read_text().splitlines() if line)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="training budget [min]")
    parser.add_argument("--threshold", type=float, default=0.9)
    parser.add_argument("--config", default="default", help="training preset (default, nav, ...)")
    parser.add_argument("--out", default=None, help="results file (default: results/train_to_success[_CONFIG].json)")
    parser.add_argument("overrides", nargs="*", help="key=value TrainConfig overrides")
    args = parser.parse_args()

    sys.path.insert(0, str(ROOT))
    from atrv_warp.rl.config import load_train_config
    from atrv_warp.rl.trainer import train

    bad = [item for item in args.overrides if "=" not in item]
    if bad:
        parser.error(f"overrides must look like key=value, got {bad}")
    suffix = "" if args.config == "default" else f"_{args.config}"
    args.out = args.out or str(RESULTS / f"train_to_success{suffix}.json")
    overrides = {"name": f"bench_train_to_success{suffix}", "out_dir": str(ROOT / "runs"), "max_minutes": args.minutes,
                 "eval_every_frames": 100_000, "eval_episodes": 1000, "final_eval_episodes": 1000,
                 **dict(item.split("=", 1) for item in args.overrides)}
    cfg = load_train_config(args.config, overrides)
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    if run_dir.exists():
        shutil.rmtree(run_dir)
    t0 = time.perf_counter()
    train(cfg)
    total_s = time.perf_counter() - t0

    scalars = run_dir / "logs" / "scalars"
    success = _series(scalars / "eval_success_rate.csv")
    wall = dict(_series(scalars / "wall_time_s.csv"))
    reached = next(((f, r) for f, r in success if r >= args.threshold), None)
    final = json.loads((run_dir / "final_eval.json").read_text())
    result = {
        "benchmark": "train_to_success",
        "threshold": args.threshold,
        "preset": args.config,
        "config": {k: v for k, v in overrides.items() if k not in ("out_dir",)},
        "reached": reached is not None,
        "frames_to_threshold": reached[0] if reached else None,
        "wall_s_to_threshold": wall.get(reached[0]) if reached else None,
        "eval_curve": [{"frames": f, "success_rate": r, "wall_s": wall.get(f)} for f, r in success],
        "final_eval_best_policy": final.get("final_eval"),
        "train_minutes": final["train_minutes"],
        "frames": final["frames"],
        "updates": final["updates"],
        "total_wall_s_including_final_eval": total_s,
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print("\n| frames | wall [s] | eval success (1,000 episodes) |\n|---:|---:|---:|")
    for row in result["eval_curve"]:
        print(f"| {row['frames']:,} | {row['wall_s']:.0f} | {100 * row['success_rate']:.1f}% |")
    if reached:
        print(f"\n{100 * args.threshold:.0f}% first reached after {reached[0]:,} frames, "
              f"{result['wall_s_to_threshold']:.0f} s of wall time")
    else:
        print(f"\n{100 * args.threshold:.0f}% not reached within {args.minutes} min")
    fe = result["final_eval_best_policy"]
    if fe:
        print(f"best policy, final: {100 * fe['success_rate']:.1f}% success over {fe['episodes']} episodes")
    print(f"written to {out}")
    return 0 if reached else 1


if __name__ == "__main__":
    sys.exit(main())
