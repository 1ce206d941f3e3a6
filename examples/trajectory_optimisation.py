"""Open-loop trajectory optimisation by gradient descent through the simulator.

Run: ``python examples/trajectory_optimisation.py [--target 2.0 0.6] [--iterations 40]``

Finds 2 s of [left, right] wheel torques that bring a rover from rest at the origin to a
target, by Adam on the gradient of the final-distance loss through the differentiable rollout
(:class:`atrv_warp.diff.DiffRollout`). Prints the loss per iteration and the final miss.
"""

from __future__ import annotations

import argparse
import sys

import torch

from atrv_warp.diff import DiffRollout


def optimise(target=(2.0, 0.6), steps: int = 40, segments: int = 5, iterations: int = 60, lr: float = 0.05,
             verbose: bool = True):
    """Returns (best final distance to target [m], its actions (steps, 1, 2), loss history).

    The torques are piecewise constant over ``segments`` equal intervals (a smoother search space
    than one value per step) and pass through tanh so they stay in [-1, 1].
    """
    roll = DiffRollout(1, steps=steps)
    state = roll.initial_state()
    goal = torch.tensor(target, dtype=torch.float32)
    raw = torch.zeros(segments, 1, 2, requires_grad=True)
    opt = torch.optim.Adam([raw], lr=lr, betas=(0.6, 0.9))
    history = []
    best = (float("inf"), raw.detach().clone())

    def actions_of(raw):
        return torch.tanh(raw).repeat_interleave(steps // segments, dim=0)

    for it in range(iterations):
        actions = actions_of(raw)
        poses = roll(actions, state)
        miss = poses[-1, 0, :2] - goal
        if miss.norm().item() < best[0]:  # keep the best iterate: Adam can overshoot near the optimum
            best = (miss.norm().item(), raw.detach().clone())
        loss = miss.square().sum() + 1e-3 * actions.square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        history.append(loss.item())
        if verbose:
            print(f"iteration {it:3d}: loss {loss.item():.4f}, final position ({poses[-1, 0, 0]:.3f}, "
                  f"{poses[-1, 0, 1]:.3f}) m", flush=True)
    return best[0], actions_of(best[1]).detach(), history


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", type=float, nargs=2, default=[2.0, 0.6])
    parser.add_argument("--iterations", type=int, default=60)
    args = parser.parse_args()
    miss, _, _ = optimise(tuple(args.target), iterations=args.iterations)
    print(f"final distance to target: {miss:.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
