"""Every shipped robot checked and measured: ``python -m atrv_warp.robot check`` for each, in one results file.

    python benchmarks/robot_check.py [--robots atrvjr,jackal,husky]

Per robot (:func:`atrv_warp.sim.robot_check.measure_robot`): mass, wheel radius, track, wheelbase and reach; the
driver gains by the rule for its wheel's inertia; the effective track factor (the median chi over 7 steady turns at
µ 0.3 and 0.8, through a differential drive's wheel targets) beside the file's and, for the Clearpath robots, beside
Clearpath's own ``wheel_separation_multiplier`` (the same quantity, tuned on their robots: J100 1.5, A200 1.875, from
``clearpathrobotics/clearpath_common@2f04d13cd607b0249032f3812101e5855592bf5c:clearpath_control/config/{j100,a200}/control.yaml``
L20); the top speed under full torque; and the ``/cmd_vel`` step response of the driver with those gains and factor
(in place at 0.5 rad/s, arcs at 0.3 m/s and 0.3 rad/s and at 1 m/s and 0.2 rad/s, µ 0.3 and 0.8; target: the first
two settle within 0.5 s).

Prints each report and writes ``benchmarks/results/robot_check.json`` (the docs' robots page reads it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from _common import pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parent / "results"
CLEARPATH_MULTIPLIER = {"jackal": 1.5, "husky": 1.875}
"""Clearpath's ``wheel_separation_multiplier`` (their effective track factor) per robot."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="atrvjr,jackal,husky")
    args = parser.parse_args()
    pin_to_one_core()
    from atrv_warp.robot import format_check
    from atrv_warp.sim.robot_check import SETTLE_TARGET, STEP_CASES, measure_robot

    robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    out = {"settle_target": SETTLE_TARGET, "robots": {}}
    for name in robots:
        report = measure_robot(name).as_dict()
        report["clearpath_multiplier"] = CLEARPATH_MULTIPLIER.get(name)
        targeted = [s for s in report["steps"] if (s["linear"], s["angular"]) in STEP_CASES[:2]]
        report["slowest_targeted_settle"] = max(s["settle"] for s in targeted)
        report["meets_settle_target"] = report["slowest_targeted_settle"] <= SETTLE_TARGET
        out["robots"][name] = report
        print(format_check(report))
        if report["clearpath_multiplier"]:
            print(f"  Clearpath's wheel_separation_multiplier: {report['clearpath_multiplier']:g}")
        print(f"  slowest of the targeted steps: {report['slowest_targeted_settle']:.2f} s (target {SETTLE_TARGET} s)\n")
    path = write_results(RESULTS / "robot_check.json", out, version=VERSION, driver=True, robots=tuple(robots))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
