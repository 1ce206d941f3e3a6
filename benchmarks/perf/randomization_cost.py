"""What domain randomization costs per env step: the ``wide`` preset against ``none``, interleaved.

Run: ``python -m benchmarks.perf.randomization_cost [--num-envs 1024] [--tasks nav reach] [--seconds 3] [--rounds 5]``

In this process pinned to one core with one torch thread, for each task: env-steps/s of ``ATRVjrEnv`` stepping
random actions with resets (``step_and_maybe_reset``, as a collector does) under ``randomization="none"`` and
``"wide"`` (every physical parameter drawn on each reset, the payload applied to the solver, the latency
buffer, observation and scan noise), measured alternately, best of ``--rounds`` each. Kernel compilation
(the first build and step of each) is timed separately and excluded. Target (issue 29): ``wide`` no more
than 10 % slower than ``none`` at N = 1024. Figures are printed and written to
``benchmarks/results/randomization_cost.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, random_step, rate, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
PRESETS = ("none", "wide")



def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--tasks", nargs="+", default=["nav", "reach"])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", default=str(RESULTS / "randomization_cost.json"))
    args = parser.parse_args()

    pin_to_one_core()
    import torch

    torch.set_num_threads(1)
    from atrv_warp.task.env import ATRVjrEnv

    compile_s = {}
    for task in args.tasks:
        for preset in PRESETS:  # the first build and step compiles (or loads) every kernel it uses
            t0 = time.perf_counter()
            ATRVjrEnv(2, task=task, randomization=preset).rollout(2)
            compile_s[f"{task}/{preset}"] = round(time.perf_counter() - t0, 2)
    print(f"first build and step (kernel compilation or cache load) [s]: {compile_s}", flush=True)

    rows = []
    for task in args.tasks:
        gen = torch.Generator().manual_seed(0)
        steppers = {p: random_step(ATRVjrEnv(args.num_envs, task=task, seed=0, randomization=p), gen) for p in PRESETS}
        best = dict.fromkeys(PRESETS, 0.0)
        for _ in range(args.rounds):  # interleaved: both see the same machine load
            for p in PRESETS:
                best[p] = max(best[p], rate(steppers[p], args.num_envs, args.seconds))
        ratio = best["wide"] / best["none"]
        row = {"task": task, "num_envs": args.num_envs, "none_env_steps_per_s": best["none"],
               "wide_env_steps_per_s": best["wide"], "wide_over_none": ratio, "slowdown_pct": 100 * (1 / ratio - 1)}
        rows.append(row)
        print(f"{task:5s} N={args.num_envs}: none {best['none']:8.0f}  wide {best['wide']:8.0f} env-steps/s -> "
              f"wide / none {ratio:.3f} (step time +{row['slowdown_pct']:.1f} %)", flush=True)
    result = {"benchmark": "randomization_cost", "target": "wide no more than 10 % slower than none at N = 1024",
              "compile_s": compile_s, "seconds": args.seconds, "rounds": args.rounds, "rows": rows,
              "time": time.strftime("%Y-%m-%d %H:%M:%S"), "python": sys.version.split()[0]}
    out = write_results(args.out, result, version=VERSION, task=True)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def randomization_cost() -> str:
    """``randomization_cost.json``: env-steps/s with ``wide`` against ``none``, interleaved."""
    d = load_results("randomization_cost.json")
    return markdown_table(["task", "N", "`none` env-steps/s", "`wide` env-steps/s", "wide / none", "step time"],
                          ["---", "---:", "---:", "---:", "---:", "---:"],
                          [[r["task"], str(r["num_envs"]), f"{r['none_env_steps_per_s']:,.0f}",
                    f"{r['wide_env_steps_per_s']:,.0f}", f"{r['wide_over_none']:.3f}", f"{r['slowdown_pct']:+.1f} %"]
                   for r in d["rows"]])


TABLES = {
    "randomization_cost": randomization_cost,
}


if __name__ == "__main__":
    sys.exit(main())
