"""The base's motor driver: how fast a ``/cmd_vel`` step takes hold, at four frictions.

    python -m benchmarks.physics.driver_response [--figure docs/driver_response.png] [--sweep]

One world per (command, µ): in place (0, 0.5), and on two arcs (0.5, 0.5) and (1.0, 0.2) [m/s, rad/s], at µ 0.2,
0.3, 0.8 and 1.0, from rest, the command re-sent every 0.05 s step (a 20 Hz controller), through the driver's
wheel-speed PI (:class:`atrv_warp.sim.driver.DriverConfig` defaults: every substep, limits off), for 5 s
(:func:`atrv_warp.sim.protocols.step_response`). Per world: when the yaw rate stays within 10 % of the command, its
overshoot, its mean and ripple over the last second, and the forward speed reached. Targets (issue 39): settled
within 0.5 s, overshoot at most 10 %, no sustained oscillation at µ 0.2.

Before the driver ran inside the physics step, the base's PI ran once per step in Python (kp 0.6, ki 3.0); the
issue measured it settling in 0.90-2.05 s in place, 1.65-3.05 s on the slow arc and 4.65-6.15 s on the fast one
(µ 0.3 and 0.8).

Prints the table, writes ``benchmarks/results/driver_response.json`` and, with ``--figure``, draws the yaw-rate
traces (the docs' physics page). ``--sweep`` also runs the same steps under other gains (:data:`SWEEP`) and
reports each pair's slowest settling time per command and its largest overshoot: how the defaults were chosen.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks._common import load_results, save_figure, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
OVERSHOOT_TARGET = 0.10
SWEEP = ((1.0, 10.0), (2.0, 20.0), (3.0, 30.0), (3.0, 60.0), (3.0, 100.0), (2.5, 120.0), (4.0, 20.0))
"""(kp, ki) pairs of ``--sweep``; kp x 0.01 s / 0.02 kg·m² (a slipping wheel) must stay below 2."""


def summarize(rows: list[dict]) -> dict:
    """The slowest settling time per command and the largest overshoot of one gain pair's rows."""
    def slowest(v, w):
        return max(r["settle"] for r in rows if (r["linear"], r["angular"]) == (v, w))

    return {"in_place_slowest": slowest(0.0, 0.5), "slow_arc_slowest": slowest(0.5, 0.5),
            "fast_arc_slowest": slowest(1.0, 0.2), "largest_overshoot": max(r["overshoot"] for r in rows)}


def draw(rows: list[dict], path: Path, results: str = "driver_response.json") -> None:
    """The yaw-rate traces, one panel per command, into ``path`` (drawn from ``results``)."""
    import matplotlib

    from atrv_warp.sim.robot_check import SETTLE_TARGET

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    commands = sorted({(r["linear"], r["angular"]) for r in rows})
    fig, axes = plt.subplots(1, len(commands), figsize=(4.2 * len(commands), 3.4), sharey=True)
    for ax, (v, w) in zip(axes, commands):
        for r in (r for r in rows if (r["linear"], r["angular"]) == (v, w)):
            ax.plot(r["time"], [x / w for x in r["yaw_rate"]], label=f"µ {r['friction']:g}")
        ax.axhspan(0.9, 1.1, color="0.85", zorder=0)
        ax.axvline(SETTLE_TARGET, color="0.5", ls=":")
        ax.set_xlim(0, 3)
        ax.set_title(f"/cmd_vel step: {v:g} m/s, {w:g} rad/s")
        ax.set_xlabel("time [s]")
    axes[0].set_ylabel("yaw rate / commanded")
    axes[0].legend(loc="lower right")
    fig.tight_layout()
    save_figure(fig, path, version=VERSION, results=(results,), dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def main() -> int:
    from atrv_warp.sim.robot_check import SETTLE_TARGET

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", type=Path, help="draw the yaw-rate traces into this PNG")
    parser.add_argument("--sweep", action="store_true", help="also measure the gain pairs of SWEEP")
    parser.add_argument("--figure-only", action="store_true",
                        help="measure nothing: draw --figure from the results file an earlier run wrote")
    args = parser.parse_args()
    if args.figure_only:
        if not args.figure:
            parser.error("--figure-only needs --figure PATH")
        draw(load_results("driver_response.json")["rows"], args.figure)
        return 0
    import torch

    torch.set_num_threads(1)
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import step_response

    cfg = DriverConfig().resolved("atrvjr")  # the ATRV-Jr's (its robot file's gains)
    print(f"The base's motor driver (kp {cfg.kp:g}, ki {cfg.ki:g}, torque limit {cfg.torque_limit:g} N·m, every "
          "substep, limits off): /cmd_vel steps from rest, re-sent at 20 Hz")
    rows = step_response()
    print(f"{'v [m/s]':>8} {'w [rad/s]':>9} {'mu':>4} {'settled [s]':>11} {'overshoot':>9} {'steady':>7} "
          f"{'ripple':>7} {'speed':>6}")
    for r in rows:
        print(f"{r['linear']:8.1f} {r['angular']:9.1f} {r['friction']:4.1f} {r['settle']:11.2f} "
              f"{100 * r['overshoot']:8.1f}% {r['steady']:7.3f} {r['ripple']:7.4f} {r['speed']:6.3f}")
    worst = max(rows, key=lambda r: r["settle"])
    met = [r for r in rows if r["settle"] <= SETTLE_TARGET]
    over = max(r["overshoot"] for r in rows)
    ripple = max(r["ripple"] for r in rows if r["friction"] == min(x["friction"] for x in rows))
    print(f"settled within {SETTLE_TARGET} s: {len(met)} of {len(rows)}; slowest {worst['settle']:.2f} s "
          f"({worst['linear']:g} m/s, {worst['angular']:g} rad/s, µ {worst['friction']:g}); largest overshoot "
          f"{100 * over:.1f} % (target {100 * OVERSHOOT_TARGET:.0f} %); ripple at the lowest µ {ripple:.4f}")
    summary = {"settled_within_target": len(met), "cases": len(rows), "slowest_settle": worst["settle"],
               "slowest_case": [worst["linear"], worst["angular"], worst["friction"]], **summarize(rows),
               "ripple_lowest_mu": ripple, "driver": {"kp": cfg.kp, "ki": cfg.ki, "torque_limit": cfg.torque_limit}}
    out = {"summary": summary, "rows": rows}
    if args.sweep:
        print("\nOther gains: slowest settling [s] in place / slow arc / fast arc, largest overshoot")
        out["sweep"] = []
        for kp, ki in SWEEP:
            s = summarize(step_response(driver=DriverConfig(kp=kp, ki=ki), seconds=3.0))
            out["sweep"].append({"kp": kp, "ki": ki, **s})
            print(f"kp {kp:4.1f} ki {ki:5.1f}: {s['in_place_slowest']:.2f} / {s['slow_arc_slowest']:.2f} / "
                  f"{s['fast_arc_slowest']:.2f} s, overshoot {100 * s['largest_overshoot']:.1f} %")
    write_results(RESULTS / "driver_response.json", out, version=VERSION, driver=True)
    print(f"wrote {RESULTS / 'driver_response.json'}")
    if args.figure:
        draw(rows, args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
