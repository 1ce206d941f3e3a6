"""Newton and Warp options that might cut the simulator's step, measured in one run, interleaved.

    python -m benchmarks.physics.solver_options                       # N = 1024, 3 rounds
    python -m benchmarks.physics.solver_options --sizes 64 1024 --rounds 5

Issue 17 asked for Newton options that make the step cheaper without patching Newton. Each
variant below is a setting a user can choose; none changes Newton's code:

- ``default``: this package's defaults. On the CPU they include ``SimConfig.fuse_cholesky=None``:
  Newton factorises the mass matrix in a kernel of its own;
- ``fused_cholesky``: ``SimConfig(fuse_cholesky=True)``, Newton's own default, which factorises it
  in the kernel that forms it (this package's default before issue 17);
- ``opt_level_3``: ``wp.config.optimization_level = 3`` (Warp compiles CPU kernels at -O2);
- ``no_grid_stride``: ``wp.config.default_grid_stride = False``, Warp's lean launch path;
- ``no_backward``: ``wp.config.enable_backward = False``, no adjoint kernels compiled. It cannot
  be a default, because ``DiffRollout`` needs them; it is here for its compile time.

Each measurement is a fresh process pinned to one core with one torch thread, and the variants
alternate within each round. Each variant has its own empty kernel cache, so its first
measurement also times its cold compilation. Per variant and size the script reports the median
env-steps/s of ``RoverSim.step`` under random torques, its ratio to ``default`` in the same round
(median over rounds), and whether 40 steps from the same start end in bit-identical poses.
Prints the table and writes ``benchmarks/results/solver_options.json``.
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

VARIANTS = {  # name: (wp.config settings, SimConfig fields)
    "default": ({}, {}),
    "fused_cholesky": ({}, {"fuse_cholesky": True}),
    "opt_level_3": ({"optimization_level": 3}, {}),
    "no_grid_stride": ({"default_grid_stride": False}, {}),
    "no_backward": ({"enable_backward": False}, {}),
}

_PROBE = r"""
import hashlib, json, os, sys, time
if hasattr(os, "sched_setaffinity"):
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
import warp as wp
wp.config.kernel_cache_dir = sys.argv[4]
for key, value in json.loads(sys.argv[5]).items():
    setattr(wp.config, key, value)
import torch
torch.set_num_threads(1)
from atrv_warp import RoverSim, SimConfig
n, seconds = int(sys.argv[1]), float(sys.argv[2])
sim_cfg = SimConfig(**json.loads(sys.argv[3]))
gen = torch.Generator().manual_seed(0)
t0 = time.perf_counter()
sim = RoverSim(n, sim=sim_cfg)
sim.reset(poses=(torch.rand(n, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
cmds = [(torch.rand(n, 2, generator=gen) * 2 - 1) * 20 for _ in range(8)]
sim.step(cmds[0])
wp.synchronize()
first_step_s = time.perf_counter() - t0
for i in range(39):
    sim.step(cmds[(i + 1) % 8])
digest = hashlib.sha256(sim.root_pose.cpu().numpy().tobytes()).hexdigest()[:16]
calls, t0 = 0, time.perf_counter()
while True:
    for c in cmds:
        sim.step(c)
    calls += 1
    elapsed = time.perf_counter() - t0
    if elapsed >= seconds:
        break
print(json.dumps({"steps_per_s": 8 * n * calls / elapsed, "first_step_s": first_step_s, "poses_after_40": digest}))
"""


def _measure(n: int, seconds: float, variant: str, cache: Path) -> dict:
    warp_config, sim_kwargs = VARIANTS[variant]
    proc = subprocess.run([sys.executable, "-c", _PROBE, str(n), str(seconds), json.dumps(sim_kwargs), str(cache),
                           json.dumps(warp_config)], check=False, capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    if proc.returncode != 0:
        raise SystemExit(f"measurement of {variant} at N={n} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=2.0, help="timed wall time per measurement [s]")
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--out", default=str(RESULTS / "solver_options.json"))
    args = parser.parse_args()
    variants = ["default", *[v for v in args.variants if v != "default"]]

    with tempfile.TemporaryDirectory(prefix="solver-options-") as tmp:
        caches = {v: Path(tmp) / v for v in variants}
        runs: dict[int, dict[str, list[dict]]] = {n: {v: [] for v in variants} for n in args.sizes}
        compile_s: dict[str, float] = {}
        for r in range(args.rounds):
            for n in args.sizes:
                order = variants if r % 2 == 0 else variants[::-1]
                for v in order:
                    m = _measure(n, args.seconds, v, caches[v])
                    compile_s.setdefault(v, m["first_step_s"])
                    runs[n][v].append(m)
                    print(f"round {r + 1}/{args.rounds}  N={n:5d}  {v:18s} {m['steps_per_s']:10,.0f} env-steps/s",
                          flush=True)

    result: dict = {"rounds": args.rounds, "seconds": args.seconds, "cold_compile_and_first_step_s": compile_s,
                    "sizes": {}}
    print()
    print("| variant | cold compile + first step [s] | "
          + " | ".join(f"N = {n}: env-steps/s, vs default" for n in args.sizes)
          + " | bit-identical to default |")
    print("|---|---:|" + "---:|" * len(args.sizes) + "---|")
    for v in variants:
        cells, identical = [], True
        for n in args.sizes:
            base = runs[n]["default"]
            ratio = statistics.median(m["steps_per_s"] / b["steps_per_s"]
                                      for m, b in zip(runs[n][v], base, strict=True))
            median = statistics.median(m["steps_per_s"] for m in runs[n][v])
            same = all(m["poses_after_40"] == base[0]["poses_after_40"] for m in runs[n][v])
            identical &= same
            result["sizes"].setdefault(str(n), {})[v] = {
                "steps_per_s": [m["steps_per_s"] for m in runs[n][v]], "median_steps_per_s": median,
                "ratio_to_default": ratio, "bit_identical_to_default": same}
            cells.append(f"{median:,.0f}, {ratio:.3f}")
        print(f"| {v} | {compile_s[v]:.1f} | " + " | ".join(cells) + f" | {'yes' if identical else 'no'} |")
    out = write_results(args.out, result, version=VERSION)
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
