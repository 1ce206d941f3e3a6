"""Every shipped robot checked and measured: ``python -m atrv_warp.robot check`` for each, in one results file.

    python -m benchmarks.robots.robot_check [--robots atrvjr,jackal,husky]

Per robot (:func:`atrv_warp.sim.robot_check.measure_robot`): mass, wheel radius, track, wheelbase and reach; the
driver gains by the rule for its wheel's inertia; the effective track factor (from 8 steady turns to the robot's
limits at µ 0.3 and 0.8, through a differential drive's wheel targets, by ``robot_check.FACTOR_RULE``; each turn's
``/cmd_vel`` yaw error and odometry error with it) beside the file's and, for the Clearpath robots, beside
Clearpath's own ``wheel_separation_multiplier`` (the same quantity, tuned on their robots: J100 1.5, A200 1.875, from
``clearpathrobotics/clearpath_common@2f04d13cd607b0249032f3812101e5855592bf5c:clearpath_control/config/{j100,a200}/control.yaml``
L20); the top speed under full torque (at most the motor's no-load speed at the rim); and the ``/cmd_vel`` step
response of the driver with those gains and factor (in place at 0.5 rad/s, arcs at 0.3 m/s and 0.3 rad/s and at 1 m/s
and 0.2 rad/s, µ 0.3 and 0.8), judged: the first two settle within 0.5 s.

Prints each report and writes ``benchmarks/results/robot_check.json`` (the docs' robots page reads it).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from benchmarks._common import load_results, markdown_cell, markdown_table, pin_to_one_core, write_results

VERSION = 2
"""This script's method (2: turns to each robot's limits, the factor by the least squared yaw error within the grip,
the top speed capped by the motor), bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
CLEARPATH_MULTIPLIER = {"jackal": 1.5, "husky": 1.875}
"""Clearpath's ``wheel_separation_multiplier`` (their effective track factor) per robot."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="atrvjr,jackal,husky")
    args = parser.parse_args()
    pin_to_one_core()
    from atrv_warp.robot import format_check
    from atrv_warp.sim.robot_check import SETTLE_TARGET, STEP_CASES, measure_robot, within_grip

    robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    out = {"settle_target": SETTLE_TARGET, "robots": {}}
    for name in robots:
        report = measure_robot(name).as_dict()
        report["clearpath_multiplier"] = CLEARPATH_MULTIPLIER.get(name)
        targeted = [s for s in report["steps"] if (s["linear"], s["angular"]) in STEP_CASES[:2]]
        report["slowest_targeted_settle"] = max(s["settle"] for s in targeted)
        report["meets_settle_target"] = not report["settle_misses"]
        report["worst_yaw_error_within_grip"] = max(abs(t["yaw_error"]) for t in report["turns"] if within_grip(t))
        out["robots"][name] = report
        print(format_check(report))
        if report["clearpath_multiplier"]:
            print(f"  Clearpath's wheel_separation_multiplier: {report['clearpath_multiplier']:g}")
        print(f"  slowest of the targeted steps: {report['slowest_targeted_settle']:.2f} s (target {SETTLE_TARGET} s)\n")
    path = write_results(RESULTS / "robot_check.json", out, version=VERSION, driver=True, robots=tuple(robots))
    print(f"wrote {path}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def robot_check() -> str:
    """``robot_check.json``: every shipped robot's check, one column per robot."""
    d = load_results("robot_check.json")
    robots = d["robots"]

    def settle(r: dict, v: float, w: float) -> str:
        cells = [s for s in r["steps"] if (s["linear"], s["angular"]) == (v, w)]
        return " / ".join("never" if not math.isfinite(s["settle"]) else f"{s['settle']:.2f} s" for s in cells)

    rows = [
        ["mass", *(f"{r['mass']:.1f} kg" for r in robots.values())],
        ["wheel radius", *(f"{r['wheel_radius']:.4g} m" for r in robots.values())],
        ["track / wheelbase", *(f"{r['track']:.3f} / {r['wheelbase']:.3f} m" for r in robots.values())],
        ["reach (centre of mass to farthest corner)", *(f"{r['reach']:.2f} m" for r in robots.values())],
        ["drivetrain (file's motor.per_side)", *("one motor per side, wheels geared" if r["file"].get("motor_per_side")
                                                  else "each wheel free under its side's torque"
                                                  for r in robots.values())],
        ["limits (file)", *(f"{r['file']['limits']['linear_velocity']:g} m/s, "
                            f"{r['file']['limits']['angular_velocity']:g} rad/s" for r in robots.values())],
        ["driver gains kp / ki (rule)", *(f"{r['gains']['kp']:g} / {r['gains']['ki']:g}" for r in robots.values())],
        ["effective track factor (measured; file)", *(f"{r['effective_track_factor']:.2f}; "
                                                      f"{r['file']['effective_track_factor']:g}"
                                                      for r in robots.values())],
        ["worst /cmd_vel yaw error with it, within the grip", *(f"{100 * r['worst_yaw_error_within_grip']:.0f} %"
                                                                for r in robots.values())],
        ["Clearpath's wheel_separation_multiplier", *(f"{r['clearpath_multiplier']:g}" if r["clearpath_multiplier"]
                                                      else "-" for r in robots.values())],
        ["top speed under full torque (µ 0.8)", *(f"{r['top_speed']:.2f} m/s" for r in robots.values())],
        ["in place 0.5 rad/s settles (µ 0.3 / 0.8)", *(settle(r, 0.0, 0.5) for r in robots.values())],
        ["arc 0.3 m/s, 0.3 rad/s settles", *(settle(r, 0.3, 0.3) for r in robots.values())],
        ["arc 1 m/s, 0.2 rad/s settles", *(settle(r, 1.0, 0.2) for r in robots.values())],
    ]
    return markdown_table(["", *(f"`{name}`" for name in robots)], ["---"] + ["---:"] * len(robots), rows)


def robot_limits() -> str:
    """The shipped robots' limits, read from their files (``atrv_warp/robots/*.toml``), with each one's source."""
    from atrv_warp.core.robot import ROBOTS, load_robot

    rows = []
    for name in ROBOTS:
        robot = load_robot(name)
        lim = robot.limits
        cells = [lim.linear_velocity, lim.angular_velocity, lim.linear_acceleration, lim.angular_acceleration]
        sources = dict.fromkeys(robot.sources.get(f"limits.{k}", "").split(" (")[0] for k in
                                ("linear_velocity", "angular_velocity", "linear_acceleration", "angular_acceleration"))
        rows.append([f"`{name}`", *("-" if c is None else f"{c:g}" for c in cells),
                     "; ".join(f"`{markdown_cell(x)}`" for x in sources if x)])
    return markdown_table(["robot", "v [m/s]", "ω [rad/s]", "a [m/s²]", "α [rad/s²]", "source (repository@commit:path)"],
                          ["---"] + ["---:"] * 4 + ["---"], rows)


TABLES = {
    "robot_check": robot_check,
    "robot_limits": robot_limits,
}


if __name__ == "__main__":
    sys.exit(main())
