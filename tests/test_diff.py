"""Differentiable rollouts: tape gradients against central finite differences, the worked
examples, and clear errors. Tolerances and horizons are those measured by
benchmarks/diff_gradients.py (README, 'Differentiable rollouts')."""

import importlib.util
from pathlib import Path

import pytest
import torch

from atrv_warp.diff import DiffRollout, NonFiniteGradientError

ROOT = Path(__file__).resolve().parent.parent


def load_example(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def roll20():
    roll = DiffRollout(1, steps=20)
    return roll, roll.initial_state()


def central(f, x, i, eps):
    xp, xm = x.clone(), x.clone()
    xp[i] += eps
    xm[i] -= eps
    return ((f(xp) - f(xm)) / (2 * eps)).item()


def test_straight_gradient_over_one_second(roll20):
    """Rolling straight: d x_final / d (left and right torque together) at every 5th step, 1 s horizon."""
    roll, state = roll20
    a = torch.full((20, 1, 2), 0.1, requires_grad=True)
    roll(a, state)[-1, 0, 0].backward()
    f = lambda x: roll(x, state)[-1, 0, 0]
    for t in (0, 5, 10, 19):
        d = torch.zeros(20, 1, 2)
        d[t] = 1.0
        fd = ((f(a.detach() + 1e-2 * d) - f(a.detach() - 1e-2 * d)) / 2e-2).item()
        tape = (a.grad * d).sum().item()
        assert tape == pytest.approx(fd, rel=0.02, abs=1e-4), t


def test_slip_friction_gradient_over_one_second(roll20):
    """Full torque, wheels spinning: d x_final / d mu and d x_final / d torque(t=10)."""
    roll, state = roll20
    a = torch.ones(20, 1, 2)
    mu = torch.tensor(0.3, requires_grad=True)
    roll(a, state, mu)[-1, 0, 0].backward()
    f = lambda m: roll(a, state, m)[-1, 0, 0]
    fd = ((f(torch.tensor(0.301)) - f(torch.tensor(0.299))) / 2e-3).item()
    assert mu.grad.item() == pytest.approx(fd, rel=0.05)
    assert fd > 1.0  # more grip, further: the gradient carries the physics


def test_turning_gradient_short_horizon():
    """Turning in place: yaw gradients agree over one step (0.05 s); beyond, stick-slip of the
    skidding wheels biases them (measured and stated in the README)."""
    roll = DiffRollout(1, steps=1)
    state = roll.initial_state()
    a = torch.tensor([[[-0.3, 0.3]]], requires_grad=True)
    roll(a, state)[-1, 0, 5].backward()  # quaternion z ~ yaw / 2
    f = lambda x: roll(x, state)[-1, 0, 5]
    for side in (0, 1):
        fd = central(f, a.detach(), (0, 0, side), 1e-2)
        assert a.grad[0, 0, side].item() == pytest.approx(fd, rel=0.05)


def test_trajectory_optimisation_example_reaches_target():
    example = load_example("trajectory_optimisation")
    miss, actions, history = example.optimise(target=(2.0, 0.6), iterations=35, verbose=False)
    assert miss < 0.25  # inside the 0.25 m target disc
    assert history[-1] < history[0] / 10
    assert actions.abs().max() <= 1.0


def test_friction_identification_example():
    example = load_example("friction_identification")
    mu, history = example.identify(true_mu=0.3, guess=0.5, verbose=False)
    assert mu == pytest.approx(0.3, abs=0.01)
    assert history[-1][1] < history[0][1] * 1e-3


def test_errors_are_clear():
    roll = DiffRollout(1, steps=2)
    with pytest.raises(ValueError, match=r"actions must have shape \(2, 1, 2\)"):
        roll(torch.zeros(3, 1, 2))
    with pytest.raises(ValueError, match="NaN/inf"):
        roll(torch.full((2, 1, 2), float("nan")))
    a = torch.zeros(2, 1, 2, requires_grad=True)
    poses = roll(a)
    with pytest.raises(NonFiniteGradientError, match="not finite"):
        poses[-1, 0, 0].backward(torch.tensor(float("inf")))
