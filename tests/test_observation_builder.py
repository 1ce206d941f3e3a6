"""The robot observation built from a robot's messages (:class:`atrv_warp.core.observation.RobotObservation`):
its maths against hand-computed cases, its construction from an exported policy's contract, its refusals; and a
saved policy that knows what it commands and observes (``load_policy``, ``evaluate``, ``train``'s warm start)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import torch

from atrv_warp.core.geometry import yaw_to_quat
from atrv_warp.core.observation import RobotObservation, Scan
from atrv_warp.task.registry import get_task
from atrv_warp.task.spec import observation_bounds, observation_fields, policy_contract

ROOT = Path(__file__).resolve().parent.parent
TASK = get_task("nav_deploy")
NAMES = [f.name for f in observation_fields(TASK)]


@pytest.fixture(scope="module")
def build() -> RobotObservation:
    return RobotObservation.from_contract(policy_contract(TASK))


def at_rest(**overrides) -> dict:
    """One robot's messages: at the origin of the odometry frame facing +x, level, still, nothing in sight."""
    scan = Scan(torch.full((64,), math.inf), -math.pi / 2, math.pi / 63, 0.1, 30.0)
    return {"odom_pose": [0.0, 0.0, 0.0], "odom_twist": [0.0, 0.0], "imu_orientation": [0.0, 0.0, 0.0, 1.0],
            "imu_angular_velocity": [0.0, 0.0, 0.0], "goal": [5.0, 0.0], "scan": scan,
            "last_actions": torch.zeros(3, 2), **overrides}


def field(obs: torch.Tensor, name: str) -> torch.Tensor:
    return obs[..., NAMES.index(name)]


def test_fields_order_and_bounds_are_the_contracts(build):
    low, high = observation_bounds(torch.float64, task=TASK)
    assert list(build.names) == NAMES and len(NAMES) == 30
    assert torch.equal(build.low, low) and torch.equal(build.high, high)
    assert build.action_history == 3 and build.action_columns == ("linear", "angular")
    obs = build(**at_rest())
    assert obs.shape == (30,) and obs.dtype == torch.float32


def test_goal_distance_and_bearing_wrap_across_pi(build):
    """Goal 2 m behind a rover at (1, 1) heading 3 rad: the bearing pi - 3 = +0.1416; heading -3 rad: -(pi - 3)
    (wrapped from pi + 3); both in one batch."""
    obs = build(**at_rest(odom_pose=[[1.0, 1.0, 3.0], [1.0, 1.0, -3.0]], odom_twist=torch.zeros(2, 2),
                          imu_orientation=torch.tensor([[0.0, 0, 0, 1]] * 2), imu_angular_velocity=torch.zeros(2, 3),
                          goal=[[-1.0, 1.0], [-1.0, 1.0]],
                          scan=Scan(torch.full((2, 64), math.inf), -math.pi / 2, math.pi / 63, 0.1, 30.0),
                          last_actions=torch.zeros(2, 3, 2)))
    assert obs.shape == (2, 30)
    bearing = torch.tensor([math.pi - 3.0, 3.0 - math.pi])
    assert torch.allclose(field(obs, "goal_distance"), torch.tensor([2.0, 2.0]))
    assert torch.allclose(field(obs, "sin_goal_bearing"), bearing.sin(), atol=1e-6)
    assert torch.allclose(field(obs, "cos_goal_bearing"), bearing.cos(), atol=1e-6)
    # the same pose as nav_msgs/Odometry carries it: position and quaternion
    pose7 = torch.cat([torch.tensor([[1.0, 1.0, 0.2]] * 2), yaw_to_quat(torch.tensor([3.0, -3.0]))], -1)
    again = build(**at_rest(odom_pose=pose7, odom_twist=torch.zeros(2, 6), imu_orientation=torch.tensor([[0.0, 0, 0, 1]] * 2),
                            imu_angular_velocity=torch.zeros(2, 3), goal=[[-1.0, 1.0], [-1.0, 1.0]],
                            scan=Scan(torch.full((2, 64), math.inf), -math.pi / 2, math.pi / 63, 0.1, 30.0),
                            last_actions=torch.zeros(2, 6)))
    assert torch.allclose(again, obs, atol=1e-6)


def test_imu_roll_pitch_yaw_rate_and_odometry_twist(build):
    """Roll 0.3 rad then pitch 0.2 rad (intrinsic Z-Y-X) from an unnormalised quaternion; the IMU's z rate; the
    odometry's linear.x and angular.z."""
    r, p = 0.3, 0.2
    qx = torch.tensor([math.sin(r / 2), 0.0, 0.0, math.cos(r / 2)])
    qy = torch.tensor([0.0, math.sin(p / 2), 0.0, math.cos(p / 2)])
    x1, y1, z1, w1 = qy  # q = qy * qx: pitch about y after roll about x (Z-Y-X: yaw, then pitch, then roll)
    x2, y2, z2, w2 = qx
    q = torch.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])
    obs = build(**at_rest(imu_orientation=2.0 * q, imu_angular_velocity=[0.5, -0.4, 0.7],
                          odom_twist=[0.8, -0.25]))
    assert abs(field(obs, "imu_roll").item() - r) < 1e-6 and abs(field(obs, "imu_pitch").item() - p) < 1e-6
    assert abs(field(obs, "imu_yaw_rate").item() - 0.7) < 1e-6
    assert abs(field(obs, "odom_linear").item() - 0.8) < 1e-6 and abs(field(obs, "odom_angular").item() + 0.25) < 1e-6
    whole = build(**at_rest(odom_twist=[0.8, 0.1, 0.0, 0.0, 0.0, -0.25]))  # nav_msgs' whole twist: x and angular z
    assert abs(field(whole, "odom_linear").item() - 0.8) < 1e-6 and abs(field(whole, "odom_angular").item() + 0.25) < 1e-6


def test_every_value_is_clipped_to_its_bound(build):
    obs = build(**at_rest(goal=[100.0, 0.0], odom_twist=[5.0, -10.0], imu_angular_velocity=[0.0, 0.0, 9.0],
                          imu_orientation=[math.sin(0.75), 0.0, 0.0, math.cos(0.75)],  # roll 1.5 rad
                          last_actions=torch.tensor([[2.0, -3.0], [0.5, 0.25], [0.0, -0.5]])))
    assert field(obs, "goal_distance").item() == 30.0
    assert (field(obs, "odom_linear").item(), field(obs, "odom_angular").item()) == (3.0, -6.0)
    assert (field(obs, "imu_yaw_rate").item(), field(obs, "imu_roll").item()) == (6.0, 1.0)
    # newest first, in the action's columns, clipped to [-1, 1]
    last = [field(obs, f"last_action_{k}_{c}").item() for k in (1, 2, 3) for c in ("linear", "angular")]
    assert last == [1.0, -1.0, 0.5, 0.25, 0.0, -0.5]


def test_a_scan_of_another_beam_count_and_field_of_view_reads_by_rep_117(build):
    """A 1,081-beam scanner over 270 deg reduces into the policy's 16 sectors (edges from the contract): a return at
    2 m in sector 8 reads 0.4; a -inf beam (too close) blocks sector 2; a sector whose beams are all NaN reads 0;
    beyond range_max (and +inf) reads clear; a beam outside the sectors' edges is not observed."""
    sectors = build.sectors
    edges = torch.tensor(sectors.edges)
    scan = Scan(torch.full((1081,), math.inf), -0.75 * math.pi, 1.5 * math.pi / 1080, 0.05, 30.0)
    angles = scan.angles()
    ranges = scan.ranges.clone()
    ranges[(angles - 0.05).abs().argmin()] = 2.0  # sector 8 spans [0, 0.1995)
    ranges[(angles + 1.0).abs().argmin()] = -math.inf  # sector 2 spans [-1.1968, -0.9973)
    ranges[(angles >= edges[12]) & (angles < edges[13])] = math.nan  # sector 12: no valid beam
    ranges[(angles >= edges[5]) & (angles < edges[6])] = 40.0  # beyond range_max: no return
    ranges[(angles - 2.0).abs().argmin()] = 0.5  # outside the last edge (1.5957 rad): not observed
    ranges[(angles - 0.5).abs().argmin()] = 0.01  # below range_min in sector 10 [0.3989, 0.5984): blocked
    obs = build(**at_rest(scan=Scan(ranges, scan.angle_min, scan.angle_increment, 0.05, 30.0)))
    expected = torch.ones(16)
    expected[[2, 10, 12]] = 0.0
    expected[8] = 2.0 / sectors.clip
    got = torch.stack([field(obs, f"scan_{k}") for k in range(16)])
    assert torch.allclose(got, expected), got


def test_built_from_an_exported_policy_and_run(tmp_path):
    """An untrained nav_deploy policy, exported with the exporter: the builder reads the .pt2's contract alone, and
    the program takes what it builds; the contract says twist, its limits and units, the robot observation."""
    from atrv_warp.policy import make_actor, save_policy
    from atrv_warp.rl.export import EXPORT_FORMAT, export_policy, load_exported

    src = tmp_path / "nav_deploy.pt"
    save_policy(make_actor(16, 1, obs_dim=len(NAMES)), src, width=16, depth=1, meta={"task": "nav_deploy"})
    module, spec = load_exported(export_policy(src, tmp_path / "nav_deploy.pt2"))
    assert spec["format"] == EXPORT_FORMAT == "atrv_warp.exported_policy/3"
    assert spec["observation_kind"] == "robot" and spec["action"]["kind"] == "twist"
    assert spec["action"]["scale"] == [TASK.max_linear, TASK.max_angular] and spec["action"]["units"] == ["m/s", "rad/s"]
    assert spec["action"]["limits"] == {"max_linear": {"value": TASK.max_linear, "unit": "m/s"},
                                        "max_angular": {"value": TASK.max_angular, "unit": "rad/s"}}
    assert spec["action_history"]["steps"] == 3 and spec["rate_hz"] == 20.0
    assert spec["scan"]["beams"] == 64 and spec["scan"]["sectors"]["count"] == 16
    built = RobotObservation.from_contract(spec)
    assert list(built.names) == NAMES == [f["name"] for f in spec["observation"]]
    assert [f["high"] for f in spec["observation"]] == built.high.tolist()
    obs = built(**at_rest(goal=[3.0, 4.0]))
    action = module(obs[None])
    assert action.shape == (1, 2) and bool(action.abs().le(1).all())


def test_a_shipped_torque_policy_exports_by_name_and_the_builder_refuses_it(tmp_path):
    from atrv_warp.rl.export import export_policy, load_exported

    _, spec = load_exported(export_policy("reach", tmp_path / "reach.pt2"))
    assert (spec["observation_kind"], spec["action"]["kind"], spec["action"]["units"]) == ("arena", "torque",
                                                                                           ["N·m", "N·m"])
    assert spec["action"]["limits"] == {"action_scale": {"value": 20.0, "unit": "N·m"}}
    with pytest.raises(ValueError, match="observes the 'arena' observation"):
        RobotObservation.from_contract(spec)


def test_the_example_drives_a_twist_policy_from_the_file(tmp_path):
    """examples/run_exported_policy.py on a twist policy made to turn left: it builds the robot observation from
    made-up messages with the builder and prints the /cmd_vel."""
    import subprocess
    import sys

    from atrv_warp.policy import make_actor, save_policy
    from atrv_warp.rl.export import export_policy

    actor = make_actor(16, 1, obs_dim=len(NAMES))
    last = actor.module[0].module[1][-1]  # the MLP's output layer: (loc linear, loc angular, scale ...)
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.tensor([0.0, 2.0, 0.0, 0.0]))
    src = tmp_path / "left.pt"
    save_policy(actor, src, width=16, depth=1, meta={"task": "nav_deploy"})
    out = export_policy(src, tmp_path / "left.pt2")
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "run_exported_policy.py"), str(out)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # tanh(2) = 0.964 of the task's yaw-rate limit
    yaw_rate = math.tanh(2.0) * get_task("nav_deploy").max_angular
    assert f"cmd_vel: linear.x +0.00 m/s, angular.z +{yaw_rate:.2f} rad/s" in proc.stdout, proc.stdout


@pytest.mark.parametrize(("change", "message"), [
    ({"odom_pose": [0.0, 0.0]}, r"odom_pose: expected shape \(\.\.\., 3\) or \(\.\.\., 7\), got \(2,\)"),
    ({"odom_pose": [0.0, math.nan, 0.0]}, "odom_pose: non-finite"),
    ({"odom_twist": [math.inf, 0.0]}, "odom_twist: non-finite"),
    ({"imu_orientation": [0.0, 0.0, math.nan, 1.0]}, "imu_orientation: non-finite"),
    ({"imu_orientation": [0.0, 0.0, 0.0, 0.0]}, "imu_orientation: a zero quaternion"),
    ({"imu_angular_velocity": [0.0, 0.0]}, "imu_angular_velocity: expected shape"),
    ({"goal": [[1.0, 2.0]]}, r"goal: expected shape \(2\)"),
    ({"scan": None}, "scan: the policy observes 16 scan sectors"),
    ({"scan": Scan(torch.ones(2, 64), -1.0, 0.03, 0.1, 30.0)}, r"scan.ranges: expected shape"),
    ({"scan": Scan(torch.ones(64), -1.0, -0.03, 0.1, 30.0)}, "scan.angle_increment"),
    ({"scan": Scan(torch.ones(64), -1.0, 0.03, 0.1, math.nan)}, "scan.range_max"),
    ({"last_actions": None}, "last_actions: the policy observes its last 3 actions"),
    ({"last_actions": torch.zeros(2, 2)}, r"last_actions: expected shape \(3, 2\)"),
    ({"last_actions": torch.full((3, 2), math.nan)}, "last_actions: non-finite"),
])
def test_bad_inputs_are_named(build, change, message):
    with pytest.raises(ValueError, match=message):
        build(**at_rest(**change))


def test_a_contract_a_robot_cannot_serve_is_refused():
    with pytest.raises(ValueError, match="observes the 'arena' observation"):
        RobotObservation.from_contract(policy_contract(get_task("nav")))
    with pytest.raises(ValueError, match="'target_x', which a robot does not publish"):
        RobotObservation([{"name": "target_x", "low": -1, "high": 1}])
    with pytest.raises(ValueError, match="declares no scan sectors"):
        RobotObservation([{"name": "scan_0", "low": 0, "high": 1}])


# ---- a saved policy knows what it commands and observes


def tiny_policy(tmp_path: Path, task: str) -> Path:
    from atrv_warp.policy import make_actor, save_policy

    path = tmp_path / f"{task}.pt"
    save_policy(make_actor(8, 1, obs_dim=len(observation_fields(get_task(task)))), path, width=8, depth=1,
                meta={"task": task})
    return path


def test_load_policy_refuses_another_action_or_observation_kind(tmp_path):
    from atrv_warp.policy import PolicyTaskMismatch, load_policy, policy_kinds
    from atrv_warp.storage import FileFormatError, atomic_save, load_weights

    deploy = tiny_policy(tmp_path, "nav_deploy")
    assert policy_kinds(deploy) == ("twist", "robot")
    load_policy(deploy, task="nav_deploy")
    with pytest.raises(PolicyTaskMismatch, match=f"^policy {deploy} commands twist but task 'nav' takes torque$"):
        load_policy(deploy, task="nav")
    assert issubclass(PolicyTaskMismatch, FileFormatError)  # the CLIs' one-line refusal of a bad policy file
    # a file from before the kinds were recorded commands torque and observes the arena observation
    payload = load_weights(tiny_policy(tmp_path, "nav"), "policy file")
    del payload["action"], payload["observation"]
    atomic_save(payload, tmp_path / "old.pt")
    assert policy_kinds(tmp_path / "old.pt") == ("torque", "arena")
    with pytest.raises(PolicyTaskMismatch, match="commands torque but task 'nav_deploy' takes twist"):
        load_policy(tmp_path / "old.pt", task="nav_deploy")
    # same action kind, another observation kind
    with pytest.raises(PolicyTaskMismatch, match="observes the arena observation but the task gives the robot one"):
        load_policy(tmp_path / "old.pt", task=get_task("nav").__class__(action="torque", observation="robot"))


def test_shipped_policies_load_by_name(monkeypatch):
    from atrv_warp.policy import (
        SHIPPED_POLICIES,
        load_policy,
        policy_kinds,
        policy_task,
        pretrained_nav_policy_path,
        pretrained_policy_path,
        shipped_policy_path,
    )

    assert shipped_policy_path("nav") == pretrained_nav_policy_path()
    assert shipped_policy_path("nav_plain") == pretrained_nav_policy_path(randomized=False)
    assert shipped_policy_path("reach") == pretrained_policy_path()
    assert policy_task("nav") == "nav" and policy_kinds("reach") == ("torque", "arena")
    load_policy("nav", task="nav")
    assert policy_kinds("nav_deploy") == ("twist", "robot") and policy_task("nav_deploy") == "nav_deploy"
    load_policy("nav_deploy", task="nav_deploy")
    # a registered policy whose file is not there yet (not trained): the message names the command that trains it
    monkeypatch.setitem(SHIPPED_POLICIES, "nav_deploy", dataclasses.replace(SHIPPED_POLICIES["nav_deploy"],
                                                                           file="not_there.pt"))
    with pytest.raises(FileNotFoundError, match="not trained yet: train it with `python -m atrv_warp.train --config "
                                                "nav_deploy batch_size=512`"):
        load_policy("nav_deploy")
    with pytest.raises(ValueError, match="no shipped policy is called 'navx'"):
        shipped_policy_path("navx")
    assert {SHIPPED_POLICIES[n].task for n in SHIPPED_POLICIES} == {"reach", "nav", "nav_deploy", "follow_path"}


def test_evaluate_refuses_before_any_step(tmp_path, capsys, monkeypatch):
    """``evaluate --task nav`` with a twist policy: exit 2, one line naming both, no simulator built."""
    from atrv_warp.cli.evaluate import main

    deploy = tiny_policy(tmp_path, "nav_deploy")
    assert main([str(deploy), "--task", "nav", "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"policy {deploy} commands twist but task 'nav' takes torque" in err[0], err
    from atrv_warp.policy import SHIPPED_POLICIES

    monkeypatch.setitem(SHIPPED_POLICIES, "nav_deploy", dataclasses.replace(SHIPPED_POLICIES["nav_deploy"],
                                                                           file="not_there.pt"))
    assert main(["--task", "nav_deploy", "--episodes", "1"]) == 2  # a shipped policy not trained yet
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "python -m atrv_warp.train --config nav_deploy" in err[0], err


def test_train_refuses_to_start_from_a_checkpoint_of_another_kind(tmp_path, run_module):
    """``train --config nav init_from=<a nav_deploy checkpoint>``: exit 2 in one line, before any step."""
    from atrv_warp.policy import make_actor, policy_payload
    from atrv_warp.storage import atomic_save

    actor = make_actor(8, 1, obs_dim=len(NAMES))
    ck = {"frames": 0, "updates": 0, "best_success": -1.0, "elapsed_s": 0.0, "next_eval": 0, "stats_ready": False,
          "rng": torch.get_rng_state(), "policy": policy_payload(actor, width=8, depth=1, meta={"task": "nav_deploy"})}
    atomic_save(ck, tmp_path / "checkpoint.pt")
    proc = run_module("atrv_warp.train", "--config", "nav", f"out_dir={tmp_path / 'runs'}",
                      f"init_from={tmp_path / 'checkpoint.pt'}", check=False)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1 and "commands twist but task 'nav' takes torque" in err[0], err
    assert not (tmp_path / "runs").exists()


# ---- the builder and the environment agree

def test_the_builder_gives_the_environments_observation_from_the_robots_signals():
    """Noise off: the builder, fed what the robot would publish in an env state (wheel odometry, the chassis as the
    IMU, the scan, the goal in the odometry frame, the actions stepped), gives the env's observation to 1e-4."""
    from torchrl.envs.utils import step_mdp

    from atrv_warp.core.geometry import quat_to_matrix
    from atrv_warp.task.env import ATRVjrEnv

    env = ATRVjrEnv(8, seed=5, task="nav_deploy")
    build = RobotObservation.from_contract(policy_contract(env.task_cfg))
    sc = env.scanner.cfg
    gen = torch.Generator().manual_seed(0)
    td, actions = env.reset(), []
    for _ in range(6):
        action = torch.rand(env.num_envs, 2, generator=gen) * 2.4 - 1.2  # beyond [-1, 1] too: the env clips
        actions.insert(0, action.clamp(-1, 1))
        td = env.step(td.set("action", action.to(env.device)))
        assert not td["next", "done"].any()  # one episode: the action history is the actions stepped
        q = env.sim.root_pose[:, 3:7].double().cpu()
        body_rate = (quat_to_matrix(q).transpose(-1, -2) @ env.sim.ang_vel.double().cpu().unsqueeze(-1)).squeeze(-1)
        history = torch.stack((actions + [torch.zeros_like(action)] * 3)[:3], 1)  # (N, 3, 2) newest first
        scan = Scan(td["next", "scan"].cpu(), -sc.fov / 2, sc.fov / (sc.beams - 1), sc.min_range, sc.max_range)
        built = build(odom_pose=env.sim.driver.fused.cpu(), odom_twist=env.sim.driver.odom_twist.cpu(),
                      imu_orientation=q, imu_angular_velocity=body_rate, goal=env.goal_odom.cpu(), scan=scan,
                      last_actions=history)
        want = td["next", "observation"].cpu()
        err = (built - want).abs().amax(0)
        bad = {n: round(e, 6) for n, e in zip(build.names, err.tolist(), strict=True) if e > 1e-4}
        assert not bad, bad
        td = step_mdp(td)
    assert env.sim.driver.fused[:, :2].abs().amax() > 1e-3  # the rovers moved: odometry and bearing changed
