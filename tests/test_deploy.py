"""The deploy node's message handling and decisions, without ROS: messages are read by their fields alone, so plain
namespaces stand for them here.

This file also runs in the slim install's fresh virtualenv (``tests/test_deploy_install.py``), where only torch and
``atrv_warp.core`` / ``atrv_warp.deploy`` exist: its imports are those, and the tests that need the simulator's
packages skip there. The policy file comes from ``ATRV_DEPLOY_TEST_POLICY`` when set (written by the install test),
else it is made here from the ``nav_deploy`` task's contract.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace as NS

import pytest
import torch

from atrv_warp.core.contract import EXPORT_FORMAT
from atrv_warp.deploy.contract import PolicyRefused, load_deployable
from atrv_warp.deploy.controller import Controller, Settings

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("warp", "newton", "torchrl", "tensordict", "rerun")


class _Tiny(torch.nn.Module):
    def __init__(self, dim: int):
        super().__init__()
        self.linear = torch.nn.Linear(dim, 2)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.linear(observation))


def write_policy(path: Path, contract: dict) -> Path:
    """A tiny exported policy with ``contract`` (random weights, seeded)."""
    torch.manual_seed(0)
    net = _Tiny(len(contract["observation"])).eval()
    program = torch.export.export(net, (torch.zeros(2, net.linear.in_features),),
                                  dynamic_shapes=({0: torch.export.Dim("batch")},))
    torch.export.save(program, str(path), extra_files={"atrv_warp.json": json.dumps(contract)})
    return path


def task_contract(task: str = "nav_deploy") -> dict:
    """An exported contract of ``task`` without exporting a trained policy (needs the package's task spec)."""
    spec = pytest.importorskip("atrv_warp.task.spec")
    registry = pytest.importorskip("atrv_warp.task.registry")
    contract = spec.policy_contract(registry.get_task(task))
    return {"format": EXPORT_FORMAT, "task": task, **contract, "step_dt": 0.05, "rate_hz": 20.0}


@pytest.fixture(scope="module")
def policy_file(tmp_path_factory) -> Path:
    given = os.environ.get("ATRV_DEPLOY_TEST_POLICY")
    if given:
        return Path(given)
    return write_policy(tmp_path_factory.mktemp("deploy") / "tiny.pt2", task_contract())


@pytest.fixture
def policy(policy_file):
    return load_deployable(policy_file)


# ------------------------------------------------------------------ messages as plain namespaces

def v3(x=0.0, y=0.0, z=0.0):
    return NS(x=x, y=y, z=z)


def odom_msg(x=0.0, y=0.0, yaw=0.0, v=0.0, w=0.0, frame="odom"):
    q = NS(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    return NS(header=NS(frame_id=frame), pose=NS(pose=NS(position=v3(x, y), orientation=q)),
              twist=NS(twist=NS(linear=v3(v), angular=v3(0.0, 0.0, w))))


def imu_msg(yaw_rate=0.0, q=(0.0, 0.0, 0.0, 1.0)):
    return NS(orientation=NS(x=q[0], y=q[1], z=q[2], w=q[3]), angular_velocity=v3(0.0, 0.0, yaw_rate))


def scan_msg(ranges, angle_min, angle_increment, range_min=0.1, range_max=20.0):
    return NS(ranges=list(ranges), angle_min=angle_min, angle_increment=angle_increment, range_min=range_min,
              range_max=range_max)


def goal_msg(x, y, frame="odom"):
    return NS(header=NS(frame_id=frame), pose=NS(position=v3(x, y)))


def tf_msg(*edges):
    """A ``tf2_msgs/TFMessage`` of (parent, child, x, y, yaw) planar transforms."""
    return NS(transforms=[NS(header=NS(frame_id=parent), child_frame_id=child,
                             transform=NS(translation=v3(x, y), rotation=NS(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                                             w=math.cos(yaw / 2))))
                          for parent, child, x, y, yaw in edges])


def fov_scan(beams, fov, seed=0):
    """``beams`` ranges over ``fov`` [rad] centred on +x, with +inf, -inf and NaN beams among them."""
    g = torch.Generator().manual_seed(seed)
    r = (0.05 + 8.0 * torch.rand(beams, generator=g, dtype=torch.float64)).tolist()
    for i in range(0, beams, 7):
        r[i] = math.inf
    for i in range(3, beams, 11):
        r[i] = -math.inf
    for i in range(5, beams, 13):
        r[i] = math.nan
    step = fov / beams if fov >= 2 * math.pi - 1e-9 else fov / (beams - 1)
    return scan_msg(r, -fov / 2 if fov < 2 * math.pi - 1e-9 else -math.pi, step)


def direct_sectors(msg, edges, clip):
    """Each sector's reading from its definition, beam by beam in plain Python (REP 117)."""
    out = []
    for lo, hi in itertools.pairwise(edges):
        best = None
        for i, r in enumerate(msg.ranges):
            a = msg.angle_min + i * msg.angle_increment
            if not lo <= a < hi or math.isnan(r):
                continue
            reading = 1.0 if r > msg.range_max else 0.0 if r < msg.range_min else min(r, clip) / clip
            best = reading if best is None else min(best, reading)
        out.append(0.0 if best is None else best)
    return out


def drive_ready(c: Controller, now=0.0, scan=None):
    assert c.on_odom(odom_msg(), now) is None
    assert c.on_imu(imu_msg(), now) is None
    if scan is not None:
        c.on_scan(scan, now)
    assert c.on_goal(goal_msg(6.0, 2.0), now).startswith("goal (6.00, 2.00) in odom")


# ------------------------------------------------------------------ tests

@pytest.mark.parametrize(("beams", "fov_deg"), [(1081, 270.0), (720, 360.0), (64, 180.0)])
def test_a_scan_of_another_geometry_reads_as_its_sectors(policy, beams, fov_deg):
    c = Controller(policy)
    msg = fov_scan(beams, math.radians(fov_deg))
    drive_ready(c, scan=msg)
    assert c.sensors["scan"].problem is None
    obs = c.observation()
    names = policy.observation.names
    got = [float(obs[names.index(f"scan_{k}")]) for k in range(policy.observation.sectors.count)]
    sectors = policy.observation.sectors
    want = direct_sectors(msg, sectors.edges, sectors.clip)
    assert got == pytest.approx(want, abs=1e-6)
    assert 0.0 in got or min(got) < 1.0  # the ranges reach into the clip: the check compares real readings
    tick = c.tick(0.05)
    assert tick.status["state"] == "active" and tick.command is not None
    assert abs(tick.command[0]) <= policy.scale[0] and abs(tick.command[1]) <= policy.scale[1]


def test_a_scan_short_of_the_sectors_is_refused_naming_both_and_the_rover_holds(policy):
    c = Controller(policy)
    narrow = fov_scan(91, math.radians(90.0))
    drive_ready(c)
    line = c.on_scan(narrow, 0.0)
    assert "91 beams" in line and "90 deg" in line and "16 sectors" in line and "183 deg" in line, line
    assert c.on_scan(narrow, 0.02) is None  # one line, at the first message
    tick = c.tick(0.05)
    assert tick.command == (0.0, 0.0) and tick.status["state"] == "holding"
    assert tick.log == ()  # the scan's own line said it
    assert c.on_scan(fov_scan(181, math.pi), 0.06) == "/scan valid again"
    tick = c.tick(0.1)
    assert tick.status["state"] == "active" and tick.log == ("resumed: driving by the policy",)


def test_non_finite_odometry_or_imu_and_a_scan_without_valid_beam_stop_until_valid(policy):
    c = Controller(policy)
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.05).status["state"] == "active"
    assert "non-finite odometry" in c.on_odom(odom_msg(x=math.nan), 0.06)
    t = c.tick(0.1)
    assert t.command == (0.0, 0.0) and "non-finite odometry" in t.status["reason"]
    assert c.on_odom(odom_msg(), 0.11) == "/odom valid again"
    assert c.tick(0.15).status["state"] == "active"
    assert "non-finite IMU" in c.on_imu(imu_msg(yaw_rate=math.inf), 0.16)
    assert c.tick(0.2).command == (0.0, 0.0)
    c.on_imu(imu_msg(), 0.21)
    assert "no valid beam" in c.on_scan(scan_msg([math.nan] * 181, -math.pi / 2, math.pi / 180), 0.21)
    assert c.tick(0.25).status["state"] == "holding"
    c.on_scan(fov_scan(181, math.pi), 0.26)
    assert c.tick(0.3).status["state"] == "active"


def test_a_stale_sensor_stops_the_rover_on_ros_time(policy):
    c = Controller(policy, Settings(stale_timeout=0.5))
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.4).status["state"] == "active"
    c.on_odom(odom_msg(), 0.6)
    c.on_scan(fov_scan(181, math.pi), 0.6)
    t = c.tick(0.6)  # the IMU's last message came at 0.0
    assert t.command == (0.0, 0.0) and t.status["reason"].startswith("/imu stale (0.60 s > 0.5 s)")
    assert t.log == ("holding still: /imu stale (0.60 s > 0.5 s)",)
    assert c.tick(0.65).log == ()  # said once
    c.on_imu(imu_msg(), 0.66)
    assert c.tick(0.7).status["state"] == "active"


def test_goals_in_another_frame_are_refused_and_the_goal_ends_reached_or_at_the_time_limit(policy):
    c = Controller(policy, Settings(goal_tolerance=1.0, time_limit=2.0, odom_jump_margin=5.0))  # the odometry hops
    c.on_odom(odom_msg(), 0.0)
    c.on_imu(imu_msg(), 0.0)
    c.on_scan(fov_scan(181, math.pi), 0.0)
    line = c.on_goal(goal_msg(3.0, 0.0, frame="map"), 0.0)  # a node that reads no /tf (no tf2_msgs)
    assert line.startswith("goal refused: it is in frame 'map'") and "'odom'" in line and "reads no /tf" in line
    assert c.tick(0.05) == c.tick(0.1) and c.tick(0.15).command is None  # no goal: nothing published
    c.on_goal(goal_msg(3.0, 0.0), 0.2)
    assert c.tick(0.25).status["state"] == "active"
    c.on_odom(odom_msg(x=2.5), 0.3)
    t = c.tick(0.3)
    assert t.command == (0.0, 0.0) and t.status["state"] == "reached" and c.goal is None
    assert c.tick(0.35).command is None
    c.on_goal(goal_msg(30.0, 0.0), 0.4)
    for k in range(1, 40):
        now = 0.4 + 0.05 * k
        c.on_odom(odom_msg(x=2.5), now)
        c.on_imu(imu_msg(), now)
        c.on_scan(fov_scan(181, math.pi), now)
        c.tick(now)
    t = c.tick(2.45)
    assert t.status["state"] == "aborted" and t.status["reason"].startswith("time limit") and t.command == (0.0, 0.0)
    stop = Controller(policy).stop("shutdown")
    assert stop.command == (0.0, 0.0) and stop.status is None


def test_a_goal_tolerance_of_zero_never_ends_the_goal_and_the_trace_holds_each_steps_input(policy):
    """``goal_tolerance`` 0: the node drives on over the goal (as ``evaluate``'s policy does until the environment ends
    the episode); a new goal ends it. Each period's trace record holds the stamps of the messages it read and, where
    the policy drove, the observation and action it computed."""
    c = Controller(policy, Settings(goal_tolerance=0.0))
    odom = odom_msg()
    odom.header.stamp = NS(sec=3, nanosec=250_000_000)
    c.on_odom(odom, 0.0)
    c.on_imu(imu_msg(), 0.0)
    c.on_scan(fov_scan(181, math.pi), 0.0)
    assert c.tick(0.0).command is None
    record = c.trace(0.0, c.tick(0.0))
    assert record["state"] is None and record["observation"] is None and record["command"] is None
    c.on_goal(goal_msg(0.0, 0.0), 0.0)  # on the goal: distance 0
    for now in (0.05, 0.1, 0.15):
        t = c.tick(now)
        assert t.status["state"] == "active" and t.status["distance"] == 0.0, t.status
    record = json.loads(json.dumps(c.trace(now, t)))
    assert record["stamps"] == {"odom": 3.25, "imu": None, "scan": None}  # a message without a header has no stamp
    assert record["steps"] == 3 and record["goal"] == [0.0, 0.0] and record["state"] == "active"
    now = c.observation().tolist()  # the messages are the tick's; its command has joined the action history since
    assert record["observation"][:-6] == now[:-6] and record["observation"][-6:-2] == now[-4:]
    assert torch.allclose(torch.tensor(record["command"]), torch.tensor(record["action"]) * torch.tensor(policy.scale))
    assert c.trace(0.2, c.stop("shutdown"))["observation"] is None  # the policy did not drive this period
    with pytest.raises(ValueError, match=r"parameter stale_timeout must be a finite number > 0 \[s\], got 0.0"):
        Settings(stale_timeout=0.0)


def test_a_speed_clamp_clips_the_command_and_counts_the_clipped_steps(policy):
    c = Controller(policy, Settings(max_linear=1e-3, max_angular=1e-3))
    drive_ready(c, scan=fov_scan(181, math.pi))
    for k in range(1, 6):
        t = c.tick(0.05 * k)
        assert all(abs(v) <= 1e-3 + 1e-12 for v in t.command)
    assert t.status["clipped_steps"] == 5 and t.status["steps"] == 5
    # the commands sent are what the policy observes next, newest first
    history = c.observation()[-6:].view(3, 2)
    assert torch.allclose(history, torch.tensor([t.command] * 3, dtype=torch.float32) / torch.tensor(policy.scale),
                          atol=1e-7)


def test_bad_policy_files_are_refused_in_one_line(tmp_path, policy_file):
    garbage = tmp_path / "garbage.pt2"
    garbage.write_bytes(b"not a policy")
    with pytest.raises(PolicyRefused, match="no such policy file"):
        load_deployable(tmp_path / "missing.pt2")
    with pytest.raises(PolicyRefused, match="not an exported policy"):
        load_deployable(garbage)
    contract = json.loads(json.dumps(load_deployable(policy_file).contract))
    torque = dict(contract, action=dict(contract["action"], kind="torque", names=["left", "right"],
                                        units=["N·m", "N·m"]))
    with pytest.raises(PolicyRefused, match=r"a 'torque' policy \(left, right \[N·m, N·m\]\)"):
        load_deployable(write_policy(tmp_path / "torque.pt2", torque))
    arena = dict(contract, observation_kind="arena",
                 observation=[{"name": "target_x", "low": -1.0, "high": 1.0}] + contract["observation"][1:])
    with pytest.raises(PolicyRefused, match=r"observes the 'arena' observation \(target_x, sin_goal_bearing"):
        load_deployable(write_policy(tmp_path / "arena.pt2", arena))
    with pytest.raises(PolicyRefused, match="contract format 'atrv_warp.exported_policy/2'"):
        load_deployable(write_policy(tmp_path / "old.pt2", dict(contract, format="atrv_warp.exported_policy/2")))


def test_the_command_line_refuses_a_bad_policy_before_ros_starts(tmp_path):
    garbage = tmp_path / "garbage.pt2"
    garbage.write_bytes(b"\x00" * 64)
    proc = subprocess.run([sys.executable, "-m", "atrv_warp.deploy", str(garbage)], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    line = (f"python -m atrv_warp.deploy: error: {garbage}: not an exported policy (not a torch.export archive: "
            "File is not a zip file)")
    assert proc.stderr.strip().splitlines() == [line], proc.stderr
    assert proc.stdout == ""


def test_the_deploy_node_loads_nothing_of_the_simulator():
    """In a fresh interpreter: the command line, the controller and (where rclpy is) the node import none of
    Warp, Newton, TorchRL, TensorDict or Rerun."""
    modules = ["atrv_warp.deploy", "atrv_warp.deploy.cli", "atrv_warp.deploy.contract", "atrv_warp.deploy.messages",
               "atrv_warp.deploy.controller"]
    try:
        import rclpy  # noqa: F401

        modules.append("atrv_warp.deploy.node")
    except ImportError:
        pass
    code = f"import sys\nimport {', '.join(modules)}\nprint(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_every_reader_of_an_exported_policy_refuses_another_format_alike(tmp_path, policy_file):
    """The deploy node, the exporter's loader and the MuJoCo twin read a ``.pt2`` through one reader
    (:func:`atrv_warp.core.contract.read_exported`): each refuses a contract of another format in the same line, and
    each reads the good file's contract as the same dict."""
    contract = load_deployable(policy_file).contract
    old = write_policy(tmp_path / "old.pt2", dict(contract, format="atrv_warp.exported_policy/2"))
    line = (f"{old}: contract format 'atrv_warp.exported_policy/2', this version reads {EXPORT_FORMAT!r}: export the "
            "policy again (python -m atrv_warp.export POLICY OUT.pt2)")
    readers = {"deploy": lambda p: load_deployable(p).contract}
    try:  # the full package (the robot's slim install has the node alone)
        from atrv_warp.integrations.mujoco.episodes import DeployablePolicy
        from atrv_warp.rl.export import load_exported
    except ImportError:
        pass
    else:
        readers.update(export=lambda p: load_exported(p)[1], twin=lambda p: DeployablePolicy.load(p).contract)
    for name, read in readers.items():
        with pytest.raises(ValueError) as refused:
            read(old)
        assert str(refused.value) == line, name
        assert read(policy_file) == contract, name


def test_the_node_names_the_base_limits_its_policy_was_trained_with(policy):
    # the deployable task's base accelerates at up to 1 m/s²: the robot's diff_drive_controller should too
    assert "linear.x.max_acceleration 1 m/s²" in policy.describe()
    bare = dict(policy.contract, action={k: v for k, v in policy.contract["action"].items() if k != "base_limits"})
    assert "max_acceleration" not in dataclasses.replace(policy, contract=bare).describe()  # an older export: silent


# ------------------------------------------------------------------ bad input: held still, never an exception

def test_an_impossible_scan_holds_the_rover_naming_why_and_a_good_one_resumes(policy):
    c = Controller(policy)
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.05).status["state"] == "active"
    line = c.on_scan(scan_msg([3.0] * 181, -math.pi / 2, math.pi / 180, range_min=5.0, range_max=1.0), 0.06)
    assert "impossible scan: range_min 5.0 m, range_max 1.0 m" in line, line
    assert c.tick(0.1).command == (0.0, 0.0)
    assert "no beams" not in line and "unusable scan geometry" in c.on_scan(scan_msg([], -1.0, 0.01), 0.11)
    assert c.tick(0.15).command == (0.0, 0.0)
    c.on_scan(fov_scan(181, math.pi), 0.16)
    assert c.tick(0.2).status["state"] == "active"


def test_an_odometry_jump_aborts_the_goal_and_the_next_goal_drives(policy):
    c = Controller(policy, Settings(odom_jump_margin=0.5))
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.05).status["state"] == "active"
    assert c.on_odom(odom_msg(x=0.1), 0.05) is None  # 0.1 m in 0.05 s: within 2 m/s x 0.05 s + 0.5 m
    line = c.on_odom(odom_msg(x=1000.1), 0.1)
    assert line.startswith("/odom jumped 1000.00 m in 0.05 s (more than the trained 2 m/s allows + odom_jump_margin "
                           "0.5 m)") and line.endswith("the goal is aborted and the rover stops"), line
    t = c.tick(0.1)
    assert t.command == (0.0, 0.0) and t.status["state"] == "aborted" and t.status["reason"].startswith("/odom jumped")
    assert t.log == () and c.goal is None  # the odometry's line said it
    assert c.tick(0.15).command is None  # no goal: nothing more
    c.on_odom(odom_msg(x=1000.15), 0.15)  # measured from the new odometry: no jump
    assert c.on_goal(goal_msg(1005.0, 0.0), 0.15).startswith("goal (1005.00, 0.00)")
    c.on_imu(imu_msg(), 0.15)
    c.on_scan(fov_scan(181, math.pi), 0.15)
    assert c.tick(0.2).status["state"] == "active"
    # with no goal a jump is only said
    idle = Controller(policy)
    idle.on_odom(odom_msg(), 0.0)
    assert idle.on_odom(odom_msg(y=50.0), 1.0).startswith("/odom jumped 50.00 m in 1.00 s")
    assert idle.pending is None


def test_a_refused_goal_stops_the_active_one(policy):
    c = Controller(policy)
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.05).status["state"] == "active"
    for k, (bad, why) in enumerate([(goal_msg(3.0, 0.0, frame="map"), "goal refused: it is in frame 'map'"),
                                    (goal_msg(math.nan, 0.0), "goal refused: non-finite position (nan, 0.0)")]):
        now = 0.1 + k
        c.on_odom(odom_msg(), now)
        c.on_imu(imu_msg(), now)
        c.on_scan(fov_scan(181, math.pi), now)
        c.on_goal(goal_msg(6.0, 2.0), now)
        assert c.tick(now).status["state"] == "active"
        line = c.on_goal(bad, now)
        assert line.startswith(why) and line.endswith("the goal is aborted and the rover stops"), line
        t = c.tick(now + 0.05)
        assert t.command == (0.0, 0.0) and t.status["state"] == "aborted" and t.status["reason"].startswith(why)
        assert c.tick(now + 0.1).command is None
    # a goal past the farthest the policy observes (its goal_distance bound, 30 m) ends at the next period
    c.on_odom(odom_msg(), 3.0)
    c.on_imu(imu_msg(), 3.0)
    c.on_scan(fov_scan(181, math.pi), 3.0)
    c.on_goal(goal_msg(500.0, 0.0), 3.0)
    t = c.tick(3.0)
    assert t.status["state"] == "aborted" and t.command == (0.0, 0.0)
    assert t.status["reason"] == "the goal is 500.0 m away, farther than max_goal_distance 30 m", t.status
    near = Controller(policy, Settings(max_goal_distance=5.0))
    drive_ready(near, scan=fov_scan(181, math.pi))  # a goal at 6.3 m
    assert near.tick(0.05).status["reason"].endswith("farther than max_goal_distance 5 m")


def test_a_policy_that_fails_or_a_callback_that_fails_holds_the_rover(policy):
    c = Controller(policy)
    drive_ready(c, scan=fov_scan(181, math.pi))
    assert c.tick(0.05).status["state"] == "active"
    broken = dataclasses.replace(policy, module=lambda obs: (_ for _ in ()).throw(AssertionError("Guard failed")))
    c.policy = broken
    t = c.tick(0.1)
    assert t.command == (0.0, 0.0) and t.status["reason"] == "the policy failed (AssertionError: Guard failed)"
    c.policy = policy
    assert c.tick(0.15).status["state"] == "active"
    t = c.fault("scan", "scan callback failed (TypeError: x)", 0.16)  # the node's guard, after an exception
    assert t.command == (0.0, 0.0) and c.sensors["scan"].problem.startswith("scan callback failed")
    assert c.tick(0.2).command == (0.0, 0.0)
    c.on_scan(fov_scan(181, math.pi), 0.21)
    assert c.tick(0.25).status["state"] == "active"
    c.fault("goal", "goal callback failed", 0.26)
    assert c.tick(0.3).status["state"] == "aborted"


def test_parameters_are_checked_by_type_and_range_in_one_line():
    from atrv_warp.deploy.parameters import ParameterError, check_parameters

    assert check_parameters({"max_linear": 1})["max_linear"] == 1.0  # an integer is a number
    assert check_parameters({})["goal_tolerance"] == -1.0  # the policy's trained radius
    cases = {"max_linear": ("abc", "parameter max_linear must be a number [m/s], got 'abc' (str)"),
             "enable_stamped_cmd_vel": ("maybe", "parameter enable_stamped_cmd_vel must be true or false, got 'maybe'"),
             "cmd_vel_topic": ("", "parameter cmd_vel_topic must be a topic name (it is empty)"),
             "odom_frame": ("", "parameter odom_frame must be a frame name (it is empty)"),
             "base_frame": ("base link", "parameter base_frame must be a tf frame id without spaces"),
             "stale_timeout": (0, "parameter stale_timeout must be a finite number > 0 [s], got 0 (an integer)"),
             "time_limit": (-1.0, "parameter time_limit must be a finite number >= 0 [s], got -1.0"),
             "goal_tolerance": (True, "parameter goal_tolerance must be a number [m], got True (bool)"),
             "trace": (3, "parameter trace must be a string, got 3 (an integer)")}
    for name, (value, message) in cases.items():
        with pytest.raises(ParameterError) as err:
            check_parameters({name: value})
        assert str(err.value).startswith(message) and "\n" not in str(err.value), str(err.value)
    with pytest.raises(ParameterError, match=r"unknown parameter\(s\) \['max_speed'\]"):
        check_parameters({"max_speed": 1.0})


def test_the_robot_is_a_name_or_a_robot_file(tmp_path):
    """``robot:=`` takes a robot file's path as the simulator node and every command do: the node runs with the name
    its file gives (and compares that with the policy's); a file that does not load is named in one line."""
    import shutil

    from atrv_warp.core.robot import robot_file
    from atrv_warp.deploy.parameters import ParameterError, check_parameters

    shipped = robot_file("jackal")  # the installed package's (the slim install runs these tests too)
    for suffix in (".toml", ".urdf"):
        shutil.copy(shipped.with_suffix(suffix), tmp_path / f"jackal{suffix}")
    assert check_parameters({"robot": str(tmp_path / "jackal.toml")})["robot"] == "jackal"
    assert check_parameters({"robot": "my_rover-2"})["robot"] == "my_rover-2"  # a robot of yours, by name
    for value, message in ((str(tmp_path / "gone.toml"), "robot file not found"),
                           ("jackal v2", "a name of letters, digits, '_' and '-', or a robot file's path")):
        with pytest.raises(ParameterError) as err:
            check_parameters({"robot": value})
        assert str(err.value).startswith("parameter robot must be") and message in str(err.value), str(err.value)
        assert "\n" not in str(err.value)


def test_a_new_file_never_overwrites_one_and_a_bad_path_is_named(tmp_path):
    from atrv_warp.core.files import OutputPathError, fresh_path

    first, line = fresh_path(tmp_path / "trace.jsonl")
    assert first == tmp_path / "trace.jsonl" and line is None and first.exists()
    first.write_text("kept\n")
    second, line = fresh_path(tmp_path / "trace.jsonl")
    assert second == tmp_path / "trace-1.jsonl" and line == f"{first} exists and is kept: writing {second}"
    assert first.read_text() == "kept\n"
    for bad, why in [(tmp_path / "missing" / "t.jsonl", "does not exist"), (tmp_path, "is a folder"),
                     (Path("/proc/atrv_trace.jsonl"), "cannot be written")]:
        with pytest.raises(OutputPathError, match=why):
            fresh_path(bad)


def test_a_policy_whose_contract_does_not_fit_its_program_or_rate_is_refused(tmp_path, policy_file):
    contract = json.loads(json.dumps(load_deployable(policy_file).contract))
    path = write_policy(tmp_path / "ok.pt2", contract)
    short = dict(contract, observation=contract["observation"][:-1])  # 29 fields for a 30-wide program
    torch.export.save(torch.export.load(path), tmp_path / "short.pt2",
                      extra_files={"atrv_warp.json": json.dumps(short)})
    with pytest.raises(PolicyRefused, match=r"the contract lists 29 observation fields, but the program refuses a "
                                            r"\(1, 29\) input"):
        load_deployable(tmp_path / "short.pt2")
    for rate in (1e9, 1e-6):
        fast = dict(contract, rate_hz=rate, step_dt=1 / rate)
        with pytest.raises(PolicyRefused, match=rf"control rate {re.escape(f'{rate:g}')} Hz is outside the 1-200 Hz"):
            load_deployable(write_policy(tmp_path / "rate.pt2", fast))
    with pytest.raises(PolicyRefused, match="rate_hz 20 disagrees with step_dt 0.1"):
        load_deployable(write_policy(tmp_path / "dt.pt2", dict(contract, step_dt=0.1)))


def test_a_malformed_robot_entry_in_a_contract_is_read_as_no_robot():
    """A contract's ``robot`` entry comes from a file: any shape reads without an exception, a name only if it is
    text."""
    from atrv_warp.deploy.contract import Deployable

    for entry, name in (({"name": ["x"], "limits": [1, 2]}, None), ("husky", None), (None, None),
                        ({"name": "husky", "title": "Husky", "limits": {"linear_velocity": 1.0}}, "husky")):
        policy = object.__new__(Deployable)  # the contract alone: what these two read
        object.__setattr__(policy, "contract", {"robot": entry})
        assert policy.robot == name
        assert policy.describe_robot().startswith("trained on")


def test_the_goal_tolerance_defaults_to_the_radius_the_policy_trained_to_reach(tmp_path, policy):
    """``goal_tolerance`` -1 (the default): the contract's ``reach_radius_m``; 1.0 m for a contract without it; a value
    given is used as is, 0 never ends a goal; below 0 only -1 is accepted."""
    from atrv_warp.deploy.parameters import ParameterError, check_parameters

    recorded = load_deployable(write_policy(tmp_path / "husky.pt2", {**policy.contract, "reach_radius_m": 1.14}))
    assert recorded.reach_radius == 1.14 and Controller(recorded).goal_tolerance == 1.14
    assert policy.reach_radius is None and Controller(policy).goal_tolerance == 1.0  # exported before it was kept
    assert Controller(recorded, Settings(goal_tolerance=0.25)).goal_tolerance == 0.25
    assert Controller(recorded, Settings(goal_tolerance=0.0)).goal_tolerance == 0.0
    assert check_parameters({"goal_tolerance": -1})["goal_tolerance"] == -1.0
    with pytest.raises(ParameterError, match="goal_tolerance must be a finite number >= 0"):
        check_parameters({"goal_tolerance": -2.0})


def test_the_transform_buffer_carries_a_point_along_the_tree():
    """Up and down the tree, through several edges, a leading slash ignored; frames it does not join give None; a
    transform with a non-finite value or a zero rotation is skipped."""
    from atrv_warp.core.tf import TransformBuffer

    tf = TransformBuffer()
    assert tf.add(tf_msg(("map", "odom", 2.0, 1.0, math.pi / 2), ("odom", "base_link", 1.0, 0.0, 0.0),
                         ("base_link", "laser", 0.2, 0.0, math.radians(10)))) == 3
    assert tf.transform_point((2.0, 4.0, 0.0), "odom", "/map") == pytest.approx((3.0, 0.0, 0.0))
    assert tf.transform_point((3.0, 0.0, 0.0), "map", "odom") == pytest.approx((2.0, 4.0, 0.0))
    laser_origin = tf.transform_point((0.0, 0.0, 0.0), "map", "laser")  # map -> odom -> base_link -> laser
    assert laser_origin == pytest.approx((2.0, 2.2, 0.0))
    assert tf.transform_point((1.0, 0.0, 0.0), "odom", "elsewhere") is None and not tf.can_transform("map", "gps")
    bad = tf_msg(("map", "gps", math.nan, 0.0, 0.0))
    bad.transforms.append(NS(header=NS(frame_id="map"), child_frame_id="imu",
                             transform=NS(translation=v3(), rotation=NS(x=0.0, y=0.0, z=0.0, w=0.0))))
    assert tf.add(bad) == 0 and not tf.can_transform("map", "gps")


def test_a_goal_in_map_is_carried_into_odom_and_follows_the_transform(policy):
    """A node that reads /tf: a goal in ``map`` waits, holding still, until /tf joins ``map`` to ``odom``; then it
    drives to the goal carried into ``odom``, again every period as the localisation's correction moves."""
    c = Controller(policy, Settings(time_limit=0.0), tf=True)
    drive_ready(c, scan=fov_scan(181, math.pi))
    line = c.on_goal(goal_msg(2.0, 4.0, frame="map"), 0.0)
    assert line.startswith("goal (2.00, 4.00) in map: waiting for the transform from 'map' to 'odom'"), line
    t = c.tick(0.05)
    assert t.command == (0.0, 0.0) and t.status["state"] == "holding"
    assert t.status["reason"] == "no transform from 'map' to 'odom' on /tf" and t.log
    c.on_tf(tf_msg(("map", "odom", 2.0, 1.0, math.pi / 2)), 0.06)
    t = c.tick(0.1)
    assert t.status["state"] == "active" and t.status["goal"] == pytest.approx([3.0, 0.0])
    c.on_tf(tf_msg(("map", "odom", 2.0, 2.0, math.pi / 2)), 0.12)  # the localisation corrects the odometry
    for s in (c.on_odom, c.on_imu):
        s(odom_msg() if s == c.on_odom else imu_msg(), 0.14)
    c.on_scan(fov_scan(181, math.pi), 0.14)
    assert c.tick(0.15).status["goal"] == pytest.approx([2.0, 0.0])
    assert c.on_goal(goal_msg(1.0, 1.0, frame=""), 0.2).startswith("goal refused: it names no frame")


def _ray_cast(origin, yaw, angles, walls, range_max=30.0):
    """Ranges from a scanner at ``origin`` (x, y) turned ``yaw`` along ``angles`` to the nearest of ``walls`` (segments
    ((x0, y0), (x1, y1))), +inf beyond ``range_max``."""
    out = []
    for a in angles:
        dx, dy = math.cos(yaw + a), math.sin(yaw + a)
        best = math.inf
        for (x0, y0), (x1, y1) in walls:
            ex, ey = x1 - x0, y1 - y0
            den = dx * ey - dy * ex
            if abs(den) < 1e-12:
                continue
            t = ((x0 - origin[0]) * ey - (y0 - origin[1]) * ex) / den
            u = ((x0 - origin[0]) * dy - (y0 - origin[1]) * dx) / den
            if t > 0 and 0 <= u <= 1:
                best = min(best, t)
        out.append(best if best <= range_max else math.inf)
    return torch.tensor(out, dtype=torch.float64)


def test_a_scanner_mounted_forward_and_yawed_reads_as_the_centred_one_after_the_transform():
    """A scanner 0.2 m forward of the trained one and yawed 10 deg, its returns carried to the trained mount
    (core.scan.remount): the same sector readings as the trained scanner's, in a room with a box and a post, to the
    beams' resolution; read as if it were at the trained mount, they differ."""
    from atrv_warp.core.scan import ScanSectors, remount, sector_readings

    room = [((-4, -3), (5, -3)), ((5, -3), (5, 4)), ((5, 4), (-4, 4)), ((-4, 4), (-4, -3))]
    box = [((1.5, -1.0), (2.2, -1.0)), ((2.2, -1.0), (2.2, -0.4)), ((2.2, -0.4), (1.5, -0.4)), ((1.5, -0.4), (1.5, -1.0))]
    post = [((0.4, 1.3), (0.6, 1.3)), ((0.6, 1.3), (0.6, 1.5)), ((0.6, 1.5), (0.4, 1.5)), ((0.4, 1.5), (0.4, 1.3))]
    walls = room + box + post
    sectors = ScanSectors.for_beams(181, math.radians(180), 16, 4.0)
    trained = torch.linspace(-math.pi / 2, math.pi / 2, 181, dtype=torch.float64)
    expected = sector_readings(_ray_cast((0.0, 0.0), 0.0, trained, walls), trained, sectors, range_min=0.05,
                               range_max=30.0)
    mount = (0.2, 0.0, math.radians(10.0))
    fine = torch.linspace(-math.radians(135), math.radians(135), 2701, dtype=torch.float64)  # a 270 deg lidar
    ranges = _ray_cast(mount[:2], mount[2], fine, walls)
    carried, bearings = remount(ranges, fine, mount, range_min=0.05, range_max=30.0)
    got = sector_readings(carried, bearings, sectors, range_min=0.05, range_max=30.0)
    assert (got - expected).abs().max() < 0.02, (got, expected)  # 8 cm: the 0.1 deg beams find corners 1 deg ones miss
    naive = sector_readings(ranges, fine, sectors, range_min=0.05, range_max=30.0)
    assert (naive - expected).abs().max() > 0.1
    # the builder does the same with Scan.mount; a scan at the trained mount is untouched
    from atrv_warp.core.observation import Scan

    scan = Scan(ranges, float(fine[0]), float(fine[1] - fine[0]), 0.05, 30.0, mount=mount)
    r, b = remount(scan.ranges, scan.angles(), scan.mount, range_min=0.05, range_max=30.0)
    assert torch.allclose(r, carried) and torch.allclose(b, bearings)  # its angles are angle_min + i * increment
    same, _ = remount(ranges, fine, (0.0, 0.0, 0.0), range_min=0.05, range_max=30.0)
    assert torch.allclose(same, ranges, rtol=0, atol=1e-12)


def test_the_node_carries_a_scanner_mounted_elsewhere_on_tf_to_the_trained_mount(policy, tmp_path):
    """The controller reads the scanner's mounting from /tf against the contract's ``scan.mount``: a scanner 0.2 m
    ahead of the trained one and yawed 10 deg gives the observation the trained scanner would (to the beams'
    resolution), and says so once; without the transform it reads the scan as mounted where the policy's was."""
    contract = json.loads(json.dumps(policy.contract))  # the fixture's (a file in the slim install's test run)
    contract["scan"] = {**contract["scan"], "mount": {"parent": "chassis", "x": 0.3, "y": 0.0, "z": 0.2, "yaw": 0.0}}
    policy = load_deployable(write_policy(tmp_path / "mounted.pt2", contract))
    sectors = policy.observation.sectors
    walls = [((-4, -3), (5, -3)), ((5, -3), (5, 4)), ((5, 4), (-4, 4)), ((-4, 4), (-4, -3)),
             ((1.5, -1.0), (2.2, -1.0)), ((2.2, -1.0), (2.2, -0.4)), ((2.2, -0.4), (1.5, -0.4)),
             ((1.5, -0.4), (1.5, -1.0))]
    fov = sectors.edges[-1] - sectors.edges[0]
    trained = torch.linspace(-fov / 2, fov / 2, 721, dtype=torch.float64)
    wide = torch.linspace(-math.radians(135), math.radians(135), 2701, dtype=torch.float64)
    yaw = math.radians(10.0)

    def observe(controller, ranges, angles, frame):
        msg = scan_msg(ranges.tolist(), float(angles[0]), float(angles[1] - angles[0]), 0.05, 30.0)
        msg.header = NS(frame_id=frame)
        line = controller.on_scan(msg, 0.0)
        controller.on_odom(odom_msg(), 0.0)
        controller.on_imu(imu_msg(), 0.0)
        controller.on_goal(goal_msg(3.0, 1.0), 0.0)
        return controller.observation(), line

    names = policy.observation.names
    scan_at = [i for i, n in enumerate(names) if n.startswith("scan_")]
    centred = Controller(policy, tf=True)
    centred.on_tf(tf_msg(("chassis", "laser", 0.3, 0.0, 0.0)), 0.0)
    expected, line = observe(centred, _ray_cast((0.0, 0.0), 0.0, trained, walls), trained, "laser")
    assert line is None  # mounted as trained: nothing to say
    moved = Controller(policy, tf=True)
    moved.on_tf(tf_msg(("chassis", "front_laser", 0.5, 0.0, yaw)), 0.0)
    got, line = observe(moved, _ray_cast((0.2, 0.0), yaw, wide, walls), wide, "front_laser")
    assert "+0.200 m, +0.000 m and +10.0 deg from where the policy's was (from /tf)" in line, line
    assert (got[scan_at] - expected[scan_at]).abs().max() < 0.02, (got[scan_at], expected[scan_at])
    assert torch.equal(got[[i for i in range(len(names)) if i not in scan_at]],
                       expected[[i for i in range(len(names)) if i not in scan_at]])
    blind = Controller(policy, tf=True)  # no transform: read as if mounted where the policy's was
    naive, _ = observe(blind, _ray_cast((0.2, 0.0), yaw, wide, walls), wide, "front_laser")
    assert (naive[scan_at] - expected[scan_at]).abs().max() > 0.1
    assert blind.mount_source.startswith("read as mounted where the policy's was (no /tf from 'chassis'")


def test_the_launch_file_is_one_for_every_robot_and_an_unknown_robot_is_named(capsys, tmp_path):
    """``atrv-deploy --launch-files <robot>`` checks the robot (a name or a file with a ``[deploy]`` table) and prints
    the one launch file; an unknown robot, or a file that says nothing of its topics, is one line, exit 2."""
    import shutil

    from atrv_warp.core.robot import robot_file
    from atrv_warp.deploy.cli import main

    assert main(["--launch-files", "jackal"]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path.name == "rover.launch.py" and path.is_file()
    assert "robot:=" in path.read_text() and "launch_description()" in path.read_text()
    for suffix in (".toml", ".urdf"):
        shutil.copy(robot_file("jackal").with_suffix(suffix), tmp_path / f"jackal{suffix}")
    mine = tmp_path / "jackal.toml"
    assert main(["--launch-files", str(mine)]) == 0 and Path(capsys.readouterr().out.strip()) == path
    mine.write_text(mine.read_text().split("\n[deploy]\n")[0] + "\n")  # the file without its [deploy] table
    for robot, message in (("warthog", "unknown robot 'warthog'; shipped robots: atrvjr, husky, jackal"),
                           (str(mine), "has no [deploy] table: its file says nothing of its topics and frames")):
        with pytest.raises(SystemExit) as ended:
            main(["--launch-files", robot])
        err = capsys.readouterr().err
        assert ended.value.code == 2 and message in err.strip().splitlines()[-1], err  # after argparse's usage


def test_a_tf_flood_is_bounded_and_its_frames_age_out():
    """Issue 70: a /tf flood of new frame names neither grows the buffer past MAX_FRAMES nor drops the frames it holds;
    a message past MAX_PER_MESSAGE is cut; /tf frames unheard for STALE_AFTER_S go, /tf_static ones stay; a lookup
    after the flood costs what it cost before it (the tree's adjacency is built once per change, not per lookup)."""
    import time

    from atrv_warp.core.tf import MAX_FRAMES, MAX_PER_MESSAGE, STALE_AFTER_S, TransformBuffer

    buf = TransformBuffer()
    buf.add(tf_msg(("map", "odom", 1.0, 0.0, 0.0)), 0.0)
    buf.add(tf_msg(("base_link", "laser", 0.2, 0.0, 0.0)), 0.0, static=True)
    for k in range(100):  # 100 messages of 50 new names each, at 100 Hz: 5,000 frames
        buf.add(tf_msg(*((f"flood_{k}_{i}", f"flood_{k}_{i}_child", 0.0, 0.0, 0.0) for i in range(50))), 0.01 * k)
        buf.add(tf_msg(("map", "odom", 1.0, 0.0, 0.0)), 0.01 * k)  # the localisation keeps publishing
    assert len(buf.edges) == MAX_FRAMES and buf.skipped > 0
    assert buf.transform_point((0.0, 0.0, 0.0), "map", "odom") == (1.0, 0.0, 0.0)
    t0 = time.perf_counter()
    for _ in range(1000):
        buf.transform_point((0.0, 0.0, 0.0), "map", "odom")
    assert time.perf_counter() - t0 < 2.0  # ~ms per thousand lookups: no rebuild of a 1,000-frame tree each time
    buf.add(tf_msg(*((f"big_{i}", f"big_{i}_child", 0.0, 0.0, 0.0) for i in range(MAX_PER_MESSAGE + 50))),
            STALE_AFTER_S + 0.5)  # the flood's names unheard for more than STALE_AFTER_S: gone; odom heard at 0.99 s
    assert set(buf.edges) == {"odom", "laser"} | {f"big_{i}_child" for i in range(MAX_PER_MESSAGE)}
    buf.add(tf_msg(), 3 * STALE_AFTER_S)
    assert set(buf.edges) == {"laser"}  # the static frame stays


def test_non_finite_goals_after_tf_and_far_scanner_mounts_are_refused_and_the_status_is_standard_json(policy, tmp_path):
    """Issue 70: a goal carried into odom as -inf (x = -1.7e308 in map, map -> odom at +1.7e308) is refused, and the
    status stays standard JSON; a /tf that puts the scanner 1,000 m from the trained mount is refused and the rover
    held."""
    contract = json.loads(json.dumps(policy.contract))
    contract["scan"] = {**contract["scan"], "mount": {"parent": "chassis", "x": 0.3, "y": 0.0, "z": 0.2, "yaw": 0.0}}
    mounted = load_deployable(write_policy(tmp_path / "mounted.pt2", contract))
    c = Controller(mounted, tf=True)
    c.on_tf(tf_msg(("map", "odom", 1.7e308, 0.0, 0.0), ("chassis", "laser", 1000.3, 0.0, 0.0)), 0.0)
    line = c.on_goal(goal_msg(-1.7e308, 0.0, frame="map"), 0.0)
    assert "goal refused" in line and "is not finite in 'odom'" in line, line
    json.loads(json.dumps(c.status("aborted")), parse_constant=lambda name: pytest.fail(f"status holds {name}"))
    edges = contract["scan"]["sectors"]["edges_rad"]
    msg = scan_msg([2.0] * 181, edges[0], (edges[-1] - edges[0]) / 180, 0.05, 30.0)
    msg.header = NS(frame_id="laser")
    line = c.on_scan(msg, 0.0)
    assert "scan refused: /tf puts its scanner ('laser') 1000.00 m from where the policy's was" in line, line
    c.on_odom(odom_msg(), 0.0)
    c.on_imu(imu_msg(), 0.0)
    c.on_goal(goal_msg(3.0, 1.0), 0.0)
    tick = c.tick(0.05)
    assert tick.command == (0.0, 0.0) and tick.status["state"] == "holding", tick
