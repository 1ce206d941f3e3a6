"""Fewer, longer substeps: what they buy in speed and cost in accuracy and stability.

Run: ``python -m benchmarks.physics.substep_study [--substeps 5 4 3] [--plain-law 3] [--nan-steps 1000]
[--held-steps 2000] [--worlds 1024]``

For each substep count (solver step ``sim_dt = 0.05 s / substeps``), in one run and on one core:
env-steps/s of ``RoverSim.step`` at ``--worlds`` worlds (random torques; the counts measured in
turn, best of 3 rounds); the reference drive's distances after 1, 3 and 4.9 s (the physics
report's protocol: the reference variant settled 1 s, then +4 N·m on every wheel); the realistic
rover's acceleration at +2 N·m against F/(M + ΣI/r²), and its rest height; and stability, three
ways: non-finite worlds after ``--nan-steps`` steps of ``--worlds`` worlds under random torques in
±20 N·m drawn fresh each step (the rovers jiggle about their start), and after ``--held-steps``
steps with each world's random torques held (they reach top speed and hit walls at it; worlds
that ever exceed 1.2x the motor's top speed are counted too); and the wall-impact sweep of
:func:`atrv_warp.sim.protocols.wall_impacts` (``--worlds`` rovers driven into the walls at top speed from
every heading; the fastest any leaves a wall). ``--plain-law`` substep counts run a second time with the
plain Hunt–Crossley law (no ``ContactConfig.damping_limit``). Figures are printed and written to
``benchmarks/results/substep_study.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, pin_to_one_core, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _reference_drive(sim_cfg, contact) -> dict:
    from atrv_warp.sim import DriveMode, RoverSim

    sim = RoverSim(1, variant="reference", sim=sim_cfg, contact=contact)
    sim.reset(height=sim.rest_height + 0.02)
    for _ in range(20):
        sim.step()
    x0 = sim.root_pose[0, 0].item()
    sim.set_mode(DriveMode.FORWARD)
    x = {}
    for k in range(1, 99):
        sim.step()
        if k in (20, 60, 98):
            x[f"x_after_{k * 0.05:.1f}_s"] = sim.root_pose[0, 0].item() - x0
    return x


def _acceleration(sim_cfg, contact) -> dict:
    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.protocols import rolling_acceleration

    sim = RoverSim(1, sim=sim_cfg, contact=contact)
    sim.reset()
    for _ in range(20):
        sim.step()
    rest = sim.root_pose[0, 2].item()
    sim.set_commands([2.0, 2.0])
    for _ in range(20):
        sim.step()
    v1 = sim.lin_vel[0, 0].item()
    for _ in range(40):
        sim.step()
    v3 = sim.lin_vel[0, 0].item()
    return {"rest_height_m": rest, "accel_2Nm": (v3 - v1) / 2.0, "accel_analytic": rolling_acceleration(sim, 2.0)}


def _nonfinite(sim_cfg, contact, worlds: int, steps: int) -> int:
    import torch

    from atrv_warp.sim import RoverSim

    sim = RoverSim(worlds, sim=sim_cfg, contact=contact)
    gen = torch.Generator().manual_seed(0)
    sim.reset(poses=(torch.rand(worlds, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
    bad = torch.zeros(worlds, dtype=torch.bool)
    for _ in range(steps):
        sim.commands.copy_(torch.rand(worlds, 2, generator=gen) * 40 - 20)
        sim.step()
        bad |= sim.nonfinite.bool()
    return int(bad.sum())


def _held(sim_cfg, contact, worlds: int, steps: int) -> dict:
    """Held commands, as a driving policy holds them: each world keeps one random torque pair in
    ±20 N·m from a random pose for ``steps`` steps, so most rovers reach top speed and many a wall
    at it. Counts the worlds that go non-finite, and those that ever move faster than 1.2x the
    motor's top speed (energy that only the contact can have put in)."""
    import torch

    from atrv_warp.sim import RoverSim

    sim = RoverSim(worlds, sim=sim_cfg, contact=contact)
    gen = torch.Generator().manual_seed(2)
    sim.reset(poses=(torch.rand(worlds, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
    sim.commands.copy_(torch.rand(worlds, 2, generator=gen) * 40 - 20)
    top = sim.rover_cfg.wheel_speed_limit * sim.rover_cfg.wheel_radius
    bad = torch.zeros(worlds, dtype=torch.bool)
    fast = torch.zeros(worlds, dtype=torch.bool)
    for _ in range(steps):
        sim.step()
        bad |= sim.nonfinite.bool()
        fast |= ~bad & (sim.lin_vel.norm(dim=-1) > 1.2 * top)
    return {"held_nonfinite_worlds": int(bad.sum()), "held_overspeed_worlds": int(fast.sum()),
            "held_world_steps": worlds * steps}


def _impacts(sim_cfg, contact, worlds: int) -> dict:
    from atrv_warp.sim.protocols import wall_impacts

    got = wall_impacts(worlds, sim=sim_cfg, contact=contact)
    return {"impact_max_speed": got.max_speed, "impact_top_speed": got.top_speed,
            "impact_overspeed_worlds": got.overspeed_worlds, "impact_nonfinite_worlds": got.nonfinite_worlds}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--substeps", type=int, nargs="+", default=[5, 4, 3])
    parser.add_argument("--plain-law", type=int, nargs="*", default=[3], help="substep counts also run with the plain "
                        "Hunt-Crossley law (ContactConfig(damping_limit=None)), for comparison")
    parser.add_argument("--worlds", type=int, default=1024)
    parser.add_argument("--nan-steps", type=int, default=1000, help="steps of fresh random torques per world")
    parser.add_argument("--held-steps", type=int, default=2000, help="steps of held random torques per world")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--out", default=str(RESULTS / "substep_study.json"))
    args = parser.parse_args()
    pin_to_one_core()
    import torch

    torch.set_num_threads(1)
    from atrv_warp.sim import ContactConfig, RoverSim, SimConfig

    default, plain = ContactConfig(), ContactConfig(damping_limit=None)
    configs = {(n, "default"): (SimConfig(sim_dt=0.05 / n), default) for n in args.substeps}
    configs.update({(n, "plain"): (SimConfig(sim_dt=0.05 / n), plain) for n in args.plain_law})
    sims = {key: RoverSim(args.worlds, sim=cfg, contact=contact) for key, (cfg, contact) in configs.items()}
    gen = torch.Generator().manual_seed(1)
    for sim in sims.values():
        sim.reset(poses=(torch.rand(args.worlds, 3, generator=gen) * 2 - 1) * torch.tensor([12.0, 12.0, 3.14]))
        sim.commands.copy_(torch.rand(args.worlds, 2, generator=gen) * 16 - 8)
        sim.step()  # graph capture
    best = dict.fromkeys(configs, 0.0)
    for _ in range(3):  # interleaved rounds
        for key, sim in sims.items():
            calls, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < args.seconds:
                sim.step()
                calls += 1
            best[key] = max(best[key], calls * args.worlds / (time.perf_counter() - t0))
    base = best.get((5, "default"))
    rows = []
    for (n, law), (cfg, contact) in configs.items():
        row = {"substeps": n, "sim_dt": cfg.sim_dt, "contact_law": law, "damping_limit": contact.damping_limit,
               "env_steps_per_s": best[n, law], "speedup_vs_5": best[n, law] / base if base else None,
               **_reference_drive(cfg, contact), **_acceleration(cfg, contact),
               "nonfinite_worlds": _nonfinite(cfg, contact, args.worlds, args.nan_steps),
               "world_steps": args.worlds * args.nan_steps,
               **_held(cfg, contact, args.worlds, args.held_steps), **_impacts(cfg, contact, args.worlds)}
        rows.append(row)
        speedup = f" ({row['speedup_vs_5']:.2f}x)" if base else ""
        print(f"substeps {n}, {law} law: {row['env_steps_per_s']:8.0f} env-steps/s{speedup} | reference drive x "
              f"{row['x_after_1.0_s']:.3f} / {row['x_after_3.0_s']:.3f} / {row['x_after_4.9_s']:.3f} m | accel "
              f"{row['accel_2Nm']:.4f} (analytic {row['accel_analytic']:.4f}) | rest {row['rest_height_m']:.4f} m | "
              f"non-finite {row['nonfinite_worlds']} of {args.worlds} worlds in {row['world_steps']:,} world-steps | "
              f"held torques: non-finite {row['held_nonfinite_worlds']}, over 1.2x top speed "
              f"{row['held_overspeed_worlds']} of {args.worlds} in {row['held_world_steps']:,} world-steps | "
              f"wall impacts: fastest {row['impact_max_speed']:.2f} m/s (top {row['impact_top_speed']:.2f}), "
              f"over 1.2x {row['impact_overspeed_worlds']}, non-finite {row['impact_nonfinite_worlds']}", flush=True)
    out = write_results(args.out, {"benchmark": "substep_study", "worlds": args.worlds, "rows": rows,
                                   "time": time.strftime("%Y-%m-%d %H:%M:%S")}, version=VERSION)
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def substep_study() -> str:
    """``substep_study.json``: speed, accuracy and stability per substep count (viscous friction law)."""
    rows = []
    for r in load_results("substep_study.json")["rows"]:
        name = f"{r['substeps']} ({r['sim_dt']:.3g} s)" + (", plain law" if r["damping_limit"] is None else "")
        rows.append([name, f"{r['env_steps_per_s']:,.0f}", f"{r['speedup_vs_5']:.2f}",
                     f"{r['x_after_1.0_s']:.3f} / {r['x_after_3.0_s']:.3f} / {r['x_after_4.9_s']:.3f}",
                     f"{r['accel_2Nm']:.4f}", str(r["nonfinite_worlds"]),
                     f"{r['held_nonfinite_worlds']} / {r['held_overspeed_worlds']}",
                     f"{r['impact_max_speed']:.2f} / {r['impact_overspeed_worlds']}"])
    return markdown_table(["substeps (sim_dt)", "env-steps/s", "vs 5", "reference drive x after 1 / 3 / 4.9 s [m]",
                   "accel at +2 N·m [m/s²]", "fresh torques: non-finite",
                   "held torques: non-finite / over 1.2× top speed", "wall impacts: fastest [m/s] / over 1.2×"],
                          ["---"] + ["---:"] * 7, rows)


TABLES = {
    "substep_study": substep_study,
}


if __name__ == "__main__":
    sys.exit(main())
