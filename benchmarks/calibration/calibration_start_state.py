"""What a replayed segment's start needs: a drive of our own simulator, replayed at its true values from starts built
with and without each recorded signal (issue 42 part 2, the fitted radius that came out small).

    python -m benchmarks.calibration.calibration_start_state [--seconds 90] [--seed 3]

1. Drives one rover (µ 0.6, motor torque x0.9, a 10 kg payload, the nominal wheel) for ``--seconds`` under smooth
   random ``/cmd_vel`` commands and records, after every 0.05 s step, what a bag gives (the reference pose with its
   full orientation and body twist, each wheel's speed, each side's effort), noise-free, and the driver's own PI
   integral, which no bag has.
2. The driver's integral at each segment's start, against the simulator's: replayed along the 20 Hz wheel speeds
   (``make_segments``), and worked out from the recorded effort (``integral_from_effort``).
3. Each segment replayed at the true values (``replay_errors``, 1 s segments, no pose smoothing) from the full start
   and with one signal taken away at a time: the effort (the integral replayed instead), the tilt and its rates
   (level), each wheel's speed (each side's mean); and from none of them (the start before the change).
4. The wheel radius fitted alone (the other values true) from the full start and from none of them.

Writes ``benchmarks/results/calibration_start_state.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
TRUTH = {"friction": 0.6, "torque_scale": 0.9, "payload_mass": 10.0, "wheel_radius": 0.125}


def record(seconds: float, seed: int):
    """The drive as a bag records it (a ``DriveLog``) and the driver's integral (steps + 1, 2) after each step."""
    import warp as wp

    from atrv_warp import RoverSim
    from atrv_warp.core.geometry import quat_to_matrix, quat_to_rpy, quat_to_yaw
    from atrv_warp.sim.config import ContactConfig, get_variant
    from atrv_warp.sim.sysid import DriveLog

    g = torch.Generator().manual_seed(seed)
    steps = round(seconds / 0.05)
    knots = (torch.rand(steps // 12 + 2, 2, generator=g) * 2 - 1) * torch.tensor([0.9, 1.0])
    cmds = torch.nn.functional.interpolate(knots.T[None], size=steps, mode="linear", align_corners=True)[0].T
    rover = dataclasses.replace(get_variant("realistic"), payload_mass=TRUTH["payload_mass"],
                                torque_scale=TRUTH["torque_scale"], wheel_radius=TRUTH["wheel_radius"])
    sim = RoverSim(1, rover=rover, contact=ContactConfig(friction=TRUTH["friction"]))
    for _ in range(10):  # settle at rest
        sim.step()
    side = torch.tensor([w.side for w in sim.description.wheels])
    rows, integral = [], []
    for k in range(steps + 1):
        pose = sim.root_pose[0].double()
        rot = quat_to_matrix(pose[3:7])
        v, w = rot.T @ sim.lin_vel[0].double(), rot.T @ sim.ang_vel[0].double()
        speed, torque = sim.wheel_speed[0].double(), sim.wheel_torque[0].double()
        rows.append([float(x) for x in (pose[0], pose[1], quat_to_yaw(pose[3:7]), *quat_to_rpy(pose[3:7])[:2],
                                        v[0], v[1], w[2], w[0], w[1], *(speed[side == s].mean() for s in (0, 1)),
                                        *(torque[side == s].mean() for s in (0, 1)), *speed)])
        integral.append(wp.to_torch(sim.driver.state.integral).double().view(-1)[:2].tolist())
        if k < steps:
            sim.set_twist(cmds[k].tolist())
            sim.step()
    a = np.array(rows)
    t = 0.05 * np.arange(steps + 1)
    a[:, 2] = np.unwrap(a[:, 2])
    log = DriveLog(path="simulated", pose_time=t, pose=a[:, 0:3], body_velocity=a[:, 5:8], joint_time=t,
                   wheel_speed=a[:, 10:12], effort=a[:, 12:14], cmd_time=t[:-1], cmd=cmds.double().numpy(),
                   tilt=a[:, 3:5], tilt_rate=a[:, 8:10], wheel_joints=tuple(w.joint for w in sim.description.wheels),
                   wheel_each=a[:, 14:])
    return log, np.array(integral)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=90.0, help="seconds of driving (%(default)s)")
    parser.add_argument("--seed", type=int, default=3, help="the commands' seed (%(default)s)")
    args = parser.parse_args()

    from atrv_warp.sim.config import ContactConfig, get_variant
    from atrv_warp.sim.sysid import CalibrationConfig, calibrate
    from atrv_warp.sim.sysid.fit import replay_errors
    from atrv_warp.sim.sysid.segments import integral_from_effort, make_segments

    t0 = time.perf_counter()
    log, true_integral = record(args.seconds, args.seed)
    cfg = CalibrationConfig(segment_seconds=1.0, pose_smoothing=0.0, latency=0.0)
    driver = cfg.driver()
    seg = make_segments(log, cfg, driver)
    at = np.round(seg.t0 / 0.05).astype(int)
    from_effort = integral_from_effort(seg.start_effort, seg.start_target, seg.wheel, driver,
                                       torque_scale=TRUTH["torque_scale"]).double().numpy()
    usable = np.isfinite(from_effort)
    integral = {"rad_mean_abs": float(np.abs(true_integral[at]).mean()),
                "replayed_error": float(np.abs(seg.integral - true_integral[at]).mean()),
                "from_effort_error": float(np.abs(from_effort[usable] - true_integral[at][usable]).mean()),
                "from_effort_usable": float(usable.mean())}
    print(f"the driver's integral at {len(seg)} segment starts (mean |integral| {integral['rad_mean_abs']:.3f} rad): "
          f"replayed along 20 Hz wheel speeds {integral['replayed_error']:.4f} rad off, from the effort "
          f"{integral['from_effort_error']:.4f} rad ({100 * integral['from_effort_usable']:.0f} % of the sides)")

    bare = dataclasses.replace(log, tilt=None, tilt_rate=None, wheel_each=None, effort=None)
    starts = {"full": log, "no_effort": dataclasses.replace(log, effort=None),
              "level": dataclasses.replace(log, tilt=None, tilt_rate=None),
              "side_wheels": dataclasses.replace(log, wheel_each=None), "none": bare}
    replay = {}
    for name, variant in starts.items():
        e = replay_errors(variant, TRUTH, cfg)
        replay[name] = float(1000 * np.mean(np.concatenate([e["train"], e["held_out"]])))
        print(f"replayed at the truth from the start {name:12s}: mean position error {replay[name]:.2f} mm", flush=True)

    rover = dataclasses.replace(get_variant("realistic"), payload_mass=TRUTH["payload_mass"],
                                torque_scale=TRUTH["torque_scale"])
    contact = ContactConfig(friction=TRUTH["friction"])
    radius = {}
    for name in ("full", "none"):
        fit = calibrate(starts[name], CalibrationConfig(params=("wheel_radius",), latency=0.0), rover=rover,
                        contact=contact)
        radius[name] = float(fit.values["wheel_radius"])
        print(f"the wheel radius fitted alone from the start {name:4s}: {1000 * radius[name]:.2f} mm "
              f"(truth {1000 * TRUTH['wheel_radius']:.1f} mm)", flush=True)

    result = {"benchmark": "calibration_start_state", "seconds": args.seconds, "seed": args.seed, "truth": TRUTH,
              "segments": len(seg), "integral": integral, "replay_error_mm": replay,
              "replay_error_ratio_none_to_full": replay["none"] / replay["full"],
              "radius_error_mm": {k: 1000 * (v - TRUTH["wheel_radius"]) for k, v in radius.items()},
              "wall_s": time.perf_counter() - t0, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = write_results(RESULTS / "calibration_start_state.json", result, version=VERSION, driver=True)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
