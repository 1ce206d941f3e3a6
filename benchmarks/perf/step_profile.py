"""Where one ``RoverSim.step`` spends its time, kernel by kernel: ``python -m benchmarks.perf.step_profile``.

Run: ``python -m benchmarks.perf.step_profile [--worlds 1024] [--steps 20] [--substeps 5]``

The step runs eagerly (no graph replay), pinned to one core, and every Warp launch, copy and
clear is timed on the host (CPU launches return when the kernel is done). The Python cost of a
launch, measured on an empty kernel, is taken off each launch, so the shares are the kernels'
own time. Each line names who owns the kernel: ``newton`` (Featherstone, including its array
clears and copies) or ``atrv_warp`` (contact, motor, state views). Figures are printed and
written to ``benchmarks/results/step_profile.json``.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import inspect
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _owner(frame) -> str:
    """``newton`` if the launch comes from Newton's code, else ``atrv_warp``."""
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if name.startswith("newton"):
            return "newton"
        if name.startswith("atrv_warp"):
            return "atrv_warp"
        frame = frame.f_back
    return "other"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=20, help="timed steps (after 5 warm-up steps)")
    parser.add_argument("--substeps", type=int, default=None, help="solver substeps per 0.05 s step (default: "
                        "the simulator's)")
    parser.add_argument("--out", default=str(RESULTS / "step_profile.json"))
    args = parser.parse_args()

    pin_to_one_core()
    import torch
    import warp as wp

    torch.set_num_threads(1)
    from atrv_warp import RoverSim, SimConfig

    cfg = dataclasses.replace(SimConfig(), use_graph=False)
    if args.substeps:
        cfg = dataclasses.replace(cfg, sim_dt=cfg.step_dt / args.substeps)
    sim = RoverSim(args.worlds, sim=cfg)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        sim.step(torch.rand(args.worlds, 2, generator=gen) * 8 - 4)

    @wp.kernel
    def _empty(x: wp.array(dtype=float)):
        x[wp.tid()] = 0.0

    probe = wp.zeros(1, dtype=float)
    wp.launch(_empty, dim=1, inputs=[probe])
    t0 = time.perf_counter()
    for _ in range(2000):
        wp.launch(_empty, dim=1, inputs=[probe])
    overhead = (time.perf_counter() - t0) / 2000

    spent: dict[tuple[str, str], float] = collections.defaultdict(float)
    calls: collections.Counter = collections.Counter()

    def timed(name_of, fn):
        def wrapper(*a, **k):
            t = time.perf_counter()
            out = fn(*a, **k)
            dt = time.perf_counter() - t
            key = (_owner(inspect.currentframe().f_back), name_of(a, k))
            spent[key] += max(dt - overhead, 0.0)
            calls[key] += 1
            return out
        return wrapper

    originals = (wp.launch, wp.launch_tiled, wp.copy, wp.array.zero_, wp.array.assign)
    wp.launch = timed(lambda a, k: (k.get("kernel") or a[0]).key, wp.launch)
    wp.launch_tiled = timed(lambda a, k: "tiled: " + (k.get("kernel") or a[0]).key.split("_locals__")[-1],
                            wp.launch_tiled)
    wp.copy = timed(lambda a, k: "array copies", wp.copy)
    wp.array.zero_ = timed(lambda a, k: "array clears", wp.array.zero_)
    wp.array.assign = timed(lambda a, k: "array copies", wp.array.assign)
    try:
        t0 = time.perf_counter()
        for _ in range(args.steps):
            sim.step(torch.rand(args.worlds, 2, generator=gen) * 8 - 4)
        total = (time.perf_counter() - t0) / args.steps
    finally:
        wp.launch, wp.launch_tiled, wp.copy, wp.array.zero_, wp.array.assign = originals

    rows = [{"owner": owner, "name": name, "ms_per_step": spent[(owner, name)] / args.steps * 1e3,
             "calls_per_step": calls[(owner, name)] / args.steps,
             "share": spent[(owner, name)] / args.steps / total} for owner, name in spent]
    rows.sort(key=lambda r: -r["ms_per_step"])
    timed_ms = sum(r["ms_per_step"] for r in rows)
    by_owner = {o: sum(r["share"] for r in rows if r["owner"] == o) for o in sorted({r["owner"] for r in rows})}
    print(f"{args.worlds} worlds, {sim.substeps} substeps, eager: {total * 1e3:.2f} ms per step, kernels "
          f"{timed_ms:.2f} ms; launch overhead taken off: {overhead * 1e6:.1f} us per launch")
    print(f"{'owner':10s} {'kernel':58s} {'ms/step':>8s} {'share':>6s} {'calls':>5s}")
    for r in rows:
        print(f"{r['owner']:10s} {r['name'][:58]:58s} {r['ms_per_step']:8.3f} {100 * r['share']:5.1f}% "
              f"{r['calls_per_step']:5.0f}")
    print("by owner: " + ", ".join(f"{o} {100 * s:.1f}%" for o, s in by_owner.items())
          + f", Python launch overhead and the rest {100 * (1 - timed_ms / 1e3 / total):.1f}%")
    ms_by_owner = {o: sum(r["ms_per_step"] for r in rows if r["owner"] == o) for o in by_owner}
    # the most that making our own kernels free could speed up the kernels' time
    ours_free_ceiling = timed_ms / (timed_ms - ms_by_owner.get("atrv_warp", 0.0))
    print("kernel ms per step by owner: " + ", ".join(f"{o} {ms:.2f}" for o, ms in ms_by_owner.items())
          + f"; with our kernels free the kernels' time would be at most {ours_free_ceiling:.2f}x shorter")
    out = write_results(args.out, {
        "benchmark": "step_profile", "worlds": args.worlds, "substeps": sim.substeps, "steps": args.steps,
        "ms_per_step_eager": total * 1e3, "kernel_ms_per_step": timed_ms, "launch_overhead_us": overhead * 1e6,
        "by_owner": by_owner, "ms_by_owner": ms_by_owner, "ours_free_ceiling": ours_free_ceiling,
        "rows": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S")}, version=VERSION)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def step_profile() -> str:
    """``step_profile.json``: where one step's kernel time goes, by kernel, at its number of worlds."""
    d = load_results("step_profile.json")
    owner = {"newton": "Newton", "atrv_warp": "ours"}
    rows = [[owner.get(r["owner"], r["owner"]), f"`{r['name']}`", f"{r['ms_per_step']:.2f}", f"{100 * r['share']:.1f} %",
             f"{r['calls_per_step']:g}"] for r in d["rows"][:10]]
    ms = d["ms_by_owner"]
    rows.append(["", "all of Newton / all of ours", f"{ms['newton']:.2f} / {ms['atrv_warp']:.2f}",
                 f"{100 * d['by_owner']['newton']:.1f} % / {100 * d['by_owner']['atrv_warp']:.1f} %", ""])
    return markdown_table(["owner", "kernel", "ms per step", "share", "launches per step"], ["---", "---", "---:", "---:", "---:"],
                          rows)


TABLES = {
    "step_profile": step_profile,
}


if __name__ == "__main__":
    sys.exit(main())
