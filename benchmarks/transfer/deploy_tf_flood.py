"""The deploy node's command period under a ``/tf`` flood: each shipped robot's policy, before, during and after.

    python -m benchmarks.transfer.deploy_tf_flood [--robots atrvjr jackal husky] [--seconds 20]

For each shipped robot's deployable policy (``nav_deploy_<robot>``, exported to a ``.pt2``), ``python -m
atrv_warp.deploy`` runs in its own process against this script's node, which plays the robot: ``/odom``, ``/imu`` and
``/scan`` at the policy's rate (standing still in open space), a goal 5 m ahead on ``/goal_pose`` (the node never
ends it: ``goal_tolerance`` 0), and every ``/cmd_vel`` timed by its stamp (``enable_stamped_cmd_vel``: the node's
clock as it publishes, so this process's own delays in receiving it do not count). Three phases: ``--seconds`` / 2 before,
``--seconds`` of flood (``/tf`` at 100 Hz, each message 50 new frame names: issue 70's 100k frames over 20 s, with the
localisation's ``map -> odom`` still published beside them), and ``--seconds`` / 2 after. Each phase's command gaps
(p50, p99, max) against the target: p99 within 1.5 x the policy's period. Writes
``benchmarks/results/deploy_tf_flood.json``. About a minute per robot (the ``ros`` extra; tf2_msgs is built from its
definition where no ROS install has it).
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import random
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results
from benchmarks.transfer.deploy_closed_loop import percentile, start, stop

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
ROBOTS = ("atrvjr", "jackal", "husky")
TARGET = 1.5
"""The p99 command gap may be at most this many control periods (issue 70)."""
FLOOD_HZ, FLOOD_FRAMES = 100.0, 50


class Robot:
    """This process's side: the robot's sensors, a goal, the ``/tf`` flood, and every ``/cmd_vel``'s arrival."""

    def __init__(self, period: float, fov: float):
        import rclpy
        from geometry_msgs.msg import PoseStamped, TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu, LaserScan

        from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

        self.node = rclpy.create_node("tf_flood_bench")
        self.tf_message, _ = load_interface(TF2_MSGS, "msg", "TFMessage")
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.odom = self.node.create_publisher(Odometry, "odom", 10)
        self.imu = self.node.create_publisher(Imu, "imu", 10)
        self.scan = self.node.create_publisher(LaserScan, "scan", 10)
        self.goal = self.node.create_publisher(PoseStamped, "goal_pose", reliable)
        self.tf = self.node.create_publisher(self.tf_message, "/tf", 100)
        self.arrivals: list[float] = []
        """Each ``/cmd_vel``'s stamp [s], in the order they came."""
        self.node.create_subscription(TwistStamped, "cmd_vel", lambda m: self.arrivals.append(
            m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec), reliable)
        self.messages = {"odom": Odometry(), "imu": Imu(), "scan": LaserScan()}
        self.messages["odom"].header.frame_id, self.messages["odom"].child_frame_id = "odom", "base_link"
        self.messages["odom"].pose.pose.orientation.w = self.messages["imu"].orientation.w = 1.0
        scan = self.messages["scan"]
        scan.header.frame_id, scan.angle_min, scan.angle_max = "laser", -fov / 2, fov / 2
        scan.angle_increment, scan.range_min, scan.range_max = fov / 180, 0.05, 30.0
        scan.ranges = [math.inf] * 181
        self.node.create_timer(period, self.publish_sensors)
        self.flooding, self.sent = False, 0
        self.node.create_timer(1.0 / FLOOD_HZ, self.flood)
        self.pose = PoseStamped()
        self.pose.header.frame_id, self.pose.pose.position.x, self.pose.pose.orientation.w = "odom", 5.0, 1.0

    def publish_sensors(self) -> None:
        stamp = self.node.get_clock().now().to_msg()
        for name, msg in self.messages.items():
            if name != "imu":
                msg.header.stamp = stamp
            getattr(self, name).publish(msg)

    def flood(self) -> None:
        stamp = self.node.get_clock().now().to_msg()
        transforms = [self._transform("map", "odom", stamp)]
        if self.flooding:
            transforms += [self._transform(f"flood_{self.sent}_{i}", f"flood_{self.sent}_{i}_child", stamp)
                           for i in range(FLOOD_FRAMES)]
            self.sent += 1
        self.tf.publish(self.tf_message(transforms=transforms))

    @staticmethod
    def _transform(parent: str, child: str, stamp):
        from geometry_msgs.msg import TransformStamped

        t = TransformStamped()
        t.header.frame_id, t.header.stamp, t.child_frame_id = parent, stamp, child
        t.transform.rotation.w = 1.0
        return t

    def spin_for(self, seconds: float) -> list[float]:
        """Spin for ``seconds``; the stamps of the ``/cmd_vel`` that came in it."""
        import rclpy

        start_at, end = len(self.arrivals), time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.005)
        return self.arrivals[start_at:]


def gaps(arrivals: list[float], period: float) -> dict:
    """The command gaps of a phase [s]: p50, p99 and max, their ratio to ``period``, and whether p99 meets the target."""
    spaced = [b - a for a, b in itertools.pairwise(arrivals)]
    p50, p99 = percentile(spaced, 50), percentile(spaced, 99)
    worst = max(range(len(spaced)), key=spaced.__getitem__) if spaced else None
    return {"commands": len(arrivals), "p50_s": p50, "p99_s": p99, "max_s": max(spaced, default=math.nan),
            "max_at_s": None if worst is None else arrivals[worst] - arrivals[0],
            "p99_periods": p99 / period, "meets_target": bool(p99 <= TARGET * period)}


def run_robot(robot: str, seconds: float, workdir: Path, env: dict) -> dict:
    """One robot's policy, exported, under the three phases: its row. Each robot's pair of nodes has a ROS domain of
    its own (``env``'s ``ROS_DOMAIN_ID``, this process's too), away from the previous pair's departing participants."""
    import rclpy

    from atrv_warp.deploy.contract import load_deployable
    from atrv_warp.policy import shipped_policy_path
    from atrv_warp.rl.export import export_policy

    pt2 = export_policy(shipped_policy_path(f"nav_deploy_{robot}"), workdir / f"{robot}.pt2", force=True)
    policy = load_deployable(pt2)
    edges = policy.observation.sectors.edges
    os.environ["ROS_DOMAIN_ID"] = env["ROS_DOMAIN_ID"]
    node = start(["-m", "atrv_warp.deploy", str(pt2), "--ros-args", "-p", "goal_tolerance:=0.0", "-p",
                  "time_limit:=0.0", "-p", f"robot:={robot}", "-p", "enable_stamped_cmd_vel:=true"], env,
                 workdir / f"{robot}.log")
    rclpy.init()
    try:
        side = Robot(policy.period, float(edges[-1] - edges[0]) + 0.2)
        deadline = time.monotonic() + 60
        while not side.arrivals and time.monotonic() < deadline:  # the node up, its goal taken
            side.goal.publish(side.pose)
            side.spin_for(0.5)
        if not side.arrivals:
            raise RuntimeError(f"{robot}: the node sent no /cmd_vel in 60 s; see {workdir / f'{robot}.log'}")
        before = side.spin_for(seconds / 2)
        side.flooding = True
        during = side.spin_for(seconds)
        side.flooding = False
        after = side.spin_for(seconds / 2)
        frames = side.sent * FLOOD_FRAMES
        side.node.destroy_node()
    finally:
        rclpy.try_shutdown()
        code = stop(node)
    return {"robot": robot, "period_s": policy.period, "flood_frames": frames, "node_exit": code,
            "before": gaps(before, policy.period), "during": gaps(during, policy.period),
            "after": gaps(after, policy.period)}


def build_parser() -> argparse.ArgumentParser:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=list(ROBOTS))
    parser.add_argument("--seconds", type=float, default=20.0, help="flood seconds (%(default)s); before and after: half")
    parser.add_argument("--out", default=str(RESULTS / "deploy_tf_flood.json"))
    return parser


def main() -> int:
    args = build_parser().parse_args()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    first = random.randint(101, 200 - len(args.robots))
    rows = []
    with tempfile.TemporaryDirectory(prefix="atrv-tf-flood-") as tmp:
        for k, robot in enumerate(args.robots):
            print(f"{robot}: ...", flush=True)
            try:
                row = run_robot(robot, args.seconds, Path(tmp), dict(env, ROS_DOMAIN_ID=str(first + k)))
            except RuntimeError as err:
                print(f"  {err}", file=sys.stderr)
                return 1
            print("  " + "; ".join(f"{phase} p99 {1e3 * row[phase]['p99_s']:.0f} ms "
                                   f"({row[phase]['p99_periods']:.2f} periods)" for phase in ("before", "during", "after"))
                  + f"; {row['flood_frames']:,} frames flooded", flush=True)
            rows.append(row)
    result = {"benchmark": "deploy_tf_flood", "seconds": args.seconds, "flood_hz": FLOOD_HZ,
              "flood_frames_per_message": FLOOD_FRAMES, "target_p99_periods": TARGET, "robots": rows,
              "all_meet": all(r[p]["meets_target"] for r in rows for p in ("before", "during", "after"))}
    from atrv_warp.policy import shipped_policy_path

    out = write_results(args.out, result, version=VERSION, dynamics=False,
                        policies=tuple(shipped_policy_path(f"nav_deploy_{r}") for r in args.robots))
    print(f"written to {out}")
    return 0


# --- the figures' tables, drawn from the results files at docs build time --------------------------

def deploy_tf_flood() -> str:
    """``deploy_tf_flood.json``: each robot's p99 command gap before, during and after the flood, in periods."""
    d = load_results("deploy_tf_flood.json")
    rows = [[r["robot"], f"{1e3 * r['period_s']:.0f} ms",
             *(f"{r[p]['p99_periods']:.2f}{'' if r[p]['meets_target'] else ' ✗'}" for p in ("before", "during", "after")),
             f"{r['flood_frames']:,}"] for r in d["robots"]]
    return markdown_table(["robot", "period", "p99 gap before", "during the flood", "after", "frames flooded"],
                          ["---", "---:", "---:", "---:", "---:", "---:"], rows)


TABLES = {"deploy_tf_flood": deploy_tf_flood}


if __name__ == "__main__":
    sys.exit(main())
