"""Every shipped robot calibrates from its own bag: the hidden rover found again on the ATRV-Jr, the Jackal and the Husky.

    python -m benchmarks.calibration.calibration_robots [--minutes 5] [--seed 1] [--robots atrvjr jackal husky]

For each robot: ``python -m atrv_warp.calibrate --record-example BAG --robot R --truth examples/calibration_truth.toml``
records ``--minutes`` of scripted driving on the robot's simulator node (needs the ``ros`` extra), its rover the truth
file's (0.8 x motor torque, a 12 kg payload, friction 0.5; the robot's own wheel), with 1 cm of noise on the
reference pose; then ``python -m atrv_warp.calibrate BAG --robot R`` fits it in a fresh process, within the robot's
own bounds (:meth:`atrv_warp.sim.sysid.config.FitParameter.bounds`). Each fitted value is judged against issue 42's
tolerances (:func:`benchmarks.calibration.calibration_sweep.tolerance`: 5 % for µ and the torque scale, 1 kg for
the payload, 1 mm for the radius) and its 95 % interval; the held-out error against issue 42's rule. Writes
``benchmarks/results/calibration_robots.json``. About two minutes per robot on two cores.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import tomllib
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results
from benchmarks.calibration.calibration_sweep import fit_bag, judge, record_bag

VERSION = 2
"""This script's method (2: a summary, the intervals' coverage and the median fit time), bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
TRUTH_FILE = ROOT / "examples" / "calibration_truth.toml"
ROBOTS = ("atrvjr", "jackal", "husky")


def truth_of(robot: str) -> dict[str, float]:
    """The hidden rover on ``robot``: the truth file's values, and the robot's own wheel radius."""
    from atrv_warp.sim.config import nominal_rover_config

    table = tomllib.loads(TRUTH_FILE.read_text())
    return {"friction": table["contact"]["friction"], "torque_scale": table["rover"]["torque_scale"],
            "payload_mass": table["rover"]["payload_mass"], "wheel_radius": nominal_rover_config(robot).wheel_radius}


def run_robot(robot: str, *, minutes: float, seed: int, work: Path, env: dict) -> dict:
    """Record and fit ``robot``'s bag in ``work/robot``: its row (:func:`judge`'s, with the robot and its bounds)."""
    from atrv_warp.sim.sysid.config import DEFAULT_FIT, FIT_PARAMETERS

    folder = work / robot
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth.toml").write_text(TRUTH_FILE.read_text())
    (folder / "drive.mcap").unlink(missing_ok=True)
    record_bag(folder, robot, ["--robot", robot, "--minutes", str(minutes), "--noise", "0.01", "--seed", str(seed),
                               "--force"], dict(env, ROS_DOMAIN_ID=str(random.Random(seed).randint(101, 200))))
    report, wall, code = fit_bag(folder, robot, env, ("--robot", robot, "--force"))
    row = judge(truth_of(robot), report)
    row.update(robot=robot, exit_code=code, process_wall_s=wall,
               bounds={p: list(FIT_PARAMETERS[p].bounds(robot)) for p in DEFAULT_FIT},
               misfit_flagged=bool((report.get("misfit") or {}).get("flagged")))
    return row


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=list(ROBOTS), help="shipped robots to calibrate (all three)")
    parser.add_argument("--minutes", type=float, default=5.0, help="sim minutes of driving per robot (%(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="seed of each robot's scripted drive (%(default)s)")
    parser.add_argument("--work", help="folder for the bags and fits (default: a temporary one)")
    parser.add_argument("--out", default=str(RESULTS / "calibration_robots.json"))
    return parser


def main() -> int:
    args = build_parser().parse_args()
    with tempfile.TemporaryDirectory(prefix="atrv-calibration-robots-") as tmp:
        work = Path(args.work or tmp)
        env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
        rows = []
        for robot in args.robots:
            print(f"{robot}: recording {args.minutes:g} min and fitting ...", flush=True)
            try:
                row = run_robot(robot, minutes=args.minutes, seed=args.seed, work=work, env=env)
            except RuntimeError as err:
                print(f"  {err}", file=sys.stderr, flush=True)
                return 1
            misses = [p for p, v in row["params"].items() if not v["within"]]
            print(f"  {'all within' if not misses else 'outside: ' + ', '.join(misses)}; held-out "
                  f"{100 * row['held_out']['before_m']:.1f} -> {100 * row['held_out']['after_m']:.1f} cm; "
                  f"{row['reason']}; fit {row['fit_s']:.0f} s", flush=True)
            rows.append(row)
    result = {"benchmark": "calibration_robots", "minutes": args.minutes, "seed": args.seed,
              "truth_file": str(TRUTH_FILE.relative_to(ROOT)), "robots": rows,
              "all_pass": all(r["all_within"] and r["converged"] and r["held_out"]["passes"] for r in rows)}
    intervals = [v["covered"] for r in rows for v in r["params"].values()]
    result["summary"] = {"intervals": len(intervals), "interval_coverage": sum(intervals) / len(intervals),
                         "fit_s_median": sorted(r["fit_s"] for r in rows)[len(rows) // 2]}
    out = write_results(args.out, result, version=VERSION, driver=True, robots=tuple(args.robots))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def calibration_robots() -> str:
    """``calibration_robots.json``: each robot's fitted values against the hidden rover's (✗ outside the tolerance),
    the held-out position error before and after, and whether the fit converged."""
    d = load_results("calibration_robots.json")

    def cell(v: dict, fmt: str) -> str:
        return f"{v['fitted']:{fmt}} ({v['truth']:{fmt}}){'' if v['within'] else ' ✗'}"

    rows = [[r["robot"], cell(r["params"]["friction"], ".3f"), cell(r["params"]["torque_scale"], ".3f"),
             cell(r["params"]["payload_mass"], ".1f"), cell(r["params"]["wheel_radius"], ".4f"),
             f"{100 * r['held_out']['before_m']:.1f} → {100 * r['held_out']['after_m']:.1f}",
             "yes" if r["converged"] else "no"] for r in d["robots"]]
    return markdown_table(["robot", "µ", "torque scale", "payload [kg]", "wheel radius [m]",
                           "held-out error [cm]", "converged"], ["---", "---:", "---:", "---:", "---:", "---:", "---"],
                          rows)


TABLES = {"calibration_robots": calibration_robots}


if __name__ == "__main__":
    sys.exit(main())
