"""Why the Jackal's gentle arc at high grip settles late: the chassis rings on its tyres, not the driver.

    python -m benchmarks.physics.arc_ripple [--robot jackal] [--figure docs/arc_ripple.png]

``robot check`` judges a ``/cmd_vel`` step by its yaw rate: the time after which it stays within 10 % of the command,
sampled every 0.05 s step. The Jackal misses the 0.5 s target on one case, the 0.3 m/s, 0.3 rad/s arc at µ 0.8.
This drives that arc (and, for comparison, at µ 0.3) with the yaw rate and each side's wheel speed sampled every
0.01 s substep (and again as the check steps it, every 0.05 s, for its settling time), on the nominal contact and with its damping and its stiffness scaled (:data:`CONTACTS`). Per run: the
yaw rate's mean over the last second over the command, its ripple (half its peak-to-peak) from 0.5 to 1 s and from
1.5 to 2 s, the ripple's period (twice the mean spacing of its mean crossings after 0.5 s), the settling time as the
check measures it (every 0.05 s) and the time after which each side's wheel speed stays within 10 % of the driver's
target.

Prints the table, writes ``benchmarks/results/arc_ripple.json`` and, with ``--figure``, draws the yaw-rate traces.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import load_results, markdown_table, save_figure, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
COMMAND = (0.3, 0.3)
"""(linear [m/s], angular [rad/s]): the check's arc (``robot_check.STEP_CASES``)."""
CONTACTS: tuple[tuple[str, float, float, float], ...] = (
    ("nominal", 0.8, 1.0, 1.0), ("nominal, µ 0.3", 0.3, 1.0, 1.0), ("damping x3", 0.8, 3.0, 1.0),
    ("damping x0.3", 0.8, 0.3, 1.0), ("stiffness x0.5", 0.8, 1.0, 0.5), ("stiffness x2", 0.8, 1.0, 2.0))
"""(label, µ, damping scale, stiffness scale) of each run."""
SECONDS = 2.0
BAND = 0.1
CHECK_STEP = 0.05
"""The check's sampling [s]."""


def drive(robot: str, friction: float, damping: float, stiffness: float) -> dict:
    """One arc from rest on ``robot`` at ``friction``, the contact's damping and stiffness scaled."""
    import dataclasses

    import torch

    from atrv_warp import RoverSim
    from atrv_warp.sim.config import ContactConfig, RoverConfig, SimConfig
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import settle_time
    from atrv_warp.sim.urdf import load_rover

    base = ContactConfig()
    contact = dataclasses.replace(base, damping=damping * base.damping, stiffness=stiffness * base.stiffness)
    rover = RoverConfig(robot=robot)
    v, w = COMMAND

    def arc(step_dt: float) -> RoverSim:
        sim = RoverSim(1, rover=rover, contact=contact, sim=SimConfig(step_dt=step_dt))
        sim.set_params(friction=[friction])
        sim.reset(poses=[[0.0, -v / w, 0.0]])
        return sim

    check = arc(CHECK_STEP)  # as the check steps it (its settling time sits on the ripple's edge: sampled as it is)
    checked = []
    for _ in range(round(SECONDS / CHECK_STEP)):
        check.set_twist(torch.tensor([COMMAND]))
        check.step()
        checked.append(float(check.ang_vel[0, 2]) / w)
    sim = arc(SimConfig().sim_dt)
    kinematics = DriverConfig().resolved(rover.robot_spec).kinematics(load_rover(rover), rover)
    goal = np.asarray(kinematics.wheel_speeds(v, w).numpy(), dtype=np.float64)  # (left, right) [rad/s]
    side = np.array([wheel.side for wheel in load_rover(rover).wheels])
    dt = sim.sim_cfg.step_dt
    rates, wheels = [], []
    for _ in range(round(SECONDS / dt)):
        sim.set_twist(torch.tensor([COMMAND]))
        sim.step()
        rates.append(float(sim.ang_vel[0, 2]))
        speed = sim.wheel_speed[0].double().numpy()
        wheels.append([speed[side == s].mean() for s in (0, 1)])
    rate, wheels = np.asarray(rates) / w, np.asarray(wheels)
    late = rate[round(0.5 / dt):] - rate[round(0.5 / dt):].mean()
    crossings = np.flatnonzero(np.diff(np.sign(late)) != 0)
    return {"friction": friction, "damping_scale": damping, "stiffness_scale": stiffness,
            "steady": float(rate[-round(1.0 / dt):].mean()),
            "ripple_early": float(np.ptp(rate[round(0.5 / dt):round(1.0 / dt)]) / 2),
            "ripple_late": float(np.ptp(rate[round(1.5 / dt):]) / 2),
            "period": float(2 * np.diff(crossings).mean() * dt) if len(crossings) > 2 else None,
            "settle_check": settle_time(checked, CHECK_STEP, BAND),
            "wheels_settle": max(settle_time(wheels[:, s] / goal[s], dt, BAND) for s in (0, 1)),
            "time": (dt * np.arange(1, len(rate) + 1)).tolist(), "yaw_rate": rate.tolist()}


def draw(path: Path, results: str = "arc_ripple.json") -> None:
    """The yaw rate over the command against time, one line per run, into ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = load_results(results)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for label, run in data["runs"].items():
        ax.plot(run["time"], run["yaw_rate"], lw=1.2 if label.startswith("nominal") else 0.8, label=label)
    ax.axhspan(1 - BAND, 1 + BAND, color="0.9", zorder=0)
    ax.set(xlabel="time [s]", ylabel="yaw rate / command", ylim=(0.0, 1.4),
           title=f"{data['robot']}: a {COMMAND[0]:g} m/s, {COMMAND[1]:g} rad/s arc from rest (band: ±10 %)")
    ax.legend(fontsize=8, ncol=3)
    save_figure(fig, path, version=VERSION, results=(results,), robots=(data["robot"],))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="jackal")
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--out", default=str(RESULTS / "arc_ripple.json"))
    args = parser.parse_args(argv)
    runs = {}
    for label, mu, damping, stiffness in CONTACTS:
        r = runs[label] = drive(args.robot, mu, damping, stiffness)
        period = "-" if r["period"] is None else f"{r['period']:.3f} s"
        print(f"{label:16s} µ {mu:g}: steady {r['steady']:.3f}, ripple {r['ripple_early']:.3f} -> {r['ripple_late']:.3f} "
              f"(period {period}), settles {r['settle_check']:.2f} s (wheels {r['wheels_settle']:.2f} s)", flush=True)
    path = write_results(args.out, {"robot": args.robot, "command": list(COMMAND), "band": BAND, "runs": runs},
                         version=VERSION, driver=True, robots=(args.robot,))
    print(f"written to {path}")
    if args.figure:
        draw(args.figure, Path(args.out).name)
        print(f"figure: {args.figure}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def arc_ripple() -> str:
    """``arc_ripple.json``: each run's steady yaw rate, ripple, period and settling times."""
    rows = []
    for label, r in load_results("arc_ripple.json")["runs"].items():
        period = "-" if r["period"] is None else f"{r['period']:.3f}"
        rows.append([label, f"{r['friction']:g}", f"{r['steady']:.3f}", f"±{r['ripple_early']:.3f}",
                     f"±{r['ripple_late']:.3f}", period, f"{r['settle_check']:.2f}", f"{r['wheels_settle']:.2f}"])
    return markdown_table(["contact", "µ", "yaw rate / command, last 1 s", "ripple 0.5-1 s", "ripple 1.5-2 s",
                           "period [s]", "settles [s]", "wheels settle [s]"],
                          ["---", "---:", "---:", "---:", "---:", "---:", "---:", "---:"], rows)


TABLES = {"arc_ripple": arc_ripple}


if __name__ == "__main__":
    sys.exit(main())
