"""The deployable task's env side: twist actions through the motor driver and the robot observation (wheel
odometry, the IMU, the goal in the odometry frame), its noise and drift, and its snapshots.

Run: ``python -m pytest -q tests/test_robot_task.py``.
"""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch
import warp as wp

from atrv_warp import ATRVjrEnv
from atrv_warp.sim.config import SENSOR_NOISE
from atrv_warp.sim.driver import DRIVE_TORQUE, DRIVE_TWIST
from atrv_warp.task.config import TaskConfig
from atrv_warp.task.randomization import Draw, RandomizationConfig
from atrv_warp.task.spec import ROBOT_OBSERVATION, observation_fields

ROBOT = {f.name: i for i, f in enumerate(ROBOT_OBSERVATION)}
BOUND = torch.tensor([f.bound for f in ROBOT_OBSERVATION])
FLAT = {"task": "reach", "action": "twist", "observation": "robot"}  # the flat arena: quick to build
FLAT_FIELDS = {"action": "twist", "observation": "robot"}  # the same as TaskConfig fields (reach's defaults)


def _drive(env, td, action, steps):
    for _ in range(steps):
        td = env.step(td.set("action", action))["next"]
    return td


def _robot_observation(env) -> torch.Tensor:
    """The robot observation's leading fields rebuilt from the robot's signals: the base's fused odometry
    (plus the noise's drift) and encoder twist, the chassis attitude and its body-frame angular velocity."""
    odom = env.sim.driver.fused + env.odom_drift
    d = env.goal_odom - odom[:, :2]
    bearing = torch.atan2(d[:, 1], d[:, 0]) - odom[:, 2]
    rpy, twist = env.sim.rpy, env.sim.driver.odom_twist
    q = env.sim.root_pose[:, 3:7]  # x, y, z, w
    rate = _rotate_inv(q, env.sim.ang_vel)[:, 2]
    cols = torch.stack([d.norm(dim=-1), torch.sin(bearing), torch.cos(bearing), twist[:, 0], twist[:, 1], rpy[:, 0],
                        rpy[:, 1], rate], -1)
    return torch.maximum(torch.minimum(cols, BOUND), -BOUND)


def _rotate_inv(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``v`` (world) in the frame of the unit quaternions ``q`` (x, y, z, w)."""
    u, w = -q[:, :3], q[:, 3:4]
    t = 2.0 * torch.cross(u, v, dim=-1)
    return v + w * t + torch.cross(u, t, dim=-1)


def test_twist_actions_drive_through_the_driver():
    env = ATRVjrEnv(2, seed=0, **FLAT)
    assert (env.sim.driver.mode == int(DRIVE_TWIST)).all()
    td = env.reset()
    start = env.sim.root_pose[:, :2].clone()
    yaw0 = env.sim.rpy[:, 2].clone()
    action = torch.tensor([[1.0, 0.0], [0.0, 2.0]])  # forward; turn left (clipped to 1)
    td = _drive(env, td, action, 30)
    c = env.task_cfg
    assert torch.equal(env.sim.driver.twist, torch.tensor([[c.max_linear, 0.0], [0.0, c.max_angular]]))
    assert (env.sim.driver.age < 0.06).all()  # commanded every step: no timeout
    heading = torch.stack([torch.cos(yaw0), torch.sin(yaw0)], -1)
    moved = ((env.sim.root_pose[:, :2] - start) * heading).sum(-1)
    assert moved[0] > 0.8  # 1.5 s at up to 1 m/s
    assert abs(moved[1]) < 0.1 and env.sim.driver.odometry[1, 2] > 0.5  # turned in place, counter-clockwise
    assert env.sim.driver.odometry[0, 0] > 0.8


def test_torque_tasks_stay_in_torque_mode():
    env = ATRVjrEnv(2, seed=0)
    assert (env.sim.driver.mode == int(DRIVE_TORQUE)).all()
    assert env.obs_dim == 10


def test_robot_observation_shape_and_fields_nav_deploy():
    env = ATRVjrEnv(3, seed=2, task="nav_deploy")
    names = [f.name for f in observation_fields(env.task_cfg)]
    assert names[:8] == [f.name for f in ROBOT_OBSERVATION] and names[8] == "scan_0"
    assert names[-6:] == [f"last_action_{k}_{s}" for k in (1, 2, 3) for s in ("linear", "angular")]
    td = env.reset()
    assert td["observation"].shape == (3, env.obs_dim) == (3, 8 + 16 + 6)
    td = _drive(env, td, torch.tensor([[0.5, 0.2]] * 3), 5)
    obs = td["observation"]
    assert torch.isfinite(obs).all() and env.observation_spec["observation"].is_in(obs)
    assert torch.allclose(obs[:, 8 + 16:8 + 16 + 2], torch.tensor([[0.5, 0.2]] * 3))  # the last twist action


def test_goal_at_reset_is_the_true_goal():
    """Odometry starts at the start pose: the observed goal is the true one."""
    env = ATRVjrEnv(4, seed=5, **FLAT)
    obs = env.reset()["observation"]
    assert torch.allclose(obs[:, ROBOT["goal_distance"]], env.target_distance.clamp(max=BOUND[0]), atol=1e-4)
    d = env.target - env.sim.root_pose[:, :2]
    bearing = torch.atan2(d[:, 1], d[:, 0]) - env.sim.rpy[:, 2]
    assert torch.allclose(obs[:, ROBOT["sin_goal_bearing"]], torch.sin(bearing), atol=1e-4)
    assert torch.allclose(obs[:, ROBOT["cos_goal_bearing"]], torch.cos(bearing), atol=1e-4)
    assert torch.allclose(env.goal_odom.norm(dim=-1), env.target_distance, atol=1e-4)


def test_robot_observation_is_rebuilt_from_the_robots_signals():
    env = ATRVjrEnv(3, seed=1, **FLAT)
    td = _drive(env, env.reset(), torch.tensor([[1.0, 0.3], [0.6, -0.5], [-0.4, 0.0]]), 25)
    assert torch.allclose(td["observation"][:, :8], _robot_observation(env), atol=1e-4)
    # the goal is seen from the base's odometry, not the true pose: after driving, the two differ (the wheels slip
    # while the rover accelerates toward 2 m/s, and the encoders count it as distance)
    true = env.target_distance
    assert torch.allclose(td["observation"][:, 0], true, atol=1.0)
    assert not torch.allclose(td["observation"][:, 0], true, atol=1e-5)


def test_the_imu_frame_is_the_chassis_frame():
    """cbimu_frame is aligned with the chassis (no rotation): the chassis rpy and body rates are the IMU's."""
    env = ATRVjrEnv(1, seed=0, **FLAT)
    env.reset()
    imu = env.sim.frame_pose("cbimu_frame")[0]
    q = env.sim.root_pose[0, 3:7].double()
    x, y, z, w = q.tolist()
    chassis = torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]], dtype=torch.float64)
    assert torch.allclose(imu[:3, :3], chassis, atol=1e-6)


def test_noise_is_seeded_and_the_odometry_drifts():
    noisy = RandomizationConfig(noise=SENSOR_NOISE)
    a, b = ATRVjrEnv(2, seed=4, randomization=noisy, **FLAT), ATRVjrEnv(2, seed=4, randomization=noisy, **FLAT)
    clean = ATRVjrEnv(2, seed=4, **FLAT)
    action = torch.tensor([[0.8, 0.2], [0.5, -0.3]])
    tds = [env.reset() for env in (a, b, clean)]
    for _ in range(15):
        tds = [env.step(td.set("action", action))["next"] for env, td in zip((a, b, clean), tds, strict=True)]
    assert torch.equal(tds[0]["observation"], tds[1]["observation"])
    assert not torch.equal(tds[0]["observation"], tds[2]["observation"])
    assert (a.odom_drift.abs().sum(-1) > 0).all() and (clean.odom_drift == 0).all()
    # the noisy goal is seen from the drifted odometry, the rest of the noise is per reading
    assert torch.allclose(tds[0]["observation"][:, :3], _robot_observation(a)[:, :3], atol=1e-4)
    assert not torch.allclose(tds[0]["observation"][:, :3], tds[2]["observation"][:, :3], atol=1e-6)
    td = a.reset(tds[0].set("_reset", torch.tensor([[True], [False]])))
    assert (a.odom_drift[0] == 0).all() and (a.odom_drift[1] != 0).any()  # each episode drifts anew
    assert torch.isfinite(td["observation"]).all()


def test_latency_delays_the_twist_and_motor_lag_goes_to_the_driver():
    cfg = RandomizationConfig(latency=(2, 2), motor_lag=Draw(0.08, 0.08))
    env = ATRVjrEnv(2, seed=0, randomization=cfg, **FLAT)
    td = env.reset()
    assert torch.allclose(env.sim.driver.lag, torch.full((2,), 0.08))
    actions = [torch.tensor([[0.1 * t, -0.1 * t]] * 2) for t in range(1, 6)]
    limits = torch.tensor([env.task_cfg.max_linear, env.task_cfg.max_angular])
    for t, action in enumerate(actions):
        td = env.step(td.set("action", action))["next"]
        expected = actions[t - 2] * limits if t >= 2 else torch.zeros(2, 2)  # a /cmd_vel two steps late
        assert torch.allclose(env.sim.driver.twist, expected)
    assert (env.sim.commands == 0).all()  # the torque path is unused


def test_nonfinite_world_observes_a_neutral_robot_observation():
    env = ATRVjrEnv(2, seed=3, **FLAT)
    td = env.reset()
    qd = wp.to_torch(env.sim.state_0.joint_qd).view(2, -1)
    qd[1, 0] = float("nan")
    nxt = env.step(td.set("action", torch.full((2, 2), 0.5)))["next"]
    obs = nxt["observation"][1]
    assert torch.isfinite(obs).all() and obs[ROBOT["cos_goal_bearing"]] == 1.0 and obs[ROBOT["goal_distance"]] > 0


def test_snapshot_restores_nav_deploy_bit_for_bit():
    g = torch.Generator().manual_seed(3)
    actions = torch.rand(24, 3, 2, generator=g) * 2 - 1
    env = ATRVjrEnv(3, seed=7, task="nav_deploy", randomization="wide_slip")
    td = env.reset()
    for act in actions[:12]:
        td = env.step_and_maybe_reset(td.set("action", act))[1]
    saved, saved_td = env.state_dict(), td.clone()
    assert {"task.goal_odom", "task.odom_drift", "task.odom_scale", "sim.driver.odometry"} <= set(saved)

    def go_on(e, t):
        out = []
        for act in actions[12:]:
            t, t_next = e.step_and_maybe_reset(t.set("action", act))
            out.append(torch.cat([t["next", "observation"], t["next", "reward"]], -1).clone())
            t = t_next
        return torch.stack(out)

    original = go_on(env, td)
    fresh = ATRVjrEnv(3, seed=0, task="nav_deploy", randomization="wide_slip")
    fresh.load_state_dict(saved)
    assert torch.equal(go_on(fresh, saved_td.clone()), original)
    assert not torch.equal(original[0], original[-1])


def drawn_on_reset(preset: str, view: str) -> torch.Tensor:
    """The per-world values of env view ``view`` that ``preset`` draws on a reset of 64 worlds (seed 5), checked to be
    the same for the same seed and different for another."""
    drawn = []
    for seed in (5, 5, 6):
        env = ATRVjrEnv(64, seed=seed, task="nav_deploy", randomization=preset)
        env.reset()
        drawn.append(getattr(env, view).clone())
    assert torch.equal(drawn[0], drawn[1]) and not torch.equal(drawn[0], drawn[2])
    return drawn[0]


def test_odometry_scale_moves_only_the_observed_odometry():
    """Encoders that over-read by 1.2: the goal is seen from 1.2 x the fused position (the gyro's heading kept) and
    the odometry's speed reads 1.2 x; the physics is the exact one; draws are seeded and within their range."""
    over = RandomizationConfig(odometry_scale=Draw(1.2, 1.2))
    envs = [ATRVjrEnv(4, seed=3, task="nav_deploy", randomization=r) for r in (None, over)]
    tds = [e.reset() for e in envs]
    act = torch.tensor([[0.5, 0.3]]).expand(4, 2)
    for _ in range(15):
        tds = [e.step(t.set("action", act))["next"] for e, t in zip(envs, tds, strict=True)]
    fused = [wp.to_torch(e.sim.driver.state.fused).view(4, 3) for e in envs]
    assert torch.equal(fused[0], fused[1]) and float(fused[0][:, :2].norm(dim=1).min()) > 0.2
    seen = torch.cat([1.2 * fused[1][:, :2], fused[1][:, 2:]], 1)
    dx = envs[1].goal_odom - seen[:, :2]
    obs = tds[1]["observation"]
    assert torch.allclose(obs[:, ROBOT["goal_distance"]], dx.norm(dim=1), atol=1e-5)
    bearing = torch.atan2(dx[:, 1], dx[:, 0]) - seen[:, 2]
    assert torch.allclose(obs[:, ROBOT["sin_goal_bearing"]], torch.sin(bearing), atol=1e-5)
    assert torch.allclose(obs[:, ROBOT["odom_linear"]], 1.2 * tds[0]["observation"][:, ROBOT["odom_linear"]], atol=1e-5)
    scales = drawn_on_reset("wide_slip", "odom_scale")
    assert 1.0 <= float(scales.min()) and float(scales.max()) <= 1.25 and float(scales.std()) > 0.05


def test_odometry_slip_gain_moves_the_observed_pose_by_the_encoders_slip():
    """Gain 1 on slippery ground: each step the goal's pose moves along the odometry's heading by the encoders'
    forward speed less the chassis's, times the step; the physics, the fused odometry and the odometry's twist are
    the exact ones; draws are seeded and within their range."""
    slippery = RandomizationConfig(friction=Draw(0.3, 0.3))
    gain = dataclasses.replace(slippery, odometry_slip_gain=Draw(1.0, 1.0))
    envs = [ATRVjrEnv(4, seed=3, task="nav_deploy", randomization=r) for r in (slippery, gain)]
    tds = [e.reset() for e in envs]
    act = torch.tensor([[1.0, 0.6]]).expand(4, 2)
    expected = torch.zeros(4, 2)
    dt = envs[1].sim.sim_cfg.step_dt
    for _ in range(15):
        tds = [e.step(t.set("action", act))["next"] for e, t in zip(envs, tds, strict=True)]
        sim = envs[1].sim
        _, pitch, yaw = sim.rpy.unbind(1)  # the chassis's forward axis in the world, ZYX Euler angles
        forward = torch.stack([torch.cos(yaw) * torch.cos(pitch), torch.sin(yaw) * torch.cos(pitch), -torch.sin(pitch)], 1)
        slip = wp.to_torch(sim.driver.state.odom_twist).view(4, 2)[:, 0] - (sim.lin_vel * forward).sum(1)
        heading = wp.to_torch(sim.driver.state.fused).view(4, 3)[:, 2]
        expected += (slip * dt).unsqueeze(1) * torch.stack([torch.cos(heading), torch.sin(heading)], 1)
    fused = [wp.to_torch(e.sim.driver.state.fused).view(4, 3) for e in envs]
    assert torch.equal(fused[0], fused[1]) and float(expected.norm(dim=1).max()) > 0.05
    assert torch.allclose(envs[1].odom_drift[:, :2], expected, atol=1e-4) and not envs[0].odom_drift.any()
    dx = envs[1].goal_odom - (fused[1][:, :2] + envs[1].odom_drift[:, :2])
    obs = tds[1]["observation"]
    assert torch.allclose(obs[:, ROBOT["goal_distance"]], dx.norm(dim=1), atol=1e-5)
    assert torch.equal(obs[:, ROBOT["odom_linear"]], tds[0]["observation"][:, ROBOT["odom_linear"]])
    gains = drawn_on_reset("wide_slip_gain", "odom_slip_gain")
    assert 0.0 <= float(gains.min()) and float(gains.max()) <= 1.5 and float(gains.std()) > 0.2


@pytest.mark.parametrize("bad", [{"action": "velocity"}, {"observation": "gps"}, {"max_linear": 0.0},
                                 {"max_angular": -1.0}, {"max_linear": math.nan}, {"linear_max_acceleration": 0.0},
                                 {"angular_max_acceleration": math.inf}])
def test_bad_action_or_observation_kinds_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        TaskConfig(**bad)
    with pytest.raises(ValueError, match=next(iter(bad))):
        ATRVjrEnv(1, task="reach", **bad)


def test_the_tasks_page_lists_every_robot_field_with_its_unit():
    from pathlib import Path

    page = (Path(__file__).resolve().parent.parent / "docs" / "tasks.md").read_text()
    rows = {line.split("|")[1].strip(): line for line in page.splitlines() if line.startswith("| `")}
    for f in ROBOT_OBSERVATION:
        row = next((line for name, line in rows.items() if f"`{f.name}`" in name), None)
        assert row is not None, f.name
        assert f"| {f.unit} |" in row and f"| {f.bound:g} |" in row, f.name


def test_the_twist_kernel_agrees_with_its_torch_twin():
    from atrv_warp.task.spec import action_to_twist

    env = ATRVjrEnv(4, seed=0, **FLAT)
    td = env.reset()
    action = torch.tensor([[0.3, -0.7], [1.5, -2.0], [-1.0, 0.25], [0.0, 0.9]])
    env.step(td.set("action", action))
    c = env.task_cfg
    assert torch.equal(env.sim.driver.twist, action_to_twist(action, c.max_linear, c.max_angular))


def test_an_exported_twist_policy_says_it_commands_a_twist():
    from pathlib import Path

    from atrv_warp.rl.export import contract

    spec = contract(Path("p.pt"), {"meta": {"task": "nav_deploy"}})  # a policy of format 1: the task as declared
    assert spec["action"]["kind"] == "twist" and spec["action"]["names"] == ["linear", "angular"]
    assert spec["action"]["scale"] == [2.0, 2.0] and spec["rate_hz"] == 20.0
    assert spec["robot"]["name"] == "atrvjr" and not spec["robot"]["recorded"]
    assert [f["name"] for f in spec["observation"][:8]] == [f.name for f in ROBOT_OBSERVATION]
    assert contract(Path("p.pt"), {"meta": {"task": "nav"}})["action"]["kind"] == "torque"


def test_the_tasks_base_limits_fill_the_drivers_unset_ones():
    from atrv_warp.sim.driver import DriverConfig

    task = TaskConfig(action="twist", linear_max_acceleration=1.0)
    assert task.driver().linear_max_acceleration == 1.0 and task.driver().angular_max_acceleration is None
    own = DriverConfig(linear_max_acceleration=3.0, angular_max_acceleration=2.0)
    assert task.driver(own) == own  # a driver's own limits stand
    assert TaskConfig().driver() == DriverConfig()
    env = ATRVjrEnv(1, seed=0, task=dataclasses.replace(task, **FLAT_FIELDS))
    assert env.sim.driver_cfg.linear_max_acceleration == 1.0
    from pathlib import Path

    from atrv_warp.rl.export import contract

    limits = contract(Path("p.pt"), {"meta": {"task": "nav_deploy"}})["action"]["base_limits"]
    assert limits == {"linear_max_acceleration": {"value": 1.0, "unit": "m/s²"}}


def test_an_acceleration_limit_keeps_the_wheels_from_spinning_out_at_a_launch():
    """A full-speed /cmd_vel from rest at the nominal µ 0.3: without a limit the driver answers with its full torque,
    the wheels spin, and the encoders' distance runs ahead of the rover's (the deployable task's goal is seen
    through them); with the nav_deploy base's 1 m/s² it stays within a few per cent."""
    runs = {}
    for limit in (None, 1.0):
        env = ATRVjrEnv(1, seed=0, task=TaskConfig(**FLAT_FIELDS, linear_max_acceleration=limit))
        td = env.reset()
        start = env.sim.root_pose[0, :2].clone()
        _drive(env, td, torch.tensor([[1.0, 0.0]]), 40)  # 2 s at 2 m/s
        true = (env.sim.root_pose[0, :2] - start).norm().item()
        runs[limit] = env.sim.driver.fused[0, 0].item() / true
    assert runs[None] > 1.15, runs  # measured 1.24
    assert abs(runs[1.0] - 1.0) < 0.03, runs  # measured 0.995
