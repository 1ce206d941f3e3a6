"""Drive with an exported policy and torch alone: no Warp, Newton, TorchRL or atrv_warp.

    python -m atrv_warp.export policy.pt2          # once, where atrv_warp is installed
    python examples/run_exported_policy.py policy.pt2

A real robot stack builds the observation from its own state estimate, in the order and units
the file's ``atrv_warp.json`` lists, and sends the wheel torques to the motor drivers. Here a
made-up rover at the origin, facing +x, is asked to reach (3, 4) m.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import torch


def observation(target, position, velocity, roll, yaw_rate, yaw, bounds) -> torch.Tensor:
    """The 10 fields in the file's order: target x, y; rover x, y; vx, vy; roll; yaw rate;
    sin and cos of the heading error; each clipped to its bound."""
    bearing = math.atan2(target[1] - position[1], target[0] - position[0]) - yaw
    err = math.atan2(math.sin(bearing), math.cos(bearing))
    values = [*target, *position, *velocity, roll, yaw_rate, math.sin(err), math.cos(err)]
    return torch.tensor([[max(-b, min(b, v)) for v, b in zip(values, bounds)]], dtype=torch.float32)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a .pt2 file written by python -m atrv_warp.export")
    args = parser.parse_args()
    extra = {"atrv_warp.json": ""}
    policy = torch.export.load(args.policy, extra_files=extra).module()
    spec = json.loads(extra["atrv_warp.json"])
    bounds = [f["bound"] for f in spec["observation"]]
    obs = observation(target=(3.0, 4.0), position=(0.0, 0.0), velocity=(0.0, 0.0), roll=0.0, yaw_rate=0.0, yaw=0.0,
                      bounds=bounds)
    with torch.no_grad():
        action = policy(obs)[0]
    left, right = (action * spec["action"]["scale"]).tolist()
    print(f"observation {[round(v, 3) for v in obs[0].tolist()]}")
    print(f"wheel torques: left {left:+.2f} N·m, right {right:+.2f} N·m")
    if not right > left:  # the target is 53° to the left: a skid-steer rover turns left with right > left
        print("unexpected: the policy does not turn toward a target on its left", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
