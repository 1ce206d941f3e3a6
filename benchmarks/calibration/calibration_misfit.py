"""What the calibration does when the recorded rover has something its model lacks (issue 42, part 4).

    python -m benchmarks.calibration.calibration_misfit [--minutes 3] [--seed 5] [--only latency_1,slope] [--work DIR]

One rover (µ 0.6, motor torque x0.9, a 10 kg payload, the nominal wheel), recorded as the calibration sweep records
(``python -m atrv_warp.calibrate --record-example``, 1 cm of reference-pose noise) once as modelled and once with each
effect the fit's replay leaves out, then fitted in a fresh process with the CLI's defaults:

- ``latency_1``, ``latency_2``: ``/cmd_vel`` reaches the driver 1 or 2 steps (0.05 s, 0.1 s) after it was recorded
  (the node's ``cmd_vel_delay``); the fit fits a whole-step latency;
- ``motor_lag``: the motors' torque lags the driver's by a first-order 0.1 s (``motor_lag``);
- ``payload_off_centre``: the payload 0.25 m ahead of and 0.15 m left of the chassis' centre of mass;
- ``slope``: the arena a plain 10 deg incline (``terrain:=slope``), the replay flat;
- ``stiffness_1.4x``: the ground's contact stiffness 1.4x the replay's.

For each it reports the fitted values against the truth (the sweep's tolerances), the held-out error before and
after, the latency found, and the fit's misfit verdict (``result.misfit``): whether the fit says, in one line, that
its model does not explain the drive. Writes ``benchmarks/results/calibration_misfit.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results
from benchmarks.calibration.calibration_sweep import fit_bag, judge, record_bag, truth_toml

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"

TRUTH = {"friction": 0.6, "torque_scale": 0.9, "payload_mass": 10.0, "wheel_radius": 0.125}
"""The rover every case records (the fit is not told it)."""
CASES: dict[str, dict] = {
    "none": {},
    "latency_1": {"node": {"cmd_vel_delay": 0.05}},
    "latency_2": {"node": {"cmd_vel_delay": 0.1}},
    "motor_lag": {"node": {"motor_lag": 0.1}},
    "payload_off_centre": {"rover": {"payload_offset": [0.25, 0.15, 0.0]}},
    "slope": {"node": {"terrain": "slope"}},
    "stiffness_1.4x": {"contact": {"stiffness": 1.4e5}},
}
"""Each case: what the recording adds to the truth (node parameters, ``[rover]`` and ``[contact]`` keys)."""


def case_toml(extra: dict) -> str:
    """The truth's simulator config with the case's ``[rover]`` and ``[contact]`` keys added."""
    text = truth_toml(TRUTH)
    for table in ("rover", "contact"):
        for key, value in extra.get(table, {}).items():
            text = text.replace(f"[{table}]\n", f"[{table}]\n{key} = {json.dumps(value)}\n", 1)
    return text


def run_case(name: str, *, seed: int, minutes: float, noise: float, work: Path, env: dict) -> dict:
    """Record and fit one case (or read what an earlier run left in ``work``): its row."""
    case = CASES[name]
    folder = work / name
    done = folder / "row.json"
    if done.is_file():
        row = json.loads(done.read_text())
        if row.get("case_spec") == case and row.get("minutes") == minutes:
            return row
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth.toml").write_text(case_toml(case))
    bag = folder / "drive.mcap"
    if not bag.is_file():
        params = [a for k, v in case.get("node", {}).items() for a in ("-p", f"{k}:={v}")]
        record_bag(folder, name, ["--minutes", str(minutes), "--noise", str(noise), "--seed", str(seed), *params],
                   dict(env, ROS_DOMAIN_ID=str(random.Random(f"{seed}{name}").randint(101, 200))))
    report, wall, code = fit_bag(folder, name, env)
    row = judge(TRUTH, report)
    row.update(case=name, case_spec=case, minutes=minutes, exit_code=code, process_wall_s=wall,
               latency=report.get("latency"), misfit=report.get("misfit"),
               held_out_errors_after_m=report["errors"]["held_out"]["after"],
               train_errors_after_m=report["errors"]["train"]["after"])
    done.write_text(json.dumps(row, indent=1) + "\n")
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0, help="sim minutes of driving per case (%(default)s)")
    parser.add_argument("--seed", type=int, default=5, help="seed of every case's drive (%(default)s)")
    parser.add_argument("--noise", type=float, default=0.01, help="reference position noise [m] (%(default)s)")
    parser.add_argument("--only", default="", help=f"comma-separated cases to run now (default: all of {list(CASES)})")
    parser.add_argument("--work", default=None, help="folder kept between runs (default: one in /tmp)")
    parser.add_argument("--out", default=str(RESULTS / "calibration_misfit.json"), help="results file (%(default)s)")
    args = parser.parse_args()
    chosen = [c.strip() for c in args.only.split(",") if c.strip()] or list(CASES)
    unknown = [c for c in chosen if c not in CASES]
    if unknown:
        parser.error(f"--only: unknown case(s) {unknown}; known: {list(CASES)}")
    work = Path(args.work or Path(tempfile.gettempdir()) / f"atrv-calibration-misfit-seed{args.seed}")
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1",
               WARP_CACHE_PATH=os.environ.get("WARP_CACHE_PATH", str(work / "warp-cache")))
    print(f"{len(chosen)} case(s), {args.minutes:g} min of driving each, kept in {work}", flush=True)
    for name in chosen:
        try:
            row = run_case(name, seed=args.seed, minutes=args.minutes, noise=args.noise, work=work, env=env)
        except RuntimeError as err:  # one case's failure is reported; the others' rows are kept
            print(f"{name}: {err}", file=sys.stderr, flush=True)
            continue
        h, lat, misfit = row["held_out"], row["latency"] or {}, row["misfit"] or {}
        misses = [p for p, v in row["params"].items() if not v["within"]]
        print(f"{name:<19} {'all within' if not misses else 'outside: ' + ', '.join(misses):<40} held-out "
              f"{100 * h['before_m']:.1f} -> {100 * h['after_m']:.1f} cm; latency {lat.get('seconds', 0):g} s; "
              f"{row['reason']}; {misfit['line'] if misfit.get('flagged') else 'no misfit flagged'}",
              flush=True)
    rows = [json.loads((work / c / "row.json").read_text()) for c in CASES if (work / c / "row.json").is_file()]
    rows = [r for r in rows if r.get("case_spec") == CASES[r["case"]] and r.get("minutes") == args.minutes]
    if not rows:
        print("no case finished: nothing to write", file=sys.stderr)
        return 1
    result = {"benchmark": "calibration_misfit", "seed": args.seed, "minutes": args.minutes,
              "pose_noise_m": args.noise, "truth": TRUTH, "cases": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = write_results(args.out, result, version=VERSION, driver=True)
    print(f"wrote {path}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def calibration_misfit() -> str:
    """``calibration_misfit.json``: what the fit does with each effect its model lacks."""
    d = load_results("calibration_misfit.json")
    effects = {"none": "nothing", "latency_1": "/cmd_vel 0.05 s late", "latency_2": "/cmd_vel 0.1 s late",
               "motor_lag": "0.1 s motor torque lag", "payload_off_centre": "payload 0.25 m ahead, 0.15 m left",
               "slope": "a 10° slope", "stiffness_1.4x": "ground 1.4× stiffer"}
    rows = []
    for r in d["cases"]:
        p, t, m = r["params"], r["truth"], r["misfit"]
        errors = [f"{100 * p['friction']['error'] / t['friction']:+.1f} %", f"{100 * p['torque_scale']['error'] / t['torque_scale']:+.1f} %",
                  f"{p['payload_mass']['error']:+.1f} kg", f"{1000 * p['wheel_radius']['error']:+.1f} mm"]
        errors = [e + ("" if p[k]["within"] else " ✗")
                  for e, k in zip(errors, ("friction", "torque_scale", "payload_mass", "wheel_radius"))]
        ratios = " / ".join(f"{m['ratio'][c]:.1f}" for c in ("position", "wheel_speed", "effort") if c in m["ratio"])
        rows.append([effects.get(r["case"], r["case"]), *errors,
                     f"{100 * r['held_out']['before_m']:.1f} → {100 * r['held_out']['after_m']:.1f} cm",
                     f"{r['latency']['seconds']:g} s", "yes" if r["converged"] else "no",
                     f"{ratios}: {'**misfit**' if m['flagged'] else 'passes'}"])
    return markdown_table(["recorded with", "µ error", "torque error", "payload error", "wheel error", "held-out error",
                   "latency found", "converged", "model check (position / wheel speed / effort ÷ noise)"],
                          ["---"] + ["---:"] * 5 + ["---:", "---", "---"], rows)


TABLES = {
    "calibration_misfit": calibration_misfit,
}


if __name__ == "__main__":
    sys.exit(main())
