"""Drive with an exported policy and torch alone: no Warp, Newton or TorchRL.

    python -m atrv_warp.export policy.pt2                      # once, where atrv_warp is installed
    python examples/run_exported_policy.py policy.pt2
    python -m atrv_warp.export runs/nav_deploy/best_policy.pt nav_deploy.pt2
    python examples/run_exported_policy.py nav_deploy.pt2      # a robot policy: twist out, robot messages in

The file's ``atrv_warp.json`` says what the policy observes and commands. A robot policy (``observation_kind``
``robot``, e.g. the ``nav_deploy`` task's) observes what a robot publishes; its input is built from those messages
by ``atrv_warp.core.observation.RobotObservation``, which imports torch alone, in the order, bounds and scan sectors
the file lists; its action is a ``/cmd_vel`` twist. An arena policy (the reference task's) observes positions in
the arena's frame, built here by hand; its action is each side's wheel torque. In both, a made-up rover at the
origin, facing +x, is asked to reach (3, 4) m, 53 deg to its left, with nothing in sight.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import torch

FORMAT = "atrv_warp.exported_policy/3"
GOAL = (3.0, 4.0)


def arena_observation(target, position, velocity, roll, yaw_rate, yaw, bounds) -> torch.Tensor:
    """The arena observation's 10 fields in the file's order: target x, y; rover x, y; vx, vy; roll; yaw rate;
    sin and cos of the heading error; each clipped to its bound."""
    bearing = math.atan2(target[1] - position[1], target[0] - position[0]) - yaw
    err = math.atan2(math.sin(bearing), math.cos(bearing))
    values = [*target, *position, *velocity, roll, yaw_rate, math.sin(err), math.cos(err)]
    return torch.tensor([max(-b, min(b, v)) for v, b in zip(values, bounds, strict=True)], dtype=torch.float32)


def robot_observation(spec: dict) -> torch.Tensor:
    """The robot observation from a robot's messages: odometry at rest at the origin, a level IMU, the goal in the
    odometry frame, a 181-beam scan over 180 deg (not the simulator's 64) with no return, no earlier actions."""
    from atrv_warp.core.observation import RobotObservation, Scan

    build = RobotObservation.from_contract(spec)
    scan = Scan(ranges=torch.full((181,), math.inf), angle_min=-math.pi / 2, angle_increment=math.pi / 180,
                range_min=0.05, range_max=30.0)
    return build(odom_pose=[0.0, 0.0, 0.0], odom_twist=[0.0, 0.0], imu_orientation=[0.0, 0.0, 0.0, 1.0],
                 imu_angular_velocity=[0.0, 0.0, 0.0], goal=GOAL, scan=scan,
                 last_actions=torch.zeros(build.action_history, len(build.action_columns)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a .pt2 file written by python -m atrv_warp.export")
    args = parser.parse_args()
    from atrv_warp.core.files import ExportedFileError, load_exported_program

    try:  # checked before torch loads it: nothing in a .pt2 can run code (a plain torch.export.load can unpickle)
        program, extra = load_exported_program(args.policy)
    except (FileNotFoundError, ExportedFileError) as err:
        print(err, file=sys.stderr)
        return 2
    policy = program.module()
    spec = json.loads(extra.get("atrv_warp.json", "{}"))
    if spec.get("format") != FORMAT:
        print(f"{args.policy}: contract {spec.get('format')!r}, this example reads {FORMAT!r}: export it again",
              file=sys.stderr)
        return 2
    if spec["observation_kind"] == "robot":
        obs = robot_observation(spec)
    else:
        obs = arena_observation(target=GOAL, position=(0.0, 0.0), velocity=(0.0, 0.0), roll=0.0, yaw_rate=0.0,
                                yaw=0.0, bounds=[f["bound"] for f in spec["observation"]])
    with torch.no_grad():
        action = policy(obs[None])[0]
    first, second = (action * torch.tensor(spec["action"]["scale"])).tolist()
    print(f"observation {[round(v, 3) for v in obs.tolist()]}")
    if spec["action"]["kind"] == "twist":
        print(f"cmd_vel: linear.x {first:+.2f} m/s, angular.z {second:+.2f} rad/s")
        left_turn = second > 0
    else:
        print(f"wheel torques: left {first:+.2f} N·m, right {second:+.2f} N·m")
        left_turn = second > first  # a skid-steer rover turns left with right > left
    if not left_turn:
        print("unexpected: the policy does not turn toward a goal on its left", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
