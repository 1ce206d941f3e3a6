"""Raw simulator throughput: env-steps/s (one step = 0.05 s of one rover) versus world count.

Run: ``python -m benchmarks.perf.sim_throughput [--sizes 1 16 64 256 1024 4096] [--warm-cache]``

Before timing, the physics is checked (reference variant drives 3 s within 10 % of the
reference's 1.72 m; random commands leave no NaN). Kernel compilation is timed separately:
by default in a fresh, empty Warp kernel cache (what a first run on a new machine pays);
``--warm-cache`` uses ``~/.cache/warp`` instead. The process is pinned to one core.
Figures are printed and written to ``benchmarks/results/sim_throughput.json``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 16, 64, 256, 1024, 4096])
    parser.add_argument("--seconds", type=float, default=3.0, help="timed wall time per size [s]")
    parser.add_argument("--warm-cache", action="store_true", help="use the user's Warp kernel cache")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--skip-choices", action="store_true", help="skip the graph/tile on-off comparison")
    parser.add_argument("--out", default=str(RESULTS / "sim_throughput.json"))
    return parser


def measure(n: int, sim_cfg, args: argparse.Namespace, gen) -> dict | None:
    """One row: ``n`` worlds with ``sim_cfg`` (a ``SimConfig``) stepped for ``args.seconds``; None if not finite."""
    import torch
    import warp as wp

    from atrv_warp import RoverSim

    t0 = time.perf_counter()
    sim = RoverSim(n, device=args.device, sim=sim_cfg)
    poses = (torch.rand(n, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14159])
    sim.reset(poses=poses)
    cmds = ((torch.rand(n, 2, generator=gen) * 2 - 1) * 20).to(sim.commands.device)
    sim.commands.copy_(cmds)
    sim.step()  # records the graph
    wp.synchronize()
    build_s = time.perf_counter() - t0
    for _ in range(3):
        sim.step()
    wp.synchronize()
    steps = 0
    t0 = time.perf_counter()
    while True:
        for _ in range(5):
            sim.step()
        steps += 5
        wp.synchronize()
        elapsed = time.perf_counter() - t0
        if elapsed >= args.seconds or steps >= 20000:
            break
    if not torch.isfinite(sim.root_pose).all() or sim.nonfinite.any():
        print(f"N={n}: non-finite state after the timed run", file=sys.stderr)
        return None
    rate = steps * n / elapsed
    return {"num_worlds": n, "use_graph": sim_cfg.use_graph, "use_tile_gemm": sim_cfg.use_tile_gemm,
            "env_steps_per_s": rate, "ms_per_step": 1e3 * elapsed / steps, "steps_timed": steps,
            "build_s": build_s}


def print_tables(rows: list[dict], choices: list[dict]) -> None:
    """Print the rows, and the choices where measured, as Markdown tables."""
    print("\n| worlds | env-steps/s | ms/step |\n|---:|---:|---:|")
    for r in rows:
        print(f"| {r['num_worlds']} | {r['env_steps_per_s']:,.0f} | {r['ms_per_step']:.3f} |")
    if choices:
        print("\n| worlds | graph replay | tile GEMM | env-steps/s |\n|---:|---|---|---:|")
        for r in choices:
            print(f"| {r['num_worlds']} | {r['use_graph']} | {r['use_tile_gemm']} | {r['env_steps_per_s']:,.0f} |")


def main() -> int:
    args = build_parser().parse_args()

    if args.device == "cpu":
        pin_to_one_core()
    import warp as wp

    tmp_cache = None
    if not args.warm_cache:
        tmp_cache = tempfile.TemporaryDirectory(prefix="warp-cache-")
        wp.config.kernel_cache_dir = tmp_cache.name
    import torch

    torch.set_num_threads(1)
    from atrv_warp import DriveMode, RoverSim, SimConfig

    # -- compile (first build + first step), measured on its own
    t0 = time.perf_counter()
    sim = RoverSim(1, variant="reference", device=args.device)
    sim.step()
    wp.synchronize()
    compile_s = time.perf_counter() - t0
    print(f"kernel compile + first step: {compile_s:.1f} s ({'warm' if args.warm_cache else 'cold'} cache)")

    # -- physics sanity before any timing
    for _ in range(19):
        sim.step()
    x0 = sim.root_pose[0, 0].item()
    sim.set_mode(DriveMode.FORWARD)
    for _ in range(60):
        sim.step()
    x3 = sim.root_pose[0, 0].item() - x0
    if abs(x3 / 1.72 - 1.0) > 0.10:
        print(f"physics check failed: x after 3 s = {x3:.3f} m, reference 1.72 m", file=sys.stderr)
        return 1
    print(f"physics check: reference variant x(3 s) = {x3:.3f} m (reference 1.72 m)")

    gen = torch.Generator().manual_seed(0)

    rows = []
    for n in args.sizes:
        row = measure(n, SimConfig(), args, gen)
        if row is None:
            return 1
        rows.append(row)
        print(f"N={n:5d}  {row['env_steps_per_s']:12,.0f} env-steps/s  {row['ms_per_step']:8.3f} ms/step  "
              f"(build {row['build_s']:.1f} s)", flush=True)

    # The choices behind the defaults: graph replay and tile GEMM, on and off.
    choices = []
    if not args.skip_choices:
        print("\nchoices (graph replay, tile GEMM):")
        for n in (1, 1024):
            for graph in (True, False):
                for tile in (True, False):
                    row = measure(n, SimConfig(use_graph=graph, use_tile_gemm=tile), args, gen)
                    if row is None:
                        return 1
                    choices.append(row)
                    print(f"N={n:5d} graph={graph!s:5s} tile={tile!s:5s} {row['env_steps_per_s']:12,.0f} env-steps/s",
                          flush=True)

    result = {
        "benchmark": "sim_throughput",
        "device": args.device,
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "cores_used": 1 if args.device == "cpu" else None,
        "kernel_cache": "warm" if args.warm_cache else "cold",
        "compile_and_first_step_s": compile_s,
        "physics_check_x3_m": x3,
        "rows": rows,
        "choices": choices,
        "time": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    out = write_results(args.out, result, version=VERSION)
    print_tables(rows, choices)
    print(f"\nwritten to {out}")
    if tmp_cache is not None:
        tmp_cache.cleanup()
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def sim_throughput(name: str = "sim_throughput.json") -> str:
    """``sim_throughput.json``: env-steps/s and ms per step against the number of worlds."""
    rows = load_results(name)["rows"]
    return markdown_table(["worlds", "env-steps/s", "ms/step"], ["---:"] * 3,
                          [[f"{r['num_worlds']:,}", f"{r['env_steps_per_s']:,.0f}", f"{r['ms_per_step']:.3f}"] for r in rows])


def sim_throughput_cuda() -> str:
    """``sim_throughput_cuda.json``: the same on one GPU."""
    return sim_throughput("sim_throughput_cuda.json")


def sim_choices() -> str:
    """``sim_throughput.json``: graph replay and tile GEMM on and off."""
    rows = load_results("sim_throughput.json")["choices"]
    on = {True: "on", False: "off"}
    return markdown_table(["worlds", "graph replay", "tile GEMM", "env-steps/s"], ["---:", "---", "---", "---:"],
                          [[str(r["num_worlds"]), on[r["use_graph"]], on[r["use_tile_gemm"]], f"{r['env_steps_per_s']:,.0f}"]
                   for r in rows])


TABLES = {
    "sim_throughput": sim_throughput,
    "sim_throughput_cuda": sim_throughput_cuda,
    "sim_choices": sim_choices,
}


if __name__ == "__main__":
    sys.exit(main())
