"""System identification: recover the tyre–ground friction coefficient from a trajectory.

Run: ``python examples/friction_identification.py [--true-mu 0.3] [--guess 0.5]``

A rover drives 1 s with full torque (the wheels slip, so the motion depends on mu); its chassis
trajectory is the "measurement". Starting from a wrong guess, gradient descent on the squared
trajectory error through the differentiable rollout recovers mu.
"""

from __future__ import annotations

import argparse
import sys

import torch

from atrv_warp.sim.diff import DiffRollout


def identify(true_mu: float = 0.3, guess: float = 0.5, steps: int = 20, iterations: int = 30, verbose: bool = True):
    """Returns (estimated mu, history of (mu, loss))."""
    roll = DiffRollout(1, steps=steps)
    state = roll.initial_state()
    actions = torch.ones(steps, 1, 2)  # 20 N·m per wheel: above the slip limit
    with torch.no_grad():
        measured = roll(actions, state, true_mu)[:, 0, :3]
    mu = torch.tensor(guess, requires_grad=True)
    opt = torch.optim.Adam([mu], lr=0.02, betas=(0.5, 0.9))
    history = []
    for it in range(iterations):
        poses = roll(actions, state, mu)[:, 0, :3]
        loss = (poses - measured).square().sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        history.append((mu.item(), loss.item()))
        if verbose:
            print(f"iteration {it:3d}: mu {mu.item():.4f}  loss {loss.item():.3e}", flush=True)
    return mu.item(), history


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--true-mu", type=float, default=0.3)
    parser.add_argument("--guess", type=float, default=0.5)
    parser.add_argument("--iterations", type=int, default=30)
    args = parser.parse_args()
    mu, _ = identify(args.true_mu, args.guess, iterations=args.iterations)
    print(f"estimated mu {mu:.4f} (true {args.true_mu})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
