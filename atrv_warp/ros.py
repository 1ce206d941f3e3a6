"""ROS 2 bridge: a real rclpy node that simulates one ATRV-Jr, publishes ``/pose`` and obeys ``/command``.

Run::

    python -m atrv_warp.ros                                   # real time, pose at 10 Hz
    python -m atrv_warp.ros --ros-args -p real_time_factor:=0.0 -p duration:=5.0 -p mode:=forward
    ros2 topic pub --once /command std_msgs/msg/String "{data: rotate_left}"

Topics:
    ``/pose`` (geometry_msgs/msg/PoseStamped, out): chassis pose; stamp = simulation time,
    frame_id = the chassis body name (parameter ``frame_id`` overrides it).
    ``/command`` (std_msgs/msg/String, in): coast | forward | backward | rotate_left |
    rotate_right (applied at the next step) | goal (drive to the last ``/goal``); anything else is
    logged and ignored.
    ``/goal`` (geometry_msgs/msg/PoseStamped, in): a target; switches to ``goal`` mode, in which a
    trained policy (the shipped one by default) drives the rover there.
    ``/goal_status`` (std_msgs/msg/String, out): ``distance=<m>`` at the pose rate, then ``reached``.
    ``/clock`` (rosgraph_msgs/msg/Clock, out): simulation time, for nodes with ``use_sim_time``.

Parameters (``--ros-args -p name:=value``): ``real_time_factor`` (1.0; 0 = as fast as
possible), ``publish_rate`` [Hz] (10.0), ``duration`` [s of sim time] (0 = until Ctrl-C),
``mode`` (initial driving mode, coast), ``variant`` (realistic), ``x``, ``y``, ``yaw`` (start),
``frame_id``, ``policy`` (policy file for goal mode; empty = shipped), ``bag`` (write an MCAP
ROS 2 bag of /pose, /command, /goal, /goal_status; empty = off), ``wait_for_subscribers`` (wait
until this many /pose subscribers are matched before starting; 0).

The simulator does not depend on ROS: this module is a thin layer over
:meth:`atrv_warp.sim.RoverSim.set_mode`.
"""

from __future__ import annotations

import math
import sys
import time

from .sim import DriveMode

__all__ = ["MISSING_ROS_MESSAGE", "main"]

MISSING_ROS_MESSAGE = (
    "ROS 2 Python packages are not installed (needed: rclpy, geometry_msgs, std_msgs, rosgraph_msgs).\n"
    "Install the extra:  pip install -e '.[ros]'   (ros-rclpy[fastrtps], ros-geometry-msgs, ros-std-msgs, "
    "mcap-ros2-support from PyPI), or source a ROS 2 installation."
)

GOAL = "goal"
COMMANDS = tuple(m.value for m in DriveMode) + (GOAL,)

_STRING_DEF = "string data\n"
_POSE_STAMPED_DEF = """std_msgs/Header header
geometry_msgs/Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
geometry_msgs/Point position
geometry_msgs/Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""


class BagWriter:
    """ROS 2 bag in MCAP format (``ros2 bag info/play`` read it), written with mcap-ros2-support."""

    def __init__(self, path: str):
        from mcap_ros2.writer import Writer

        self._fh = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._fh)
        self._schemas = {
            "geometry_msgs/msg/PoseStamped": self._writer.register_msgdef("geometry_msgs/msg/PoseStamped",
                                                                          _POSE_STAMPED_DEF),
            "std_msgs/msg/String": self._writer.register_msgdef("std_msgs/msg/String", _STRING_DEF),
        }

    def write(self, topic: str, type_name: str, message: dict, stamp_ns: int) -> None:
        self._writer.write_message(topic=topic, schema=self._schemas[type_name], message=message,
                                   log_time=stamp_ns, publish_time=stamp_ns)

    def close(self) -> None:
        self._writer.finish()
        self._fh.close()


def _pose_dict(msg) -> dict:
    p, q = msg.pose.position, msg.pose.orientation
    return {"header": {"stamp": {"sec": msg.header.stamp.sec, "nanosec": msg.header.stamp.nanosec},
                       "frame_id": msg.header.frame_id},
            "pose": {"position": {"x": p.x, "y": p.y, "z": p.z},
                     "orientation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w}}}


def run(args: list[str] | None = None) -> int:
    try:
        import rclpy
        from builtin_interfaces.msg import Time
        from geometry_msgs.msg import PoseStamped
        from rclpy.executors import ExternalShutdownException
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import String
    except ImportError:
        print(MISSING_ROS_MESSAGE, file=sys.stderr)
        return 2
    from .env import ATRVjrEnv

    rclpy.init(args=args)
    node = Node("atrv_sim")
    declare = node.declare_parameter
    params = {name: declare(name, default).value for name, default in (
        ("real_time_factor", 1.0), ("publish_rate", 10.0), ("duration", 0.0), ("mode", "coast"),
        ("variant", "realistic"), ("x", 0.0), ("y", 0.0), ("yaw", 0.0), ("frame_id", ""), ("policy", ""),
        ("bag", ""), ("wait_for_subscribers", 0), ("reach_radius", 1.0))}
    log = node.get_logger()
    if params["mode"] not in COMMANDS or params["mode"] == GOAL:
        log.error(f"parameter mode={params['mode']!r} is not a driving mode; use one of {list(COMMANDS[:-1])}")
        node.destroy_node()
        rclpy.try_shutdown()
        return 2
    if params["real_time_factor"] < 0 or params["publish_rate"] <= 0:
        log.error("real_time_factor must be >= 0 and publish_rate > 0")
        node.destroy_node()
        rclpy.try_shutdown()
        return 2

    env = ATRVjrEnv(1, variant=params["variant"])  # goal mode reads the policy's own observation kernel
    sim = env.sim
    try:
        sim.reset(poses=[[params["x"], params["y"], params["yaw"]]])
    except ValueError as err:
        log.error(f"parameters x, y, yaw: {err}")
        node.destroy_node()
        rclpy.try_shutdown()
        return 2
    sim.set_mode(params["mode"])
    dt = sim.sim_cfg.step_dt
    every = max(1, round(1.0 / (params["publish_rate"] * dt)))
    frame_id = params["frame_id"] or sim.description.chassis
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    pose_pub = node.create_publisher(PoseStamped, "/pose", qos)
    status_pub = node.create_publisher(String, "/goal_status", 10)
    clock_pub = node.create_publisher(Clock, "/clock", 10)
    bag = BagWriter(params["bag"]) if params["bag"] else None

    state = {"mode": params["mode"], "pending": params["mode"], "goal": None, "policy": None}

    def stamp_ns() -> int:
        return round(sim.sim_time * 1e9)

    def on_command(msg: String) -> None:
        text = msg.data.strip()
        if bag:
            bag.write("/command", "std_msgs/msg/String", {"data": msg.data}, stamp_ns())
        if text not in COMMANDS:
            log.warning(f"ignored unknown command {msg.data!r}; known: {list(COMMANDS)}")
            return
        if text == GOAL and state["goal"] is None:
            log.warning("ignored 'goal': no goal received on /goal yet")
            return
        state["pending"] = text

    def on_goal(msg: PoseStamped) -> None:
        g = (msg.pose.position.x, msg.pose.position.y)
        if not all(math.isfinite(v) for v in g):
            log.warning(f"ignored non-finite goal {g}")
            return
        if bag:
            bag.write("/goal", "geometry_msgs/msg/PoseStamped", _pose_dict(msg), stamp_ns())
        state["goal"] = g
        state["pending"] = GOAL
        log.info(f"goal ({g[0]:.2f}, {g[1]:.2f}) received: driving there")

    node.create_subscription(String, "/command", on_command, qos)
    node.create_subscription(PoseStamped, "/goal", on_goal, qos)

    def publish_pose() -> None:
        p = sim.root_pose[0].tolist()
        ns = stamp_ns()
        msg = PoseStamped()
        msg.header.stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        msg.header.frame_id = frame_id
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p[0], p[1], p[2]
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = p[3], p[4], p[5], p[6]
        pose_pub.publish(msg)
        if bag:
            bag.write("/pose", "geometry_msgs/msg/PoseStamped", _pose_dict(msg), ns)

    def goal_action():
        import torch

        from .task_spec import action_to_torque

        if state["policy"] is None:
            from tensordict import TensorDict

            from .agents import load_policy

            state["policy"] = (load_policy(params["policy"] or None), TensorDict)
        policy, td_cls = state["policy"]
        obs = env.observe(torch.tensor([state["goal"]]))
        dist = float(env.target_distance[0])
        action = policy(td_cls(observation=obs, batch_size=[1]))["action"]
        return action_to_torque(action[0], env.task_cfg.action_scale), dist

    deadline = params["duration"] if params["duration"] > 0 else math.inf
    if params["wait_for_subscribers"] > 0:
        while rclpy.ok() and pose_pub.get_subscription_count() < params["wait_for_subscribers"]:
            rclpy.spin_once(node, timeout_sec=0.05)
    log.info(f"simulating {sim} at real-time factor {params['real_time_factor']}, publishing /pose every "
             f"{every * dt:.3f} s of sim time, mode {state['mode']}")
    step = 0
    wall0 = time.monotonic()
    try:
        publish_pose()
        while rclpy.ok() and sim.sim_time < deadline - 1e-9:
            rclpy.spin_once(node, timeout_sec=0.0)
            if state["pending"] != state["mode"]:
                state["mode"] = state["pending"]
                log.info(f"mode -> {state['mode']}")
                if state["mode"] != GOAL:
                    sim.set_mode(state["mode"])
            dist = None
            if state["mode"] == GOAL:
                torques, dist = goal_action()
                if dist < params["reach_radius"]:
                    status_pub.publish(String(data="reached"))
                    if bag:
                        bag.write("/goal_status", "std_msgs/msg/String", {"data": "reached"}, stamp_ns())
                    log.info("goal reached")
                    state["mode"] = state["pending"] = DriveMode.COAST.value
                    sim.set_mode(DriveMode.COAST)
                else:
                    sim.set_commands(torques)
            sim.step()
            step += 1
            clock_pub.publish(Clock(clock=Time(sec=stamp_ns() // 1_000_000_000, nanosec=stamp_ns() % 1_000_000_000)))
            if step % every == 0:
                publish_pose()
                if dist is not None and state["mode"] == GOAL:
                    text = f"distance={dist:.3f}"
                    status_pub.publish(String(data=text))
                    if bag:
                        bag.write("/goal_status", "std_msgs/msg/String", {"data": text}, stamp_ns())
            rtf = params["real_time_factor"]
            if rtf > 0:
                ahead = sim.sim_time / rtf - (time.monotonic() - wall0)
                if ahead > 0:
                    rclpy.spin_once(node, timeout_sec=ahead)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if bag:
            bag.close()
        log.info(f"stopped at sim time {sim.sim_time:.2f} s")
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    if any(a in ("-h", "--help") for a in argv[1:]) and "--ros-args" not in argv:
        print(__doc__)
        return 0
    return run(argv)


if __name__ == "__main__":
    sys.exit(main())
