"""Wall time and environment steps until SAC's evaluation success first reaches 90 %, per seed.

Run: ``python benchmarks/train_to_success.py [--config default|nav] [--seeds 0 1 2] [--minutes 10]
[--threshold 0.9] [key=value ...]``

Trains with a preset (``configs/default.toml`` by default, ``--config nav`` for the navigation
task; overrides as in ``python -m atrv_warp.train``) once per seed, one after the other,
evaluating every 100k frames on the 1,000-episode seeded evaluation set. Per seed it reports when
the success rate first reached the threshold (wall time since the start of training, evaluations
included), the final rate of the best policy, and updates/s and frames/s; then the medians.
Kernel compilation is paid once, before the first seed, and reported separately. Figures are
printed and written to ``benchmarks/results/train_to_success.json``
(``train_to_success_<config>.json`` for another preset); the run folders are kept under
``runs/bench_train_to_success[_<config>]_seed<k>``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"


def _series(path: Path) -> list[tuple[int, float]]:
    if not path.is_file():
        return []
    return [(int(a), float(b)) for a, b in (line.split(",") for line in path.read_text().splitlines() if line)]


def _one_seed(config: str, overrides: dict, threshold: float) -> dict:
    from atrv_warp.rl.config import load_train_config
    from atrv_warp.rl.trainer import train

    cfg = load_train_config(config, overrides)
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    if run_dir.exists():
        shutil.rmtree(run_dir)
    t0 = time.perf_counter()
    train(cfg)
    total_s = time.perf_counter() - t0
    scalars = run_dir / "logs" / "scalars"
    success = _series(scalars / "eval_success_rate.csv")
    wall = dict(_series(scalars / "wall_time_s.csv"))
    reached = next(((f, r) for f, r in success if r >= threshold), None)
    final = json.loads((run_dir / "final_eval.json").read_text())
    train_s = final["train_minutes"] * 60
    return {
        "seed": cfg.run.seed,
        "run_dir": str(run_dir.relative_to(ROOT)) if run_dir.is_relative_to(ROOT) else str(run_dir),
        "reached": reached is not None,
        "frames_to_threshold": reached[0] if reached else None,
        "wall_s_to_threshold": wall.get(reached[0]) if reached else None,
        "eval_curve": [{"frames": f, "success_rate": r, "wall_s": wall.get(f)} for f, r in success],
        "final_eval_best_policy": final.get("final_eval"),
        "train_minutes": final["train_minutes"],
        "frames": final["frames"],
        "updates": final["updates"],
        "updates_per_s": final["updates"] / train_s,
        "frames_per_s": final["frames"] / train_s,
        "total_wall_s_including_final_eval": total_s,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="training budget per seed [min]")
    parser.add_argument("--threshold", type=float, default=0.9)
    parser.add_argument("--config", default="default", help="training preset (default, nav, ...)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds, run one after another")
    parser.add_argument("--out", default=None, help="results file (default: results/train_to_success[_CONFIG].json)")
    parser.add_argument("overrides", nargs="*", help="key=value TrainConfig overrides")
    args = parser.parse_args()

    sys.path.insert(0, str(ROOT))
    bad = [item for item in args.overrides if "=" not in item]
    if bad:
        parser.error(f"overrides must look like key=value, got {bad}")
    suffix = "" if args.config == "default" else f"_{args.config}"
    out = Path(args.out or RESULTS / f"train_to_success{suffix}.json")
    extra = dict(item.split("=", 1) for item in args.overrides)

    from atrv_warp.rl.config import load_train_config
    from atrv_warp.task.env import ATRVjrEnv

    task = load_train_config(args.config, extra).env.task
    t0 = time.perf_counter()
    ATRVjrEnv(2, task=task).rollout(2)  # compiles (or loads) every kernel the run uses
    compile_s = time.perf_counter() - t0
    print(f"kernel compilation / cache load before the first seed: {compile_s:.1f} s", flush=True)

    runs = []
    for seed in args.seeds:
        overrides = {"name": f"bench_train_to_success{suffix}_seed{seed}", "out_dir": str(ROOT / "runs"),
                     "max_minutes": args.minutes, "seed": seed, "eval_every_frames": 100_000, "eval_episodes": 1000,
                     "final_eval_episodes": 1000, **extra}
        runs.append(_one_seed(args.config, overrides, args.threshold))
        r = runs[-1]
        reached = f"{r['wall_s_to_threshold']:.0f} s" if r["reached"] else "not reached"
        print(f"seed {seed}: {100 * args.threshold:.0f}% after {reached}; best policy final "
              f"{100 * r['final_eval_best_policy']['success_rate']:.1f}%; {r['updates_per_s']:.1f} updates/s, "
              f"{r['frames_per_s']:.0f} frames/s", flush=True)

    times = [r["wall_s_to_threshold"] for r in runs if r["reached"]]
    median = {
        "wall_s_to_threshold": statistics.median(times) if len(times) == len(runs) else None,
        "final_success_rate": statistics.median(r["final_eval_best_policy"]["success_rate"] for r in runs),
        "updates_per_s": statistics.median(r["updates_per_s"] for r in runs),
        "frames_per_s": statistics.median(r["frames_per_s"] for r in runs),
    }
    result = {"benchmark": "train_to_success", "preset": args.config, "threshold": args.threshold,
              "minutes_per_seed": args.minutes, "overrides": extra, "compile_s": compile_s, "seeds": runs,
              "median": median, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print("\n| seed | frames | wall [s] | eval success (1,000 episodes) |\n|---:|---:|---:|---:|")
    for r in runs:
        for row in r["eval_curve"]:
            print(f"| {r['seed']} | {row['frames']:,} | {row['wall_s']:.0f} | {100 * row['success_rate']:.1f}% |")
    med = median["wall_s_to_threshold"]
    med_text = f"{med:.0f} s" if med is not None else "not reached by every seed"
    print(f"\nmedian over {len(runs)} seed(s): {100 * args.threshold:.0f}% after {med_text}; final "
          f"{100 * median['final_success_rate']:.1f}%; {median['updates_per_s']:.1f} updates/s, "
          f"{median['frames_per_s']:.0f} frames/s (kernel compilation {compile_s:.1f} s, excluded)")
    print(f"written to {out}")
    return 0 if len(times) == len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
