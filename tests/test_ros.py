"""ROS 2 bridge: a real node in its own process, driven by a real rclpy client, on loopback only."""

import itertools
import math
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
from geometry_msgs.msg import PoseStamped, Twist
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from atrv_warp.core.geometry import quat_to_yaw


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
    """The simulator node with ``params`` (``name:=value`` each, or ``--params-file``, ``FILE``)."""
    args = [sys.executable, "-m", "atrv_warp.ros", "--ros-args"]
    for p in params:
        args += [p] if p.startswith("-") or p.endswith(".yaml") else ["-p", p]
    return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def stop(proc, signum=signal.SIGINT):
    """Ctrl-C (or ``signum``): the node ends its step loop and closes with its context alive."""
    proc.send_signal(signum)
    try:
        out, _ = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def yaw_of(msg):
    q = msg.pose.orientation
    return float(quat_to_yaw((q.x, q.y, q.z, q.w)))


@pytest.mark.slow  # a live ROS 2 node
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
        start = len(client.poses) - 1
        client.spin(1.0)
        # +-5 N·m exceeds what a Coulomb turn in place needs, so the rover spins up; summing the 10 Hz
        # poses' increments (each under half a turn) unwraps its yaw
        yaws = [yaw_of(p) for p in client.poses[start:]]
        turned = sum((b - a + math.pi) % (2 * math.pi) - math.pi for a, b in itertools.pairwise(yaws))
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
    # the last log line goes out on a live context (rclpy's own Ctrl-C handler shut it down under the node)
    assert "stopped at sim time" in out and "context is invalid" not in out, out[-2000:]


@pytest.mark.slow  # a live ROS 2 node
def test_fast_run_matches_simulator_and_records_bag(ros_env, tmp_path):
    kept = tmp_path / "run.mcap"
    kept.write_text("an earlier recording\n")  # is kept: the node records to the next free name, and says so
    bag = tmp_path / "run-1.mcap"
    proc = start_node(ros_env, "real_time_factor:=0.0", "duration:=3.0", "mode:=forward", "x:=1.0", "y:=-2.0",
                      "yaw:=0.5", "wait_for_subscribers:=1", f"bag:={kept}")
    client = Client("atrv_fast_client")
    try:
        assert client.wait_for(lambda: proc.poll() is not None, timeout=120), "node did not finish"
        client.spin(0.5)
    finally:
        client.close()
        out = stop(proc) if proc.poll() is None else proc.communicate()[0]
    assert proc.returncode == 0, out[-2000:]
    assert kept.read_text() == "an earlier recording\n" and f"{kept} exists and is kept: writing {bag}" in out
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

    messages = list(read_ros2_messages(str(bag)))
    topics = [m.channel.topic for m in messages]
    assert topics.count("/pose") == 31
    check_bag_frames(messages)


def _matrix(t):
    from atrv_warp.integrations.ros.frames import pose_matrix

    r, p = t.transform.rotation, t.transform.translation
    return pose_matrix((p.x, p.y, p.z), (r.x, r.y, r.z, r.w))


def check_bag_frames(messages):
    """The bag's /tf and /tf_static (tf2_msgs/TFMessage, written from its definition) against the node's
    own /odom, /ground_truth/odom and /joint_states of the same stamps."""
    import numpy as np

    from atrv_warp.integrations.ros.frames import pose_matrix, turn_matrix
    from atrv_warp.sim.urdf import load_rover

    by_topic = {}
    for m in messages:
        by_topic.setdefault(m.channel.topic, []).append(m)
    assert by_topic["/tf"][0].schema.name == "tf2_msgs/msg/TFMessage"
    assert "<robot" in by_topic["/robot_description"][0].ros_msg.data
    static = {t.child_frame_id: t for t in by_topic["/tf_static"][0].ros_msg.transforms}
    assert static["center_link"].header.frame_id == "base_link"
    lrf = static["lrf_frame"].transform.translation  # the URDF's lrf_frame joint: 0.3 0 0.19
    assert (lrf.x, lrf.y, lrf.z) == pytest.approx((0.3, 0.0, 0.19))

    def stamped(topic):
        return {_stamp(m.ros_msg): m.ros_msg for m in by_topic[topic]}

    odom, truth, joints = stamped("/odom"), stamped("/ground_truth/odom"), stamped("/joint_states")
    desc = load_rover()
    assert len(by_topic["/tf"]) == len(odom) > 10
    for m in by_topic["/tf"]:
        tf = {t.child_frame_id: t for t in m.ros_msg.transforms}
        stamp = _stamp(tf["odom"])
        assert tf["odom"].header.frame_id == "world" and tf["base_link"].header.frame_id == "odom"
        o, g = odom[stamp].pose.pose, truth[stamp].pose.pose
        # odom -> base_link is the wheel odometry; world -> odom -> base_link is the true pose
        np.testing.assert_allclose(_matrix(tf["base_link"]), pose_matrix(
            (o.position.x, o.position.y, o.position.z),
            (o.orientation.x, o.orientation.y, o.orientation.z, o.orientation.w)), atol=1e-9)
        np.testing.assert_allclose(_matrix(tf["odom"]) @ _matrix(tf["base_link"]), pose_matrix(
            (g.position.x, g.position.y, g.position.z),
            (g.orientation.x, g.orientation.y, g.orientation.z, g.orientation.w)), atol=1e-6)
        # each wheel sits at its joint origin, turned by its /joint_states position about its axis
        position = dict(zip(joints[stamp].name, joints[stamp].position))
        for wheel in desc.wheels:
            expected = np.asarray(wheel.origin) @ turn_matrix(wheel.axis, position[wheel.joint])
            np.testing.assert_allclose(_matrix(tf[wheel.link]), expected, atol=1e-9)
    spin = [dict(zip(joints[s].name, joints[s].position))[desc.wheels[0].joint] for s in sorted(joints)]
    assert abs(spin[-1] - spin[0]) > 1.0  # driving forward, the wheels turned


def test_frames_round_trip_quaternions():
    import numpy as np

    from atrv_warp.integrations.ros.frames import pose_matrix, transform_dict, turn_matrix

    rng = np.random.default_rng(0)
    for q in rng.normal(size=(200, 4)):
        q = q / np.linalg.norm(q)
        q = q if q[3] >= 0 else -q
        rotation = transform_dict("a", "b", 0, pose_matrix((0, 0, 0), q))["transform"]["rotation"]
        assert [rotation[k] for k in "xyzw"] == pytest.approx(q.tolist(), abs=1e-6)
    m = turn_matrix((0, 0, 1), np.pi / 2)
    np.testing.assert_allclose(m[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    t = transform_dict("a", "b", 1_500_000_000, pose_matrix((1, 2, 3), (0, 0, 0, 1)))
    assert t["header"] == {"stamp": {"sec": 1, "nanosec": 500_000_000}, "frame_id": "a"}
    assert t["transform"]["translation"] == {"x": 1.0, "y": 2.0, "z": 3.0}


def test_world_markers_of_a_nav_world_and_a_non_finite_one_left_out():
    """Real visualization_msgs messages from a nav world: four walls, each obstacle where the simulator
    has it, the goal on the ground, a height-coloured terrain mesh; a world with a NaN is left out, named."""
    import dataclasses
    import math

    import numpy as np
    from visualization_msgs.msg import Marker

    from atrv_warp import ATRVjrEnv
    from atrv_warp.integrations.ros.markers import scene_of, world_markers

    env = ATRVjrEnv(2, task="nav", seed=3)
    env.reset()
    good = scene_of(env.sim, 0, ns="rover_0/", goal=(4.0, -2.0), goal_radius=1.0)
    bad = scene_of(env.sim, 1, ns="rover_1/", goal=None, goal_radius=1.0)
    pose = bad.pose.copy()
    pose[0, 0] = np.nan
    msg, skipped = world_markers(env.sim.arena_cfg, [good, dataclasses.replace(bad, pose=pose)], "world", None)
    assert skipped == ["rover_1/"]
    assert msg.markers[0].action == Marker.DELETEALL
    by_ns = {}
    for m in msg.markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
        assert m.header.frame_id == "world"
        p, q = m.pose.position, m.pose.orientation
        assert all(math.isfinite(v) for v in (p.x, p.y, p.z, q.x, q.y, q.z, q.w))
    assert set(by_ns) == {"arena", "rover_0/obstacles", "rover_0/goal", "rover_0/terrain"}
    assert len(by_ns["arena"]) == 4 and max(m.pose.position.x for m in by_ns["arena"]) > env.sim.arena_cfg.half_size
    kind, xy = env.sim.obstacles.kind[0].numpy(), env.sim.obstacles.pose[0, :, :2].numpy()
    placed = sorted((m.pose.position.x, m.pose.position.y) for m in by_ns["rover_0/obstacles"])
    assert placed and np.allclose(placed, sorted(map(tuple, xy[kind > 0].tolist())), atol=1e-6)
    goal = by_ns["rover_0/goal"][0]
    assert (goal.pose.position.x, goal.pose.position.y, goal.scale.x) == pytest.approx((4.0, -2.0, 2.0))
    assert goal.pose.position.z == pytest.approx(good.ground_at(4.0, -2.0) + 0.02)
    terrain = by_ns["rover_0/terrain"][0]
    assert terrain.type == Marker.TRIANGLE_LIST and len(terrain.points) == len(terrain.colors)
    assert len(terrain.points) % 3 == 0 and len(terrain.points) >= 3 * 2 * 30 ** 2
    z = np.array([pt.z for pt in terrain.points])
    heights = good.heights
    assert z.min() == pytest.approx(good.terrain_base + heights.min(), abs=0.05)
    assert len({(c.r, c.g, c.b) for c in terrain.colors}) > 50  # coloured by height


@pytest.mark.slow  # a live ROS 2 node
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
    """Without rclpy (its import blocked in a fresh interpreter) the node says how to install the extra, exit 2."""
    code = "import sys\nsys.modules['rclpy'] = None\nfrom atrv_warp.cli.ros import main\nsys.exit(main(['atrv-ros']))\n"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "ROS 2 Python packages are not installed" in proc.stderr and "pip install -e '.[ros]'" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.slow  # a live ROS 2 node
def test_the_node_noise_reaches_its_messages(ros_env):
    """The node's default sensor noise is the noise training randomizes with (SENSOR_NOISE), measured in its
    messages: a rover at rest, its /imu, /joint_states and /scan over 80 readings."""
    import statistics

    from atrv_warp.sim.config import SENSOR_NOISE

    proc = start_node(ros_env, "wait_for_subscribers:=1", "real_time_factor:=0.0", "publish_rate:=20.0")
    client = DriverClient("atrv_noise_client", [""])
    try:
        assert client.wait(lambda: len(client.msgs["/imu"]) >= 100 and len(client.msgs["/scan"]) >= 100
                           and len(client.msgs["/joint_states"]) >= 100, timeout=120), "too few messages"
    finally:
        client.node.destroy_node()
        stop(proc)
    imu, scans, joints = (client.msgs[k][20:100] for k in ("/imu", "/scan", "/joint_states"))  # after settling
    accel = statistics.stdev(m.linear_acceleration.z for m in imu)
    gyro = statistics.stdev(m.angular_velocity.z for m in imu)
    wheel = statistics.stdev(v for m in joints for v in m.velocity)
    beams = list(zip(*(m.ranges for m in scans)))
    scan = statistics.mean(statistics.stdev(b) for b in beams if all(math.isfinite(r) for r in b))
    for got, want in ((accel, SENSOR_NOISE.accel), (gyro, SENSOR_NOISE.gyro), (wheel, SENSOR_NOISE.wheel_speed),
                      (scan, SENSOR_NOISE.scan_range)):
        assert got == pytest.approx(want, rel=0.3), (accel, gyro, wheel, scan)
    seen = [b for b in beams if any(math.isfinite(r) for r in b)]  # beams that hit something (walls in range)
    dropped = sum(not math.isfinite(r) for b in seen for r in b) / sum(len(b) for b in seen)
    assert dropped == pytest.approx(SENSOR_NOISE.scan_dropout, abs=0.02)


class DriverClient:
    """Subscribes to every base-driver topic of the rovers under ``prefixes``; publishes /cmd_vel."""

    def __init__(self, name, prefixes):
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Imu, JointState, LaserScan

        self.node = rclpy.create_node(name)
        self.msgs = {}
        for prefix in prefixes:
            for topic, kind in (("odom", Odometry), ("ground_truth/odom", Odometry), ("joint_states", JointState),
                                ("imu", Imu), ("scan", LaserScan)):
                key = f"{prefix}/{topic}"
                self.msgs[key] = []
                self.node.create_subscription(kind, key, self.msgs[key].append, 100)
        self.poses = []  # the node waits for a /pose subscriber of its first rover before starting
        self.node.create_subscription(PoseStamped, f"{prefixes[0]}/pose", self.poses.append, 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL)
        self.description = []
        self.node.create_subscription(String, "/robot_description", lambda m: self.description.append(m.data),
                                      latched)
        self.cmd = {p: self.node.create_publisher(Twist, f"{p}/cmd_vel", 10) for p in prefixes}

    def drive(self, seconds, commands):
        """Publish ``commands`` {prefix: (v, w)} at 10 Hz for ``seconds`` of wall time, spinning."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for prefix, (v, w) in commands.items():
                msg = Twist()
                msg.linear.x, msg.angular.z = v, w
                self.cmd[prefix].publish(msg)
            t = time.monotonic() + 0.1
            while time.monotonic() < t:
                rclpy.spin_once(self.node, timeout_sec=0.02)

    def last(self, key):
        return self.msgs[key][-1]

    def wait(self, cond, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not cond():
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return cond()


def _planar(odom):
    p = odom.pose.pose.position
    return p.x, p.y


def _yaw(odom):
    q = odom.pose.pose.orientation
    return float(quat_to_yaw((q.x, q.y, q.z, q.w)))


def _wrap(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _stamp(msg):
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def _paired(client, a, b):
    """The newest messages of topics ``a`` and ``b`` with the same stamp (one simulator step)."""
    stamps = {_stamp(m): m for m in client.msgs[b]}
    return next((m, stamps[_stamp(m)]) for m in reversed(client.msgs[a]) if _stamp(m) in stamps)


@pytest.mark.slow  # a live ROS 2 node
def test_base_driver_two_rovers_cmd_vel_odometry_imu_watchdog(ros_env):
    proc = start_node(ros_env, "num_rovers:=2", "wait_for_subscribers:=1", "duration:=40.0")
    client = DriverClient("atrv_driver_client", ["/rover_0", "/rover_1"])
    try:
        assert client.wait(lambda: all(client.msgs[k] for k in client.msgs), 90), "no state topics"
        # rover 0 drives straight at 0.5 m/s, rover 1 turns in place at 0.3 rad/s: independently
        client.drive(1.5, {"/rover_0": (0.5, 0.0), "/rover_1": (0.0, 0.3)})  # past the spin-up slip
        truth, odom = _paired(client, "/rover_0/ground_truth/odom", "/rover_0/odom")
        start0, odom0 = _planar(truth), _planar(odom)
        truth, odom = _paired(client, "/rover_1/ground_truth/odom", "/rover_1/odom")
        start1, yaw_truth1, yaw_odom1 = _planar(truth), _yaw(truth), _yaw(odom)
        client.drive(3.0, {"/rover_0": (0.5, 0.0), "/rover_1": (0.0, 0.3)})
        truth0, truth1 = client.last("/rover_0/ground_truth/odom"), client.last("/rover_1/ground_truth/odom")
        assert truth0.twist.twist.linear.x == pytest.approx(0.5, rel=0.10)
        assert abs(truth0.twist.twist.angular.z) < 0.02
        assert truth1.twist.twist.angular.z == pytest.approx(0.3, rel=0.15)
        assert math.dist(_planar(truth1), start1) < 0.1  # turned in place
        # wheel odometry against the truth, cruising: a straight run agrees within 5 % of the distance,
        # and the turn's heading change within 5 % (the effective track is calibrated for skid)
        truth, odom = _paired(client, "/rover_0/ground_truth/odom", "/rover_0/odom")
        driven, odo_driven = math.dist(_planar(truth), start0), math.dist(_planar(odom), odom0)
        assert driven > 1.0
        assert odo_driven == pytest.approx(driven, rel=0.05), (odo_driven, driven)
        truth, odom = _paired(client, "/rover_1/ground_truth/odom", "/rover_1/odom")
        turned, odo_turned = _wrap(_yaw(truth) - yaw_truth1), _wrap(_yaw(odom) - yaw_odom1)
        assert turned > 0.5 and odo_turned == pytest.approx(turned, rel=0.05), (odo_turned, turned)
        # message types, frames, joints, IMU at rest-ish on flat ground: specific force ~ +g up
        odom = client.last("/rover_0/odom")  # the frames /tf names: one rule for /tf and the headers
        assert (odom.header.frame_id, odom.child_frame_id) == ("rover_0/odom", "rover_0/base_link")
        assert client.last("/rover_1/ground_truth/odom").child_frame_id == "rover_1/base_link"
        assert len(odom.pose.covariance) == 36 and odom.pose.covariance[0] > 0
        joints = client.last("/rover_1/joint_states")
        assert len(joints.name) == 4 and len(joints.position) == 4 and len(joints.velocity) == 4
        imu = client.last("/rover_0/imu")
        assert imu.header.frame_id == "rover_0/cbimu_frame"
        assert imu.linear_acceleration.z == pytest.approx(9.81, abs=0.5)
        assert "<robot" in client.description[0]
        # /scan: 181 beams over 180 deg from lrf_frame (0.3 m ahead of the chassis origin); the forward
        # beam meets the +x wall (inner face at x = 15 m) and the leftmost the +y wall, same stamp as the truth
        scan, truth = _paired(client, "/rover_0/scan", "/rover_0/ground_truth/odom")
        assert scan.header.frame_id == "rover_0/lrf_frame" and len(scan.ranges) == 181
        assert scan.angle_min == pytest.approx(-math.pi / 2) and scan.angle_max == pytest.approx(math.pi / 2)
        assert (scan.range_min, scan.range_max) == pytest.approx((0.1, 20.0))
        x, y = _planar(truth)
        assert scan.ranges[90] == pytest.approx(15.0 - (x + 0.3), abs=0.05)
        assert scan.ranges[180] == pytest.approx(15.0 - y, abs=0.05)
        n = len(client.msgs["/rover_0/odom"])
        client.drive(2.0, {})
        rate = (len(client.msgs["/rover_0/odom"]) - n) / 2.0
        assert 7.0 <= rate <= 13.0, rate  # 10 Hz of sim time, in real time
        # watchdog: no /cmd_vel for 0.5 s stops the rover; a NaN command is ignored
        bad = Twist()
        bad.linear.x = float("nan")
        client.cmd["/rover_1"].publish(bad)
        client.drive(2.0, {})
        assert abs(client.last("/rover_0/ground_truth/odom").twist.twist.linear.x) < 0.05
        assert abs(client.last("/rover_1/ground_truth/odom").twist.twist.angular.z) < 0.02
        assert proc.poll() is None
    finally:
        client.node.destroy_node()
        out = stop(proc)
    assert "/rover_0/cmd_vel silent for 0.5 s: stopping" in out
    assert "ignored non-finite /rover_1/cmd_vel" in out
    assert proc.returncode == 0, out[-2000:]


def test_the_simulator_nodes_parameters_are_checked_in_the_deploy_nodes_style():
    """Every parameter of ``python -m atrv_warp.ros`` has its type and range (:mod:`atrv_warp.core.parameters`, as
    the deploy node's): a number takes an integer, an integer an integral float, -1 means the robot's where it may;
    anything else is one line naming the parameter, what it needs and what it got."""
    from atrv_warp.core.parameters import ParameterError, check_parameters
    from atrv_warp.integrations.ros.parameters import PARAMETERS, unknown_parameters

    ok = check_parameters(PARAMETERS, {"real_time_factor": 1, "num_rovers": 2.0, "wheel_kp": -1, "x": -3})
    assert ok["real_time_factor"] == 1.0 and ok["wheel_kp"] == -1.0 and ok["x"] == -3.0
    assert ok["num_rovers"] == 2 and isinstance(ok["num_rovers"], int) and ok["mode"] == "coast"
    cases = [("num_rovers", "abc", "parameter num_rovers must be an integer, got 'abc' (str)"),
             ("num_rovers", 2.5, "parameter num_rovers must be a whole number in [1, 64], got 2.5 (float)"),
             ("num_rovers", 65, "parameter num_rovers must be an integer in [1, 64], got 65 (an integer)"),
             ("tf", "maybe", "parameter tf must be true or false, got 'maybe' (str)"),
             ("lockstep", 1, "parameter lockstep must be true or false, got 1 (an integer)"),
             ("mode", "goal", ("parameter mode must be one of ['coast', 'forward', 'backward', 'rotate_right', "
                               "'rotate_left'], got 'goal'")),
             ("variant", "fast", "parameter variant must be one of ['realistic', 'reference']"),
             ("scan_dropout", 1.5, "parameter scan_dropout must be a finite number in [0, 1], got 1.5"),
             ("publish_rate", 0.0, "parameter publish_rate must be a finite number > 0 [Hz], got 0.0"),
             ("wheel_ki", -2.0, "parameter wheel_ki must be a finite number >= 0 [N·m/rad], or -1 (the robot's)"),
             ("effective_track_factor", 0.0, ("parameter effective_track_factor must be a finite number > 0, or -1 "
                                              "(the robot's), got 0.0")),
             ("x", math.nan, "parameter x must be a finite number [m], got nan (float)"),
             ("seed", -1, "parameter seed must be an integer >= 0, got -1"),
             ("odom_frame", "/odom", "parameter odom_frame must be a tf frame id without spaces or a leading '/'"),
             ("sim_config", "a\x00b.toml", "parameter sim_config must be text without control characters")]
    for name, value, message in cases:
        with pytest.raises(ParameterError) as err:
            check_parameters(PARAMETERS, {name: value})
        assert str(err.value).startswith(message) and "\n" not in str(err.value), (name, str(err.value))
    assert unknown_parameters(["-p", "num_rovrs:=2", "-p", "seed:=1"], {"p.yaml": ["tf", "lock_step"]}) == [
        "num_rovrs", "lock_step (in p.yaml)"]


def test_a_publish_rate_the_steps_cannot_give_is_said_with_the_rate_it_gets():
    from atrv_warp.integrations.ros.parameters import publish_every

    assert publish_every(20.0, 0.05) == (1, None) and publish_every(10.0, 0.05) == (2, None)
    every, line = publish_every(20.0, 0.09)  # the ATRV-Jr's 11.1 Hz steps
    assert every == 1 and line == ("publish_rate 20 Hz: state topics every 1 step(s) of 0.09 s, 11.1 Hz (the "
                                   "simulator's step rate, the most there is)")
    assert publish_every(4.0, 0.09)[1] == "publish_rate 4 Hz: state topics every 3 step(s) of 0.09 s, 3.7 Hz"


@pytest.mark.slow  # a live ROS 2 node
def test_bad_parameters_are_refused_at_start(ros_env, tmp_path):
    from atrv_warp.policy import make_actor, save_policy

    old = tmp_path / "old_nav.pt"  # a nav policy from before the nav task observed its last actions
    save_policy(make_actor(16, 1, obs_dim=26), old, width=16, depth=1, meta={"task": "nav"})
    params_file = tmp_path / "params.yaml"
    params_file.write_text("atrv_sim:\n  ros__parameters:\n    num_rovrs: 2\n")
    from atrv_warp.core.robot import robot_file

    shipped = robot_file("jackal")  # a robot whose URDF loops through the chassis' parent: it hung the node for 90 s
    (tmp_path / "loop.urdf").write_text(shipped.with_suffix(".urdf").read_text().replace(
        "</robot>", '<joint name="back" type="fixed"><parent link="chassis_link"/><child link="base_link"/></joint></robot>'))
    (tmp_path / "loop.toml").write_text(shipped.read_text().replace('urdf = "jackal.urdf"', 'urdf = "loop.urdf"'))
    starting = []
    for params, message in ((["bogus_param:=1"], "unknown parameter(s) bogus_param; known: "),
                            (["num_rovers:=0"], "parameter num_rovers must be an integer in [1, 64], got 0"),
                            (["num_rovers:=abc"], "parameter num_rovers must be an integer, got 'abc' (str)"),
                            (["tf:=maybe"], "parameter tf must be true or false, got 'maybe' (str)"),
                            ([f"robot:={tmp_path / 'loop.toml'}"], "parameter robot: " + str(tmp_path / "loop.urdf")),
                            (["--params-file", str(params_file)], f"unknown parameter(s) num_rovrs (in {params_file})"),
                            (["task:=maze"], "task='maze' is not a task"),
                            (["cmd_vel_delay:=-0.1"], "parameter cmd_vel_delay must be a finite number >= 0 [s], got -0.1"),
                            (["terrain:=moon"], "terrain='moon' is not a terrain"),
                            (["task:=nav", f"policy:={old}"], "observes 26 values, task 'nav' observes 32"),
                            ([f"policy:={tmp_path / 'none.pt'}"], "parameter policy: policy file not found"),
                            ([f"bag:={tmp_path / 'missing' / 'x.mcap'}"], "parameter bag: "),
                            ([f"bag:={tmp_path}"], "is a folder"),
                            (["bag:=/proc/atrv.mcap"], "cannot write in /proc")):
        starting.append((start_node(ros_env, *params), params, message))
        if len(starting) == 2:  # two at a time: each refusal is an interpreter's start, mostly imports
            refused(*starting.pop(0))
    for case in starting:
        refused(*case)


def refused(proc, params, message):
    """``proc``, a node started with ``params``, exits 2 saying ``message``."""
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 2, (params, out[-2000:])
    assert message in out, (params, out[-2000:])


@pytest.mark.slow  # a live ROS 2 node
def test_latched_markers_show_the_nav_world_and_the_goal(ros_env):
    """A late subscriber gets the world (transient local): the nav world's obstacles where the node's
    simulator put them, its terrain; after a /goal, the goal disc. Live /tf places base_link at the
    true pose; /tf_static holds the URDF's sensor frames."""
    import numpy as np
    from nav_msgs.msg import Odometry
    from visualization_msgs.msg import MarkerArray

    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

    TFMessage, where = load_interface(TF2_MSGS, "msg", "TFMessage")
    assert TFMessage is not None, where
    proc = start_node(ros_env, "task:=nav", "seed:=4", "wait_for_subscribers:=1", "duration:=30.0")
    client = Client("atrv_marker_client")
    arrays, tf, tf_static, truth = [], [], [], []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL)
    client.node.create_subscription(TFMessage, "/tf", tf.append, 100)
    client.node.create_subscription(Odometry, "/ground_truth/odom", truth.append, 100)
    try:
        assert client.wait_for(lambda: len(client.poses) > 0, timeout=120), "no /pose received"
        client.node.create_subscription(MarkerArray, "/visualization_marker_array", arrays.append, latched)
        client.node.create_subscription(TFMessage, "/tf_static", tf_static.append, latched)
        assert client.wait_for(lambda: bool(arrays) and bool(tf_static), timeout=30), "no latched markers or /tf_static"
        # live /tf (tf2_msgs built from its definition where no ROS install has it): the true pose, composed
        assert client.wait_for(lambda: len(tf) > 5, timeout=30), "no live /tf"
        static = {t.child_frame_id: t for t in tf_static[-1].transforms}
        assert static["lrf_frame"].header.frame_id == "center_link"
        stamps = {_stamp(m): m for m in truth}
        live = [{t.child_frame_id: t for t in m.transforms} for m in tf]
        both = [f for f in live if _stamp(f["odom"]) in stamps]
        assert both, "no /tf with the stamp of a /ground_truth/odom"
        for f in both:
            g = stamps[_stamp(f["odom"])].pose.pose
            world_base = _matrix(f["odom"]) @ _matrix(f["base_link"])
            assert world_base[:3, 3] == pytest.approx([g.position.x, g.position.y, g.position.z], abs=1e-5)
        first = {m.ns for m in arrays[-1].markers[1:]}
        assert first == {"arena", "obstacles", "terrain"}, first
        obstacles = sorted((m.pose.position.x, m.pose.position.y) for m in arrays[-1].markers if m.ns == "obstacles")
        goal = PoseStamped()
        goal.pose.position.x, goal.pose.position.y = 3.0, 1.0
        assert client.wait_for(lambda: client.goal.publish(goal) or any(
            m.ns == "goal" for m in arrays[-1].markers), timeout=30), "no goal marker"
        disc = next(m for m in arrays[-1].markers if m.ns == "goal")
        assert (disc.pose.position.x, disc.pose.position.y) == pytest.approx((3.0, 1.0))
    finally:
        client.close()
        out = stop(proc, signal.SIGTERM)  # as a launch system stops it
    assert proc.returncode == 0, out[-2000:]
    assert "context is invalid" not in out, out[-2000:]
    from atrv_warp import ATRVjrEnv

    env = ATRVjrEnv(1, task="nav", seed=4)  # the node's own world: its first episode
    env.reset()
    kind, xy = env.sim.obstacles.kind[0].numpy(), env.sim.obstacles.pose[0, :, :2].numpy()
    assert obstacles and np.allclose(obstacles, sorted(map(tuple, xy[kind > 0].tolist())), atol=1e-5)


@pytest.mark.slow  # a live ROS 2 node
def test_a_map_is_served_on_map_and_the_rover_starts_in_its_free_space(ros_env, tmp_path):
    """``map:=FILE``: a late subscriber gets /map as map_server serves it (transient local, frame map, the cells as
    the file holds them); /tf's tree starts at map (map -> odom -> base_link: the true pose, in the map); the rover
    starts clear of the walls; a bad map stops the node in one line; ``publish_map`` and ``map_to_odom`` off leave
    both to a Nav2 stack's map_server and amcl."""
    import numpy as np
    from nav_msgs.msg import OccupancyGrid, Odometry
    from test_map_worlds import two_rooms

    from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface
    from atrv_warp.world import load_map, save_map

    TFMessage, where = load_interface(TF2_MSGS, "msg", "TFMessage")
    assert TFMessage is not None, where
    path = save_map(two_rooms(), tmp_path / "rooms.yaml")
    site = load_map(path)
    # "-p" before it: a .yaml alone is a params file
    proc = start_node(ros_env, "-p", f"map:={path}", "task:=nav_deploy", "wait_for_subscribers:=1", "duration:=30.0")
    client = Client("atrv_map_client")
    grids, tf, truth = [], [], []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL)
    client.node.create_subscription(TFMessage, "/tf", tf.append, 100)
    client.node.create_subscription(Odometry, "/ground_truth/odom", truth.append, 100)
    try:
        live = client.wait_for(lambda: len(client.poses) > 0 and len(tf) > 3, timeout=120)
        if live:  # a late subscriber
            client.node.create_subscription(OccupancyGrid, "/map", grids.append, latched)
            client.wait_for(lambda: bool(grids), timeout=30)
    finally:
        client.close()
        out = stop(proc, signal.SIGTERM)
    assert live and grids and proc.returncode == 0, out[-3000:]
    grid = grids[-1]
    assert grid.header.frame_id == "map" and grid.info.resolution == pytest.approx(site.resolution)
    assert (grid.info.width, grid.info.height) == (site.shape[1], site.shape[0])
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == pytest.approx(site.origin)
    assert np.array_equal(np.array(grid.data, dtype=np.int8).reshape(site.shape), site.cells)
    frames = {t.child_frame_id: t for m in tf for t in m.transforms}
    assert frames["odom"].header.frame_id == "map" and truth[-1].header.frame_id == "map"
    g = truth[-1].pose.pose.position
    row, col = site.cell_of(g.x, g.y)
    assert not site.walls[row, col] and "rovers start at their first episodes' starts" in out
    bad = start_node(ros_env, "-p", f"map:={tmp_path / 'gone.yaml'}")
    out, _ = bad.communicate(timeout=120)
    assert bad.returncode != 0 and f"parameter map: map not found: {tmp_path / 'gone.yaml'}" in out
    # under a stack that runs map_server and amcl: neither /map nor map -> odom, odom -> base_link still
    proc = start_node(ros_env, "-p", f"map:={path}", "task:=nav_deploy", "wait_for_subscribers:=1", "duration:=3.0",
                      "publish_map:=false", "map_to_odom:=false")
    client, grids, tf = Client("atrv_map_client_2"), [], []
    client.node.create_subscription(TFMessage, "/tf", tf.append, 100)
    client.node.create_subscription(OccupancyGrid, "/map", grids.append, latched)
    try:
        live = client.wait_for(lambda: len(tf) > 10, timeout=120)
    finally:
        client.close()
        out = stop(proc, signal.SIGTERM)
    frames = {(t.header.frame_id, t.child_frame_id) for m in tf for t in m.transforms}
    assert live and ("odom", "base_link") in frames and not any(c == "odom" for _, c in frames), (frames, out[-2000:])
    assert not grids and "on /map" not in out


def test_the_clock_counts_whole_steps_however_long_the_run():
    """The node's ROS time is its steps times the step's nanoseconds. It was ``round(sim_time * 1e9)``, the float sum
    of the steps: after 14,796 steps of 0.2 s (2,959 s) 1 ns short, so the deploy node's timer, due at the step,
    skipped it, and in lockstep the step went unanswered (one in nine of ten 200-episode closed loops over ROS 2)."""
    from atrv_warp.integrations.ros.rover_io import step_time_ns

    short = {}
    for step_dt in (0.2, 0.09, 0.05, 0.01):
        step_ns, sim_time = round(step_dt * 1e9), 0.0
        for k in range(1, 20_001):
            sim_time += step_dt  # as RoverSim.step sums it
            assert step_time_ns(sim_time, step_dt) == k * step_ns, (step_dt, k)
            if round(sim_time * 1e9) < k * step_ns:
                short.setdefault(step_dt, k)
    assert short[0.2] == 14_796, short  # where the closed loops' unanswered step was


def test_a_plan_is_published_as_nav2s_planner_hands_it_on_and_no_plan_as_no_poses():
    """``plan_message``: each pose facing the next, the last the goal's heading, in the given frame; a plan of one point
    is the goal; no plan (none was found) is a path without poses, not an error in the simulator's step."""
    from atrv_warp.integrations.ros.rover_io import plan_message

    def yaws(msg):
        return [2 * math.atan2(p.pose.orientation.z, p.pose.orientation.w) for p in msg.poses]

    msg = plan_message([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]], 3.0, "map")
    assert msg.header.frame_id == "map" and [p.header.frame_id for p in msg.poses] == ["map"] * 3
    assert [(p.pose.position.x, p.pose.position.y) for p in msg.poses] == [(0.0, 0.0), (1.0, 0.0), (1.0, 2.0)]
    assert yaws(msg) == pytest.approx([0.0, math.pi / 2, 3.0])
    assert yaws(plan_message([[4.0, 5.0]], -1.0, "map")) == pytest.approx([-1.0])
    assert plan_message([], 1.0, "map").poses == []


def test_foxglove_layout_shows_what_the_node_publishes():
    """docs/foxglove_layout.json: a 3D panel with the URDF from /robot_description, the markers, the scan and
    the odometry, following base_link; every topic it names is one the node publishes."""
    import json
    from pathlib import Path

    layout = json.loads((Path(__file__).resolve().parent.parent / "docs" / "foxglove_layout.json").read_text())
    panels = layout["configById"]
    scene = next(v for k, v in panels.items() if k.startswith("3D!"))
    assert scene["followTf"] == "base_link"
    assert {"/visualization_marker_array", "/scan", "/odom", "/ground_truth/odom"} <= set(scene["topics"])
    urdf = [layer for layer in scene["layers"].values() if layer["layerId"] == "foxglove.Urdf"]
    assert urdf and urdf[0]["topic"] == "/robot_description"
    named = set(scene["topics"]) | {p["value"].split(".")[0] for k, v in panels.items() if k.startswith("Plot!")
                                    for p in v["paths"]} | {v["topicPath"] for v in panels.values() if "topicPath" in v}
    published = {"/visualization_marker_array", "/scan", "/odom", "/ground_truth/odom", "/pose", "/goal_status",
                 "/joint_states", "/imu", "/robot_description"}
    assert named <= published, named - published
    ids = json.dumps(layout["layout"])
    assert all(k in ids for k in panels)  # every configured panel is placed


def test_interface_build_without_a_compiler_says_so(tmp_path, monkeypatch):
    from atrv_warp.core.ros_interfaces import TF2_MSGS, build_interfaces

    monkeypatch.setenv("PATH", str(tmp_path))  # no gcc, no g++
    with pytest.raises(RuntimeError, match=r"no gcc on PATH \(a C and C\+\+ compiler builds tf2_msgs's type support\)"):
        build_interfaces(TF2_MSGS, tmp_path / "tf2")
    assert not (tmp_path / "tf2").exists()
