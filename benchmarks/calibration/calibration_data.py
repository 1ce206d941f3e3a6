"""How much driving the calibration needs: the fit's errors against the seconds of a bag it is given.

    python -m benchmarks.calibration.calibration_data [--minutes 3] [--seconds 30 60 120 180] [--figure docs/calibration_data.png]

1. Records one bag per rover of :data:`ROVERS` (``examples/calibration_truth.toml`` and two more), each
   ``--minutes`` long, as ``benchmarks/calibration/calibration.py`` does: ``python -m atrv_warp.calibrate --record-example``
   (the ROS 2 node driven by the scripted driver; needs the ``ros`` extra), 1 cm of noise on the reference pose.
2. Fits the first ``--seconds`` of each (``atrv-calibrate --duration``, the default fit from the velocity
   commands), in this process (the kernels compile once, on the first fit).
3. Measures each fit on the same segments: the held-out segments of the whole bag (every fifth, which no fit
   trains on), with the nominal rover and with the fitted one.

Writes ``benchmarks/results/calibration_data.json``; ``--figure`` draws the held-out error and each parameter's
error against the seconds of driving.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, save_figure, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
ROVERS = {
    "example": {"rover": {"torque_scale": 0.8, "payload_mass": 12.0, "wheel_radius": 0.125},
                "contact": {"friction": 0.5}},
    "worn_light": {"rover": {"torque_scale": 1.0, "payload_mass": 5.0, "wheel_radius": 0.121},
                   "contact": {"friction": 0.35}},
    "weak_loaded": {"rover": {"torque_scale": 0.6, "payload_mass": 25.0, "wheel_radius": 0.128},
                    "contact": {"friction": 0.8}},
}
"""The recorded rovers (simulator configs the fit is not told): the docs' example (``examples/calibration_truth.toml``),
a worn tyre on slippery ground with a light load, and weak motors under a heavy load on grippy ground."""


def _toml(config: dict) -> str:
    return "".join(f"[{table}]\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items())
                   for table, values in config.items())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0, help="sim minutes of each recorded drive (%(default)s)")
    parser.add_argument("--seconds", type=float, nargs="+", default=[30.0, 60.0, 120.0, 180.0],
                        help="seconds of driving to fit, from each bag's start (%(default)s)")
    parser.add_argument("--seed", type=int, default=1, help="the scripted driver's seed (%(default)s)")
    parser.add_argument("--noise", type=float, default=0.01, help="reference position noise [m] (%(default)s)")
    parser.add_argument("--figure", default=None, help="draw the errors against the seconds of driving here (PNG)")
    parser.add_argument("--figure-only", action="store_true",
                        help="fit nothing: draw --figure from the results file an earlier run wrote")
    args = parser.parse_args()
    if args.figure_only:
        if not args.figure:
            parser.error("--figure-only needs --figure PATH")
        _figure(load_results("calibration_data.json")["rovers"], ROOT / args.figure)
        return 0

    from atrv_warp.sim.config import get_variant
    from atrv_warp.sim.sysid import CalibrationConfig, Topics, calibrate, read_drive_log
    from atrv_warp.sim.sysid.fit import replay_errors
    from atrv_warp.sim.urdf import load_rover

    work = Path(tempfile.mkdtemp(prefix="atrv-calibration-data-"))
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(random.randint(101, 200)),
               PYTHONUNBUFFERED="1")
    wheels = {w.joint: (w.side, w.drive_sign) for w in load_rover(get_variant("realistic")).wheels}
    rovers = {}
    for name, config in ROVERS.items():
        truth_file, bag = work / f"{len(rovers)}.toml", work / f"{len(rovers)}.mcap"
        truth_file.write_text(_toml(config))
        proc = subprocess.run([sys.executable, "-m", "atrv_warp.calibrate", "--record-example", str(bag), "--minutes",
                               str(args.minutes), "--truth", str(truth_file), "--noise", str(args.noise), "--seed",
                               str(args.seed)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800,
                              check=False)
        if proc.returncode != 0:
            print(proc.stdout, proc.stderr, file=sys.stderr)
            return 1
        truth = {"wheel_radius": 0.125, **config["rover"], **config["contact"]}
        log = read_drive_log(bag, wheels, Topics())
        nominal = replay_errors(log, {})["held_out"]
        fits = []
        for seconds in args.seconds:
            result = calibrate(log, CalibrationConfig(duration=seconds))
            held = replay_errors(log, result.values)["held_out"]
            fits.append({"seconds": seconds, "converged": result.converged, "reason": result.reason,
                         "fitted": result.values, "fit_s": result.seconds, "compile_s": result.compile_seconds,
                         "segments": {"train": int((~result.segments.held_out).sum()),
                                      "held_out": int(result.segments.held_out.sum())},
                         "relative_error": {p: (v - truth[p]) / truth[p] for p, v in result.values.items()},
                         "held_out_after_m": float(np.median(held))})
            f = fits[-1]
            print(f"{name:14s} {seconds:5.0f} s: " + "  ".join(
                f"{p} {v:.4g} ({100 * f['relative_error'][p]:+.1f} %)" for p, v in result.values.items())
                + f"  held-out {100 * np.median(nominal):.1f} -> {100 * f['held_out_after_m']:.1f} cm; "
                f"fit {result.seconds:.0f} s ({result.reason})", flush=True)
        rovers[name] = {"truth": truth, "held_out_segments": len(nominal),
                        "held_out_before_m": float(np.median(nominal)), "fits": fits}

    result = {"benchmark": "calibration_data", "minutes": args.minutes, "seed": args.seed, "pose_noise_m": args.noise,
              "rovers": rovers, "cores": os.cpu_count(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = write_results(RESULTS / "calibration_data.json", result, version=VERSION, driver=True)
    print(f"wrote {path}")
    if args.figure:
        _figure(rovers, ROOT / args.figure)
        print(f"figure: {args.figure}")
    return 0


def _figure(rovers: dict, path: Path) -> None:
    """Each rover's errors against the seconds of driving fitted, into ``path`` (from ``calibration_data.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for (name, r), color in zip(rovers.items(), ("C0", "C1", "C2")):
        s = [f["seconds"] for f in r["fits"]]
        name = name.replace("_", " ")
        axes[0].plot(s, [100 * f["held_out_after_m"] for f in r["fits"]], "o-", color=color, label=f"{name}, fitted")
        axes[0].axhline(100 * r["held_out_before_m"], color=color, ls=":", label=f"{name}, nominal")
        for p, style in (("friction", "o-"), ("torque_scale", "s--")):
            axes[1].plot(s, [100 * abs(f["relative_error"][p]) for f in r["fits"]], style, color=color,
                         label=f"{name}: {'µ' if p == 'friction' else 'torque scale'}")
        axes[2].plot(s, [abs(f["relative_error"]["payload_mass"]) * r["truth"]["payload_mass"] for f in r["fits"]],
                     "o-", color=color, label=f"{name}: payload [kg]")
        axes[2].plot(s, [1000 * abs(f["relative_error"]["wheel_radius"]) * r["truth"]["wheel_radius"]
                         for f in r["fits"]], "s--", color=color, label=f"{name}: radius [mm]")
    axes[0].set(xlabel="driving fitted [s]", ylabel="held-out position error, median [cm]",
                title="the whole bag's held-out segments")
    axes[1].set(xlabel="driving fitted [s]", ylabel="|error| [%]", title="µ and torque scale (target 5 %)")
    axes[2].set(xlabel="driving fitted [s]", ylabel="|error| [kg] / [mm]", title="payload (1 kg) and radius (1 mm)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=6)
    fig.tight_layout()
    save_figure(fig, path, version=VERSION, results=("calibration_data.json",), dpi=110)
    plt.close(fig)


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def calibration_data() -> str:
    """``calibration_data.json``: each recorded rover's fit against the seconds of driving it was given."""
    d = load_results("calibration_data.json")
    rows = []
    for name, r in d["rovers"].items():
        t = r["truth"]
        for f in r["fits"]:
            e = f["relative_error"]
            rows.append([name.replace("_", " ") if f is r["fits"][0] else "", f"{f['seconds']:.0f} s",
                         f"{100 * e['friction']:+.1f} %", f"{100 * e['torque_scale']:+.1f} %",
                         f"{e['payload_mass'] * t['payload_mass']:+.1f} kg",
                         f"{1000 * e['wheel_radius'] * t['wheel_radius']:+.1f} mm",
                         f"{100 * r['held_out_before_m']:.1f} → {100 * f['held_out_after_m']:.1f} cm",
                         "yes" if f["converged"] else "no", f"{f['fit_s']:.0f} s"])
    return markdown_table(["rover", "driving fitted", "µ", "torque scale", "payload", "wheel radius",
                   "held-out error (median)", "converged", "fit"], ["---"] + ["---:"] * 6 + ["---", "---:"], rows)


TABLES = {
    "calibration_data": calibration_data,
}


if __name__ == "__main__":
    sys.exit(main())
