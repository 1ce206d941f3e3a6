"""Open-loop trajectory optimisation by gradient descent through the simulator.

Run: ``python examples/trajectory_optimisation.py [--target 1.5 1.5] [--heading 90] [--iterations 40]``

Finds 3 s of [left, right] wheel torques that bring a rover from rest at the origin (facing +x)
to a target pose: by default 1.5 m ahead and 1.5 m to the left, arriving facing +y, a quarter
turn that needs the skid-steer's left-against-right gradient. Adam on the gradient of the
final-pose loss through the differentiable rollout (:class:`atrv_warp.sim.diff.DiffRollout`), with a
cosine learning-rate decay. Prints the loss per iteration and the final miss.
"""

from __future__ import annotations

import argparse
import math
import sys

import torch

from atrv_warp.core.geometry import quat_to_yaw
from atrv_warp.sim.diff import DiffRollout


def final_pose(poses: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(x, y) [m] and yaw [rad] of world 0 at the end of a rollout."""
    return poses[-1, 0, :2], quat_to_yaw(poses[-1, 0, 3:7])


def optimise(target=(1.5, 1.5), heading: float | None = 90.0, steps: int = 60, segments: int = 10,
             iterations: int = 40, lr: float = 0.05, start: tuple[float, float] = (0.1, 0.4), verbose: bool = True):
    """Returns (best position miss [m], its heading miss [deg] or None, its actions (steps, 1, 2), loss history).

    The torques are piecewise constant over ``segments`` equal intervals (a smoother search space
    than one value per step) and pass through tanh so they stay in [-1, 1]. ``heading`` is the
    final yaw [deg] to arrive with (``None``: position only). ``start`` is the first guess, (left,
    right) in [-1, 1] on every segment: a gentle left arc. Not zero: with Coulomb friction a rover
    turns only once the difference between its sides' torques overcomes its wheels' sideways grip
    (about 2 x 3.2 N·m in place), so below that the final heading does not depend on the steering at
    all, and a search that starts from zero torques sees no gradient to turn with.
    """
    if steps % segments:
        raise ValueError(f"steps ({steps}) must be a multiple of segments ({segments})")
    roll = DiffRollout(1, steps=steps)
    state = roll.initial_state()
    goal = torch.tensor(target, dtype=torch.float32)
    raw = torch.atanh(torch.tensor(start, dtype=torch.float32)).expand(segments, 1, 2).clone().requires_grad_(True)
    opt = torch.optim.Adam([raw], lr=lr, betas=(0.6, 0.9))
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, iterations, eta_min=0.1 * lr)
    history = []
    best = (float("inf"), None, raw.detach().clone())

    def actions_of(raw):
        return torch.tanh(raw).repeat_interleave(steps // segments, dim=0)

    for it in range(iterations):
        actions = actions_of(raw)
        position, yaw = final_pose(roll(actions, state))
        miss = (position - goal).norm()
        loss = (position - goal).square().sum() + 1e-3 * actions.square().mean()
        yaw_miss = None
        if heading is not None:
            yaw_error = torch.remainder(yaw - math.radians(heading) + math.pi, 2 * math.pi) - math.pi
            yaw_miss = abs(math.degrees(yaw_error.item()))
            loss = loss + 0.5 * (1.0 - torch.cos(yaw_error))  # 10 deg off weighs as 8.7 cm off
        score = miss.item() + (0.0 if yaw_miss is None else math.radians(yaw_miss))
        if score < best[0]:  # keep the best iterate: Adam can overshoot near the optimum
            best = (score, (miss.item(), yaw_miss), raw.detach().clone())
        opt.zero_grad()
        loss.backward()
        opt.step()
        schedule.step()
        history.append(loss.item())
        if verbose:
            print(f"iteration {it:3d}: loss {loss.item():.4f}, final pose ({position[0]:.3f}, {position[1]:.3f}) m, "
                  f"{math.degrees(yaw.item()):6.1f} deg", flush=True)
    (miss, yaw_miss), raw_best = best[1], best[2]
    return miss, yaw_miss, actions_of(raw_best).detach(), history


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", type=float, nargs=2, default=[1.5, 1.5], help="x y [m]")
    parser.add_argument("--heading", type=float, default=90.0, help="final yaw [deg], 0 = +x")
    parser.add_argument("--no-heading", action="store_true", help="optimise the final position only")
    parser.add_argument("--seconds", type=float, default=3.0, help="horizon [s] (a multiple of 0.5 s)")
    parser.add_argument("--iterations", type=int, default=40)
    args = parser.parse_args()
    steps = round(args.seconds / 0.05)
    miss, yaw_miss, _, _ = optimise(tuple(args.target), None if args.no_heading else args.heading, steps=steps,
                                    iterations=args.iterations)
    print(f"final distance to target: {miss:.3f} m" + ("" if yaw_miss is None else f", heading off by {yaw_miss:.1f} deg"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
