"""The TorchRL environment: spec conformance, task math, resets, seeding, errors, TorchRL tooling."""

import math

import numpy as np
import pytest
import torch
import warp as wp
from tensordict import TensorDict
from torchrl.envs import InitTracker, ObservationNorm, RewardSum, StepCounter, TransformedEnv, VecNormV2
from torchrl.envs.utils import check_env_specs, step_mdp

from atrv_warp import ATRVjrEnv
from atrv_warp.task.baseline import scripted_policy
from atrv_warp.task.env import END_REASONS, OBSERVATION_NAMES

REASON = {name: i for i, name in enumerate(END_REASONS)}


def random_actions(n, steps, seed):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(steps, n, 2, generator=g) * 2 - 1


def run(env, actions):
    """Step with given actions, resetting done worlds as TorchRL collectors do."""
    td = env.reset()
    out = []
    for a in actions:
        td["action"] = a
        td, td_next = env.step_and_maybe_reset(td)
        out.append(td["next"].clone())
        td = td_next
    return torch.stack(out)


def test_specs_and_rollout(tiny_env):
    env = tiny_env
    check_env_specs(env)
    assert env.observation_spec["observation"].shape == (4, 10)
    assert env.action_spec.shape == (4, 2)
    assert env.action_spec.space.low.min() == -1 and env.action_spec.space.high.max() == 1
    assert env.reward_spec.shape == (4, 1)
    assert set(env.done_keys) == {"done", "terminated", "truncated"}
    high = env.observation_spec["observation"].space.high[0]
    assert high.tolist() == pytest.approx([12, 12, 30, 30, 6, 6, 0.25, 6, 1, 1])
    assert len(OBSERVATION_NAMES) == 10
    td = env.rollout(50, policy=scripted_policy())
    assert td["next", "observation"].dtype == torch.float32
    assert torch.isfinite(td["next", "observation"]).all()


def test_reset_samples_and_observation_order():
    env = ATRVjrEnv(256, seed=5)
    td = env.reset()
    obs = td["observation"]
    target, pos = obs[:, 0:2], obs[:, 2:4]
    assert target.abs().max() <= 12 and pos.abs().max() <= 12
    assert target.std(0).min() > 5  # uniform on [-12, 12]: std 6.9
    torch.testing.assert_close(pos, env.sim.root_pose[:, :2])
    torch.testing.assert_close(target, env.target)
    assert obs[:, 4:8].abs().max() == 0  # at rest, level
    yaw = env.sim.rpy[:, 2]
    assert yaw.min() < -2.8 and yaw.max() > 2.8
    # heading error: angle from rover heading to the target direction
    err = torch.atan2(target[:, 1] - pos[:, 1], target[:, 0] - pos[:, 0]) - yaw
    torch.testing.assert_close(obs[:, 8], torch.sin(err), atol=1e-5, rtol=0)
    torch.testing.assert_close(obs[:, 9], torch.cos(err), atol=1e-5, rtol=0)
    torch.testing.assert_close(td["distance"][:, 0], (target - pos).norm(dim=-1))


def place(env, world, x, y, yaw, target, height=None):
    mask = torch.zeros(env.num_envs, dtype=torch.bool)
    mask[world] = True
    env.sim.reset(mask=mask, poses=[[x, y, yaw]], height=height)
    env.target[world] = torch.tensor(target)


def test_reward_and_termination_on_built_states():
    env = ATRVjrEnv(4, seed=0, max_steps=200)
    env.reset()
    place(env, 0, 0.0, 0.0, 0.0, [0.3, 0.0])  # already within 1 m: success
    place(env, 1, 14.69, 0.0, 0.0, [0.0, 5.0])  # front wheels touching the +x wall
    place(env, 2, 0.0, 0.0, 0.0, [8.0, 0.0], height=0.6)  # rolled by hand below, in the air
    place(env, 3, -5.0, 0.0, 0.0, [5.0, 0.0])  # plain progress
    # roll world 2 by 0.3 rad
    q = wp.to_torch(env.sim.state_0.joint_q).view(4, -1)
    q[2, 3:7] = torch.tensor([math.sin(0.15), 0.0, 0.0, math.cos(0.15)])
    env.sim.set_state(env.sim.get_state())
    # prime the progress terms from the hand-built states, as a reset would (world 3 faces its target)
    env.observe(env.target.clone())
    action = torch.tensor([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [0.5, 0.5]])
    nxt = env.step(TensorDict(action=action, batch_size=[4]))["next"]
    reason = nxt["end_reason"][:, 0].tolist()
    assert reason[:3] == [REASON["success"], REASON["wall"], REASON["flip"]]
    assert nxt["reward"][:3, 0].tolist() == [4.0, -4.0, -4.0]
    assert nxt["terminated"][:3].all() and not nxt["truncated"].any()
    assert reason[3] == REASON["running"] and not nxt["done"][3]
    # progress reward: (previous distance - distance) + 4 (previous |err| - |err|) - 0.03
    obs = nxt["observation"][3]
    d = (obs[0:2] - obs[2:4]).norm()
    err = torch.atan2(obs[8], obs[9]).abs()
    expected = (10.0 - d) + 4.0 * (0.0 - err) - 0.03
    assert nxt["reward"][3, 0].item() == pytest.approx(expected.item(), abs=1e-5)
    assert d.item() < 10.0  # it moved towards the target


def test_timeout_truncates():
    env = ATRVjrEnv(2, seed=1, max_steps=3)
    td = env.reset()
    for i in range(3):
        td["action"] = torch.zeros(2, 2)
        td = env.step(td)
        nxt = td["next"]
        td = step_mdp(td)
    assert nxt["truncated"].all() and not nxt["terminated"].any() and nxt["done"].all()
    assert (nxt["end_reason"] == REASON["timeout"]).all()


def test_partial_reset_leaves_other_worlds_bit_identical():
    env = ATRVjrEnv(4, seed=2)
    td = env.reset()
    for a in random_actions(4, 10, 0):
        td["action"] = a
        td = step_mdp(env.step(td))
    before_q = wp.to_torch(env.sim.state_0.joint_q).clone().view(4, -1)
    before_qd = wp.to_torch(env.sim.state_0.joint_qd).clone().view(4, -1)
    before_obs = td["observation"].clone()
    mask = torch.tensor([[False], [True], [False], [True]])
    td.set("_reset", mask)
    out = env.reset(td)
    q = wp.to_torch(env.sim.state_0.joint_q).view(4, -1)
    qd = wp.to_torch(env.sim.state_0.joint_qd).view(4, -1)
    keep = torch.tensor([0, 2])
    assert torch.equal(q[keep], before_q[keep]) and torch.equal(qd[keep], before_qd[keep])
    assert torch.equal(out["observation"][keep], before_obs[keep])
    assert not torch.equal(q[1], before_q[1]) and qd[[1, 3]].abs().max() == 0
    assert env.step_count[[1, 3]].tolist() == [0, 0] and env.step_count[keep].tolist() == [10, 10]


def test_seed_determinism():
    actions = random_actions(8, 60, 1)
    a = run(ATRVjrEnv(8, seed=42), actions)
    b = run(ATRVjrEnv(8, seed=42), actions)
    c = run(ATRVjrEnv(8, seed=43), actions)
    assert torch.equal(a["observation"], b["observation"]) and torch.equal(a["reward"], b["reward"])
    assert not torch.equal(a["observation"], c["observation"])


def _go_on(env, td, actions) -> torch.Tensor:
    """Step on from ``td`` with ``actions`` (resetting ended worlds); every step's observation, reward and end."""
    seq = []
    for act in actions:
        td, td_next = env.step_and_maybe_reset(td.set("action", act))
        nxt = td["next"]
        seq.append(torch.cat([nxt["observation"], nxt["reward"], nxt["end_reason"].float()], -1).clone())
        td = td_next
    return torch.stack(seq)


@pytest.mark.parametrize("task", ["reach", "nav"])
def test_restore_then_continue_equals_continuing(task):
    """A snapshot is everything the next step reads: restoring it and stepping on gives, bit for bit, what the
    original gave when it stepped on (under 'wide': per-world physics, delay, motor lag, sensor noise)."""
    actions = random_actions(8, 40, 3)
    env = ATRVjrEnv(8, seed=7, task=task, randomization="wide")
    td = env.reset()
    for act in actions[:20]:
        td = env.step_and_maybe_reset(td.set("action", act))[1]
    saved, saved_td = env.state_dict(), td.clone()
    original = _go_on(env, td, actions[20:])  # the original goes on
    env.load_state_dict(saved)
    assert torch.equal(_go_on(env, saved_td.clone(), actions[20:]), original)
    fresh = ATRVjrEnv(8, seed=0, task=task, randomization="wide")  # into another env of the same kind
    fresh.load_state_dict(saved)
    assert torch.equal(_go_on(fresh, saved_td.clone(), actions[20:]), original)
    assert not torch.equal(original[0], original[-1])  # the worlds moved


def test_a_snapshot_that_does_not_fit_is_refused_and_the_env_is_unchanged():
    env = ATRVjrEnv(4, seed=1)
    env.reset()
    before = env.state_dict()
    cases = [
        (ATRVjrEnv(2, seed=1).state_dict(), "the snapshot is of 2 worlds, this env has 4"),
        (ATRVjrEnv(4, seed=1, max_steps=100).state_dict(), r"task differs .*max_steps=100 \(here 200\)"),
        (ATRVjrEnv(4, seed=1, randomization="mild").state_dict(), "randomization differs"),
        ({k: v for k, v in before.items() if k != "sim.impulses"}, r"simulator snapshot lacks \['impulses'\]"),
        ({k: v for k, v in before.items() if k != "snapshot.format"}, "not a snapshot this version restores"),
    ]
    for snapshot, message in cases:
        with pytest.raises(ValueError, match=message):
            env.load_state_dict(snapshot)
    after = env.state_dict()
    assert all(torch.equal(torch.as_tensor(before[k]), torch.as_tensor(after[k])) for k in before
               if not k.startswith("snapshot."))


def test_a_snapshot_from_before_the_accelerometer_filter_restores_its_state_as_zero():
    """The driver's accelerometer-filter entries (``SNAPSHOT_ADDED``) came after snapshots were first written: a
    snapshot without them still restores, the entries zero, as they were wherever the filter is off."""
    from atrv_warp.sim.driver import SNAPSHOT_ADDED

    env = ATRVjrEnv(2, seed=1)
    env.reset()
    older = {k: v for k, v in env.state_dict().items() if k.removeprefix("sim.") not in SNAPSHOT_ADDED}
    assert len(older) == len(env.state_dict()) - len(SNAPSHOT_ADDED)
    env.sim.driver.state.velocity.fill_(wp.vec3(1.0, 2.0, 3.0))
    env.load_state_dict(older)
    assert not wp.to_torch(env.sim.driver.state.velocity).any()


def test_bad_actions_raise_clear_errors():
    env = ATRVjrEnv(3, seed=0)
    td = env.reset()
    with pytest.raises(ValueError, match=r"action must have shape \(3, 2\).*got \(3,\)"):
        env.step(td.set("action", torch.zeros(3)))
    with pytest.raises(TypeError, match="floating-point"):
        env.step(td.set("action", torch.zeros(3, 2, dtype=torch.int64)))
    bad = torch.zeros(3, 2)
    bad[2, 1] = float("nan")
    pose = env.sim.root_pose.clone()
    with pytest.raises(ValueError, match=r"NaN/inf in world\(s\) \[2\]"):
        env.step(td.set("action", bad))
    assert torch.equal(env.sim.root_pose, pose)  # nothing was stepped
    # out-of-range values are clipped to [-1, 1]
    big = run(ATRVjrEnv(1, seed=4), torch.full((5, 1, 2), 7.0))
    one = run(ATRVjrEnv(1, seed=4), torch.full((5, 1, 2), 1.0))
    assert torch.equal(big["observation"], one["observation"])


def test_nonfinite_world_is_contained():
    env = ATRVjrEnv(3, seed=3)
    ref = ATRVjrEnv(3, seed=3)
    td, tdr = env.reset(), ref.reset()
    qd = wp.to_torch(env.sim.state_0.joint_qd).view(3, -1)
    qd[1, 0] = float("nan")  # world 1 blows up
    act = torch.full((3, 2), 0.5)
    td["action"], tdr["action"] = act, act.clone()
    td, td_next = env.step_and_maybe_reset(td)
    tdr, _ = ref.step_and_maybe_reset(tdr)
    nxt = td["next"]
    assert torch.isfinite(nxt["observation"]).all() and torch.isfinite(nxt["reward"]).all()
    assert nxt["end_reason"][1, 0].item() == REASON["nonfinite"] and nxt["terminated"][1]
    assert nxt["reward"][1, 0].item() == 0.0
    keep = torch.tensor([0, 2])
    assert torch.equal(nxt["observation"][keep], tdr["next", "observation"][keep])
    assert env.nonfinite_count == 1
    # the collector-style reset brought world 1 back
    assert torch.isfinite(wp.to_torch(env.sim.state_0.joint_qd)).all()
    assert torch.isfinite(td_next["observation"]).all() and env.sim.nonfinite.sum() == 0


def test_transforms(tiny_env):
    env = TransformedEnv(tiny_env)
    env.append_transform(StepCounter())
    env.append_transform(RewardSum())
    env.append_transform(InitTracker())
    env.append_transform(ObservationNorm(in_keys=["observation"], standard_normal=True))
    env.transform[-1].init_stats(num_iter=20, reduce_dim=(0, 1), cat_dim=0)
    env.append_transform(VecNormV2(in_keys=["reward"], decay=0.99))
    check_env_specs(env)
    td = env.rollout(30, break_when_any_done=False)
    assert td["next", "step_count"].max() == 30
    assert "episode_reward" in td["next"] and "is_init" in td
    assert torch.isfinite(td["next", "observation"]).all()


def test_scripted_baseline_reaches_targets():
    from atrv_warp.task.evaluation import evaluate

    r = evaluate(scripted_policy(), num_episodes=64, seed=11)
    assert r.success_rate > 0.85
    assert r.success_rate + r.wall_rate + r.flip_rate + r.timeout_rate == pytest.approx(1.0)


def test_gymnasium_adapter():
    import gymnasium
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("atrv_warp.integrations.gymnasium:ATRVjr-v0")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=1)
    assert obs.shape == (10,) and obs.dtype == np.float32 and info["end_reason"] == "running"
    venv = gymnasium.make_vec("ATRVjr-v0", num_envs=3)
    obs, _ = venv.reset(seed=1)
    ends = 0
    for _ in range(210):
        obs, _rew, term, trunc, _info = venv.step(venv.action_space.sample())
        ends += int((term | trunc).sum())
    assert obs.shape == (3, 10) and ends >= 3  # every world truncates by step 200


def test_collector_single_process():
    from torchrl.collectors import Collector

    env = ATRVjrEnv(8, seed=0, max_steps=4)  # short episodes: the collector must reset within a batch
    collector = Collector(env, scripted_policy(), frames_per_batch=80, total_frames=160)
    batches = [b for b in collector]
    collector.shutdown()
    assert [b.numel() for b in batches] == [80, 80]
    assert batches[0].batch_size == (8, 10)
    b = batches[0]
    assert b["next", "truncated"][:, 3].all()  # every world times out at its 4th step ...
    # ... and the collector starts a new episode there: new target, step counter back to zero
    assert not torch.equal(b["observation"][:, 4, :2], b["observation"][:, 3, :2])
    assert int(env.step_count.max()) <= 4
    assert torch.isfinite(batches[-1]["next", "observation"]).all()


@pytest.mark.slow  # two worker processes
def test_multisync_collector_two_workers():
    from torchrl.collectors import MultiSyncCollector

    from atrv_warp import EnvFactory

    collector = MultiSyncCollector([EnvFactory(8, seed=1, core=0), EnvFactory(8, seed=2, core=1)],
                                   scripted_policy(), frames_per_batch=320, total_frames=640)
    batches = [b for b in collector]
    collector.shutdown()
    assert len(batches) == 2 and all(b.numel() == 320 for b in batches)
    obs = batches[0]["observation"]
    assert obs.shape[-1] == 10 and torch.isfinite(obs).all()
    # the two workers were seeded differently: their first targets differ
    assert not torch.equal(obs[0, :, 0, :2], obs[1, :, 0, :2])


def test_observe_matches_reset_observation():
    """observe() (used by the ROS goal mode) runs the very kernel a reset does."""
    env = ATRVjrEnv(3, seed=8)
    td = env.reset()
    again = env.observe(env.target.clone())
    assert torch.equal(again, td["observation"])
    moved = env.observe(torch.tensor([[5.0, 5.0]] * 3))
    assert moved[:, :2].tolist() == [[5.0, 5.0]] * 3 and torch.equal(moved[:, 2:8], td["observation"][:, 2:8])


def test_the_spec_bounds_clip_the_observation():
    """Measured from a step: a target far outside the arena and a rover thrown through the air (2 m up, touching
    nothing during the step) at 20 m/s, or spinning at 8 rad/s, observe exactly the spec's bounds, in both signs; the
    spec the env declares has the same bounds."""
    from atrv_warp.task.spec import OBS_INDEX, observation_bounds

    env = ATRVjrEnv(4, seed=5)
    env.reset()
    sim, d = env.sim, env.sim.layout.chassis_dof
    q, qd = wp.to_torch(sim.buffers.joint_q).clone(), wp.to_torch(sim.buffers.joint_qd).clone()
    thrown = {0: [20.0, 20.0, 0, 0, 0, 0], 1: [-20.0, -20.0, 0, 0, 0, 0], 2: [0, 0, 0, 0, 0, 8.0], 3: [0, 0, 0, 0, 0, -8.0]}
    for world, velocity in thrown.items():  # vx, vy, vz [m/s]; roll, pitch, yaw rate [rad/s]
        k = world * sim.layout.dofs_per_world + d
        qd[k:k + 6] = torch.tensor(velocity)
        q[world * sim.layout.coords_per_world + sim.layout.chassis_coord + 2] += 2.0  # z [m]
    sim.set_joints(q, qd)
    env.target.copy_(torch.tensor([[50.0, 50.0], [-50.0, -50.0]] * 2))
    obs = env.step(TensorDict(action=torch.zeros(4, 2), batch_size=[4]))["next", "observation"]
    low, high = observation_bounds()
    for name, (up, down) in {"target_x": (0, 1), "target_y": (0, 1), "rover_vx": (0, 1), "rover_vy": (0, 1),
                             "yaw_rate": (2, 3)}.items():
        i = OBS_INDEX[name]
        assert obs[up, i] == high[i] and obs[down, i] == low[i], (name, obs[:, i])
    spec = env.observation_spec["observation"].space
    assert torch.equal(spec.low[0], low) and torch.equal(spec.high[0], high)


def test_reward_terms_sum_to_the_reward_and_follow_the_spec():
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.spec import END_REASONS, OBS_DIM, EndReason
    from atrv_warp.task.terms import REWARD_TERMS

    env = ATRVjrEnv(32, seed=5)
    assert env.observation_spec["observation"].shape[-1] == OBS_DIM
    # the codes a results file or a consumer stores
    assert END_REASONS == ("running", "success", "wall", "flip", "timeout", "nonfinite", "obstacle", "no_progress")
    assert [int(r) for r in EndReason] == list(range(len(END_REASONS)))
    td = env.rollout(200, scripted_policy(), break_when_any_done=False)
    nxt = td["next"]
    terms = torch.cat([nxt["reward_terms", name] for name in REWARD_TERMS], -1)
    assert torch.equal(terms.sum(-1, keepdim=True), nxt["reward"])  # summed in the kernel, in this order
    reason = nxt["end_reason"]
    success, failure = reason == EndReason.SUCCESS, (reason == EndReason.WALL) | (reason == EndReason.FLIP)
    assert success.any()
    assert (nxt["reward_terms", "success"][success] == 4.0).all()
    assert (nxt["reward_terms", "success"][~success] == 0.0).all()
    assert (nxt["reward_terms", "failure"][failure] == -4.0).all()
    running = ~(success | failure)
    assert (nxt["reward_terms", "step_penalty"][running] == -0.03).all()
    assert (nxt["reward_terms", "progress"][~running] == 0.0).all()


def test_reset_to_episodes_replays_the_evaluation_sets_episodes_in_fewer_worlds():
    """World 0 of a one-world env, reset to episode k of seed 2024, draws what world k of evaluate's env draws: the
    start, the target and the obstacles (the ROS node's ``reset_episode``)."""
    big = ATRVjrEnv(6, task="nav_deploy")
    big.set_seed(2024)
    big.reset()
    one = ATRVjrEnv(1, task="nav_deploy", seed=3)
    one.reset()
    for k in (5, 2):
        one.reset_to_episodes([0], [k], seed=2024)
        assert torch.equal(one.target[0], big.target[k])
        assert torch.equal(one.sim.root_pose[0], big.sim.root_pose[k])
        assert torch.equal(one.sim.obstacles.pose[0], big.sim.obstacles.pose[k])
        assert torch.equal(one.episode_start[0], big.episode_start[k])
    with pytest.raises(ValueError, match="world indices in"):
        one.reset_to_episodes([1], [0], seed=2024)


def test_the_odometry_frame_is_the_drawn_start_where_the_goal_is_seen():
    """The robot observation sees the goal from the odometry frame at ``episode_start`` (the start as drawn): the
    chassis rests at its x, y, and ``goal_odom`` is the target in that frame. On terrain the settled chassis's yaw
    differs from the drawn one (a fraction of a degree), so a bridge (the ROS node's odometry) must take this frame,
    not the chassis's pose, to show the policy the goal as the environment does."""
    env = ATRVjrEnv(8, task="nav_deploy", seed=2024)
    env.reset()
    x, y, yaw = env.episode_start.double().unbind(-1)
    assert torch.equal(env.episode_start[:, :2], env.sim.root_pose[:, :2])
    d = env.target.double() - torch.stack([x, y], -1)
    local = torch.stack([yaw.cos() * d[:, 0] + yaw.sin() * d[:, 1], -yaw.sin() * d[:, 0] + yaw.cos() * d[:, 1]], -1)
    assert torch.allclose(env.goal_odom.double(), local, atol=1e-5)
    assert (env.sim.rpy[:, 2].double() - yaw).abs().max() > 1e-5  # why the chassis's yaw would not do
