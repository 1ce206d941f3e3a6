"""Does SAC learn as fast on three substeps as on five? ``python benchmarks/substep_training.py``.

Run: ``python benchmarks/substep_training.py [--new 85706cd] [--old 4fc2a2d] [--seeds 3 4 5] [--minutes 2.2]``, or
``--summarize`` to print the table from the results already in ``benchmarks/results/substep_training/``.

Issue 17 made three substeps (``SimConfig.sim_dt = FAST_SIM_DT``) cheaper per step. This checks what
they do to training: for each seed, in turn, ``train_to_success.py`` on the default recipe in
``--new``, a revision whose default was three substeps (85706cd), and in ``--old``, one whose default
is five (4fc2a2d), each checked out into a temporary git worktree. Each run writes
``results/substep_training/{three_substeps,five_substeps_OLD}_seedS.json``; the summary reads every
file there whose name starts with ``three_substeps`` or ``five_substeps`` and prints, per seed, the
seconds to 90 % and the first three evaluations' success, then the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "substep_training"


def _train(tree: Path, seed: int, minutes: float, out: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    subprocess.run([sys.executable, "train_to_success.py", "--minutes", str(minutes), "--seeds", str(seed),
                    "--out", str(out)], cwd=tree / "benchmarks", env=env, check=True)


def summarize() -> dict:
    """Per-seed and median figures of every results file in :data:`OUT`."""
    kinds: dict[str, list[dict]] = {"five": [], "three": []}
    for path in sorted([*OUT.glob("three_substeps*.json"), *OUT.glob("five_substeps*.json")]):
        kind = "three" if path.name.startswith("three") else "five"
        for s in json.loads(path.read_text())["seeds"]:
            curve = [round(100 * e["success_rate"], 1) for e in s["eval_curve"][:3]]
            kinds[kind].append({"seed": s["seed"], "file": path.name, "first_evals_percent": curve,
                                "seconds_to_90": s["wall_s_to_threshold"] if s["reached"] else None})
    summary = {}
    for kind, rows in kinds.items():
        rows.sort(key=lambda r: r["seed"])
        reached = [r["seconds_to_90"] for r in rows if r["seconds_to_90"] is not None]
        summary[kind] = {"seeds": rows, "runs": len(rows), "reached": len(reached),
                         "median_seconds_to_90": statistics.median(reached) if reached else None,
                         "first_eval_mean_percent": statistics.mean(r["first_evals_percent"][0] for r in rows),
                         "passed_at_first_eval": sum(r["first_evals_percent"][0] >= 90.0 for r in rows)}
        print(f"{kind} substeps:")
        for r in rows:
            print(f"  seed {r['seed']}: 90 % after {r['seconds_to_90']:.0f} s; first evaluations "
                  f"{' / '.join(f'{c:.1f}' for c in r['first_evals_percent'])} %  ({r['file']})")
        s = summary[kind]
        print(f"  median {s['median_seconds_to_90']:.0f} s to 90 %; first evaluation {s['first_eval_mean_percent']:.1f} % "
              f"on average, >= 90 % in {s['passed_at_first_eval']} of {s['runs']} runs")
    return summary


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", default="4fc2a2d", help="a revision whose default is five substeps")
    parser.add_argument("--new", default="85706cd", help="a revision whose default is three substeps")
    parser.add_argument("--seeds", type=int, nargs="+", default=[3, 4, 5])
    parser.add_argument("--minutes", type=float, default=2.2, help="training budget per run [min]")
    parser.add_argument("--summarize", action="store_true", help="train nothing; print the table of kept results")
    args = parser.parse_args()
    if not args.summarize:
        OUT.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            trees = {}
            for name, rev in (("old", args.old), ("new", args.new)):
                trees[name] = Path(tmp) / name
                subprocess.run(["git", "worktree", "add", "--detach", str(trees[name]), rev], cwd=ROOT, check=True)
            try:
                for seed in args.seeds:  # alternating, so both trees see the same machine load
                    _train(trees["new"], seed, args.minutes, OUT / f"three_substeps_seed{seed}.json")
                    _train(trees["old"], seed, args.minutes, OUT / f"five_substeps_{args.old}_seed{seed}.json")
            finally:
                for tree in trees.values():
                    subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
    summary = summarize()
    (OUT / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"written to {OUT / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
