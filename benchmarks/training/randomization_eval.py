"""The nav policies under shift: the randomized and the plain policy on the nominal rover and on the ``wide``
test distribution, with success by parameter bin.

Run: ``python -m benchmarks.training.randomization_eval [--episodes 1000] [--figure docs/randomization_eval.png]
[--randomized PATH] [--plain PATH]``

Each policy runs one deterministic episode in each of ``--episodes`` worlds of the nav task, from the
evaluation seed (:data:`atrv_warp.task.evaluation.EVAL_SEED`, which training never uses), twice: on the nominal
rover with perfect sensors (``randomization="none"``), and with the ``wide`` preset (per world: mu 0.2-1.0,
payload 0-25 kg, motors +-20 %, wheel radius, ground stiffness, latency 0-2 steps, sensor noise), the same
draws for both policies. This is ``python -m atrv_warp.evaluate --task nav --randomization wide`` for the two.
Targets (issue 29): the randomized policy >= 90 % on ``wide``; on the nominal rover within 3 points of the plain
one. Figures are printed and written to ``benchmarks/results/randomization_eval.json``; ``--figure`` draws the
success by friction, payload and latency bin of both policies.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, save_figure, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def draw(result: dict, out: Path, results: str | Path = "randomization_eval.json") -> None:
    """Success by parameter bin under ``wide``, both policies, into ``out`` (drawn from ``results``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {"friction": "ground friction mu", "payload_mass": "payload [kg]", "latency": "action latency [steps]"}
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
    policies = list(result["policies"])
    width = 0.8 / len(policies)
    for ax, (name, label) in zip(axes, labels.items()):
        for k, policy in enumerate(policies):
            rows = result["policies"][policy]["wide"]["success_by_bin"][name]
            x = [i + (k - (len(policies) - 1) / 2) * width for i in range(len(rows))]
            ax.bar(x, [100 * r["success"] for r in rows], width, label=f"{policy} policy")
        ax.set_xticks(range(len(rows)))
        ax.set_xticklabels([f"{r['low'] + 0.5:g}" if name == "latency" else f"{r['low']:g}-{r['high']:g}"
                            for r in rows], fontsize=8)
        ax.set_xlabel(label)
        ax.axhline(90, color="0.5", lw=0.8, ls="--")
        ax.set_ylim(0, 100)
    axes[0].set_ylabel("success [%]")
    axes[0].legend(loc="lower right", fontsize=8)
    overall = ", ".join(f"{p} {100 * result['policies'][p]['wide']['success_rate']:.1f} %" for p in policies)
    fig.suptitle(f"nav task under the 'wide' randomization, {result['episodes']} episodes: {overall}", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out, version=VERSION, results=(results,), dpi=110)
    plt.close(fig)
    print(f"figure: {out}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--randomized", default=None, help="randomized policy (default: the shipped nav policy)")
    parser.add_argument("--plain", default=None, help="plain policy (default: the shipped nav_policy_plain.pt)")
    parser.add_argument("--figure", default=None, help="draw the success-by-bin figure to this PNG")
    parser.add_argument("--out", default=str(RESULTS / "randomization_eval.json"))
    parser.add_argument("--figure-only", action="store_true",
                        help="evaluate nothing: draw --figure from the results file (--out) an earlier run wrote")
    args = parser.parse_args()
    if args.figure_only:
        if not args.figure:
            parser.error("--figure-only needs --figure PATH")
        draw(json.loads(Path(args.out).read_text()), Path(args.figure), results=Path(args.out).resolve())
        return 0

    import torch

    torch.set_num_threads(1)
    from atrv_warp.policy import load_policy, pretrained_nav_policy_path
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import EVAL_SEED, format_bins, format_result, run_episodes, success_by_bin

    paths = {"randomized": args.randomized or str(pretrained_nav_policy_path()),
             "plain": args.plain or str(pretrained_nav_policy_path(randomized=False))}
    envs = {preset: ATRVjrEnv(args.episodes, task="nav", randomization=preset) for preset in ("none", "wide")}
    result = {"benchmark": "randomization_eval", "episodes": args.episodes, "seed": EVAL_SEED,
              "targets": "randomized >= 90 % on wide; on the nominal rover within 3 points of the plain policy",
              "policies": {}}
    for name, path in paths.items():
        policy = load_policy(path)
        result["policies"][name] = {"path": str(path)}
        for preset, env in envs.items():
            t0 = time.perf_counter()
            record = run_episodes(policy, env, seed=EVAL_SEED)
            summary = record.summary()
            row = {**summary.as_dict(), "seconds": round(time.perf_counter() - t0, 1)}
            print(format_result(f"{name} policy, randomization {preset}", summary), flush=True)
            if preset == "wide":
                row["success_by_bin"] = success_by_bin(record)
                print(format_bins(row["success_by_bin"]), flush=True)
            result["policies"][name][preset] = row
    rnd, plain = result["policies"]["randomized"], result["policies"]["plain"]
    result["nominal_gap_points"] = 100 * (rnd["none"]["success_rate"] - plain["none"]["success_rate"])
    result["wide_gain_points"] = 100 * (rnd["wide"]["success_rate"] - plain["wide"]["success_rate"])
    print(f"randomized - plain: {result['wide_gain_points']:+.1f} points on 'wide', "
          f"{result['nominal_gap_points']:+.1f} points on the nominal rover")
    result["time"] = time.strftime("%Y-%m-%d %H:%M:%S")
    out = write_results(args.out, result, version=VERSION, task=True, policies=tuple(paths.values()))
    print(f"written to {out}")
    if args.figure:
        draw(result, Path(args.figure), results=out.resolve())
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def randomization_eval() -> str:
    """``randomization_eval.json``: the randomized and the plain nav policy, nominal and under ``wide``."""
    d = load_results("randomization_eval.json")
    rows = []
    for name, p in d["policies"].items():
        rows.append([f"{name} (`{Path(p['path']).name}`)", f"**{100 * p['wide']['success_rate']:.1f} %**",
                     f"{100 * p['none']['success_rate']:.1f} %", f"{100 * p['wide']['obstacle_rate']:.1f} %",
                     f"{100 * p['wide']['wall_rate']:.1f} %", f"{100 * p['wide']['timeout_rate']:.1f} %"])
    return markdown_table([f"nav policy ({d['episodes']:,} episodes each)", "success, `wide`", "success, nominal rover",
                   "obstacle, `wide`", "wall, `wide`", "timeout, `wide`"], ["---"] + ["---:"] * 5, rows)


def randomization_bins() -> str:
    """``randomization_eval.json``: success by parameter bin under ``wide``, both policies."""
    d = load_results("randomization_eval.json")
    policies = list(d["policies"])
    rows = []
    for param, label in (("friction", "µ"), ("payload_mass", "payload [kg]"), ("latency", "latency [steps]")):
        bins = [d["policies"][p]["wide"]["success_by_bin"][param] for p in policies]
        for i, r in enumerate(bins[0]):
            span = f"{r['low'] + 0.5:g}" if param == "latency" else f"{r['low']:g}–{r['high']:g}"
            rows.append([f"{label} {span}", f"{r['episodes']}",
                         *(f"{100 * b[i]['success']:.1f} %" for b in bins)])
    return markdown_table(["bin", "episodes", *(f"{p} policy" for p in policies)], ["---"] + ["---:"] * (1 + len(policies)),
                          rows)


TABLES = {
    "randomization_eval": randomization_eval,
    "randomization_bins": randomization_bins,
}


if __name__ == "__main__":
    sys.exit(main())
