"""Calibration from a recorded bag with a hidden truth: how close, how much better, how long.

    python -m benchmarks.calibration.calibration [--minutes 3] [--seed 1] [--figure docs/calibration_paths.png] [--old REV]

1. Records a bag as a user would on a real rover, with the simulator standing in for it:
   ``python -m atrv_warp.calibrate --record-example`` (the ROS 2 node driven over ROS 2 by a scripted
   driver; needs the ``ros`` extra) for ``--minutes`` of sim time, with the rover of
   ``examples/calibration_truth.toml`` (0.8 x motor torque, a 12 kg payload, friction 0.5), 1 cm of noise on
   the reference pose, 0.02 rad/s on the wheel speeds.
2. Fits it, ``python -m atrv_warp.calibrate BAG``, in a fresh process with an empty Warp kernel cache, so
   the kernel compilation is measured apart from the fit: from the velocity commands (the default) and from
   the wheel efforts (``--command effort``, warm cache).
3. With ``--old REV``: fits the same bag from the velocity commands with git revision ``REV``'s code (exported
   into a temporary folder, its own kernel cache), right after, for the old fit's time and values beside the new.

Prints the truth against the fitted values, the position error before and after on the held-out
segments, the fit's wall time (compilation apart), and writes ``benchmarks/results/calibration.json`` (and
the default fit's console output to ``calibration_console.txt``);
``--figure`` copies the default fit's plot of held-out paths.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

from benchmarks._common import figure_provenance, load_results, markdown_table, write_png_provenance, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
TRUTH_FILE = ROOT / "examples" / "calibration_truth.toml"


def _run(args: list[str], env: dict, root: Path = ROOT) -> tuple[float, subprocess.CompletedProcess]:
    """``python -m atrv_warp.calibrate ARGS`` with the code of the tree at ``root``."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "atrv_warp.calibrate", *args], check=False, cwd=root,
                          env=dict(env, PYTHONPATH=str(root)), capture_output=True, text=True, timeout=3600)
    return time.perf_counter() - t0, proc


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0, help="sim minutes of recorded drive (%(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="the scripted driver's seed (%(default)s)")
    parser.add_argument("--noise", type=float, default=0.01, help="reference position noise [m] (%(default)s)")
    parser.add_argument("--figure", default=None, help="copy the default fit's held-out paths PNG here")
    parser.add_argument("--old", metavar="REV", help="also fit the bag with this git revision's code")
    args = parser.parse_args()

    truth_toml = tomllib.loads(TRUTH_FILE.read_text())
    truth = {**truth_toml.get("rover", {}), **truth_toml.get("contact", {})}
    truth.setdefault("wheel_radius", 0.125)
    work = Path(tempfile.mkdtemp(prefix="atrv-calibration-"))
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(random.randint(101, 200)),
               WARP_CACHE_PATH=str(work / "warp-cache-record"), PYTHONUNBUFFERED="1")
    bag = work / "drive.mcap"
    wall, proc = _run(["--record-example", str(bag), "--minutes", str(args.minutes), "--truth", str(TRUTH_FILE),
                       "--noise", str(args.noise), "--seed", str(args.seed)], env)
    if proc.returncode != 0:
        print(proc.stdout, proc.stderr, file=sys.stderr)
        return 1
    print(f"recorded {args.minutes:g} min of drive in {wall:.0f} s ({bag.stat().st_size / 1e6:.1f} MB)", flush=True)

    env["WARP_CACHE_PATH"] = str(work / "warp-cache-fit")  # empty: the fit's first use compiles every kernel
    runs = {}
    for name, extra in (("cmd_vel", []), ("effort", ["--command", "effort"])):
        out = work / f"calibrated_{name}.toml"
        wall, proc = _run([str(bag), "--out", str(out), *extra], env)
        report = json.loads(out.with_suffix(".report.json").read_text())
        fitted = report["values"]
        runs[name] = {
            "converged": report["converged"], "reason": report["reason"], "exit_code": proc.returncode,
            "fitted": fitted, "standard_error": report["standard_error"], "spread": report["spread"],
            "relative_error": {p: abs(v - truth[_key(p)]) / truth[_key(p)] for p, v in fitted.items()},
            "error_summary": report["error_summary"], "segments": report["segments"],
            "fit_s": report["fit_seconds"], "compile_s": report["compile_seconds"], "process_wall_s": wall,
        }
        print(f"\n== {name} replay (exit {proc.returncode}: {report['reason']})")
        print("parameter        truth    fitted   error  ± std err    spread")
        for p, v in fitted.items():
            print(f"{p:14s} {truth[_key(p)]:8.4g} {v:9.4g} {100 * runs[name]['relative_error'][p]:6.1f} % "
                  f"{report['standard_error'][p]:10.2g} {report['spread'][p]:9.2g}")
        held = report["error_summary"]["held_out"]
        print(f"held-out position error {100 * held['before_m']:.1f} cm -> {100 * held['after_m']:.1f} cm "
              f"({held['reduction']:.1f}x); fit {report['fit_seconds']:.0f} s + compile "
              f"{report['compile_seconds']:.0f} s ({'cold' if name == 'cmd_vel' else 'warm'} kernel cache)", flush=True)
        if name == "cmd_vel":  # the console output, as docs/calibration.md shows it, and the figure: written after
            # the results file, whose provenance would otherwise count them as uncommitted changes
            console = proc.stdout.replace(str(bag), "drive.mcap").replace(str(work) + "/", "")
            figure = out.with_suffix(".png") if args.figure and out.with_suffix(".png").is_file() else None
            if figure is not None:
                shutil.copy(figure, work / "figure.png")

    old = None
    if args.old:
        old_root = work / "old"
        old_root.mkdir()
        archive = subprocess.run(["git", "archive", args.old], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old_root)], input=archive, check=True)
        out = work / "calibrated_old.toml"
        env["WARP_CACHE_PATH"] = str(work / "warp-cache-old")
        wall, proc = _run([str(bag), "--out", str(out)], env, root=old_root)
        report = json.loads(out.with_suffix(".report.json").read_text())
        old = {"revision": subprocess.run(["git", "rev-parse", args.old], cwd=ROOT, capture_output=True, text=True,
                                          check=True).stdout.strip(),
               "converged": report["converged"], "fitted": report["values"],
               "relative_error": {p: abs(v - truth[_key(p)]) / truth[_key(p)] for p, v in report["values"].items()},
               "error_summary": report["error_summary"], "fit_s": report["fit_seconds"],
               "compile_s": report["compile_seconds"], "process_wall_s": wall}
        held = report["error_summary"]["held_out"]
        print(f"\n== cmd_vel replay, {args.old}'s fit: " + "  ".join(
            f"{p} {v:.4g} ({100 * old['relative_error'][p]:.1f} %)" for p, v in report["values"].items())
            + f"; held-out {100 * held['before_m']:.1f} -> {100 * held['after_m']:.1f} cm; fit {old['fit_s']:.0f} s, "
            f"{old['fit_s'] / runs['cmd_vel']['fit_s']:.1f}x this tree's", flush=True)

    result = {"benchmark": "calibration", "minutes": args.minutes, "seed": args.seed, "pose_noise_m": args.noise,
              "truth": truth, "truth_file": str(TRUTH_FILE.relative_to(ROOT)), "runs": runs, "old": old,
              "cores": os.cpu_count(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = write_results(RESULTS / "calibration.json", result, version=VERSION, driver=True)
    print(f"\nwrote {path}")
    (RESULTS / "calibration_console.txt").write_text(console)
    if figure is not None:
        # the CLI drew it in this run: it carries this run's provenance and goes stale with its results file
        write_png_provenance((work / "figure.png").read_bytes(), ROOT / args.figure,
                             figure_provenance(VERSION, driver=True, results=(path,)))
        print(f"figure: {args.figure}")
    shutil.rmtree(work, ignore_errors=True)
    return 0


def _key(param: str) -> str:
    """The truth file's key of a fit parameter."""
    return {"speed_limit": "wheel_speed_limit"}.get(param, param)


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def calibration() -> str:
    """``calibration.json``: a hidden rover's parameters against the fitted ones, per command source (and the old
    fit's, where the file has one)."""
    d = load_results("calibration.json")
    runs = dict(d["runs"])
    header = ["", "truth"] + [f"fitted ({name} replay)" for name in runs]
    if d.get("old"):
        runs["old"] = d["old"]
        header.append(f"fitted (cmd_vel, the fit of {d['old']['revision'][:7]})")
    rows = []
    for p in runs["cmd_vel"]["fitted"]:
        truth = d["truth"]["wheel_speed_limit" if p == "speed_limit" else p]
        cells = []
        for run in runs.values():
            if p in run["fitted"] and "standard_error" in run:
                se, spread = (("—" if math.isnan(v) else f"{v:.2g}") for v in (run["standard_error"][p], run["spread"][p]))
                cells.append(f"{run['fitted'][p]:.4g} ± {se}, spread {spread} ({100 * run['relative_error'][p]:.1f} % off)")
            elif p in run["fitted"]:
                cells.append(f"{run['fitted'][p]:.4g} ({100 * run['relative_error'][p]:.1f} % off)")
            else:
                cells.append("not fitted (applied as recorded)")
        rows.append([p, f"{truth:g}", *cells])
    for split in ("train", "held_out"):
        cells = []
        for run in runs.values():
            e = run["error_summary"][split]
            cells.append(f"{100 * e['before_m']:.1f} → {100 * e['after_m']:.1f} cm ({e['reduction']:.1f}×)")
        rows.append([f"position error, {split.replace('_', '-')} (median)", "", *cells])
    rows.append(["converged", "", *[("yes" if r["converged"] else "no: " + r.get("reason", "").split(": ", 1)[-1])
                                     for r in runs.values()]])
    rows.append(["fit wall time (2 cores)", "", *[f"{r['fit_s']:.0f} s (+ {r['compile_s']:.0f} s compiling)"
                                                for r in runs.values()]])
    return markdown_table(header, ["---", "---:"] + ["---"] * len(runs), rows)


TABLES = {
    "calibration": calibration,
}


if __name__ == "__main__":
    sys.exit(main())
