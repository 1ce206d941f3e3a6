"""Drive five ways side by side, one world each, and print what happened.

Run: ``python -m atrv_warp.demo [--seconds 3] [--robot atrvjr] [--variant realistic] [--drive base|torque]
[--map MAP.yaml]``

By default each world drives through the robot's base as ``/cmd_vel`` would, at the robot's own limits (its file's
``[limits]``): still, forward and backward at its top speed, turning right and left in place at its top yaw rate.
``--drive torque`` applies the reference tutorial's fixed wheel torques instead (:class:`DriveMode`), which drive the
rover far past what its base allows.
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
    parser.add_argument("--drive", choices=("base", "torque"), default="base",
                        help="base: twists at the robot's limits through its base (default); torque: the reference "
                             "tutorial's fixed wheel torques")
    parser.add_argument("--device", default="cpu", help="Warp device, e.g. cpu or cuda:0")
    parser.add_argument("--map", metavar="MAP.yaml", help="drive in a Nav2 map_server map, from its most open spot")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import torch

    from atrv_warp.sim.simulator import DriveMode, RoverSim

    modes = list(DriveMode)
    print(f"building {len(modes)} worlds (first run compiles Warp kernels, ~1 min on CPU) ...", flush=True)
    t0 = time.perf_counter()
    try:
        sim = RoverSim(len(modes), robot=args.robot, variant=args.variant, device=args.device,
                       maps=[args.map] if args.map else ())
    except ValueError as err:  # an unknown robot, a bad robot file or URDF, a bad map
        print(f"error: {err}", file=sys.stderr)
        return 2
    sim.step()
    print(f"ready in {time.perf_counter() - t0:.1f} s: {sim}")
    if args.map:
        x, y = sim.maps.open_spot(0)
        print(f"in {args.map}, from its most open spot ({x:.2f}, {y:.2f}) m")
    for _ in range(19):
        sim.step()
    start = sim.root_pose[:, :3].clone()
    yaw0 = sim.rpy[:, 2].clone()
    limits = sim.rover_cfg.robot_spec.limits
    v, w = limits.linear_velocity, limits.angular_velocity
    twists = {DriveMode.COAST: (0.0, 0.0), DriveMode.FORWARD: (v, 0.0), DriveMode.BACKWARD: (-v, 0.0),
              DriveMode.ROTATE_RIGHT: (0.0, -w), DriveMode.ROTATE_LEFT: (0.0, w)}
    command = torch.tensor([twists[mode] for mode in modes])

    def drive() -> None:  # the base stops a command older than its timeout, as diff_drive_controller does
        if args.drive == "base":
            sim.set_twist(command)

    for i, mode in enumerate(modes):
        if args.drive == "torque":
            sim.set_mode(mode, worlds=[i])
    turned = sim.rpy[:, 2] * 0
    prev = yaw0.clone()
    steps = round(args.seconds / sim.sim_cfg.step_dt)
    for _ in range(steps):
        drive()
        sim.step()
        d = sim.rpy[:, 2] - prev
        turned += (d + math.pi) % (2 * math.pi) - math.pi
        prev = sim.rpy[:, 2].clone()
    moved = sim.root_pose[:, :3] - start
    rover = sim.rover_cfg.robot_spec.title + (f", {args.variant}" if args.variant != "realistic" else "")
    how = (f"through its base at its limits, {v:g} m/s and {w:g} rad/s" if args.drive == "base"
           else "the reference tutorial's fixed wheel torques")
    print(f"\nafter {args.seconds:.1f} s in each mode ({rover}, {how}; rest height {sim.rest_height:.4f} m):")
    print(f"{'mode':13s} {'dx [m]':>8s} {'dy [m]':>8s} {'z [m]':>7s} {'yaw [deg]':>10s} {'speed [m/s]':>12s}")
    names = {DriveMode.COAST: "still"} if args.drive == "base" else {}
    for i, mode in enumerate(modes):
        print(f"{names.get(mode, mode.value):13s} {moved[i, 0].item():8.3f} {moved[i, 1].item():8.3f} "
              f"{sim.root_pose[i, 2].item():7.4f} {math.degrees(turned[i].item()):10.1f} "
              f"{sim.lin_vel[i, :2].norm().item():12.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
