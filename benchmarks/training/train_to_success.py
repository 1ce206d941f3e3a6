"""Wall time and environment steps until the evaluation success first reaches 90 %, per seed.

Run: ``python -m benchmarks.training.train_to_success [--config default|nav|ppo|nav_ppo] [--seeds 0 1 2] [--minutes 10]
[--threshold 0.9] [--figure docs/learning_curve.png [--figure-only]] [key=value ...]``

Trains with a preset (``configs/default.toml`` by default, ``--config nav`` for the navigation
task, ``--config ppo`` / ``nav_ppo`` for PPO on many worlds; overrides as in
``python -m atrv_warp.train``) once per seed, one after the other,
evaluating every 100k frames on 1,000 seeded validation episodes (``VALIDATION_SEED``, on which the run picks
its best policy). Per seed it reports when the success rate first reached the threshold (wall time since the
start of training, evaluations included, until that validation's figures were known: in the background, the
validation runs beside the training and ends later than the weights it judged were taken), the best policy's
rate on the 1,000-episode test set (``EVAL_SEED``, unseen by training), and updates/s and frames/s; then the
medians.
Kernel compilation is paid once, before the first seed, and reported separately. Figures are
printed and written to ``benchmarks/results/train_to_success.json``
(``train_to_success_<config>.json`` for another preset); the run folders are kept under
``runs/bench_<results file's stem>_seed<k>``. ``--figure`` draws every seed's evaluation
success against wall time into one PNG.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, logged_series, markdown_table, results_path, save_figure, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = Path(__file__).resolve().parents[1] / "results"


def _one_seed(config: str, overrides: dict, threshold: float) -> dict:
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.loop import train

    cfg = load_train_config(config, overrides)
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    if run_dir.exists():
        shutil.rmtree(run_dir)
    t0 = time.perf_counter()
    train(cfg)
    return _summarize(run_dir, cfg.run.seed, threshold, time.perf_counter() - t0)


def _summarize(run_dir: Path, seed: int, threshold: float, total_s: float | None) -> dict:
    """One seed's figures from its run folder's logs and ``final_eval.json``."""
    scalars = run_dir / "logs" / "scalars"
    success = logged_series(scalars / "eval_success_rate.csv")
    taken = dict(logged_series(scalars / "wall_time_s.csv"))  # when the weights were taken
    # when the validation's figures were known: later than the weights by the validation (in the trainer), or by
    # the validation and the poll (in the background); runs from before eval_known_wall_s have only `taken`
    known = dict(logged_series(scalars / "eval_known_wall_s.csv"))
    wall = known or taken
    # rates are logged as float32: 900 of 1,000 episodes reads 0.89999998, which is 90 %
    reached = next(((f, r) for f, r in success if r >= threshold - 1e-6), None)
    final = json.loads((run_dir / "final_eval.json").read_text())
    train_s = final["train_minutes"] * 60
    return {
        "seed": seed,
        "run_dir": str(run_dir.relative_to(ROOT)) if run_dir.is_relative_to(ROOT) else str(run_dir),
        "reached": reached is not None,
        "frames_to_threshold": reached[0] if reached else None,
        "wall_s_to_threshold": wall.get(reached[0]) if reached else None,
        "wall_s_counts": "validation known" if known else "weights taken",
        "eval_curve": [{"frames": f, "success_rate": r, "wall_s": wall.get(f), "weights_wall_s": taken.get(f)}
                       for f, r in success],
        "final_eval_best_policy": final.get("final_eval"),
        "train_minutes": final["train_minutes"],
        "frames": final["frames"],
        "updates": final["updates"],
        "updates_per_s": final["updates"] / train_s,
        "frames_per_s": final["frames"] / train_s,
        "total_wall_s_including_final_eval": total_s,
    }


def _train_seed(args, name: str, extra: dict, seed: int) -> dict:
    overrides = {"name": name, "out_dir": str(ROOT / "runs"),
                 "max_minutes": args.minutes, "seed": seed, "eval_every_frames": args.eval_every, "eval_episodes": 1000,
                 "final_eval_episodes": 1000, **extra}
    r = _one_seed(args.config, overrides, args.threshold)
    reached = f"{r['wall_s_to_threshold']:.0f} s" if r["reached"] else "not reached"
    print(f"seed {seed}: {100 * args.threshold:.0f}% after {reached}; best policy final "
          f"{100 * r['final_eval_best_policy']['success_rate']:.1f}%; {r['updates_per_s']:.1f} updates/s, "
          f"{r['frames_per_s']:.0f} frames/s", flush=True)
    return r


def _title(algo: str, preset: str, overrides: dict | None) -> str:
    shown = "".join(f" {k}={v}" for k, v in (overrides or {}).items())
    return f"{algo.upper()}, {preset} preset{shown}: validation success per seed"


def _figure(runs: list[dict], threshold: float, title: str, path: Path, results: tuple[str | Path, ...] = ()) -> None:
    """Every seed's validation success against wall time into ``path`` (drawn from the results files ``results``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=100)
    for r in runs:
        rows = [row for row in r["eval_curve"] if row["wall_s"] is not None]
        ax.plot([row["wall_s"] for row in rows], [100 * row["success_rate"] for row in rows], "o-", ms=3,
                label=f"seed {r['seed']}")
    ax.axhline(100 * threshold, color="grey", ls="--", lw=1)
    ax.set_xlabel("wall time since the start of training [s] (2 CPU cores, evaluations included)")
    ax.set_ylabel("validation success, 1,000 episodes [%]")
    ax.set_ylim(0, 101)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, path, version=VERSION, results=results)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="training budget per seed [min]")
    parser.add_argument("--threshold", type=float, default=0.9)
    parser.add_argument("--eval-every", type=int, default=100_000,
                        help="frames between evaluations (PPO collects ~30k frames a batch: 327680 = every 10th batch)")
    parser.add_argument("--config", default="default", help="training preset (default, nav, ...)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds, run one after another")
    parser.add_argument("--out", default=None, help="results file (default: results/train_to_success[_CONFIG].json)")
    parser.add_argument("--summarize", action="store_true",
                        help="train nothing: rebuild the results (and figure) from the run folders an earlier "
                             "invocation kept, e.g. for another --threshold")
    parser.add_argument("--figure", default=None, help="PNG of every seed's evaluation success against wall time")
    parser.add_argument("--figure-only", action="store_true",
                        help="train nothing: draw --figure from the results file an earlier invocation wrote")
    parser.add_argument("overrides", nargs="*", help="key=value TrainConfig overrides")
    args = parser.parse_args()

    bad = [item for item in args.overrides if "=" not in item]
    if bad:
        parser.error(f"overrides must look like key=value, got {bad}")
    suffix = "" if args.config == "default" else f"_{args.config}"
    out = Path(args.out or RESULTS / f"train_to_success{suffix}.json")
    extra = dict(item.split("=", 1) for item in args.overrides)

    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.task.env import RoverEnv

    if args.figure_only:
        if not args.figure:
            parser.error("--figure-only needs --figure PATH")
        if not out.is_file():
            parser.error(f"--figure-only: no results file at {out}")
        earlier = json.loads(out.read_text())
        title = _title(earlier["algo"], earlier["preset"], earlier.get("overrides"))
        _figure(earlier["seeds"], earlier["threshold"], title, Path(args.figure), results=(out.resolve(),))
        print(f"figure: {args.figure} (from {out})")
        return 0
    if args.summarize:
        runs = []
        for seed in args.seeds:
            run_dir = ROOT / "runs" / f"bench_{out.stem}_seed{seed}"
            if not (run_dir / "final_eval.json").is_file():
                parser.error(f"--summarize: no finished run at {run_dir}")
            runs.append(_summarize(run_dir, seed, args.threshold, None))
        earlier = json.loads(out.read_text()) if out.is_file() else {}
        # measured or set by the invocation that trained
        compile_s, minutes, extra = earlier.get("compile_s"), earlier.get("minutes_per_seed"), earlier.get("overrides")
        totals = {r["seed"]: r.get("total_wall_s_including_final_eval") for r in earlier.get("seeds", [])}
        for r in runs:
            r["total_wall_s_including_final_eval"] = totals.get(r["seed"])
    else:
        env_cfg = load_train_config(args.config, extra).env
        t0 = time.perf_counter()
        RoverEnv(2, task=env_cfg.task, robot=env_cfg.robot).rollout(2)  # compiles (or loads) every kernel the run uses
        compile_s, minutes = time.perf_counter() - t0, args.minutes
        print(f"kernel compilation / cache load before the first seed: {compile_s:.1f} s", flush=True)
        runs = [_train_seed(args, f"bench_{out.stem}_seed{seed}", extra, seed) for seed in args.seeds]

    times = [r["wall_s_to_threshold"] for r in runs if r["reached"]]
    median = {
        "wall_s_to_threshold": statistics.median(times) if len(times) == len(runs) else None,
        "final_success_rate": statistics.median(r["final_eval_best_policy"]["success_rate"] for r in runs),
        "updates_per_s": statistics.median(r["updates_per_s"] for r in runs),
        "frames_per_s": statistics.median(r["frames_per_s"] for r in runs),
    }
    cfg = load_train_config(args.config, extra)
    result = {"benchmark": "train_to_success", "preset": args.config, "algo": cfg.optim.algo, "task": cfg.env.task,
              "robot": cfg.env.robot,
              "num_envs": cfg.env.num_envs, "eval_every_frames": args.eval_every, "threshold": args.threshold,
              "minutes_per_seed": minutes, "overrides": extra, "compile_s": compile_s,
              "summarized_from_kept_runs": args.summarize, "seeds": runs,
              "median": median, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    write_results(out, result, version=VERSION, task=True, robots=(cfg.env.robot,),
                  tasks=((cfg.env.task, cfg.env.robot),))
    print(f"\n| seed | {100 * args.threshold:.0f} % after [s] | frames then | final success of the best policy | updates/s | frames/s |"
          "\n|---:|---:|---:|---:|---:|---:|")
    for r in runs:
        when = (f"{r['wall_s_to_threshold']:.0f} | {r['frames_to_threshold']:,}" if r["reached"]
                else "not reached | -")
        print(f"| {r['seed']} | {when} | {100 * r['final_eval_best_policy']['success_rate']:.1f} % | "
              f"{r['updates_per_s']:.1f} | {r['frames_per_s']:.0f} |")
    print("\n| seed | frames | wall [s] | validation success (1,000 episodes) |\n|---:|---:|---:|---:|")
    for r in runs:
        for row in r["eval_curve"]:
            print(f"| {r['seed']} | {row['frames']:,} | {row['wall_s']:.0f} | {100 * row['success_rate']:.1f}% |")
    med = median["wall_s_to_threshold"]
    med_text = f"{med:.0f} s" if med is not None else "not reached by every seed"
    print(f"\nmedian over {len(runs)} seed(s): {100 * args.threshold:.0f}% after {med_text}; final "
          f"{100 * median['final_success_rate']:.1f}%; {median['updates_per_s']:.1f} updates/s, "
          f"{median['frames_per_s']:.0f} frames/s (kernel compilation "
          f"{'n/a' if compile_s is None else f'{compile_s:.1f} s'}, excluded)")
    print(f"written to {out}")
    if args.figure:
        _figure(runs, args.threshold, _title(cfg.optim.algo, args.config, extra), Path(args.figure),
                results=(Path(out).resolve(),))
        print(f"figure: {args.figure}")
    return 0 if len(times) == len(runs) else 1


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def _train_to_success(name: str) -> str:
    d = load_results(name)
    rows = []
    for s in d["seeds"]:
        reached = s["reached"]
        rows.append([str(s["seed"]), f"{s['wall_s_to_threshold']:.0f} s" if reached else "not reached",
                     f"{s['frames_to_threshold']:,}" if reached else "", f"{100 * s['final_eval_best_policy']['success_rate']:.1f} %",
                     f"{s['updates_per_s']:.1f}", f"{s['frames_per_s']:,.0f}"])
    m = d["median"]
    median_wall = "not reached" if m["wall_s_to_threshold"] is None else f"{m['wall_s_to_threshold']:.0f} s"
    rows.append(["median", f"**{median_wall}**", "", f"**{100 * m['final_success_rate']:.1f} %**",
                 f"{m['updates_per_s']:.1f}", f"{m['frames_per_s']:,.0f}"])
    return markdown_table(["seed", "90 % after", "frames then", "best policy, final (1,000 episodes)", "updates/s", "frames/s"],
                          ["---:"] * 6, rows)


def train_to_success() -> str:
    """``train_to_success.json``: the reach task's time to 90 % per seed."""
    return _train_to_success("train_to_success.json")


PPO_VS_SAC = (("reach", "SAC", "train_to_success.json", "--seeds 0 1 2 --minutes 10"),
              ("reach", "PPO", "train_to_success_ppo.json", "--config ppo --seeds 0 1 2 --minutes 10 --eval-every 327680"),
              ("nav", "SAC", "train_to_success_nav.json", "--config nav --seeds 0 1 2 --minutes 12"),
              ("nav", "PPO", "train_to_success_nav_ppo.json",
               "--config nav_ppo --seeds 0 1 2 --minutes 20 --eval-every 327680"))
"""(task, algorithm, results file of ``benchmarks/training/train_to_success.py``, its arguments) of the PPO-SAC table."""


def ppo_vs_sac() -> str:
    """``train_to_success*.json``: SAC and PPO on both tasks, medians over seeds; a file not in the tree (not
    measured yet, or measured before results files recorded their provenance and kept in git only) is a row saying
    which command writes it."""
    rows = []
    for task, algo, name, args in PPO_VS_SAC:
        if not results_path(name).is_file():
            rows.append([task, algo, "no current measurement", "", "", "", f"`python -m benchmarks.training.train_to_success {args}`"])
            continue
        d = load_results(name)
        m, seeds = d["median"], d["seeds"]
        reached = sum(s["reached"] for s in seeds)
        wall = "not reached by every seed" if m["wall_s_to_threshold"] is None else f"{m['wall_s_to_threshold']:.0f} s"
        rows.append([task, algo, f"**{wall}** ({reached} of {len(seeds)} seeds)", f"**{100 * m['final_success_rate']:.1f} %**",
                     f"{m['updates_per_s']:.1f}", f"{m['frames_per_s']:,.0f}",
                     f"`{name}` ({d['preset']}, {d.get('num_envs', 'n/a')} worlds, {d['minutes_per_seed']:g} min per seed)"])
    return markdown_table(["task", "algorithm", "90 % after (median)", "final success (median)", "updates/s", "frames/s",
                   "results file"], ["---", "---", "---:", "---:", "---:", "---:", "---"], rows)


def train_to_success_nav_deploy() -> str:
    """``train_to_success_nav_deploy.json``: the deployable nav task's time to 90 % per seed (under ``wide``)."""
    return _train_to_success("train_to_success_nav_deploy.json")


def train_to_success_nav_deploy_shipped() -> str:
    """``train_to_success_nav_deploy_shipped.json``: the run the shipped deployable policy comes from (seed 0)."""
    return _train_to_success("train_to_success_nav_deploy_shipped.json")


TABLES = {
    "train_to_success": train_to_success,
    "train_to_success_nav_deploy": train_to_success_nav_deploy,
    "train_to_success_nav_deploy_shipped": train_to_success_nav_deploy_shipped,
    "train_to_success_parking": lambda: _train_to_success("train_to_success_parking.json"),
    "train_to_success_nav_deploy_batch512": lambda: _train_to_success("train_to_success_nav_deploy_batch512.json"),
    "train_to_success_nav_deploy_slip": lambda: _train_to_success("train_to_success_nav_deploy_slip.json"),
    "train_to_success_nav_deploy_slip_gain": lambda: _train_to_success("train_to_success_nav_deploy_slip_gain.json"),
    "ppo_vs_sac": ppo_vs_sac,
}


if __name__ == "__main__":
    sys.exit(main())
