"""The deploy node live over ROS 2, in its own process: a stale sensor and shutdown stop the rover, and closed-loop
episodes with the simulator node playing the robot (``benchmarks/transfer/deploy_closed_loop.py``)."""

from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, LaserScan
from std_msgs.msg import String
from test_deploy import task_contract, write_policy

ROOT = Path(__file__).resolve().parent.parent
NS = "/rover_1"


class Robot:
    """A stand-in robot under :data:`NS`: publishes odometry, IMU and a 181-beam scan; records what the node says."""

    def __init__(self, cmd_topic: str = "cmd_vel"):
        self.node = rclpy.create_node("fake_rover")
        self.cmds, self.status = [], []
        self.odom = self.node.create_publisher(Odometry, f"{NS}/odom", 10)
        self.imu = self.node.create_publisher(Imu, f"{NS}/imu", 10)
        self.scan = self.node.create_publisher(LaserScan, f"{NS}/scan", 10)
        self.goal = self.node.create_publisher(PoseStamped, f"{NS}/goal_pose", 10)
        self.node.create_subscription(Twist, f"{NS}/{cmd_topic}", lambda m: self.cmds.append(
            (time.monotonic(), m.linear.x, m.angular.z)), 100)
        self.node.create_subscription(String, f"{NS}/goal_status", lambda m: self.status.append(json.loads(m.data)), 100)
        self.imu_on = True
        self.odom_x = 0.0
        """The odometry's x [m] (a fault sets it far away, or to NaN)."""
        self.odom_y = self.odom_yaw = 0.0
        self.scan_fault: dict = {}
        """LaserScan fields to publish instead of the good scan's (``ranges``, ``range_min``…)."""

    def publish(self):
        odom = Odometry()
        odom.header.frame_id = "odom"
        odom.pose.pose.position.x, odom.pose.pose.position.y = self.odom_x, self.odom_y
        odom.pose.pose.orientation.z = math.sin(self.odom_yaw / 2)
        odom.pose.pose.orientation.w = math.cos(self.odom_yaw / 2)
        self.odom.publish(odom)
        if self.imu_on:
            imu = Imu()
            imu.orientation.w = 1.0
            self.imu.publish(imu)
        scan = LaserScan()
        scan.angle_min, scan.angle_increment = -math.pi / 2, math.pi / 180
        scan.range_min, scan.range_max = 0.1, 20.0
        scan.ranges = [3.0] * 181
        for name, value in self.scan_fault.items():
            setattr(scan, name, value)
        self.scan.publish(scan)

    def send_goal(self, x: float, y: float, frame: str = "odom") -> None:
        goal = PoseStamped()
        goal.header.frame_id = frame
        goal.pose.position.x, goal.pose.position.y = x, y
        self.goal.publish(goal)

    def driving(self) -> bool:
        """The node's last status is active and its last command moves the rover."""
        return bool(self.status) and self.status[-1]["state"] == "active" and bool(self.cmds) and \
            abs(self.cmds[-1][1]) + abs(self.cmds[-1][2]) > 0

    def run(self, seconds, until=None):
        """Publish at 20 Hz for ``seconds`` (or until ``until()``); returns whether ``until`` came true."""
        end, due = time.monotonic() + seconds, 0.0
        while time.monotonic() < end:
            if time.monotonic() >= due:
                self.publish()
                due = time.monotonic() + 0.05
            rclpy.spin_once(self.node, timeout_sec=0.01)
            if until is not None and until():
                return True
        return until is None


def _interrupt(proc, robot: Robot) -> str:
    """Ctrl-C to a node under test while ``robot`` goes on publishing (a node's shutdown stops the rover it drives);
    killed after 10 s; its output."""
    proc.send_signal(2)
    robot.run(10, lambda: proc.poll() is not None)
    if proc.poll() is None:
        proc.kill()
    return proc.communicate(timeout=30)[0]


@pytest.mark.slow  # a live ROS 2 node
def test_a_stale_sensor_and_shutdown_stop_the_rover_in_a_namespace(ros_env, tmp_path):
    policy = write_policy(tmp_path / "tiny.pt2", task_contract())
    proc = subprocess.Popen([sys.executable, "-m", "atrv_warp.deploy", str(policy), "--ros-args", "-r",
                             f"__ns:={NS}", "-p", "stale_timeout:=0.5"], env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    robot = Robot()
    try:
        assert robot.run(120, lambda: robot.goal.get_subscription_count() > 0), "the node did not subscribe"
        goal = PoseStamped()
        goal.header.frame_id = "odom"
        goal.pose.position.x, goal.pose.position.y = 20.0, 5.0
        robot.goal.publish(goal)
        assert robot.run(20, lambda: any(s["state"] == "active" for s in robot.status)), robot.status[-3:]
        robot.run(0.5)
        assert any(abs(v) + abs(w) > 0 for _, v, w in robot.cmds[-5:])  # the random policy drives
        rate = sum(1 for t, _, _ in robot.cmds if t > time.monotonic() - 0.5) / 0.5
        assert 15 <= rate <= 25, rate  # the policy's 20 Hz
        robot.imu_on = False
        silenced = time.monotonic()
        assert robot.run(5, lambda: robot.status[-1]["state"] == "holding"), robot.status[-3:]
        assert robot.status[-1]["reason"].startswith("/imu stale"), robot.status[-1]
        stopped = next(t for t, v, w in robot.cmds if t > silenced and v == 0.0 and w == 0.0)
        assert stopped - silenced < 0.5 + 0.3, stopped - silenced  # the timeout, a period and delivery
        robot.run(0.5)
        assert all(v == 0.0 and w == 0.0 for t, v, w in robot.cmds if t > stopped)
        robot.imu_on = True
        assert robot.run(5, lambda: robot.status[-1]["state"] == "active")
        robot.run(0.3)
        assert abs(robot.cmds[-1][1]) + abs(robot.cmds[-1][2]) > 0
        proc.send_signal(2)  # Ctrl-C while it drives
        interrupted = time.monotonic()
        robot.run(15, lambda: proc.poll() is not None)
        exit_s = time.monotonic() - interrupted
        robot.run(0.3)
    finally:
        if proc.poll() is None:
            proc.kill()
        out = proc.communicate(timeout=30)[0]
        robot.node.destroy_node()
    assert proc.returncode == 0, out[-2000:]
    print(f"exited {exit_s:.2f} s after Ctrl-C")
    assert robot.cmds[-1][1:] == (0.0, 0.0), robot.cmds[-3:]
    assert robot.status[-1]["state"] == "aborted" and robot.status[-1]["reason"] == "shutdown", robot.status[-1]
    assert out.count("holding still: /imu stale") == 1 and "resumed: driving by the policy" in out, out[-2000:]
    assert f"on {NS}/cmd_vel" in out and f"{NS}/goal_pose" in out


@pytest.mark.slow  # a live ROS 2 node
def test_no_input_ends_the_node_each_fault_stops_the_rover_and_good_input_drives_it_again(ros_env, tmp_path):
    """Every fault of the hostile-user sweep, in sequences (bad then good, good then bad): the node stays up, commands
    zero within 0.8 s of each fault (measured from the fault's first message), and drives again after it; what
    crashed it before (one logging call site at two severities) is among them."""
    policy = write_policy(tmp_path / "tiny.pt2", task_contract())
    proc = subprocess.Popen([sys.executable, "-m", "atrv_warp.deploy", str(policy), "--ros-args", "-r",
                             f"__ns:={NS}", "-p", "time_limit:=0.0"], env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    robot = Robot()
    faults = []

    def stopped_after(name: str, fault) -> None:
        """Apply ``fault``; the rover gets a zero command within 0.8 s and the node is still up."""
        began = time.monotonic()
        fault()
        assert robot.run(3, lambda: any(t > began and v == 0.0 and w == 0.0 for t, v, w in robot.cmds)), name
        first_zero = next(t for t, v, w in robot.cmds if t > began and v == 0.0 and w == 0.0)
        faults.append((name, first_zero - began))
        assert first_zero - began < 0.8, (name, first_zero - began)
        robot.run(0.3)
        assert proc.poll() is None, f"the node died after {name}"

    def drives_again(name: str, fix=None) -> None:
        if fix is not None:
            fix()
        assert robot.run(10, robot.driving), (name, robot.status[-2:])

    try:
        assert robot.run(120, lambda: robot.goal.get_subscription_count() > 0), "the node did not subscribe"
        # a bad /odom before any goal, then a goal (crashed the node: warning, then info, at one call site)
        robot.odom_x = math.nan
        robot.run(0.5)
        robot.odom_x = 0.0
        robot.send_goal(20.0, 5.0)
        drives_again("a goal after a bad /odom")
        # a goal in map, which no /tf joins to odom here: taken, and the rover holds still; a valid goal drives again
        # (a goal in another frame crashed the node)
        stopped_after("goal in map", lambda: robot.send_goal(3.0, 0.0, frame="map"))
        assert robot.status[-1]["state"] == "holding", robot.status[-1]
        assert robot.status[-1]["reason"] == "no transform from 'map' to 'odom' on /tf", robot.status[-1]
        drives_again("a valid goal after one in map", lambda: robot.send_goal(20.0, 5.0))
        # a valid goal, then bad scans (a 0-beam scan crashed the node), then good ones
        for name, fault in [("0-beam scan", {"ranges": []}), ("range_min > range_max", {"range_min": 5.0,
                                                                                         "range_max": 1.0}),
                            ("all-NaN scan", {"ranges": [math.nan] * 181})]:
            stopped_after(name, lambda f=fault: robot.scan_fault.update(f))
            assert robot.status[-1]["state"] == "holding", (name, robot.status[-1])
            drives_again(name, robot.scan_fault.clear)
        stopped_after("NaN odometry", lambda: setattr(robot, "odom_x", math.nan))
        drives_again("NaN odometry", lambda: setattr(robot, "odom_x", 0.0))
        # odometry that jumps 1 km: the goal is aborted; a new goal in the new odometry drives
        stopped_after("odometry jump", lambda: setattr(robot, "odom_x", 1000.0))
        assert robot.status[-1]["state"] == "aborted" and "/odom jumped" in robot.status[-1]["reason"]
        drives_again("a goal after the jump", lambda: robot.send_goal(1020.0, 5.0))
        stopped_after("a goal 1 km away", lambda: robot.send_goal(3000.0, 0.0))
        assert "farther than max_goal_distance 30 m" in robot.status[-1]["reason"], robot.status[-1]
        drives_again("a valid goal after a far one", lambda: robot.send_goal(1020.0, 5.0))
        stopped_after("a NaN goal", lambda: robot.send_goal(math.nan, 0.0))
        drives_again("a valid goal after a NaN one", lambda: robot.send_goal(1020.0, 5.0))
        proc.send_signal(2)
        robot.run(15, lambda: proc.poll() is not None)
    finally:
        if proc.poll() is None:
            proc.kill()
        out = proc.communicate(timeout=30)[0]
        robot.node.destroy_node()
    print("\n".join(f"{name}: zero after {1000 * dt:.0f} ms" for name, dt in faults))
    assert proc.returncode == 0 and "Traceback" not in out, out[-3000:]
    assert len(faults) == 8
    assert robot.cmds[-1][1:] == (0.0, 0.0)


@pytest.mark.slow  # live ROS 2 contexts
def test_every_parameter_type_and_unknown_keys_are_named_in_one_line(ros_env, tmp_path):
    """Each bad parameter (its type, a value, a topic, a file, an unknown key in a --params-file) is one error line
    naming it and exit 2 (here: the node's NodeConfigError, in this process, with the same rclpy)."""
    from atrv_warp.deploy.contract import load_deployable
    from atrv_warp.deploy.node import DeployNode, NodeConfigError

    policy = load_deployable(write_policy(tmp_path / "tiny.pt2", task_contract()))
    params = tmp_path / "params.yaml"
    params.write_text("atrv_deploy:\n  ros__parameters:\n    max_linear: 0.5\n    max_speed: 1.0\n")
    others = tmp_path / "others.yaml"
    others.write_text("some_other_node:\n  ros__parameters:\n    anything: 1\n")
    (tmp_path / "taken.jsonl").write_text("kept\n")
    cases = [(["-p", "max_linear:=abc"], "parameter max_linear must be a number [m/s], got 'abc'"),
             (["-p", "enable_stamped_cmd_vel:=maybe"], "parameter enable_stamped_cmd_vel must be true or false"),
             (["-p", "scan_topic:=bad topic!"], "parameter scan_topic must be a ROS topic name, got 'bad topic!'"),
             (["-p", "cmd_vel_topic:=''"], "parameter cmd_vel_topic must be a topic name (it is empty)"),
             (["-p", "odom_frame:=''"], "parameter odom_frame must be a frame name (it is empty)"),
             (["-p", f"trace:={tmp_path / 'missing' / 't.jsonl'}"], "parameter trace: "),
             (["-p", "trace:=/proc/atrv_trace.jsonl"], "cannot be written"),
             (["-p", "max_speed:=1.0"], "unknown parameter(s) max_speed;"),
             (["--params-file", str(params)], f"unknown parameter(s) max_speed (in {params})")]
    for args, message in cases:
        ctx = rclpy.Context()
        rclpy.init(args=["atrv-deploy", "--ros-args", *args], context=ctx)
        try:
            with pytest.raises(NodeConfigError) as err:
                DeployNode(policy, ["--ros-args", *args], context=ctx)
            assert message in str(err.value) and "\n" not in str(err.value), (args, str(err.value))
        finally:
            rclpy.shutdown(context=ctx)
    for args in (["-p", "max_linear:=1"], ["--params-file", str(others)],
                 ["-p", f"trace:={tmp_path / 'taken.jsonl'}"]):  # an integer, another node's file, a kept file
        ctx = rclpy.Context()
        rclpy.init(args=["atrv-deploy", "--ros-args", *args], context=ctx)
        try:
            node = DeployNode(policy, ["--ros-args", *args], context=ctx)
            node.stop("test")
            node.destroy_node()
        finally:
            rclpy.shutdown(context=ctx)
    assert (tmp_path / "taken.jsonl").read_text() == "kept\n" and (tmp_path / "taken-1.jsonl").is_file()
    proc = subprocess.run([sys.executable, "-m", "atrv_warp.deploy", str(tmp_path / "tiny.pt2"), "--ros-args", "-p",
                           "max_linear:=abc"], env=ros_env, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stdout + proc.stderr, proc.stdout + proc.stderr
    assert [line for line in (proc.stdout + proc.stderr).splitlines() if "max_linear" in line], proc.stderr


@pytest.mark.slow  # two live ROS 2 nodes and the simulator
def test_closed_loop_episodes_over_ros_end_as_evaluate_judges_them(tmp_path):
    """Ten seeded nav_deploy episodes through ROS 2 (an untrained policy: how they end is not the point; that they
    run, end by the environment's rules, and the node reports its compute time, is)."""
    from atrv_warp.policy import make_actor, save_policy
    from atrv_warp.task.registry import get_task
    from atrv_warp.task.spec import END_REASONS, observation_fields

    task = get_task("nav_deploy")
    actor = make_actor(width=32, depth=1, obs_dim=len(observation_fields(task)))
    save_policy(actor, tmp_path / "random.pt", width=32, depth=1, meta={"task": "nav_deploy"})
    out = tmp_path / "closed_loop.json"
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(101, 200)))
    proc = subprocess.run([sys.executable, "-m", "benchmarks.transfer.deploy_closed_loop", str(tmp_path /
                          "random.pt"), "--episodes", "10", "--out", str(out)], capture_output=True, text=True,
                          timeout=900, env=env, check=False, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    result = json.loads(out.read_text())
    rows = result["episodes_detail"]
    assert [r["episode"] for r in rows] == list(range(10))
    assert all(r["end_reason"] in END_REASONS and r["end_reason"] != "running" for r in rows), rows
    assert all(0 < r["steps"] <= task.max_steps for r in rows), rows
    assert all(r["node_state"] in ("active", "holding", "reached", "aborted") for r in rows), rows
    assert result["compute_ms"]["steps"] >= sum(r["steps"] for r in rows) // 2
    assert 0 < result["compute_ms"]["p50"] <= result["compute_ms"]["p99"] < 1000
    assert result["ci95"][0] <= result["difference"] <= result["ci95"][1]


@pytest.mark.slow  # the simulator node, the deploy node and the script's client: about 50 s
def test_follow_path_episodes_over_ros_start_on_evaluates_plan_and_take_every_replan(tmp_path):
    """Two episodes of the shipped Jackal ``follow_path`` policy in the example office, through ROS 2 as the closed-loop
    script runs them: each episode's first plan over ROS is ``evaluate``'s (the script stops otherwise), every replan
    the simulator publishes (one a second: every fifth 0.2 s step but the last) goes to the node as a FollowPath
    goal, every step waits for the node's answer, and both episodes reach the goal, as under ``evaluate``."""
    out = tmp_path / "closed_loop.json"
    env = dict(os.environ)
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(101, 200)))
    proc = subprocess.run([sys.executable, "-m", "benchmarks.transfer.deploy_closed_loop", "follow_path_jackal",
                           "--episodes", "2", "--out", str(out)], capture_output=True, text=True, timeout=900,
                          env=env, check=False, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    result = json.loads(out.read_text())
    rows = result["episodes_detail"]
    assert result["map"] == "atrv_warp/assets/maps/office.yaml"
    assert [r["unanswered"] for r in rows] == [0, 0], rows
    assert all(r["replans"] >= (r["steps"] - 1) // 5 - 1 for r in rows), rows  # the last may cross the end
    assert [(r["end_reason"], r["evaluate_end_reason"]) for r in rows] == [("success", "success")] * 2, rows
    assert 0 < result["compute_ms"]["p50"] <= result["compute_ms"]["p99"] < 1000


@pytest.mark.slow  # two live ROS 2 nodes and the simulator
def test_over_ros_each_step_is_the_nodes_answer_to_the_state_evaluate_would_observe(tmp_path):
    """Two consecutive episodes of the shipped ``nav_deploy`` policy over ROS 2, replayed in a one-world environment
    from the node's trace: the node's first observation of each episode is the environment's reset observation
    (the reset state, no action yet: evaluate's first), and after each step with the node's action, the node's next
    observation is the environment's, to float32 rounding; the replay ends as the episode did over ROS. So the
    transport changes nothing: the same state, observation and action at every step (nothing a step late, no stale
    command from the previous episode, the goal seen from the environment's odometry frame)."""
    import torch
    from torchrl.envs.utils import step_mdp

    from atrv_warp.policy import policy_record
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.spec import END_REASONS

    out, trace = tmp_path / "closed_loop.json", tmp_path / "trace.jsonl"
    env = dict(os.environ)
    env.setdefault("ROS_DOMAIN_ID", str(random.randint(101, 200)))
    proc = subprocess.run([sys.executable, "-m", "benchmarks.transfer.deploy_closed_loop", "--episodes", "2",
                           "--out", str(out), "--trace", str(trace)], capture_output=True, text=True, timeout=900,
                          env=env, check=False, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = json.loads(out.read_text())["episodes_detail"]
    assert [r["unanswered"] for r in rows] == [0, 0], rows  # every step waited for the node's answer
    records = [json.loads(line) for line in trace.read_text().splitlines()]
    sim = ATRVjrEnv(1, task=policy_record("nav_deploy").task)  # the task the policy records, as the script runs it
    for row in rows:
        td = sim.reset_to_episodes([0], [row["episode"]], seed=2024)
        goal = sim.target[0].tolist()
        mine = [r for r in records if r["goal"] and max(abs(a - b) for a, b in zip(r["goal"], goal)) < 1e-5]
        mine = mine[max(i for i, r in enumerate(mine) if r["steps"] == 1):]  # its last run (the first is a warm-up)
        assert [r["steps"] for r in mine[:row["steps"]]] == list(range(1, row["steps"] + 1))
        for step, record in enumerate(mine[:row["steps"]]):
            seen = torch.tensor(record["observation"])
            err = (seen - td["observation"][0]).abs().max().item()
            assert err < 5e-5, f"episode {row['episode']} step {step}: the node saw an observation {err:.2e} off"
            assert record["stamps"] == dict.fromkeys(("odom", "imu", "scan"), pytest.approx(record["time"]))
            td = sim.step(td.set("action", torch.tensor([record["action"]])))
            if step + 1 < row["steps"]:
                assert not td["next", "done"].any(), f"episode {row['episode']} ended early in the replay"
                td = step_mdp(td)
        assert td["next", "done"].all() and END_REASONS[int(td["next", "end_reason"])] == row["end_reason"]


def _tf(parent: str, child: str, x: float, y: float, yaw: float):
    """A ``tf2_msgs/TFMessage`` holding one transform (``child`` in ``parent``)."""
    from geometry_msgs.msg import TransformStamped

    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

    TFMessage, where = load_interface(TF2_MSGS, "msg", "TFMessage")
    assert TFMessage is not None, where
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y = x, y
    t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return TFMessage(transforms=[t])


@pytest.mark.slow  # a live ROS 2 node and an action client
def test_navigate_to_pose_in_map_drives_feeds_back_cancels_and_is_replaced(ros_env, tmp_path):
    """Goals in ``map`` with ``map`` -> ``odom`` offset and rotated on /tf_static, on ``goal_pose`` and through Nav2's
    ``NavigateToPose``, which replaces it: accepted, driving, feedback with the distance in ``odom``; a goal with no frame rejected while the
    active one drives on; a cancel stops the rover within 0.8 s (result cancelled); a new goal aborts the old one;
    a goal the rover reaches succeeds."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface
    from atrv_warp.deploy.nav2 import load_navigate_to_pose

    NavigateToPose, where = load_navigate_to_pose()
    assert NavigateToPose is not None, where
    TFMessage, _ = load_interface(TF2_MSGS, "msg", "TFMessage")
    policy = write_policy(tmp_path / "tiny.pt2", task_contract())
    robot = Robot()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    robot.node.create_publisher(TFMessage, "/tf_static", latched).publish(_tf("map", "odom", 2.0, 1.0, math.pi / 2))
    proc = subprocess.Popen([sys.executable, "-m", "atrv_warp.deploy", str(policy), "--ros-args", "-r",
                             f"__ns:={NS}", "-p", "goal_tolerance:=0.5"], env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    client = ActionClient(robot.node, NavigateToPose, f"{NS}/navigate_to_pose")
    feedback = []

    def send(x, y, frame="map"):
        request = NavigateToPose.Goal()
        request.pose.header.frame_id = frame
        request.pose.pose.position.x, request.pose.pose.position.y = x, y
        future = client.send_goal_async(request, feedback_callback=lambda m: feedback.append(m.feedback))
        assert robot.run(10, future.done), "no answer to the goal"
        return future.result()

    try:
        assert robot.run(120, lambda: client.server_is_ready()), "no NavigateToPose server"
        # on goal_pose in map: map -> odom is (2, 1) turned 90 deg, so (4, 1) in map is (0, -2) in odom
        robot.send_goal(4.0, 1.0, frame="map")
        assert robot.run(10, lambda: any(s["state"] == "active" and s["goal"] is not None and max(
            abs(a - b) for a, b in zip(s["goal"], [0.0, -2.0])) < 1e-6 for s in robot.status)), robot.status[-1:]
        first = send(5.0, 1.0)  # in map: map -> odom is (2, 1) turned 90 deg, so (5, 1) in map is (0, -3) in odom
        assert first.accepted
        assert robot.run(10, lambda: robot.status[-1]["goal"] is not None and
                         max(abs(a - b) for a, b in zip(robot.status[-1]["goal"], [0.0, -3.0])) < 1e-6), robot.status[-1]
        assert robot.run(5, lambda: len(feedback) >= 3)
        assert abs(feedback[-1].distance_remaining - 3.0) < 0.01 and feedback[-1].current_pose.header.frame_id == "odom"
        refused = send(1.0, 1.0, frame="")  # rejected: no frame; the active goal drives on
        assert not refused.accepted
        robot.run(0.3)
        assert robot.driving(), robot.status[-1]
        cancel = first.cancel_goal_async()
        cancelled = time.monotonic()
        assert robot.run(5, lambda: robot.status[-1]["state"] == "aborted"), robot.status[-1]
        stopped = next(t for t, v, w in robot.cmds if t > cancelled and v == 0.0 and w == 0.0)
        assert stopped - cancelled < 0.8, stopped - cancelled
        result = first.get_result_async()
        assert robot.run(5, lambda: cancel.done() and result.done())
        assert result.result().status == GoalStatus.STATUS_CANCELED
        second = send(5.0, 1.0)
        third = send(2.0, 1.2)  # (0.2, 0) in odom: within goal_tolerance of the rover, which stays at the origin
        old = second.get_result_async()
        assert robot.run(5, old.done)
        assert old.result().status == GoalStatus.STATUS_ABORTED
        if hasattr(old.result().result, "error_msg"):
            assert old.result().result.error_msg == "replaced by a new NavigateToPose goal"
        reached = third.get_result_async()
        assert robot.run(5, reached.done) and reached.result().status == GoalStatus.STATUS_SUCCEEDED
    finally:
        client.destroy()
        out = _interrupt(proc, robot)
        robot.node.destroy_node()
    assert proc.returncode == 0, out[-3000:]
    assert "NavigateToPose goal rejected: it names no frame" in out and "the active goal goes on" in out, out[-3000:]


@pytest.mark.slow  # a live ROS 2 node and an action client
def test_follow_path_in_map_is_served_as_nav2s_controller_serves_it(ros_env, tmp_path):
    """A plan-following policy's node serves Nav2's ``FollowPath`` on ``follow_path`` (not ``navigate_to_pose``) and
    publishes on ``cmd_vel_nav``: a path in ``map`` around a corner, with ``map`` -> ``odom`` offset and turned on
    /tf_static, is accepted and driven, with feedback of the distance along it; a replan takes over without stopping
    and the replaced goal ends aborted with an empty result; an empty path is aborted with INVALID_PATH and the rover
    stops; a path whose end the rover is at, turned to its heading, succeeds; a storm of 30 goals each cancelled
    twice ends each cancelled or replaced, the rover still, and the next goal drives; the node stays up throughout."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface
    from atrv_warp.deploy.nav2 import FOLLOW_PATH_CODES, load_follow_path
    from atrv_warp.deploy.node import ACTION_REQUEST_DEPTH

    FollowPath, where = load_follow_path()
    assert FollowPath is not None, where
    TFMessage, _ = load_interface(TF2_MSGS, "msg", "TFMessage")
    policy = write_policy(tmp_path / "path.pt2", task_contract("follow_path"))
    robot = Robot(cmd_topic="cmd_vel_nav")
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    robot.node.create_publisher(TFMessage, "/tf_static", latched).publish(_tf("map", "odom", 2.0, 1.0, math.pi / 2))
    proc = subprocess.Popen([sys.executable, "-m", "atrv_warp.deploy", str(policy), "--ros-args", "-r",
                             f"__ns:={NS}"], env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    client = ActionClient(robot.node, FollowPath, f"{NS}/follow_path")
    feedback = []

    def request(points, yaw=math.pi):
        request = FollowPath.Goal()
        request.path.header.frame_id = "map"
        for k, (x, y) in enumerate(points):
            pose = PoseStamped()
            pose.header.frame_id = "map"
            pose.pose.position.x, pose.pose.position.y = x, y
            last = yaw if k == len(points) - 1 else 0.0
            pose.pose.orientation.z, pose.pose.orientation.w = math.sin(last / 2), math.cos(last / 2)
            request.path.poses.append(pose)
        request.controller_id = "FollowPath"
        return request

    def send(points, yaw=math.pi):
        future = client.send_goal_async(request(points, yaw), feedback_callback=lambda m: feedback.append(m.feedback))
        assert robot.run(10, future.done), "no answer to the goal"
        return future.result()

    def result(handle):
        answer = handle.get_result_async()
        assert robot.run(5, answer.done), "no result"
        return answer.result()

    corner = [(2.0, 1.0), (2.0, 4.0), (0.0, 4.0)]  # from the rover (odom's origin is (2, 1) in map) up, then left
    try:
        assert robot.run(120, lambda: client.server_is_ready()), "no FollowPath server"
        assert not robot.node.get_publishers_info_by_topic(f"{NS}/cmd_vel")  # the velocity smoother's input only
        first = send(corner)
        assert first.accepted
        assert robot.run(10, robot.driving), robot.status[-1:]
        assert robot.run(5, lambda: len(feedback) >= 3)
        assert abs(feedback[-1].distance_to_goal - 5.0) < 0.01, feedback[-1]
        replanned = time.monotonic()
        second = send([(2.0, 1.1), *corner[1:]])  # the behaviour tree's replan a second later
        old = result(first)
        assert old.status == GoalStatus.STATUS_ABORTED
        if hasattr(old.result, "error_code"):
            assert (old.result.error_code, old.result.error_msg) == (0, "")  # Nav2's empty result
        robot.run(0.5)
        assert all(abs(v) + abs(w) > 0 for t, v, w in robot.cmds if t > replanned), "the replan stopped the rover"
        empty = send([])  # accepted, as Nav2 accepts every goal, then aborted
        assert empty.accepted
        aborted, refused = result(empty), time.monotonic()
        assert aborted.status == GoalStatus.STATUS_ABORTED
        if hasattr(aborted.result, "error_code"):
            assert aborted.result.error_code == FOLLOW_PATH_CODES["INVALID_PATH"] == 103
            assert aborted.result.error_msg == "INVALID_PATH: the path has no poses", aborted.result.error_msg
        assert result(second).status == GoalStatus.STATUS_ABORTED  # replaced by the empty path: it does not drive on
        robot.run(0.5)
        assert all(v == 0.0 and w == 0.0 for t, v, w in robot.cmds if t > refused + 0.3), robot.cmds[-3:]
        robot.odom_x, robot.odom_y, robot.odom_yaw = 3.0, 2.0, math.pi / 2  # odom (3, 2) is map (0, 4), facing -x
        robot.run(0.3)  # the odometry's jump there is said with no goal to abort
        reached = send(corner)
        assert result(reached).status == GoalStatus.STATUS_SUCCEEDED
        # a cancel storm: 30 goals down the corridor at once, each cancelled twice as soon as it is accepted, and
        # each one's result asked for (a client whose queues hold the burst: the node's hold ACTION_REQUEST_DEPTH)
        deep = QoSProfile(depth=ACTION_REQUEST_DEPTH)
        stormer = ActionClient(robot.node, FollowPath, f"{NS}/follow_path", goal_service_qos_profile=deep,
                               result_service_qos_profile=deep, cancel_service_qos_profile=deep)
        ahead = [(0.0, 4.0), (-3.0, 4.0)]
        assert robot.run(10, stormer.server_is_ready)
        sent = [stormer.send_goal_async(request(ahead)) for _ in range(30)]
        assert robot.run(10, lambda: all(f.done() for f in sent)), f"{sum(f.done() for f in sent)} of 30 answered"
        assert all(f.result().accepted for f in sent)
        cancels = [f.result().cancel_goal_async() for f in sent for _ in range(2)]
        answers = [f.result().get_result_async() for f in sent]
        assert robot.run(10, lambda: all(a.done() for a in (*cancels, *answers))), (
            f"{sum(c.done() for c in cancels)} of 60 cancels, {sum(a.done() for a in answers)} of 30 results answered")
        stormed = time.monotonic()
        ends = [a.result().status for a in answers]
        assert set(ends) <= {GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED}, ends  # cancelled or replaced
        assert ends[-1] == GoalStatus.STATUS_CANCELED
        robot.run(0.5)
        assert all(v == 0.0 and w == 0.0 for t, v, w in robot.cmds if t > stormed + 0.3), robot.cmds[-3:]
        assert send(ahead).accepted  # and the next goal drives
        assert robot.run(5, robot.driving), robot.status[-1:]
        assert proc.poll() is None
    finally:
        client.destroy()
        out = _interrupt(proc, robot)
        robot.node.destroy_node()
    assert proc.returncode == 0, out[-3000:]
    assert f"FollowPath on {NS}/follow_path" in out and f"on {NS}/cmd_vel_nav" in out, out[-3000:]
    assert "navigate_to_pose" not in out, out[-3000:]


def _seen_planner(env):
    """A planner of the plan a Nav2 stack would hand its controller once its obstacle layer has seen every unmapped
    obstacle: the env's map with its obstacles drawn in as occupied cells, planned by our planner (Nav2's inflation,
    NavFn's weights); ``plan(start, goal)`` gives the path's points. A test client's planner, not Nav2's."""
    import dataclasses

    import numpy as np
    import torch

    from atrv_warp.sim.contact import OBSTACLE_KINDS
    from atrv_warp.sim.maps import GridWorlds
    from atrv_warp.sim.planner import Planner
    from atrv_warp.world.nav2_map import OCCUPIED

    site = env.sim.maps.maps[0]
    rows, cols = site.shape
    y, x = np.meshgrid(site.origin[1] + (np.arange(rows) + 0.5) * site.resolution,
                       site.origin[0] + (np.arange(cols) + 0.5) * site.resolution, indexing="ij")
    cells = site.cells.copy()
    o = env.sim.obstacles
    for kind, (ox, oy, yaw), (a, b) in zip(o.kind[0].tolist(), o.pose[0].tolist(), o.size[0].tolist(), strict=True):
        c, s = math.cos(yaw), math.sin(yaw)
        lx, ly = (x - ox) * c + (y - oy) * s, -(x - ox) * s + (y - oy) * c
        if kind == OBSTACLE_KINDS["cylinder"]:
            cells[np.hypot(lx, ly) <= a] = OCCUPIED
        elif kind == OBSTACLE_KINDS["box"]:
            cells[(abs(lx) <= a) & (abs(ly) <= b)] = OCCUPIED
    planner = Planner(GridWorlds([dataclasses.replace(site, cells=cells)], [0], "cpu"), env.sim.footprint_radii)

    def plan(start, goal):
        planner.plan([0], torch.tensor([start], dtype=torch.float32), torch.tensor([goal], dtype=torch.float32))
        return planner.points(0)

    return plan


@pytest.mark.slow  # the simulator node, the deploy node and a client: about a minute
def test_a_trained_follow_path_policy_drives_nav2s_plan_to_the_goal_in_the_simulated_office(ros_env, tmp_path):
    """The simulator as a Nav2 test site: the simulator node in the example office map (``/map``, ``map -> odom``,
    ``/odom``, ``/scan``, ``/imu``, on the clock), ``atrv-deploy`` with the shipped Jackal ``follow_path`` policy, and a
    client playing Nav2's part: it plans from the robot's pose in ``map`` to the test-set episode's goal and sends
    ``FollowPath`` with a fresh plan every second of simulated time, as the behaviour tree does, until the node
    answers; the goal is reached in the map frame (the true pose) and the answer is SUCCEEDED."""
    import numpy as np
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rosgraph_msgs.msg import Clock

    from atrv_warp.deploy.nav2 import load_follow_path
    from atrv_warp.rl.export import export_policy
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.world import load_map

    office = ROOT / "atrv_warp" / "assets" / "maps" / "office.yaml"
    FollowPath, where = load_follow_path()
    assert FollowPath is not None, where
    policy = export_policy("follow_path_jackal", tmp_path / "jackal_path.pt2")
    env = RoverEnv(1, robot="jackal", task="follow_path", seed=0, maps=[load_map(office)])  # the node's first episode
    env.reset()
    start = env.sim.root_pose[0, :2].tolist()
    goal, goal_yaw = env.target[0].tolist(), float(env.target_yaw[0])
    plan = _seen_planner(env)
    sim_args = ("robot:=jackal", "task:=follow_path", f"map:={office}", "publish_rate:=20.0", "real_time_factor:=2.0",
                "duration:=150.0")  # twice real time: the deploy node keeps the simulated clock
    sim = subprocess.Popen([sys.executable, "-m", "atrv_warp.ros", "--ros-args",
                            *(a for p in sim_args for a in ("-p", p))], env=ros_env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    node = subprocess.Popen([sys.executable, "-m", "atrv_warp.deploy", str(policy), "--ros-args", "-p",
                             "use_sim_time:=true", "-p", "robot:=jackal", "-p", "cmd_vel_topic:=cmd_vel"],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    client_node = rclpy.create_node("nav2_stand_in")
    truth, clock = [], [0.0]
    client_node.create_subscription(Odometry, "/ground_truth/odom", truth.append, 10)
    client_node.create_subscription(
        Clock, "/clock", lambda m: clock.__setitem__(0, m.clock.sec + 1e-9 * m.clock.nanosec), 10)
    client = ActionClient(client_node, FollowPath, "/follow_path")

    def spin(seconds, until):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(client_node, timeout_sec=0.02)
            if until():
                return True
        return False

    def send():
        p = truth[-1].pose.pose.position
        request = FollowPath.Goal()
        request.path.header.frame_id = "map"
        points = plan([p.x, p.y], goal)
        for k, (x, y) in enumerate(points):
            pose = PoseStamped()
            pose.header.frame_id = "map"
            pose.pose.position.x, pose.pose.position.y = float(x), float(y)
            yaw = goal_yaw if k == len(points) - 1 else 0.0
            pose.pose.orientation.z, pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
            request.path.poses.append(pose)
        sent = client.send_goal_async(request)
        assert spin(10, sent.done) and sent.result().accepted
        return sent.result()

    answer, replans = None, 0
    try:
        assert spin(180, lambda: client.server_is_ready() and bool(truth)), "no FollowPath server or no robot"
        first = truth[-1].pose.pose.position
        assert math.hypot(first.x - start[0], first.y - start[1]) < 0.05  # the episode the client was given
        handle = send()
        while answer is None and clock[0] < 120.0:
            last = clock[0]
            spin(30, lambda last=last: clock[0] >= last + 1.0)
            result = handle.get_result_async()
            if spin(0.05, result.done):
                answer = result.result()
                break
            handle, replans = send(), replans + 1  # the behaviour tree's replan, about once a second
    finally:
        client.destroy()
        outs = []
        for proc in (node, sim):
            proc.send_signal(2)
            try:
                outs.append(proc.communicate(timeout=30)[0])
            except subprocess.TimeoutExpired:
                proc.kill()
                outs.append(proc.communicate()[0])
        client_node.destroy_node()
    p = truth[-1].pose.pose
    yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
    where = (f"at ({p.position.x:.2f}, {p.position.y:.2f}, {yaw:.2f}) after {clock[0]:.0f} s and {replans} replans, "
             f"goal ({goal[0]:.2f}, {goal[1]:.2f}, {goal_yaw:.2f})")
    assert answer is not None and answer.status == GoalStatus.STATUS_SUCCEEDED, (where, outs[0][-3000:])
    assert np.hypot(p.position.x - goal[0], p.position.y - goal[1]) < 0.3 and replans > 5, where
    assert abs(math.remainder(yaw - goal_yaw, 2 * math.pi)) < 0.3, where


@pytest.mark.slow  # live ROS 2 contexts
def test_each_shipped_robot_has_deploy_parameters_the_node_runs_with(tmp_path):
    """Every shipped robot: its file's ``[deploy]`` table gives parameters the node takes (every key known, every
    value valid, the robot named), written as the launch writes them; its topics resolved in the robot's namespace,
    and an RViz view of those topics. One launch file serves them all."""
    import yaml

    from atrv_warp.core.robot import ROBOTS, load_robot
    from atrv_warp.deploy.contract import load_deployable
    from atrv_warp.deploy.launching import LAUNCH_FILE, deploy_robots, params_file, robot_parameters, rviz_config
    from atrv_warp.deploy.node import DeployNode

    policy = load_deployable(write_policy(tmp_path / "tiny.pt2", task_contract()))
    assert deploy_robots() == ROBOTS  # every shipped robot says how it deploys
    assert "def generate_launch_description():" in LAUNCH_FILE.read_text()
    assert {r: load_robot(r).deploy.get("tf_in_namespace", False) for r in ROBOTS} == {
        "atrvjr": False, "husky": True, "jackal": True}  # Clearpath's stack keeps /tf in the robot's namespace
    for robot in ROBOTS:
        params = robot_parameters(robot)
        assert params["robot"] == robot
        view = yaml.safe_load(rviz_config(robot))["Visualization Manager"]
        topics = {d["Name"]: d["Topic"]["Value"] for d in view["Displays"] if "Topic" in d}
        assert topics["Scan"] == params["scan_topic"] and topics["Path driven"] == params["odom_topic"]
        assert topics["Command"] == "command_path"
        assert view["Global Options"]["Fixed Frame"] == params["odom_frame"]
        args = ["--ros-args", "-r", "__ns:=/robot_7", "--params-file", str(params_file(robot, tmp_path)),
                "-p", "allow_other_robot:=true"]  # the test's policy was trained on the ATRV-Jr
        ctx = rclpy.Context()
        rclpy.init(args=["atrv-deploy", *args], context=ctx)
        try:
            node = DeployNode(policy, args, context=ctx)
            names = {name for name, _ in node.get_topic_names_and_types()} | {
                p.topic_name for p in node.publishers}
            subscribed = {s.topic_name for s in node.subscriptions}
            assert f"/robot_7/{params['scan_topic']}" in subscribed and f"/robot_7/{params['odom_topic']}" in subscribed
            assert f"/robot_7/{params['cmd_vel_topic']}" in names and node.stamped == params["enable_stamped_cmd_vel"]
            assert "/robot_7/command_path" in names
            node.stop("test")
            node.destroy_node()
        finally:
            rclpy.shutdown(context=ctx)
