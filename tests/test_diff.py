"""Differentiable rollouts: tape gradients against central finite differences, the worked
examples, and clear errors. Tolerances and horizons are those measured by
benchmarks/physics/diff_gradients.py (docs/differentiable.md)."""

import importlib.util
import math
from pathlib import Path

import pytest
import torch

from atrv_warp.sim.diff import DEFAULT_ACTION_SCALE, DiffRollout, NonFiniteGradientError
from atrv_warp.task.config import TaskConfig
from atrv_warp.task.reward import progress_reward

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
    """Full torque, wheels spinning: d x_final / d mu over 1 s."""
    roll, state = roll20
    a = torch.ones(20, 1, 2)
    mu = torch.tensor(0.3, requires_grad=True)
    roll(a, state, mu)[-1, 0, 0].backward()
    f = lambda m: roll(a, state, m)[-1, 0, 0]
    fd = ((f(torch.tensor(0.301)) - f(torch.tensor(0.299))) / 2e-3).item()
    assert mu.grad.item() == pytest.approx(fd, rel=0.02)
    assert fd > 1.0  # more grip, further: the gradient carries the physics


@pytest.mark.parametrize("left,right", [(0.2, 0.4), (-0.3, 0.3)], ids=["curve", "spin"])
def test_turning_gradient_over_one_second(roll20, left, right):
    """Steering (left against right) over 1 s while curving and while skidding in place.

    This is the derivative that Newton's in-place wrench conversion corrupted (see
    ``diff.restore_external_wrench``: without it the error is tens of percent here);
    ``benchmarks/physics/diff_gradients.py`` measures under 0.5 % over 2 s."""
    roll, state = roll20
    a = torch.empty(20, 1, 2)
    a[..., 0], a[..., 1] = left, right
    aa = a.clone().requires_grad_(True)
    objective = lambda poses: poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]  # position + yaw
    objective(roll(aa, state)).backward()
    gen = torch.Generator().manual_seed(0)
    directions = []
    for t in (0, 10, 19):  # one step's left-minus-right at a time, then random weights over time
        d = torch.zeros(20, 1, 2)
        d[t, 0] = torch.tensor([1.0, -1.0])
        directions.append(d)
    w = torch.rand(20, 1, 1, generator=gen)
    directions.append(torch.cat([w, -w], dim=-1))
    for d in directions:
        d = d / d.norm()
        fd = ((objective(roll(a + 3e-3 * d, state)) - objective(roll(a - 3e-3 * d, state))) / 6e-3).item()
        tape = (aa.grad * d).sum().item()
        assert tape == pytest.approx(fd, rel=0.02, abs=1e-4)


def test_chassis_mass_gradient_over_one_second(roll20):
    """d(final pose) / d(chassis mass) in a curve over 1 s; the mass is an input of the tape."""
    roll, state = roll20
    a = torch.empty(20, 1, 2)
    a[..., 0], a[..., 1] = 0.2, 0.4
    m0 = roll.nominal_chassis_mass
    objective = lambda poses: poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]
    mass = torch.tensor(m0, requires_grad=True)
    objective(roll(a, state, None, mass)).backward()
    fd = ((objective(roll(a, state, None, m0 + 0.1)) - objective(roll(a, state, None, m0 - 0.1))) / 0.2).item()
    assert fd < 0  # heavier: slower, less far
    assert mass.grad.item() == pytest.approx(fd, rel=0.02)
    # the rollout's nominal mass is restored on the next call without an explicit mass
    assert roll(a, state)[-1, 0, 0].item() == pytest.approx(roll(a, state, None, m0)[-1, 0, 0].item(), abs=0)


def test_initial_heading_gradient_while_turning():
    """d(final pose) / d(initial heading), through the free joint's quaternion, over 0.5 s of spinning."""
    roll = DiffRollout(1, steps=10)
    q0, qd0 = roll.initial_state()
    a = torch.tensor([[-0.3, 0.3]]).expand(10, 1, 2).contiguous()
    objective = lambda poses: poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]
    qq = q0.clone().requires_grad_(True)
    objective(roll(a, (qq, qd0))).backward()

    def turned(angle):  # the initial state rotated by `angle` about the vertical
        q = q0.clone()
        x, y, z, w = q[3:7]
        c, s = math.cos(angle / 2), math.sin(angle / 2)
        q[3:7] = torch.stack([c * x - s * y, c * y + s * x, c * z + s * w, c * w - s * z])
        return q

    tangent = (turned(1e-4) - turned(-1e-4)) / 2e-4
    tape = (qq.grad * tangent).sum().item()
    fd = ((objective(roll(a, (turned(3e-3), qd0))) - objective(roll(a, (turned(-3e-3), qd0)))) / 6e-3).item()
    assert abs(fd) > 0.1  # heading moves where the spinning rover ends up
    assert tape == pytest.approx(fd, rel=0.02)


@pytest.mark.slow  # an optimisation run of 40 iterations
def test_trajectory_optimisation_example_reaches_target_pose():
    """3 s open loop to (1.5, 1.5) m arriving at 90 deg, in the example's 40 iterations."""
    example = load_example("trajectory_optimisation")
    miss, yaw_miss, actions, history = example.optimise(verbose=False)
    assert miss < 0.05  # metres
    assert yaw_miss < 5.0  # degrees
    assert history[-1] < history[0] / 100
    assert actions.shape == (60, 1, 2)
    assert actions.abs().max() <= 1.0


@pytest.mark.slow  # an identification run
def test_friction_identification_example():
    example = load_example("friction_identification")
    mu, history = example.identify(true_mu=0.3, guess=0.5, verbose=False)
    assert mu == pytest.approx(0.3, abs=0.01)
    assert history[-1][1] < history[0][1] * 1e-3


def test_friction_rise_gradient_while_spinning(roll20):
    """d(final yaw) / d(friction_rise) skidding in place over 1 s: the sliding friction's rise with slip
    (ContactConfig.friction_rise) is an input of the tape. Under torque commands the sliding wheels' friction both
    drives the turn and resists it, so only the tape's agreement with the finite difference is asserted."""
    roll, state = roll20
    a = torch.empty(20, 1, 2)
    a[..., 0], a[..., 1] = -0.6, 0.6
    rise = torch.tensor(0.5, requires_grad=True)
    roll(a, state, friction_rise=rise)[-1, 0, 5].backward()
    f = lambda r: roll(a, state, friction_rise=r)[-1, 0, 5].item()
    fd = (f(0.52) - f(0.48)) / 0.04
    assert abs(fd) > 0.05  # the rise changes the turn
    assert rise.grad.item() == pytest.approx(fd, rel=0.05)
    # zero is the contact config's default and a valid value; a negative one is refused by name
    assert roll(a, state, friction_rise=0.0)[-1, 0, 5].item() == roll(a, state)[-1, 0, 5].item()
    with pytest.raises(ValueError, match=r"friction_rise must be >= 0 and finite"):
        roll(a, state, friction_rise=-0.1)


def test_errors_are_clear():
    roll = DiffRollout(1, steps=2)
    with pytest.raises(ValueError, match=r"actions must have shape \(2, 1, 2\)"):
        roll(torch.zeros(3, 1, 2))
    with pytest.raises(ValueError, match="NaN/inf"):
        roll(torch.full((2, 1, 2), float("nan")))
    with pytest.raises(ValueError, match=r"chassis_mass must be > 0 and finite, got \[-1.0\]"):
        roll(torch.zeros(2, 1, 2), chassis_mass=-1.0)
    a = torch.zeros(2, 1, 2, requires_grad=True)
    poses = roll(a)
    with pytest.raises(NonFiniteGradientError, match="not finite"):
        poses[-1, 0, 0].backward(torch.tensor(float("inf")))
    # One tape per DiffRollout: a stale rollout's backward fails loudly instead of using the newer tape.
    first = roll(a)
    second = roll(a + 0.5)
    with pytest.raises(RuntimeError, match="tape is gone"):
        first[-1, 0, 0].backward()
    a.grad = None
    second[-1, 0, 0].backward()
    assert a.grad.abs().sum() > 0


def test_progress_reward_matches_the_environment():
    """task.reward.progress_reward, applied to the poses the env visited, gives the env's non-terminal rewards."""
    from tensordict import TensorDict

    from atrv_warp import ATRVjrEnv

    env = ATRVjrEnv(num_envs=4, seed=3)
    env.reset()
    targets = env.target.clone()
    poses, rewards = [env.sim.root_pose.clone()], []
    gen = torch.Generator().manual_seed(0)
    for _ in range(12):
        action = torch.rand(4, 2, generator=gen) * 1.2 - 0.2
        out = env.step(TensorDict(action=action, batch_size=[4]))["next"]
        assert not out["done"].any()  # every step non-terminal, so the rewards are the dense ones
        poses.append(env.sim.root_pose.clone())
        rewards.append(out["reward"].squeeze(-1))
    dense = progress_reward(torch.stack(poses), targets)
    assert dense.shape == (12, 4)
    assert torch.allclose(dense, torch.stack(rewards), atol=2e-5)


def test_action_scale_is_an_argument_that_defaults_to_the_reference_task():
    """The simulator knows no task: the task's action scale is passed in, and the default is the task's."""
    assert DEFAULT_ACTION_SCALE == TaskConfig().action_scale
    half = DiffRollout(1, steps=4, action_scale=0.5 * DEFAULT_ACTION_SCALE)
    full = DiffRollout(1, steps=4)
    actions = torch.full((4, 1, 2), 0.4)
    # the same torques: half the scale, twice the action (both within [-1, 1])
    assert torch.allclose(half(2 * actions), full(actions), atol=1e-6)
    assert not torch.allclose(half(actions), full(actions), atol=1e-4)


def test_actions_are_clipped_as_the_env_clips_them():
    """One rule per input: an action of 1.6 drives as 1.0 does, in the env and in a rollout, and its gradient is
    zero (the clamp's), while an in-range action's is not."""
    roll = DiffRollout(1, steps=4)
    inside = torch.full((4, 1, 2), 0.9, requires_grad=True)
    outside = torch.full((4, 1, 2), 1.6, requires_grad=True)
    assert torch.equal(roll(outside), roll(torch.ones(4, 1, 2)))
    for actions in (inside, outside):
        roll(actions)[-1, 0, 0].backward()
    assert inside.grad.abs().sum() > 0 and torch.equal(outside.grad, torch.zeros_like(outside.grad))
    from tensordict import TensorDict

    from atrv_warp import ATRVjrEnv

    env = ATRVjrEnv(1, seed=0)
    env.reset()
    env.step(TensorDict(action=torch.full((1, 2), 1.6), batch_size=[1]))
    assert torch.equal(env.sim.commands, torch.full((1, 2), DEFAULT_ACTION_SCALE))


def test_progress_reward_gradient_reaches_the_actions(roll20):
    """Summed dense reward over 1 s is differentiable with respect to the torques."""
    roll, state = roll20
    a = torch.full((20, 1, 2), 0.2, requires_grad=True)
    targets = torch.tensor([[3.0, 2.0]])
    progress_reward(roll(a, state), targets).sum().backward()
    # right against left turns the rover left, towards a target on its left: more reward
    assert torch.isfinite(a.grad).all()
    assert a.grad[:, 0, 1].sum() > a.grad[:, 0, 0].sum()


@pytest.mark.parametrize("with_fix", [True, False], ids=["with_fix", "without_fix_canary"])
def test_featherstone_wrench_adjoint_one_substep(with_fix):
    """One Featherstone substep with contact wrenches: d(joint_qd out) / d(heading in).

    Newton 1.8's eval_rigid_tau converts external wrenches in place, so Warp's adjoint replay
    reads converted values and the orientation derivative comes out wrong; recording
    diff.restore_external_wrench after the step fixes it. The canary checks that the bug is
    still there without the fix: if it fails after a Newton upgrade, upstream fixed it and the
    workaround can go."""
    import newton
    import warp as wp

    from atrv_warp.sim.diff import restore_external_wrench

    roll = DiffRollout(1, steps=10)
    a = torch.tensor([[-0.3, 0.3]]).expand(10, 1, 2).contiguous()
    roll(a, roll.initial_state())  # spinning in place: wheel wrenches with large moment arms
    as_t = lambda arr: wp.to_torch(arr).detach().clone()
    q0, qd0 = as_t(roll.states[-1].joint_q), as_t(roll.states[-1].joint_qd)
    wrench, torque = as_t(roll.states[-2].body_f), as_t(roll.controls[-1].joint_f)
    model, solver = roll.sim.model, roll.sim.solver
    s_in, s_out = model.state(requires_grad=True), model.state(requires_grad=True)
    control = model.control(clone_variables=True)
    weights = torch.randn(qd0.shape, generator=torch.Generator().manual_seed(0))

    def step(q, tape=None):
        wp.to_torch(s_in.joint_q).detach().copy_(q)
        wp.to_torch(s_in.joint_qd).detach().copy_(qd0)
        wp.to_torch(s_in.body_f).detach().copy_(wrench)
        wp.to_torch(control.joint_f).detach().copy_(torque)
        newton.eval_fk(model, s_in.joint_q, s_in.joint_qd, s_in)
        if tape is None:
            solver.step(s_in, s_out, control, None, 0.01)
        else:
            with tape:
                solver.step(s_in, s_out, control, None, 0.01)
                if with_fix:
                    tape.record_func(backward=restore_external_wrench(s_out, s_in), arrays=[])
        return (as_t(s_out.joint_qd).double() * weights).sum().item()

    def turned(angle):
        q = q0.clone()
        x, y, z, w = q[3:7].double()
        c, s = math.cos(angle / 2), math.sin(angle / 2)
        q[3:7] = torch.stack([c * x - s * y, c * y + s * x, c * z + s * w, c * w - s * z]).float()
        return q

    tape = wp.Tape()
    step(q0, tape)
    tape.backward(grads={s_out.joint_qd: wp.from_torch(weights.contiguous())})
    tangent = (turned(1e-4).double() - turned(-1e-4).double()) / 2e-4
    grad = (as_t(s_in.joint_q.grad).double() * tangent).sum().item()
    fd = (step(turned(1e-3)) - step(turned(-1e-3))) / 2e-3
    if with_fix:
        assert grad == pytest.approx(fd, rel=0.03, abs=1e-3)
    else:
        assert abs(grad - fd) > 0.25 * abs(fd) + 0.05


def assert_steering_gradient(roll: DiffRollout, linear: float, angular: float, rel: float) -> None:
    """Ten steps of (``linear``, ``angular``) actions on the Husky: the gradient of a pose objective along a
    left-right steering change at steps 0 and 5 agrees with central finite differences (steps of 1e-3: at 3e-3 the
    differences at step 5 straddle a wheel's stick-slip kink)."""
    state = roll.initial_state()
    a = torch.empty(10, 1, 2)
    a[..., 0], a[..., 1] = linear, angular
    aa = a.clone().requires_grad_(True)
    objective = lambda poses: poses[-1, 0, 0] + poses[-1, 0, 1] + 2.0 * poses[-1, 0, 5]
    objective(roll(aa, state)).backward()
    for t in (0, 5):
        d = torch.zeros(10, 1, 2)
        d[t, 0] = torch.tensor([1.0, -1.0]) / math.sqrt(2.0)
        fd = ((objective(roll(a + 1e-3 * d, state)) - objective(roll(a - 1e-3 * d, state))) / 2e-3).item()
        assert (aa.grad * d).sum().item() == pytest.approx(fd, rel=rel, abs=1e-4), t


@pytest.mark.parametrize("in_the_solve", [False, True])
def test_turning_gradient_through_a_geared_drivetrain(in_the_solve):
    """The Husky's sides are geared (``motor.per_side``): the chain's torque is in the tape (the drive's, or inside
    the friction solve: ``ContactConfig.solve_geared_sides``), and steering's gradient through it agrees with finite
    differences as the free-wheeled ATRV-Jr's does."""
    from atrv_warp.sim.config import ContactConfig, RoverConfig

    roll = DiffRollout(1, steps=10, rover=RoverConfig(robot="husky"),
                       contact=ContactConfig(solve_geared_sides=in_the_solve))
    assert roll.sim.rover_cfg.robot_spec.motor_per_side
    assert_steering_gradient(roll, 0.2, 0.4, rel=0.02)


def test_twist_gradient_through_an_implicit_speed_loop():
    """With the driver's loop implicit (``DriverConfig.implicit_speed_loop``: its damping in the friction solve,
    one array per substep on the tape), steering's gradient through ``/cmd_vel`` agrees with finite differences."""
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.sim.driver import DriverConfig

    roll = DiffRollout(1, steps=10, rover=RoverConfig(robot="husky"), twist=True,
                       driver=DriverConfig(implicit_speed_loop=True))
    assert_steering_gradient(roll, 0.3, 0.4, rel=0.03)
