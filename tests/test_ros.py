"""ROS 2 bridge: a real node in its own process, driven by a real rclpy client, on loopback only."""

import itertools
import math
import os
import random
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
from geometry_msgs.msg import PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String


@pytest.fixture(scope="module")
def ros_env():
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(random.randint(1, 100)),
               PYTHONUNBUFFERED="1")
    old = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")}
    os.environ.update({k: env[k] for k in old})
    rclpy.init()
    yield env
    rclpy.try_shutdown()
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


class Client:
    def __init__(self, name):
        self.node = rclpy.create_node(name)
        qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
        self.poses, self.status = [], []
        self.node.create_subscription(PoseStamped, "/pose", self.poses.append, qos)
        self.node.create_subscription(String, "/goal_status", lambda m: self.status.append(m.data), 10)
        self.cmd = self.node.create_publisher(String, "/command", qos)
        self.goal = self.node.create_publisher(PoseStamped, "/goal", qos)

    def spin(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.02)

    def wait_for(self, cond, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not cond():
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return cond()

    def send(self, text):
        self.cmd.publish(String(data=text))

    def close(self):
        self.node.destroy_node()


def start_node(env, *params):
    args = [sys.executable, "-m", "atrv_warp.ros", "--ros-args"]
    for p in params:
        args += ["-p", p]
    return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def stop(proc):
    proc.send_signal(2)  # Ctrl-C
    try:
        out, _ = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def yaw_of(msg):
    q = msg.pose.orientation
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def test_live_node_rate_stamps_and_commands(ros_env):
    proc = start_node(ros_env, "wait_for_subscribers:=1")
    client = Client("atrv_test_client")
    try:
        assert client.wait_for(lambda: len(client.poses) > 3, timeout=90), "no /pose received"
        client.poses.clear()
        t0 = time.monotonic()
        client.spin(2.0)
        elapsed = time.monotonic() - t0
        rate = len(client.poses) / elapsed
        assert 8.0 <= rate <= 12.0, rate  # 10 Hz in real time
        stamps = [p.header.stamp.sec + 1e-9 * p.header.stamp.nanosec for p in client.poses]
        steps = [b - a for a, b in itertools.pairwise(stamps)]
        assert all(abs(s - 0.1) < 1e-6 for s in steps), steps  # simulation time, 0.1 s apart
        assert client.poses[-1].header.frame_id == "center_link"
        x0 = client.poses[-1].pose.position.x
        client.send("forward")
        client.spin(1.5)
        assert client.poses[-1].pose.position.x > x0 + 0.5
        client.send("rotate_left")
        client.spin(0.5)
        yaw0 = yaw_of(client.poses[-1])
        client.spin(1.0)
        turned = (yaw_of(client.poses[-1]) - yaw0 + math.pi) % (2 * math.pi) - math.pi
        assert turned > 0.3
        n = len(client.poses)
        client.send("fly to the moon")
        client.send("")
        client.spin(1.0)
        assert len(client.poses) >= n + 8  # still publishing after garbage
        assert proc.poll() is None
    finally:
        client.close()
        out = stop(proc)
    assert "ignored unknown command 'fly to the moon'" in out
    assert proc.returncode == 0, out[-2000:]


def test_fast_run_matches_simulator_and_records_bag(ros_env, tmp_path):
    bag = tmp_path / "run.mcap"
    proc = start_node(ros_env, "real_time_factor:=0.0", "duration:=3.0", "mode:=forward", "x:=1.0", "y:=-2.0",
                      "yaw:=0.5", "wait_for_subscribers:=1", f"bag:={bag}")
    client = Client("atrv_fast_client")
    try:
        assert client.wait_for(lambda: proc.poll() is not None, timeout=120), "node did not finish"
        client.spin(0.5)
    finally:
        client.close()
        out = stop(proc) if proc.poll() is None else proc.communicate()[0]
    assert proc.returncode == 0, out[-2000:]
    published = [(p.header.stamp.sec + 1e-9 * p.header.stamp.nanosec, p.pose.position.x, p.pose.position.y)
                 for p in client.poses]
    assert len(published) == 31  # t = 0, 0.1, ..., 3.0 s

    from atrv_warp import RoverSim

    sim = RoverSim(1)
    sim.reset(poses=[[1.0, -2.0, 0.5]])
    sim.set_mode("forward")
    own = [(0.0, sim.root_pose[0, 0].item(), sim.root_pose[0, 1].item())]
    for i in range(60):
        sim.step()
        if i % 2 == 1:
            own.append((sim.sim_time, sim.root_pose[0, 0].item(), sim.root_pose[0, 1].item()))
    for (ts, x, y), (ts2, x2, y2) in zip(published, own):
        assert ts == pytest.approx(ts2, abs=1e-9)
        assert (x, y) == pytest.approx((x2, y2), abs=1e-6)
    assert published[-1][1] > published[0][1] + 1.0

    from mcap_ros2.reader import read_ros2_messages

    topics = [m.channel.topic for m in read_ros2_messages(str(bag))]
    assert topics.count("/pose") == 31


def test_goal_mode_drives_to_goal(ros_env):
    proc = start_node(ros_env, "real_time_factor:=0.0", "duration:=15.0", "wait_for_subscribers:=1")
    client = Client("atrv_goal_client")
    try:
        assert client.wait_for(lambda: len(client.poses) > 0, timeout=90)
        goal = PoseStamped()
        goal.pose.position.x, goal.pose.position.y = 4.0, 3.0
        # The node runs as fast as possible: send the goal at once, repeatedly until it is taken.
        assert client.wait_for(lambda: (client.goal.publish(goal) or bool(client.status)), timeout=60)
        assert client.wait_for(lambda: "reached" in client.status, timeout=60), client.status[-3:]
        last = client.poses[-1].pose.position
        assert math.hypot(last.x - 4.0, last.y - 3.0) < 1.5
    finally:
        client.close()
        out = stop(proc) if proc.poll() is None else proc.communicate()[0]
    assert "goal reached" in out


def test_missing_extra_message():
    from atrv_warp.integrations.ros import MISSING_ROS_MESSAGE

    assert "pip install -e '.[ros]'" in MISSING_ROS_MESSAGE
