"""Speed of this tree against an earlier revision, measured in one run, interleaved.

    python -m benchmarks.perf.compare_revisions --old 98b8398            # sim and env throughput
    python -m benchmarks.perf.compare_revisions --old HEAD~3 --sizes 64 1024 --rounds 5
    python -m benchmarks.perf.compare_revisions --old 2d88b0e --new-substeps 3   # this tree on 3 substeps

Absolute figures on a shared machine drift by tens of percent between runs, so this script
checks out ``--old`` into a temporary git worktree and measures both trees alternately
(old, new, old, new, …), each measurement in a fresh process pinned to one core with one torch
thread, after a warm-up (kernels compiled and cached beforehand). Per size it reports the median
env-steps/s of ``RoverSim.step`` (random torques) and of ``ATRVjrEnv.rollout`` (random actions)
for both trees and their ratio. Prints the table and writes
``benchmarks/results/compare_revisions.json``. ``--new-substeps K`` runs this tree's simulator and
environment on K solver substeps per step (``SimConfig(sim_dt=step_dt / K)``) and the old tree on its
defaults. ``--kinds twist`` times this tree's simulator driven by ``/cmd_vel`` through its motor driver (random
twists, the driver's command written in place each step as the env's kernel does) against the old tree's
``sim`` (random torques): what velocity control costs.
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

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"

_PROBE = r"""
import json, os, sys, time
if hasattr(os, "sched_setaffinity"):
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
import torch
torch.set_num_threads(1)
from atrv_warp import ATRVjrEnv, RoverSim
kind, n, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
kwargs = {}
if len(sys.argv) > 4:  # only this tree is given a substep count
    from atrv_warp import SimConfig
    kwargs["sim"] = SimConfig(sim_dt=SimConfig().step_dt / int(sys.argv[4]))
gen = torch.Generator().manual_seed(0)
if kind == "twist":
    sim = RoverSim(n, **kwargs)
    sim.reset(poses=(torch.rand(n, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
    cmds = [(torch.rand(n, 2, generator=gen) * 2 - 1) * torch.tensor([1.0, 1.0]) for _ in range(8)]
    sim.set_twist(cmds[0])
    def run():
        for c in cmds:
            sim.driver.twist.copy_(c)
            sim.driver.age.zero_()
            sim.step()
    frames = 8 * n
elif kind == "sim":
    sim = RoverSim(n, **kwargs)
    sim.reset(poses=(torch.rand(n, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
    cmds = [(torch.rand(n, 2, generator=gen) * 2 - 1) * 20 for _ in range(8)]
    def run():
        for c in cmds:
            sim.step(c)
    frames = 8 * n
else:
    env = ATRVjrEnv(n, seed=0, **kwargs)
    env.reset()
    def run():
        env.rollout(20, auto_reset=False, tensordict=env.reset(), break_when_any_done=False)
    frames = 20 * n
run()
run()
calls, t0 = 0, time.perf_counter()
while True:
    run()
    calls += 1
    elapsed = time.perf_counter() - t0
    if elapsed >= seconds:
        break
print(json.dumps({"rate": calls * frames / elapsed, "module": __import__("atrv_warp").__file__}))
"""


def _measure(tree: Path, kind: str, n: int, seconds: float, substeps: int | None = None) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    extra = [] if substeps is None else [str(substeps)]
    proc = subprocess.run([sys.executable, "-c", _PROBE, kind, str(n), str(seconds), *extra], capture_output=True,
                          text=True, env=env, check=False, cwd=tree)
    if proc.returncode != 0:
        raise SystemExit(f"measurement in {tree} failed:\n{proc.stderr[-3000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if not out["module"].startswith(str(tree)):
        raise SystemExit(f"measured {out['module']}, not the tree {tree}")
    return out["rate"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", required=True, help="git revision to compare against")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 1024])
    parser.add_argument("--kinds", nargs="+", default=["sim", "env"], choices=["sim", "env", "twist"])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=3.0, help="timed wall time per measurement [s]")
    parser.add_argument("--new-substeps", type=int, default=None,
                        help="solver substeps per step for this tree (default: its SimConfig)")
    parser.add_argument("--out", default=str(RESULTS / "compare_revisions.json"))
    args = parser.parse_args()
    if args.new_substeps is not None and args.new_substeps < 1:
        parser.error(f"--new-substeps must be a positive integer, got {args.new_substeps}")

    old_rev = subprocess.run(["git", "rev-parse", "--short", args.old], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.strip()
    new_rev = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory(prefix="atrv-old-") as tmp:
        old_tree = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(old_tree), old_rev], cwd=ROOT, check=True)
        try:
            for kind in args.kinds:
                for n in args.sizes:
                    old_kind = "sim" if kind == "twist" else kind  # the old tree drives by torque
                    # warm-up: compile both trees' kernels before timing
                    _measure(old_tree, old_kind, n, 0.2)
                    _measure(ROOT, kind, n, 0.2, args.new_substeps)
                    old, new = [], []
                    for _ in range(args.rounds):
                        old.append(_measure(old_tree, old_kind, n, args.seconds))
                        new.append(_measure(ROOT, kind, n, args.seconds, args.new_substeps))
                    row = {"kind": kind, "num_worlds": n, "old_median": statistics.median(old),
                           "new_median": statistics.median(new), "old": old, "new": new}
                    row["ratio"] = row["new_median"] / row["old_median"]
                    rows.append(row)
                    print(f"{kind:>3} N={n:>5}: old {row['old_median']:>9,.0f}  new {row['new_median']:>9,.0f} "
                          f"env-steps/s  new/old {row['ratio']:.3f}", flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old_tree)], cwd=ROOT, check=False)
    result = {"old": old_rev, "new": new_rev, "new_substeps": args.new_substeps, "rounds": args.rounds,
              "seconds": args.seconds, "rows": rows}
    write_results(args.out, result, version=VERSION)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
