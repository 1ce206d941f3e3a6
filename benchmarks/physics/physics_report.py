"""Physics figures against the reference: rest height, straight-line drive, acceleration, turning.

Run: ``python -m benchmarks.physics.physics_report``; prints a table and writes
``benchmarks/results/physics_report.json``, which the docs' physics page shows.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def main() -> int:
    from atrv_warp import RoverSim
    from atrv_warp.sim import FAST_SIM_DT, SimConfig
    from atrv_warp.sim.protocols import reference_drive, rolling_acceleration, wheel_contact_xy

    rows: list[tuple[str, float, str]] = []

    # 1. reference variant: drop 2 cm, settle 1 s, +4 N·m on all wheels for 4.9 s
    run = reference_drive()
    sim, z = run.sim, run.settle_z
    xs, ys, zs, vs = run.track[:, 0], run.track[:, 1], run.track[:, 2], run.forward_speed
    ref_accel = (vs[97] - vs[19]) / (0.05 * 78)  # from 1 s to 4.9 s of driving
    ref_analytic = rolling_acceleration(sim, 4.0)
    ref_depth = sim.arena_cfg.ground_top + sim.rover_cfg.wheel_radius - sim.rest_height
    # the reference tutorial's distances after 1, 3 and 4.9 s of driving, and how far ahead of them we are
    drive = {"t_s": [1.0, 3.0, 4.9], "x_m": [float(xs[i]) for i in (19, 59, 97)], "reference_x_m": [0.17, 1.72, 4.70]}
    drive["ahead"] = [x / r - 1.0 for x, r in zip(drive["x_m"], drive["reference_x_m"])]
    rows += [
        ("reference: z range while settling [m]", f"{min(z):.3f} .. {max(z):.3f}", "0.125 .. 0.150"),
        ("reference: x after 1 s of driving [m]", f"{xs[19]:.3f}", "0.17"),
        ("reference: x after 3 s [m]", f"{xs[59]:.3f}", "1.72"),
        ("reference: x after 4.9 s [m]", f"{xs[97]:.3f}", "4.70"),
        ("reference: lateral drift [mm]", f"{1e3 * np.abs(ys).max():.2f}", "< 6"),
        ("reference: height while driving [m]", f"{np.mean(zs[40:]):.4f}", "0.137"),
        ("reference: acceleration, 1 .. 4.9 s [m/s²]", f"{ref_accel:.3f}", f"{ref_analytic:.3f} = F/(M+ΣI/r²)"),
        ("reference: static tyre depth of the law [mm]", f"{1e3 * ref_depth:.1f}", "(m g / 4 kp)^(1/n), 54 kg"),
    ]

    # 2. realistic variant at rest, +2 N·m (below slip), rotate_left
    sim = RoverSim(3)
    sim.reset(height=sim.rest_height + 0.02)
    for _ in range(200):
        sim.step()
    rest = sim.root_pose[0, 2].item()
    sim.set_commands([[2.0, 2.0], [-5.0, 5.0], [0.0, 0.0]])
    for _ in range(10):
        sim.step()
    v0, yaw_prev = sim.lin_vel[0, 0].item(), sim.rpy[1, 2].item()
    p1 = sim.root_pose[1, :2].clone()
    turned = 0.0
    for _ in range(30):
        sim.step()
        d = sim.rpy[1, 2].item() - yaw_prev
        turned += (d + math.pi) % (2 * math.pi) - math.pi
        yaw_prev = sim.rpy[1, 2].item()
    accel = (sim.lin_vel[0, 0].item() - v0) / 1.5
    analytic = rolling_acceleration(sim, 2.0)
    # The wheel torque a turn in place needs under pure Coulomb friction (equal loads): each wheel's
    # force mu N points along its slip, at atan(y / x) from the rolling direction, and only its
    # rolling part is the motor's.
    xy = np.abs(wheel_contact_xy(sim)[0])
    load = sim.description.total_mass * abs(sim.sim_cfg.gravity) / len(sim.description.wheels)
    turn_torque = sim.rover_cfg.wheel_radius * sim.contact_cfg.friction * load * math.cos(math.atan2(xy[1], xy[0]))
    depth = sim.arena_cfg.ground_top + sim.rover_cfg.wheel_radius - sim.rest_height
    rows += [
        ("realistic: rest height [m]", f"{rest:.4f}", f"{sim.rest_height:.4f} (static HC equilibrium)"),
        ("realistic: static tyre depth of the law [mm]", f"{1e3 * depth:.1f}", "(m g / 4 kp)^(1/n), 58 kg"),
        ("realistic: accel at +2 N·m [m/s²]", f"{accel:.4f}", f"{analytic:.4f} = F/(M+ΣI/r²)"),
        ("realistic: rotate_left yaw rate [rad/s]", f"{turned / 1.5:.3f}",
         f"spins up: 5 N·m > {turn_torque:.2f} N·m, a Coulomb turn in place"),
        ("realistic: rotate_left translation [m]", f"{(sim.root_pose[1, :2] - p1).norm().item():.4f}", "< 0.10"),
    ]

    # 3. where the damping ceiling (ContactConfig.damping_limit) takes over: kc d^n = its cap
    onset = []
    for rovers in (sim, RoverSim(1, sim=SimConfig(sim_dt=FAST_SIM_DT))):
        law = rovers.contact.params
        onset.append(1e3 * (law.damping_cap / law.damping) ** (1.0 / law.exponent))
    rows.append(("realistic: damping ceiling engages beyond [mm], 0.01 / 1/60 s", f"{onset[0]:.1f} / {onset[1]:.1f}",
                 "(c_max / kc)^(1/n), c_max = 0.1 (m/4) / sim_dt"))

    width = max(len(r[0]) for r in rows)
    print(f"{'quantity':{width}s}  {'atrv_warp':>16s}  reference / analytic")
    for name, ours, ref in rows:
        print(f"{name:{width}s}  {ours:>16s}  {ref}")
    out = write_results(RESULTS / "physics_report.json",
                        {"rows": [dict(zip(("quantity", "atrv_warp", "reference"), r)) for r in rows],
                         "reference_drive": drive,
                         "static_depth_mm": {"reference": 1e3 * ref_depth, "realistic": 1e3 * depth},
                         "damping_ceiling": {"sim_dt_s": [0.01, FAST_SIM_DT], "onset_mm": onset},
                         "time": time.strftime("%Y-%m-%d %H:%M:%S")}, version=VERSION)
    print(f"\nwritten to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def physics_report() -> str:
    """``physics_report.json``: the physics figures against the reference's and analytic ones."""
    rows = load_results("physics_report.json")["rows"]
    return markdown_table(["quantity", "atrv_warp", "reference / analytic"], ["---", "---:", "---"],
                          [[r["quantity"], r["atrv_warp"], r["reference"]] for r in rows])


TABLES = {
    "physics_report": physics_report,
}


if __name__ == "__main__":
    sys.exit(main())
