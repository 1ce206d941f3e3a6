"""Drive the five reference driving modes side by side, one world each, and print what happened.

Run: ``python -m atrv_warp.demo [--seconds 3] [--robot atrvjr] [--variant realistic]``
"""

from __future__ import annotations

import argparse
import math
import sys
import time

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.demo", description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="driving time after 1 s of settling [s]")
    parser.add_argument("--robot", default=None, help="a shipped robot's name (atrvjr, jackal, husky) or a robot "
                                                      "file's path (default: the ATRV-Jr)")
    parser.add_argument("--variant", default="realistic", help="ATRV-Jr variant: realistic | reference")
    parser.add_argument("--device", default="cpu", help="Warp device, e.g. cpu or cuda:0")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from atrv_warp.sim.simulator import DriveMode, RoverSim

    modes = list(DriveMode)
    print(f"building {len(modes)} worlds (first run compiles Warp kernels, ~1 min on CPU) ...", flush=True)
    t0 = time.perf_counter()
    try:
        sim = RoverSim(len(modes), robot=args.robot, variant=args.variant, device=args.device)
    except ValueError as err:  # an unknown robot, a bad robot file or URDF
        print(f"error: {err}", file=sys.stderr)
        return 2
    sim.step()
    print(f"ready in {time.perf_counter() - t0:.1f} s: {sim}")
    for _ in range(19):
        sim.step()
    start = sim.root_pose[:, :3].clone()
    yaw0 = sim.rpy[:, 2].clone()
    for i, mode in enumerate(modes):
        sim.set_mode(mode, worlds=[i])
    turned = sim.rpy[:, 2] * 0
    prev = yaw0.clone()
    steps = round(args.seconds / sim.sim_cfg.step_dt)
    for _ in range(steps):
        sim.step()
        d = sim.rpy[:, 2] - prev
        turned += (d + math.pi) % (2 * math.pi) - math.pi
        prev = sim.rpy[:, 2].clone()
    moved = sim.root_pose[:, :3] - start
    rover = sim.rover_cfg.robot_spec.title + (f", {args.variant}" if args.variant != "realistic" else "")
    print(f"\nafter {args.seconds:.1f} s in each mode ({rover}, rest height {sim.rest_height:.4f} m):")
    print(f"{'mode':13s} {'dx [m]':>8s} {'dy [m]':>8s} {'z [m]':>7s} {'yaw [deg]':>10s} {'speed [m/s]':>12s}")
    for i, mode in enumerate(modes):
        print(f"{mode.value:13s} {moved[i, 0].item():8.3f} {moved[i, 1].item():8.3f} "
              f"{sim.root_pose[i, 2].item():7.4f} {math.degrees(turned[i].item()):10.1f} "
              f"{sim.lin_vel[i, :2].norm().item():12.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
