"""Skid-steer calibration: how much slower the rover turns than a differential drive would.

    python benchmarks/skid_calibration.py

A skid-steer rover's wheels slide sideways in a turn, so its yaw rate is
``r (w_right - w_left) / B_eff`` with an effective track ``B_eff`` larger than the wheel track.
This drives one world per (linear, angular) command with the ROS node's own wheel-speed PI
controller (:class:`atrv_warp.integrations.ros.base.VelocityController`, factor 1, so the wheel
targets are a differential drive's), lets it settle for 3 s, and measures ``B_eff`` from the
wheel speeds and the yaw rate. The node's default ``effective_track_factor`` is the median ratio
``B_eff / track``. Then it runs the node's wheel odometry (:class:`WheelOdometry`, with that
factor) from a standstill, straight at 0.5 m/s and in place at 0.3 rad/s for 4 s, against the
simulator's truth. Prints a table and writes ``benchmarks/results/skid_calibration.json``.
"""

from __future__ import annotations

import math
import statistics
import sys
from pathlib import Path

from _common import write_results

RESULTS = Path(__file__).resolve().parent / "results"
COMMANDS = [(0.0, 0.25), (0.0, 0.5), (0.0, 1.0), (0.3, 0.3), (0.5, 0.5), (0.5, -0.25), (1.0, 0.2)]


def odometry_error(linear: float, angular: float, factor: float, seconds: float = 4.0) -> dict:
    """Wheel odometry against the truth from a standstill, under the node's PI controller."""
    import torch

    from atrv_warp import RoverSim
    from atrv_warp.integrations.ros.base import BaseParams, VelocityController, WheelOdometry

    sim = RoverSim(1)
    side = torch.tensor([w.side for w in sim.description.wheels])
    base = BaseParams(wheel_radius=sim.rover_cfg.wheel_radius, track_width=0.5, effective_track_factor=factor)
    control, odo = VelocityController(base), WheelOdometry(base)
    control.command(linear, angular, now=0.0)

    def speeds():
        ws = sim.wheel_speed[0]
        return torch.stack([ws[side == 0].mean(), ws[side == 1].mean()])

    for _ in range(round(seconds / sim.sim_cfg.step_dt)):
        sim.step(control.torques(speeds(), now=0.0, dt=sim.sim_cfg.step_dt).view(1, 2))
        odo.update(speeds(), sim.sim_cfg.step_dt)
    true_xy = sim.root_pose[0, :2].tolist()
    row = {"linear": linear, "angular": angular, "seconds": seconds, "true_distance": math.hypot(*true_xy),
           "odometry_distance": math.hypot(odo.x, odo.y), "true_yaw": sim.rpy[0, 2].item(), "odometry_yaw": odo.yaw}
    print(f"odometry from rest, cmd v {linear} m/s w {angular} rad/s for {seconds:g} s: distance "
          f"{row['odometry_distance']:.3f} m (true {row['true_distance']:.3f} m), yaw {row['odometry_yaw']:.4f} rad "
          f"(true {row['true_yaw']:.4f} rad)")
    return row


def main() -> int:
    import torch

    torch.set_num_threads(1)
    from atrv_warp import RoverSim
    from atrv_warp.integrations.ros.base import BaseParams, VelocityController

    n = len(COMMANDS)
    sim = RoverSim(n)
    sim.reset(poses=[[0.0, 4.0 * (i - n / 2), 0.0] for i in range(n)])
    desc = sim.description
    side = torch.tensor([w.side for w in desc.wheels])
    track = abs(float(desc.wheels[0].origin[1, 3]) - float(desc.wheels[-1].origin[1, 3])) + 2 * sim.rover_cfg.wheel_offset
    base = BaseParams(wheel_radius=sim.rover_cfg.wheel_radius, track_width=track, effective_track_factor=1.0)
    controllers = [VelocityController(base) for _ in COMMANDS]
    for c, (v, w) in zip(controllers, COMMANDS):
        c.command(v, w, now=0.0)
    dt = sim.sim_cfg.step_dt
    for _ in range(60):
        ws = sim.wheel_speed
        speeds = torch.stack([ws[:, side == 0].mean(-1), ws[:, side == 1].mean(-1)], -1)
        sim.step(torch.stack([c.torques(speeds[i], now=0.0, dt=dt) for i, c in enumerate(controllers)]))
    ws = sim.wheel_speed
    rows = []
    for i, (v, w) in enumerate(COMMANDS):
        left, right = ws[i, side == 0].mean().item(), ws[i, side == 1].mean().item()
        yaw_rate = sim.ang_vel[i, 2].item()
        speed = sim.lin_vel[i, :2].norm().item()
        b_eff = base.wheel_radius * (right - left) / yaw_rate if abs(w) > 0 else None
        rows.append({"linear": v, "angular": w, "wheel_left": left, "wheel_right": right, "yaw_rate": yaw_rate,
                     "speed": speed, "effective_track": b_eff, "factor": b_eff / track if b_eff else None})
        print(f"cmd v {v:+.2f} m/s w {w:+.2f} rad/s: wheels {left:+6.2f} {right:+6.2f} rad/s, yaw rate "
              f"{yaw_rate:+.3f} rad/s, speed {speed:.3f} m/s, effective track "
              f"{b_eff if b_eff is None else round(b_eff, 3)} m")
    factor = statistics.median(r["factor"] for r in rows if r["factor"])
    print(f"wheel track {track:.3f} m; effective track factor (median) {factor:.2f}")
    odometry = [odometry_error(v, w, factor) for v, w in ((0.5, 0.0), (0.0, 0.3))]
    out = {"track_width": track, "effective_track_factor": factor, "rows": rows, "odometry": odometry}
    write_results(RESULTS / "skid_calibration.json", out)
    print(f"wrote {RESULTS / 'skid_calibration.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
