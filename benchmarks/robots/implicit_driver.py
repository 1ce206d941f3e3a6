"""The motor driver's ``/cmd_vel`` step response with its wheel-speed loop explicit (the gains of
``robot_check.GAIN_RATIO``'s rule, bounded by the substep) and implicit (``DriverConfig.implicit_speed_loop``, the
default, with the robot file's gains: ``robot_check.LOOP_TIME``'s rule), for every shipped robot and the test robots
of ``tests/data``.

    python -m benchmarks.robots.implicit_driver

Per robot and loop: each step case of ``robot_check.STEP_CASES`` at µ 0.3 and 0.8 (its settle time, overshoot, and
steady yaw rate and its ripple over the last second, over the command,
``sim.protocols.step_response``), with the robot file's effective track factor, and the slowest of the judged cases
(in place and the 0.3 m/s arc, target ``robot_check.SETTLE_TARGET``). Writes
``benchmarks/results/implicit_driver.json``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from benchmarks._common import ROOT, load_results, markdown_table, pin_to_one_core, write_results

VERSION = 3
"""This script's method (2: each step's steady yaw rate and ripple kept; 3: the file's gains are the implicit loop's,
the explicit loop's come from its rule), bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
TEST_ROBOTS = ("sixwheel", "eightwheel", "heavywheel", "lightwheel")
"""The test robots of ``tests/data`` (six and eight wheels; wheels of 2 and 0.005 kg·m²)."""


def measure(spec: str) -> dict:
    """The robot ``spec``'s step response under both loops."""
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import step_response
    from atrv_warp.sim.robot_check import SETTLE_TARGET, STEP_CASES, check_robot, driver_gains, wheel_inertia

    robot, description = check_robot(spec)
    out = {"robot": robot.name, "wheels": len(description.wheels), "wheel_inertia": wheel_inertia(description),
           "mass": description.total_mass}
    explicit = driver_gains(description, implicit=False)
    for loop, (kp, ki) in (("explicit", explicit), ("implicit", (robot.kp, robot.ki))):
        driver = DriverConfig(kp=kp, ki=ki, implicit_speed_loop=loop == "implicit")
        steps = step_response(STEP_CASES, (0.3, 0.8), rover=RoverConfig(robot=robot.path), driver=driver)
        rows = [{k: s[k] for k in ("linear", "angular", "friction", "settle", "overshoot", "steady", "ripple")}
                for s in steps]
        judged = [r["settle"] for r in rows if (r["linear"], r["angular"]) in STEP_CASES[:2]]
        out[loop] = {"kp": kp, "ki": ki, "gain_ratio": kp * 0.01 / out["wheel_inertia"], "steps": rows,
                     "slowest_judged": max(judged), "meets": max(judged) <= SETTLE_TARGET}
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    pin_to_one_core()
    from atrv_warp.core.robot import ROBOTS

    specs = [*ROBOTS, *(str(ROOT / "tests" / "data" / f"{name}.toml") for name in TEST_ROBOTS)]
    robots = {}
    for spec in specs:
        r = measure(spec)
        robots[r["robot"]] = r
        print(f"{r['robot']:>10}: explicit kp {r['explicit']['kp']:g} slowest {r['explicit']['slowest_judged']:.2f} s"
              f" | implicit kp {r['implicit']['kp']:g} ({r['implicit']['gain_ratio']:.2f}) slowest "
              f"{r['implicit']['slowest_judged']:.2f} s", flush=True)
    path = write_results(RESULTS / "implicit_driver.json", {"robots": robots}, version=VERSION, driver=True,
                         robots=tuple(specs))
    print(f"wrote {path}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def implicit_driver() -> str:
    """``implicit_driver.json``: each robot's slowest judged settle under both loops."""
    robots = load_results("implicit_driver.json")["robots"]

    def cell(loop: dict) -> str:
        s = loop["slowest_judged"]
        return f"kp {loop['kp']:g}: {'never' if not math.isfinite(s) else f'{s:.2f} s'}"

    rows = [[f"`{name}`", f"{r['wheel_inertia']:.4g}", cell(r["explicit"]), cell(r["implicit"])]
            for name, r in robots.items()]
    return markdown_table(["robot", "wheel J [kg·m²]", "explicit loop (its rule's gains)", "implicit loop (the file's gains)"],
                          ["---", "---:", "---:", "---:"], rows)


TABLES = {"implicit_driver": implicit_driver}


if __name__ == "__main__":
    sys.exit(main())
