"""Skid-steer physics against Coulomb friction: turning, rolling, traction and slopes.

    python -m benchmarks.physics.skid_calibration

1. **Turning.** One world per (linear, angular) command, driven for 15 s by the base's motor driver
   (:func:`atrv_warp.sim.protocols.turning_response`, factor 1, so the wheel targets are a differential drive's). Over the last 4 s: the effective track ratio
   ``chi = r (w_right - w_left) / (yaw_rate x track)``, at mu = 0.3, 0.5, 0.8 and 1.0, against the
   pure-Coulomb prediction for the same wheel speeds (:func:`atrv_warp.sim.protocols.coulomb_twist`)
   and against the 0.1.x viscous law (``ContactConfig(friction_law="viscous")``). The ROS node's
   default ``effective_track_factor`` is the median chi at the default mu. Target band 1.3–2.0.
2. **Rolling.** The slip ratio at +2 N·m per wheel (target under 3 %), and the driver's wheel
   odometry (with the new factor) from rest at 0.5 m/s and at 0.3 rad/s for 4 s against the truth
   (target within 2 %).
3. **Traction limit.** Full torque (20 N·m) from rest: the mean acceleration while the tyres slide
   (:func:`atrv_warp.sim.protocols.full_torque_acceleration`) against mu g.
4. **Slopes.** A rover parked across a slope of 0.8 and 1.2 x atan(mu), its motors braking
   (:func:`atrv_warp.sim.protocols.parked_on_slope`): how far it moves in 5 s.

Prints each table and writes ``benchmarks/results/skid_calibration.json``.
"""

from __future__ import annotations

import math
import statistics
import sys
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
COMMANDS = [(0.0, 0.25), (0.0, 0.5), (0.0, 1.0), (0.3, 0.3), (0.5, 0.5), (0.5, -0.25), (1.0, 0.2)]
FRICTIONS = (0.3, 0.5, 0.8, 1.0)
BAND = (1.3, 2.0)


def track_width(sim) -> float:
    """Distance between the left and right wheels' contact points [m]."""
    from atrv_warp.sim.protocols import wheel_contact_xy

    y = wheel_contact_xy(sim)[:, 1]
    return float(y.max() - y.min())


def turning(mu: float, law: str = "coulomb") -> list[dict]:
    """chi for every command at friction ``mu`` under ``law``, with the Coulomb prediction."""
    import numpy as np

    from atrv_warp import RoverSim
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import coulomb_twist, turning_response, wheel_contact_xy

    contact = ContactConfig(friction=mu, friction_law=law)
    sim = RoverSim(1, contact=contact)
    r, track = sim.rover_cfg.wheel_radius, track_width(sim)
    driver = DriverConfig(wheel_radius=r, track_width=track, effective_track_factor=1.0)
    contacts = wheel_contact_xy(sim)
    side = np.array([w.side for w in sim.description.wheels])
    rows = []
    for row in turning_response(COMMANDS, driver=driver, contact=contact, seconds=15.0, average=4.0):
        left, right = row["wheel_left"], row["wheel_right"]
        predicted = coulomb_twist(contacts, r * np.where(side == 0, left, right))[2]
        row.update(mu=mu, law=law, chi=r * (right - left) / (row["yaw_rate"] * track),
                   chi_coulomb=r * (right - left) / (predicted * track))
        rows.append(row)
    return rows


def odometry(linear: float, angular: float, factor: float, seconds: float = 4.0) -> dict:
    """The base's wheel odometry (the motor driver's, in the simulator) against the truth from a standstill, the
    command re-sent every step."""
    from atrv_warp import RoverSim
    from atrv_warp.sim.driver import DriverConfig

    geometry = RoverSim(1)
    sim = RoverSim(1, driver=DriverConfig(wheel_radius=geometry.rover_cfg.wheel_radius, track_width=track_width(geometry),
                                          effective_track_factor=factor))
    dt = sim.sim_cfg.step_dt
    for _ in range(round(seconds / dt)):
        sim.set_twist([linear, angular])
        sim.step()
    true_xy = sim.root_pose[0, :2].tolist()
    x, y, yaw = sim.driver.odometry[0].tolist()
    return {"linear": linear, "angular": angular, "seconds": seconds, "true_distance": math.hypot(*true_xy),
            "odometry_distance": math.hypot(x, y), "true_yaw": sim.rpy[0, 2].item(), "odometry_yaw": yaw}


def traction(mu: float) -> dict:
    """Mean acceleration at full torque from rest, tyres sliding, against mu g."""
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.protocols import full_torque_acceleration

    return {"mu": mu, "acceleration": full_torque_acceleration(ContactConfig(friction=mu)), "mu_g": mu * 9.81}


def main() -> int:
    import torch

    torch.set_num_threads(1)
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.protocols import parked_on_slope, slip_ratio

    print("1. Turning under the base's motor driver (factor 1), 15 s per command, means over the last 4 s")
    print(f"{'law':>8} {'mu':>4} {'v [m/s]':>8} {'w [rad/s]':>9} {'wheels L, R [rad/s]':>20} {'yaw rate':>9} "
          f"{'chi':>6} {'Coulomb':>8}")
    rows = []
    for law, frictions in (("coulomb", FRICTIONS), ("viscous", (0.3, 0.8))):
        for mu in frictions:
            for row in turning(mu, law):
                rows.append(row)
                print(f"{law:>8} {mu:4.1f} {row['linear']:8.2f} {row['angular']:9.2f} "
                      f"{row['wheel_left']:9.2f} {row['wheel_right']:9.2f} {row['yaw_rate']:9.4f} "
                      f"{row['chi']:6.2f} {row['chi_coulomb']:8.2f}")
    coulomb = [r for r in rows if r["law"] == "coulomb"]
    chis = [r["chi"] for r in coulomb]
    default_mu = ContactConfig().friction
    factor = statistics.median(r["chi"] for r in coulomb if r["mu"] == default_mu)
    inside = all(BAND[0] <= c <= BAND[1] for c in chis)
    print(f"chi over every command and mu: {min(chis):.2f} .. {max(chis):.2f} (band {BAND[0]}–{BAND[1]}: "
          f"{'inside' if inside else 'OUTSIDE'}); viscous law: "
          f"{min(r['chi'] for r in rows if r['law'] == 'viscous'):.2f} .. "
          f"{max(r['chi'] for r in rows if r['law'] == 'viscous'):.2f}")
    print(f"effective track factor (median chi at mu = {default_mu}): {factor:.2f}")

    print("\n2. Rolling")
    slip = slip_ratio(2.0)
    print(f"slip ratio at +2 N·m per wheel (1–2 s): {100 * slip:.3f} % (target < 3 %)")
    odo = [odometry(v, w, factor) for v, w in ((0.5, 0.0), (0.0, 0.3))]
    for o in odo:
        err = (abs(o["odometry_distance"] - o["true_distance"]) / o["true_distance"] if o["true_distance"] > 0.05
               else abs(o["odometry_yaw"] - o["true_yaw"]) / abs(o["true_yaw"]))
        o["relative_error"] = err
        print(f"odometry from rest, cmd v {o['linear']} m/s w {o['angular']} rad/s for {o['seconds']:g} s: "
              f"distance {o['odometry_distance']:.3f} m (true {o['true_distance']:.3f}), yaw {o['odometry_yaw']:.4f} "
              f"rad (true {o['true_yaw']:.4f}): {100 * err:.2f} % off (target < 2 %)")

    print("\n3. Traction limit: full torque (20 N·m) from rest, mean acceleration while the tyres slide")
    trac = [traction(mu) for mu in FRICTIONS]
    for t in trac:
        print(f"mu {t['mu']:.1f}: {t['acceleration']:.3f} m/s² (mu g = {t['mu_g']:.3f}, "
              f"{t['acceleration'] / t['mu_g']:.3f} of it)")

    print("\n4. Parked across a slope, motors braking, moved in 5 s")
    slopes = []
    for mu in (0.3, 0.5, 0.8):
        limit = math.degrees(math.atan(mu))
        degrees = (0.8 * limit, 1.2 * limit)
        moved = parked_on_slope(degrees, contact=ContactConfig(friction=mu))
        for deg, m, fraction in zip(degrees, moved, (0.8, 1.2)):
            slopes.append({"mu": mu, "degrees": deg, "fraction_of_atan_mu": fraction, "moved": float(m)})
            print(f"mu {mu:.1f}: {fraction:.1f} x atan(mu) = {deg:5.2f} deg: moved {m:.4f} m "
                  f"({'holds' if m < 0.01 else 'slides'})")

    from atrv_warp import RoverSim

    viscous = [r["chi"] for r in rows if r["law"] == "viscous"]
    out = {"track_width": track_width(RoverSim(1)), "effective_track_factor": factor, "band": BAND,
           "chi_inside_band": inside, "chi_min": min(chis), "chi_max": max(chis), "viscous_chi_min": min(viscous),
           "viscous_chi_max": max(viscous), "turning": rows, "slip_ratio_2Nm": slip, "odometry": odo, "traction": trac,
           "slopes": slopes}
    write_results(RESULTS / "skid_calibration.json", out, version=VERSION, driver=True)
    print(f"\nwrote {RESULTS / 'skid_calibration.json'}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def skid_turning() -> str:
    """``skid_calibration.json``: the effective track ratio chi per command and mu, against Coulomb."""
    d = load_results("skid_calibration.json")
    rows = d["turning"]
    commands = sorted({(r["linear"], r["angular"]) for r in rows}, key=lambda c: (c[0], -abs(c[1])))
    columns = [(r["law"], r["mu"]) for r in rows]
    columns = sorted(set(columns), key=lambda c: (c[0] != "coulomb", c[1]))
    chi = {(r["law"], r["mu"], r["linear"], r["angular"]): r["chi"] for r in rows}
    coulomb = {(r["linear"], r["angular"]): r["chi_coulomb"] for r in rows if r["law"] == "coulomb"}
    header = ["v [m/s], ω [rad/s]"] + [f"µ {mu:g}" + ("" if law == "coulomb" else f" ({law})") for law, mu in columns]
    body = [[f"{v:g}, {w:g}"] + [f"{chi[(law, mu, v, w)]:.2f}" for law, mu in columns] for v, w in commands]
    table = markdown_table(header + ["pure Coulomb"], ["---"] + ["---:"] * (len(columns) + 1),
                           [row + [f"{coulomb[c]:.2f}"] for row, c in zip(body, commands)])
    return table + f"\n\nMedian chi at µ 0.3, the ROS node's `effective_track_factor`: **{d['effective_track_factor']:.2f}**."


def skid_checks() -> str:
    """``skid_calibration.json``: rolling slip, wheel odometry, traction limit and slopes."""
    d = load_results("skid_calibration.json")
    rows = [["slip ratio at +2 N·m per wheel", f"{100 * d['slip_ratio_2Nm']:.2f} %", "< 3 %"]]
    for o in d["odometry"]:
        what = f"{o['linear']:g} m/s" if o["linear"] else f"{o['angular']:g} rad/s in place"
        rows.append([f"wheel odometry from rest, {what}, {o['seconds']:g} s", f"{100 * o['relative_error']:.2f} % off",
                     "< 2 %"])
    for t in d["traction"]:
        rows.append([f"full torque, µ {t['mu']:g}: acceleration [m/s²]", f"{t['acceleration']:.2f}",
                     f"µ g = {t['mu_g']:.2f}"])
    for s in d["slopes"]:
        rows.append([f"parked, µ {s['mu']:g}, {s['fraction_of_atan_mu']:g} × atan µ = {s['degrees']:.1f}°: moved in 5 s",
                     f"{1000 * s['moved']:.1f} mm" if s["moved"] < 1.0 else f"{s['moved']:.2f} m",
                     "holds" if s["fraction_of_atan_mu"] < 1 else "slides"])
    return markdown_table(["check", "atrv_warp", "target"], ["---", "---:", "---"], rows)


TABLES = {
    "skid_turning": skid_turning,
    "skid_checks": skid_checks,
}


if __name__ == "__main__":
    sys.exit(main())
