"""Does SAC learn as fast on three substeps as on five? ``python -m benchmarks.training.substep_training``.

Run: ``python -m benchmarks.training.substep_training [--seeds 0 1 2 3 4 5 6 7] [--frames 250000] [--every 50000]``,
or ``--summarize`` to print the table from the results already in ``benchmarks/results/substep_training/``.

Issue 17 made three substeps (``SimConfig.sim_dt = FAST_SIM_DT``) about 1.4x cheaper per step. This
checks what they do to training, in this tree: for each seed, in turn, ``train_to_success.py`` on the
default recipe with ``substeps=3`` and then ``substeps=5`` (the order alternates from seed to seed,
so both see the same machine load), each in its own process. Every run trains for ``--frames``
frames and is evaluated every ``--every`` frames on the 1,000-episode seeded evaluation set, under
its own substeps. Each writes ``results/substep_training/{three,five}_substeps_seedS.json``.

The summary reads every such file and prints, per arm: the mean success at each evaluation, the
frames and seconds until 90 % (wall time includes the evaluations, which cost the three-substep arm
less), and how many runs were at 90 % by each evaluation. The comparison is of frames: the recipe
does a fixed number of updates per frame, so frames measure learning, and seconds add the step's cost.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "benchmarks" / "results" / "substep_training"
ARMS = {"three": 3, "five": 5}


def _train(arm: str, seed: int, frames: int, every: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = OUT / f"{arm}_substeps_seed{seed}.json"
    out.unlink(missing_ok=True)
    # train_to_success exits with 1 when a seed does not reach 90 %, which is a result here, not a failure
    subprocess.run([sys.executable, "train_to_success.py", "--minutes", "0", "--seeds", str(seed), "--out", str(out),
                    f"substeps={ARMS[arm]}", f"total_frames={frames}", f"eval_every_frames={every}"],
                   cwd=Path(__file__).resolve().parent, env=env, check=False)
    if not out.is_file():
        raise RuntimeError(f"train_to_success.py wrote no {out}: see its output above")


def _welch_t(a: list[float], b: list[float]) -> float | None:
    if len(a) < 2 or len(b) < 2:
        return None
    se = (statistics.variance(a) / len(a) + statistics.variance(b) / len(b)) ** 0.5
    return (statistics.mean(a) - statistics.mean(b)) / se if se > 0 else None


def summarize() -> dict:
    """Per-arm figures of every results file in :data:`OUT`, and the difference at each evaluation."""
    runs: dict[str, list[dict]] = {arm: [] for arm in ARMS}
    for arm in ARMS:
        for path in sorted(OUT.glob(f"{arm}_substeps_seed*.json")):
            for s in json.loads(path.read_text())["seeds"]:
                runs[arm].append({"seed": s["seed"], "file": path.name,
                                  "curve": {e["frames"]: e["success_rate"] for e in s["eval_curve"]},
                                  "frames_to_90": s["frames_to_threshold"], "seconds_to_90": s["wall_s_to_threshold"],
                                  "final_success": s["final_eval_best_policy"]["success_rate"]})
    frames = sorted(set.intersection(*(set(r["curve"]) for rows in runs.values() for r in rows)) if any(runs.values())
                    else [])
    summary: dict = {"evaluated_at_frames": frames, "arms": {}}
    for arm, rows in runs.items():
        rows.sort(key=lambda r: r["seed"])
        reached = [r for r in rows if r["frames_to_90"] is not None]
        summary["arms"][arm] = {
            "substeps": ARMS[arm], "runs": len(rows), "seeds": [r["seed"] for r in rows],
            "mean_success_percent": {f: 100 * statistics.mean(r["curve"][f] for r in rows) for f in frames},
            "at_90_by": {f: sum(r["frames_to_90"] is not None and r["frames_to_90"] <= f for r in rows) for f in frames},
            "reached_90": len(reached),
            "median_frames_to_90": statistics.median(r["frames_to_90"] for r in reached) if reached else None,
            "median_seconds_to_90": statistics.median(r["seconds_to_90"] for r in reached) if reached else None,
            "final_success_percent": [round(100 * r["final_success"], 1) for r in rows],
            "per_seed": rows,
        }
    if all(runs.values()):
        summary["welch_t_three_minus_five"] = {
            f: _welch_t([r["curve"][f] for r in runs["three"]], [r["curve"][f] for r in runs["five"]]) for f in frames}
    print("evaluation success, mean over seeds [%] (runs at >= 90 % by then)")
    print("| frames | " + " | ".join(f"{arm} substeps" for arm in ARMS) + " | Welch t (three - five) |")
    print("|---:|" + "---:|" * (len(ARMS) + 1))
    for f in frames:
        cells = [f"{summary['arms'][a]['mean_success_percent'][f]:.1f} ({summary['arms'][a]['at_90_by'][f]}/"
                 f"{summary['arms'][a]['runs']})" for a in ARMS]
        t = summary.get("welch_t_three_minus_five", {}).get(f)
        print(f"| {f:,} | " + " | ".join(cells) + f" | {'n/a' if t is None else f'{t:+.2f}'} |")
    for arm, s in summary["arms"].items():
        if s["reached_90"]:
            print(f"{arm} substeps: 90 % in {s['reached_90']} of {s['runs']} runs, median of those after "
                  f"{s['median_frames_to_90']:,.0f} frames / {s['median_seconds_to_90']:.0f} s; "
                  f"final success of the best policies "
                  f"{min(s['final_success_percent']):.1f}-{max(s['final_success_percent']):.1f} %")
        else:
            print(f"{arm} substeps: 90 % in none of {s['runs']} runs")
    return summary


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(8)))
    parser.add_argument("--frames", type=int, default=250_000, help="frames per run")
    parser.add_argument("--every", type=int, default=50_000, help="evaluation interval [frames]")
    parser.add_argument("--summarize", action="store_true", help="train nothing; print the table of kept results")
    args = parser.parse_args()
    if not args.summarize:
        OUT.mkdir(parents=True, exist_ok=True)
        for i, seed in enumerate(args.seeds):
            order = list(ARMS) if i % 2 == 0 else list(ARMS)[::-1]
            for arm in order:
                _train(arm, seed, args.frames, args.every)
    summary = summarize()
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"written to {OUT / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
