"""Differentiable rollouts: gradient agreement with finite differences, and forward/backward cost.

Run: ``python benchmarks/diff_gradients.py [--horizons 1 2 5 10 20 40] [--sizes 1 64 1024]``

Agreement: for each driving scenario and horizon T (env steps of 0.05 s), the tape gradient of
``L = x_T + y_T + 2 qz_T`` (final position and heading) with respect to all actions is compared
with central finite differences (eps = 1e-2) along random unit directions of two kinds:
common mode (both wheels together, random weights over time) and differential (left against
right: what turns the rover). Reported: the worst relative error |g.d - fd| / max(|fd|, 1e-3)
of each kind and, for the friction coefficient, the same for dL/dmu. Scenarios: ``straight`` (+2 N·m, rolling), ``slip`` (+20 N·m, wheels spinning),
``curve`` (left 4, right 8 N·m), ``spin`` (left -6, right +6 N·m, skidding in place).

Cost: wall time of the taped forward pass and of the backward pass per world-step at N worlds
(T = 20), on one core; graph replay and tile GEMM are off on this path.
Figures are printed and written to ``benchmarks/results/diff_gradients.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
SCENARIOS = {"straight": (0.1, 0.1), "slip": (1.0, 1.0), "curve": (0.2, 0.4), "spin": (-0.3, 0.3)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 2, 5, 10, 20, 40])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument("--directions", type=int, default=3, help="random directions per kind")
    parser.add_argument("--out", default=str(RESULTS / "diff_gradients.json"))
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    import torch
    import warp as wp

    wp.config.quiet = True
    torch.set_num_threads(1)
    from atrv_warp.diff import DiffRollout

    def objective(poses):
        return poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]

    agreement = []
    gen = torch.Generator().manual_seed(0)
    for T in args.horizons:
        roll = DiffRollout(1, steps=T)
        state = roll.initial_state()
        for name, (left, right) in SCENARIOS.items():
            a = torch.empty(T, 1, 2)
            a[..., 0], a[..., 1] = left, right
            mu = torch.tensor(0.3)
            aa = a.clone().requires_grad_(True)
            mm = mu.clone().requires_grad_(True)
            objective(roll(aa, state, mm)).backward()
            errs = {}
            for kind in ("common", "differential"):
                worst = 0.0
                for _ in range(args.directions):
                    w = torch.rand(T, 1, 1, generator=gen)  # random weights over time
                    d = torch.cat([w, w if kind == "common" else -w], dim=-1)
                    d /= d.norm()
                    eps = 1e-2
                    fd = (objective(roll(a + eps * d, state, mu)) - objective(roll(a - eps * d, state, mu))) / (2 * eps)
                    tape = (aa.grad * d).sum()
                    worst = max(worst, abs(tape.item() - fd.item()) / max(abs(fd.item()), 1e-3))
                errs[kind] = worst
            fd_mu = (objective(roll(a, state, mu + 1e-3)) - objective(roll(a, state, mu - 1e-3))) / 2e-3
            err_mu = abs(mm.grad.item() - fd_mu.item()) / max(abs(fd_mu.item()), 1e-3)
            agreement.append({"scenario": name, "horizon_steps": T, "horizon_s": 0.05 * T,
                              "common_mode_rel_err": errs["common"], "differential_rel_err": errs["differential"],
                              "friction_rel_err": err_mu,
                              "friction_grad": mm.grad.item(), "friction_fd": fd_mu.item()})
            print(f"T={T:3d} ({0.05 * T:4.2f} s) {name:8s} common {100 * errs['common']:7.2f}%  "
                  f"differential {100 * errs['differential']:7.2f}%  "
                  f"friction: {100 * err_mu:7.2f}%  (tape {mm.grad.item():+.4f}, fd {fd_mu.item():+.4f})", flush=True)

    cost = []
    for n in args.sizes:
        T = 20
        roll = DiffRollout(n, steps=T)
        state = roll.initial_state()
        a = (torch.rand(T, n, 2, generator=gen) * 2 - 1).requires_grad_(True)
        roll(a, state)  # warm-up
        t0 = time.perf_counter()
        poses = roll(a, state)
        t_fwd = time.perf_counter() - t0
        t0 = time.perf_counter()
        poses[-1, :, :2].sum().backward()
        t_bwd = time.perf_counter() - t0
        row = {"num_worlds": n, "steps": T, "forward_us_per_world_step": 1e6 * t_fwd / (n * T),
               "backward_us_per_world_step": 1e6 * t_bwd / (n * T), "backward_over_forward": t_bwd / t_fwd}
        cost.append(row)
        print(f"N={n:5d}: forward {row['forward_us_per_world_step']:9.1f} us, backward "
              f"{row['backward_us_per_world_step']:9.1f} us per world-step; backward/forward "
              f"{row['backward_over_forward']:.2f}", flush=True)

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "diff_gradients", "agreement": agreement, "cost": cost,
                               "time": time.strftime("%Y-%m-%d %H:%M:%S")}, indent=2) + "\n")
    for key, label in (("common_mode_rel_err", "both wheels together"), ("differential_rel_err", "left vs right"),
                       ("friction_rel_err", "friction mu")):
        print(f"\nworst relative error, {label}:")
        print("| scenario | " + " | ".join(f"T={T} ({0.05 * T:.2f} s)" for T in args.horizons) + " |")
        print("|---|" + "---:|" * len(args.horizons))
        for name in SCENARIOS:
            errs = [r[key] for r in agreement if r["scenario"] == name]
            print(f"| {name} | " + " | ".join(f"{100 * e:.1f}%" for e in errs) + " |")
    print("\n| N | forward us/world-step | backward us/world-step | backward/forward |\n|---:|---:|---:|---:|")
    for r in cost:
        print(f"| {r['num_worlds']} | {r['forward_us_per_world_step']:.1f} | {r['backward_us_per_world_step']:.1f} | "
              f"{r['backward_over_forward']:.2f} |")
    print(f"\nwritten to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
