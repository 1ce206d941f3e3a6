"""The deploy node in closed loop over ROS 2, paired with ``evaluate`` on the same episodes.

Run: ``python -m benchmarks.transfer.deploy_closed_loop [POLICY] [--episodes 200] [--seed 2024] [--map YAML]
[--node-param NAME:=VALUE ...] [--out FILE] [--trace FILE]``

POLICY is a policy file (``best_policy.pt``) or a shipped policy's name (default: ``nav_deploy``). Two ways over
the same seeded episodes of its task (the evaluation set of ``--seed``: each episode's world, start and goal):

1. ``evaluate``: :func:`atrv_warp.task.evaluation.run_episodes`, one world per episode, the policy reading the
   environment's observation;
2. over ROS 2, as on a robot: the policy exported (``.pt2``) and run by ``python -m atrv_warp.deploy`` in its own
   process, seeing only topics; the simulator node (``python -m atrv_warp.ros -p task:=nav_deploy``) plays the
   robot, publishing ``/scan``, ``/odometry/filtered``, ``/imu`` and ``/clock`` at the policy's rate, with the
   evaluation's sensors (no noise, 64 beams over 180 deg). For episode k this script sends the node episode k's
   goal on ``/goal_pose`` in the odometry frame, then publishes ``reset_episode`` k (the simulator replays evaluation
   episode k: :meth:`atrv_warp.task.env.ATRVjrEnv.reset_to_episodes`, and says so on ``episode`` with the goal,
   checked against evaluate's); the simulator ends the episode as ``evaluate`` does (reached, wall, flip, obstacle,
   timeout) and says how. The simulator steps in lockstep with the node (a step waits for the ``/cmd_vel`` that
   answers the state before it), so the run goes as fast as both can on any machine, and each step's action is the
   node's answer to the step's state, as each of ``evaluate``'s is the policy's answer to its observation: the node
   acts first on the reset state (a reset advances ``/clock`` one period), and between episodes the simulator holds
   (the last state goes out without ``/clock``), so the next goal reaches the node before it acts again. The node
   never ends a goal itself (``goal_tolerance`` 0), as ``evaluate``'s policy drives until the environment ends the
   episode on the true position.

A ``follow_path`` policy (its observation is Nav2's plan) runs its episodes in a map (``--map``, default the example
office floor: ``evaluate --map`` on the same episodes), and this script plays Nav2's part as its behaviour tree does
(:class:`PathDriver`): the episode's first plan goes to the node as a ``FollowPath`` goal in ``map`` before the reset;
the simulator, as Nav2's planner server, publishes each replan on ``plan`` (every second, with the obstacle layer's
marks, as the environment replans), and each goes to the node as a new goal, which takes over the path without
stopping. The simulator publishes ``/tf`` (``map -> odom`` puts the fused odometry's ``base_link`` at the true pose,
``tf_odometry``), through which the node carries each plan into its odometry frame; the node's goal and progress
checkers are Nav2's defaults, as the task's are. A new plan reaches the node while it acts, so a step may act on the
plan of a second before (on a robot too); an episode the node ended itself (its goal checker, on its pose) while
the simulator's goes on holds the rover still (this script answers each state with a zero ``cmd_vel``,
``held_after_goal``). The node's answer to the last goal is usually ``running``: in lockstep the episode's last
state goes out without ``/clock``, so the node does not judge it.

Prints both success rates, their paired difference (ROS 2 - evaluate) with its 95 % confidence interval (normal
approximation of the per-episode differences), how many episodes ended identically (the same end after the same
number of steps: the same computation), how the episodes ended each way, ``evaluate``'s success with a node's stop
within 0.25 m of the goal on its odometry (as ``goal_tolerance`` 0.25 m would stop it), the steps the simulator took
without the node's answer (``unanswered``: 0 unless the node stalled), and the node's compute time per step
(observation + policy, from its goal status; p50, p99). Writes ``benchmarks/results/deploy_closed_loop.json``;
``--trace FILE``: the node's trace (its observation and action at every step, JSON lines).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import load_results, markdown_table, paired_difference, write_results

VERSION = 2
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"
EXAMPLE_MAP = "atrv_warp/assets/maps/office.yaml"
"""Where a path policy's episodes run (``--map``; from the repository's root): the example office floor, a map no
policy trained in."""
SIM_PARAMETERS = ("real_time_factor:=0.0", "lockstep:=true", "lockstep_timeout:=10.0",
                  "scan_beams:=64", "scan_noise:=0.0", "scan_dropout:=0.0",
                  "imu_accel_noise:=0.0", "imu_gyro_noise:=0.0", "wheel_speed_noise:=0.0")
"""The simulator node's parameters: the evaluation's sensors (no noise, the task's 64-beam scan), in lockstep with the
controller (at the policy's rate: :func:`world_parameters`): a step without the node's answer (``unanswered``, after
10 s) would act on the held command and put the answers a step late for the rest of the episode."""
DEPLOY_PARAMETERS = ("use_sim_time:=true", "odom_topic:=odometry/filtered", "cmd_vel_topic:=cmd_vel",
                     "goal_tolerance:=0.0", "odom_jump_margin:=1000.0")
"""The deploy node's: the simulator's clock, the fused odometry (encoders + gyro, what the robot observation is
trained on), its commands straight to the simulated base (a path policy's go to Nav2's velocity smoother,
``cmd_vel_nav``, by default), a time limit past the episode's (the simulator ends each episode first), no
odometry-jump check (each episode's reset restarts the odometry under the goal sent for it, on purpose; on a robot
such a jump aborts the goal), and no goal tolerance:
``evaluate`` ends an episode when the *true* position is within 1 m and its policy drives on until then, while a
node judges the goal on its odometry, which wheel slip makes overshoot, and stops (at 0.25 m it stopped short in 35
of 200 episodes, 15 of them reached by ``evaluate``: ``STOP_TOLERANCE``)."""
STOP_TOLERANCE = 0.25
"""A goal tolerance [m] on the odometry whose stops ``evaluate`` is also run with (``node_stop``): what a node on a
robot judging the goal would do."""


class StopWithin:
    """``policy``, stopping each world for good (zero action) from the first observation whose ``goal_distance`` (on
    the odometry) is within ``tolerance`` [m], as the deploy node ends a goal it judges reached."""

    def __init__(self, policy, index: int, tolerance: float):
        self.policy, self.index, self.tolerance = policy, index, tolerance
        self.stopped = None

    def __call__(self, td):
        td = self.policy(td)
        near = td["observation"][:, self.index] < self.tolerance
        self.stopped = near if self.stopped is None else self.stopped | near
        td["action"] = td["action"].masked_fill(self.stopped[:, None], 0.0)
        return td


def resolve_policy(name: str) -> Path:
    """The policy file of ``name`` (a path or a shipped name); exits with the command that trains it if missing."""
    from atrv_warp.policy import SHIPPED_POLICIES, policy_path

    path = policy_path(name)
    if not path.is_file():
        how = (f"train it: {SHIPPED_POLICIES[name].train}, then copy its best_policy.pt to atrv_warp/assets/"
               f"{SHIPPED_POLICIES[name].file}" if name in SHIPPED_POLICIES else "pass a policy file")
        sys.exit(f"deploy_closed_loop: policy {name!r} not found ({path}); {how}")
    return path


def evaluate_episodes(path: Path, episodes: int, seed: int, site: str | None = None
                      ) -> tuple[list[dict], list[dict], float | None]:
    """Each episode's ``end_reason`` and ``steps`` under ``evaluate``; what a controller is handed for it (its
    ``goal`` (x, y) [m] in the world (= the odometry frame at its start) and, in the map ``site`` (a path task), its
    ``goal_yaw`` and first ``plan``); the success rate with :class:`StopWithin` :data:`STOP_TOLERANCE` (None for a
    path task, whose node judges the goal as the environment does)."""
    from atrv_warp.policy import load_policy, policy_record
    from atrv_warp.task.env import ATRVjrEnv
    from atrv_warp.task.evaluation import run_episodes
    from atrv_warp.task.spec import END_REASONS, observation_fields
    from atrv_warp.world.places import read_map_files

    record = policy_record(path)
    task = record.task.name
    maps = read_map_files([site] if site else [])
    # the task as it trained, on its robot
    env = ATRVjrEnv(episodes, task=record.task, robot=robot_of(record), maps=maps)
    env.set_seed(seed)
    env.reset()  # the episodes run_episodes draws again (it seeds and resets the same way)
    given = [{"goal": tuple(g)} for g in env.target.tolist()]
    if site:
        for k, g in enumerate(given):
            g["goal_yaw"], g["plan"] = float(env.target_yaw[k]), env.planner.points(k).tolist()
    policy = load_policy(path, task=task)
    record = run_episodes(policy, env, seed=seed)
    ends = [{"end_reason": END_REASONS[int(r)], "steps": int(n)} for r, n in zip(record.end_reason, record.steps)]
    if site:
        return ends, given, None
    index = [f.name for f in observation_fields(env.task_cfg)].index("goal_distance")
    stopping = run_episodes(StopWithin(policy, index, STOP_TOLERANCE), env, seed=seed)
    return ends, given, float(stopping.success.float().mean())


class Driver:
    """This script's rclpy node: resets the simulator to each episode, sends its goal, collects how it ends."""

    def __init__(self):
        import rclpy
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Int32, String

        self.rclpy, self.PoseStamped, self.Int32 = rclpy, PoseStamped, Int32
        self.node = rclpy.create_node("deploy_closed_loop")
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.events, self.status = [], []
        self.node.create_subscription(String, "/episode", lambda m: self.events.append(json.loads(m.data)), qos)
        self.node.create_subscription(String, "/goal_status", lambda m: self.status.append(json.loads(m.data)), qos)
        self.reset = self.node.create_publisher(Int32, "/reset_episode", qos)
        self.goal = self.node.create_publisher(PoseStamped, "/goal_pose", qos)

    def wait(self, cond, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end and not cond():
            self.rclpy.spin_once(self.node, timeout_sec=0.02)
        return bool(cond())

    def ready(self, timeout: float) -> bool:
        """Both nodes are up: the simulator takes resets, the deploy node takes goals."""
        return self.wait(lambda: self.reset.get_subscription_count() > 0 and self.goal.get_subscription_count() > 0,
                         timeout)

    def run(self, episode: int, given: dict, timeout: float) -> dict:
        """One episode through ROS 2, its ``goal`` first (the node has it before the simulator's reset state, and the
        simulator holds between episodes): ``end_reason``, ``steps``, the deploy node's last ``state`` and ``reason``,
        ``stop_step`` (the first step at which its odometry was within :data:`STOP_TOLERANCE` of the goal, or None),
        and its ``compute_ms`` per step."""
        from rclpy.duration import Duration

        goal = given["goal"]
        self.events.clear()
        self.status.clear()
        msg = self.PoseStamped()
        msg.header.frame_id = "odom"
        msg.pose.position.x, msg.pose.position.y = goal
        self.goal.publish(msg)
        if not self.goal.wait_for_all_acked(Duration(seconds=30)):
            raise RuntimeError(f"the deploy node did not take episode {episode}'s goal in 30 s")
        self.reset.publish(self.Int32(data=episode))
        started = lambda: any(e["event"] == "start" and e["episode"] == episode for e in self.events)
        if not self.wait(started, 30.0):
            raise RuntimeError(f"the simulator did not start episode {episode} in 30 s")
        start = next(e for e in self.events if e["event"] == "start")
        if max(abs(a - b) for a, b in zip(start["goal"], goal)) > 1e-4:
            raise RuntimeError(f"the simulator's episode {episode} has goal {start['goal']}, evaluate's {list(goal)}: "
                               "not the same episode (episode_seed, task or simulator config differ)")
        ended = lambda: any(e["event"] == "end" and e["episode"] == episode for e in self.events)
        if not self.wait(ended, timeout):
            raise RuntimeError(f"episode {episode} did not end in {timeout:g} s")
        end = next(e for e in self.events if e["event"] == "end")
        self.wait(lambda: False, 0.05)  # the node's status of the last step
        last = self.status[-1] if self.status else {}
        stop = next((s["steps"] for s in self.status if s.get("goal") == list(goal) and s.get("distance") is not None
                     and s["distance"] < STOP_TOLERANCE), None)
        return {"episode": episode, "end_reason": end["end_reason"], "steps": end["steps"],
                "unanswered": end.get("unanswered"),
                "node_state": last.get("state"), "node_reason": last.get("reason"), "stop_step": stop,
                "compute_ms": [s["compute_ms"] for s in self.status if s.get("state") == "active"
                               and s.get("compute_ms") is not None]}


class PathDriver(Driver):
    """For a path task: Nav2's part as its behaviour tree plays it, with the simulator as its planner server. Each
    episode's first plan goes to the deploy node as a ``FollowPath`` goal before the simulator's reset (as a goal
    does for :class:`Driver`); each plan the simulator publishes on ``plan`` after that (every replan, with the
    obstacle layer's marks, as ``evaluate``'s environment replans) goes as a new goal, which takes over the path
    without stopping. A goal the episode's end leaves running is cancelled, so the next episode's starts afresh."""

    def __init__(self):
        super().__init__()
        from nav_msgs.msg import Path as PathMsg
        from rclpy.action import ActionClient
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from atrv_warp.deploy.nav2 import load_follow_path

        self.FollowPath, where = load_follow_path()
        if self.FollowPath is None:
            raise RuntimeError(f"no FollowPath action here: {where}")
        self.PathMsg = PathMsg
        self.client = ActionClient(self.node, self.FollowPath, "/follow_path")
        from geometry_msgs.msg import Twist
        from rosgraph_msgs.msg import Clock

        self.plans = []
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(PathMsg, "/plan", self.plans.append, qos)
        self.ticks = 0  # /clock messages seen: each is a state the rover's controller answers
        self.node.create_subscription(Clock, "/clock", lambda _m: setattr(self, "ticks", self.ticks + 1), 10)
        self.zero, self.cmd = Twist(), self.node.create_publisher(Twist, "/cmd_vel", 10)
        self.handles, self.results = [], {}  # this episode's goals' send futures, in order; their result futures

    def ready(self, timeout: float) -> bool:
        return self.wait(lambda: self.reset.get_subscription_count() > 0 and self.client.server_is_ready(), timeout)

    @staticmethod
    def path_message(given: dict):
        """The episode's first plan (``evaluate``'s) as the simulator publishes it."""
        from atrv_warp.integrations.ros.rover_io import plan_message

        return plan_message(given["plan"], given["goal_yaw"], "map")

    def send(self, path_msg):
        goal = self.FollowPath.Goal()
        goal.path = path_msg
        self.handles.append(self.client.send_goal_async(goal))
        return self.handles[-1]

    def goal_over(self) -> bool:
        """The latest goal has ended (the node answered it): nothing drives the rover any more."""
        k = len(self.handles) - 1
        if not self.handles[k].done():
            return False
        if not self.handles[k].result().accepted:
            return True
        if k not in self.results:
            self.results[k] = self.handles[k].result().get_result_async()
        return self.results[k].done()

    def finish_goal(self) -> None:
        """Cancel the last goal where it still runs (the episode ended on the simulator's side: a collision, the
        step limit); the node carries the cancel out when the next goal comes."""
        if self.handles and self.handles[-1].done() and self.handles[-1].result().accepted:
            handle = self.handles[-1].result()
            result = handle.get_result_async()
            if not self.wait(result.done, 0.1):
                cancel = handle.cancel_goal_async()
                self.wait(cancel.done, 10.0)

    def run(self, episode: int, given: dict, timeout: float) -> dict:
        """One episode through ROS 2: its first plan as a ``FollowPath`` goal, then the reset, then every replan as
        a new goal, until the simulator ends it: ``end_reason``, ``steps``, the node's answer to the last goal
        (``node_state``: succeeded / aborted / canceled / running, ``node_reason``: its error code), ``replans``
        and the node's ``compute_ms`` per step."""
        from action_msgs.msg import GoalStatus

        self.finish_goal()
        self.events.clear()
        self.status.clear()
        self.handles, self.results = [], {}
        sent = self.send(self.path_message(given))
        if not self.wait(sent.done, 30.0) or not sent.result().accepted:
            raise RuntimeError(f"the deploy node did not accept episode {episode}'s FollowPath goal in 30 s")
        self.plans.clear()
        self.reset.publish(self.Int32(data=episode))
        started = lambda: any(e["event"] == "start" and e["episode"] == episode for e in self.events) and self.plans
        if not self.wait(started, 30.0):
            raise RuntimeError(f"the simulator did not start episode {episode} (with its plan) in 30 s")
        start, first = next(e for e in self.events if e["event"] == "start"), self.plans.pop(0)
        points = [(p.pose.position.x, p.pose.position.y) for p in first.poses]
        if (max(abs(a - b) for a, b in zip(start["goal"], given["goal"])) > 1e-4 or len(points) != len(given["plan"])
                or max(abs(a - b) for p, q in zip(points, given["plan"]) for a, b in zip(p, q)) > 1e-4):
            raise RuntimeError(f"the simulator's episode {episode} has goal {start['goal']} and a plan of "
                               f"{len(points)} points, evaluate's {list(given['goal'])} and {len(given['plan'])}: not "
                               "the same episode (episode_seed, task, map or simulator config differ)")
        ended = lambda: any(e["event"] == "end" and e["episode"] == episode for e in self.events)
        replans, held, answered, deadline = 0, 0, self.ticks, time.monotonic() + timeout
        while not ended():
            if time.monotonic() > deadline:
                raise RuntimeError(f"episode {episode} did not end in {timeout:g} s")
            self.rclpy.spin_once(self.node, timeout_sec=0.005)
            while self.plans:  # the behaviour tree hands each new plan on
                self.send(self.plans.pop(0))
                replans += 1
            if self.ticks > answered and self.goal_over():
                # the node ended its goal (reached on its pose, or aborted) while the simulator's episode goes on: the
                # rover holds still, as under Nav2 once FollowPath ends; the zero answers the state in lockstep
                self.cmd.publish(self.zero)
                answered, held = self.ticks, held + 1
        end = next(e for e in self.events if e["event"] == "end")
        self.wait(lambda: all(h.done() for h in self.handles), 5.0)
        self.wait(lambda: False, 0.05)  # the node's status of the last step
        state, code = "running", None
        last = self.handles[-1].result() if self.handles[-1].done() else None
        if last is not None and last.accepted:
            result = last.get_result_async()
            if self.wait(result.done, 0.2):
                state = {GoalStatus.STATUS_SUCCEEDED: "succeeded", GoalStatus.STATUS_ABORTED: "aborted",
                         GoalStatus.STATUS_CANCELED: "canceled"}.get(result.result().status, "unknown")
                code = getattr(result.result().result, "error_code", None)
        return {"episode": episode, "end_reason": end["end_reason"], "steps": end["steps"],
                "unanswered": end.get("unanswered"), "node_state": state, "node_reason": code, "replans": replans,
                "held_after_goal": held,
                "compute_ms": [s["compute_ms"] for s in self.status if s.get("state") == "active"
                               and s.get("compute_ms") is not None]}


def start(args: list[str], env: dict, log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *args], env=env, stdout=log.open("w"), stderr=subprocess.STDOUT)


def stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.send_signal(2)  # Ctrl-C
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def robot_of(record) -> str:
    """The robot a policy's record names: a shipped robot's name, else its file's path."""
    from atrv_warp.core.robot import robot_spec

    return robot_spec(record.robot) or record.robot.path


def world_parameters(path: Path, site: str | None = None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(the simulator node's, the deploy node's) parameters that follow the policy at ``path``: the world runs the
    task it records on its robot (``policy:=``), publishing at its control rate, in the map ``site`` (a path task:
    with ``/tf``, through which the node carries the plan from ``map`` to its odometry; else none); the node's
    time limit is twice its episode."""
    from atrv_warp.policy import policy_record
    from atrv_warp.sim.config import SimConfig

    record = policy_record(path)
    period = record.task.config.control_period or SimConfig().step_dt
    episode = record.task.config.max_steps * period
    # the node reads the fused odometry (DEPLOY_PARAMETERS), so /tf's odom -> base_link follows it: map -> base_link
    # through the node's pose is then the true pose, which the environment's plan observation reads
    where = (f"map:={Path(site).resolve()}", "tf:=true", "tf_odometry:=odometry/filtered") if site else ("tf:=false",)
    return ((f"policy:={path}", f"task:={record.task.name}", f"robot:={robot_of(record)}",
             f"publish_rate:={float(1 / period)!r}", *where),
            (f"time_limit:={float(2 * episode)!r}",))  # float literals: ROS reads "20" as an integer


def is_path_task(path: Path) -> bool:
    """The policy at ``path`` follows a plan (``observation="path"``): its episodes run in a map, over FollowPath."""
    from atrv_warp.policy import policy_record

    return policy_record(path).task.config.observation == "path"


def ros_episodes(pt2: Path, given: list[dict], seed: int, workdir: Path, timeout: float,
                 trace: str | None = None, world: tuple[tuple[str, ...], tuple[str, ...]] = ((), ()),
                 paths: bool = False) -> list[dict]:
    """Each episode (of ``given``: :func:`evaluate_episodes`) through ROS 2 (the simulator and the deploy node in
    their own processes, on loopback); ``trace``: the node's trace file; ``world``: :func:`world_parameters`;
    ``paths``: a path task's (:class:`PathDriver`)."""
    import rclpy

    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", str(random.randint(101, 200))), PYTHONUNBUFFERED="1")
    os.environ.update({k: env[k] for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")})
    params = lambda ps: [a for p in ps for a in ("-p", p)]
    sim = start(["-m", "atrv_warp.ros", "--ros-args", *params((*SIM_PARAMETERS, *world[0], f"episode_seed:={seed}"))],
                env, workdir / "sim.log")
    deploy = (*DEPLOY_PARAMETERS, *world[1], *((f"trace:={Path(trace).resolve()}",) if trace else ()))
    node = start(["-m", "atrv_warp.deploy", str(pt2), "--ros-args", *params(deploy)], env, workdir / "deploy.log")
    rclpy.init()
    driver = PathDriver() if paths else Driver()
    rows = []
    try:
        if not driver.ready(180.0):
            raise RuntimeError(f"the nodes did not come up in 180 s; see {workdir}/sim.log and deploy.log")
        # a first run of episode 0, not counted, leaves the simulator holding as between episodes (before any, it
        # steps on lockstep_timeout, and a goal could reach the node a step before the reset)
        driver.run(0, given[0], timeout)
        for k, episode in enumerate(given):
            rows.append(driver.run(k, episode, timeout))
            print(f"  episode {k}: {rows[-1]['end_reason']} in {rows[-1]['steps']} steps (node: "
                  f"{rows[-1]['node_state']})", flush=True)
    finally:
        driver.node.destroy_node()
        rclpy.try_shutdown()
        codes = stop(node), stop(sim)
        if codes != (0, 0):
            print(f"  exit statuses (deploy, sim) {codes}; logs in {workdir}", file=sys.stderr)
    return rows


def paired(ros: list[bool], evaluate: list[bool]) -> dict:
    """Success rates, their paired difference (ros - evaluate) and its 95 % confidence interval."""
    n, p = len(ros), paired_difference(ros, evaluate)
    return {"episodes": n, "ros_success": sum(ros) / n, "evaluate_success": sum(evaluate) / n,
            "difference": p["difference"], "ci95": p["ci95"], "only_ros": p["only_a"], "only_evaluate": p["only_b"]}


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100 * len(s)) - 1))]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", nargs="?", default="nav_deploy", help="policy file or shipped name (nav_deploy)")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=None, help="evaluation-set seed (default: the standard set)")
    parser.add_argument("--timeout", type=float, default=300.0, help="wall seconds one ROS episode may take")
    parser.add_argument("--out", default=str(RESULTS / "deploy_closed_loop.json"))
    parser.add_argument("--trace", default=None, help="write the deploy node's trace here (JSON lines per step)")
    parser.add_argument("--map", default=EXAMPLE_MAP, help=f"a path policy's map ({EXAMPLE_MAP})")
    parser.add_argument("--node-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a further parameter of the deploy node (e.g. its collision monitor's stop_zone); "
                             "repeatable")
    args = parser.parse_args()
    from atrv_warp.rl.export import export_policy
    from atrv_warp.task.evaluation import EVAL_SEED

    seed = EVAL_SEED if args.seed is None else args.seed
    path = resolve_policy(args.policy)
    workdir = Path(tempfile.mkdtemp(prefix="deploy_closed_loop_"))
    pt2 = export_policy(path, workdir / "policy.pt2", force=True)
    t0 = time.perf_counter()
    paths = is_path_task(path)
    site = args.map if paths else None
    print(f"evaluate: {args.episodes} episodes of seed {seed}{' in ' + site if site else ''} ...", flush=True)
    evaluated, given, stopping = evaluate_episodes(path, args.episodes, seed, site)
    t1 = time.perf_counter()
    print(f"over ROS 2 (logs in {workdir}) ...", flush=True)
    sim_params, node_params = world_parameters(path, site)
    rows = ros_episodes(pt2, given, seed, workdir, args.timeout, args.trace,
                        (sim_params, (*node_params, *args.node_param)), paths)
    t2 = time.perf_counter()
    for row, ev in zip(rows, evaluated, strict=True):
        row["evaluate_end_reason"], row["evaluate_steps"] = ev["end_reason"], ev["steps"]
    stats = paired([r["end_reason"] == "success" for r in rows], [r["evaluate_end_reason"] == "success" for r in rows])
    stats["identical"] = sum(r["end_reason"] == r["evaluate_end_reason"] and r["steps"] == r["evaluate_steps"]
                             for r in rows)
    if stopping is not None:
        stats["node_stop"] = {"goal_tolerance": STOP_TOLERANCE, "evaluate_success": stopping}
    else:  # a path task: how the node answered the last FollowPath goal of each episode, and how often it was replanned
        stats["node_answers"] = {}
        for r in rows:
            key = f"{r['node_state']}" + (f" {r['node_reason']}" if r["node_reason"] else "")
            stats["node_answers"][key] = stats["node_answers"].get(key, 0) + 1
        stats["replans"] = sum(r["replans"] for r in rows)
    stats["unanswered"] = sum(r["unanswered"] or 0 for r in rows)
    compute = [ms for r in rows for ms in r.pop("compute_ms")]
    ends = {"ros": {}, "evaluate": {}}
    for r in rows:
        ends["ros"][r["end_reason"]] = ends["ros"].get(r["end_reason"], 0) + 1
        ends["evaluate"][r["evaluate_end_reason"]] = ends["evaluate"].get(r["evaluate_end_reason"], 0) + 1
    result = {"benchmark": "deploy_closed_loop", "policy": str(path), "seed": seed, "map": site,
              "node_parameters": args.node_param, **stats,
              "end_reasons": ends,
              "compute_ms": {"steps": len(compute), "p50": percentile(compute, 50), "p99": percentile(compute, 99)},
              "wall_s": {"evaluate": round(t1 - t0, 1), "ros": round(t2 - t1, 1)}, "episodes_detail": rows}
    print(f"success over ROS 2 {100 * stats['ros_success']:.1f} %, evaluate {100 * stats['evaluate_success']:.1f} % "
          f"on the same {stats['episodes']} episodes: difference {100 * stats['difference']:+.1f} points "
          f"(95 % CI {100 * stats['ci95'][0]:+.1f} … {100 * stats['ci95'][1]:+.1f}; {stats['only_ros']} only over ROS, "
          f"{stats['only_evaluate']} only in evaluate)")
    print(f"{stats['identical']} of {stats['episodes']} episodes ended identically (the same end after as many steps); "
          f"{stats['unanswered']} steps went without the node's answer")
    print(f"ends over ROS 2 {ends['ros']}; evaluate {ends['evaluate']}")
    if stopping is not None:
        print(f"evaluate stopping within {STOP_TOLERANCE:g} m of the goal on its odometry (as a node judging the "
              f"goal does): {100 * stopping:.1f} %")
    else:
        print(f"the node's answers to each episode's last FollowPath goal {stats['node_answers']}; "
              f"{stats['replans']} replans handed on")
    print(f"node compute per step: p50 {result['compute_ms']['p50']:.3f} ms, p99 {result['compute_ms']['p99']:.3f} ms "
          f"over {len(compute)} steps")
    out = write_results(args.out, result, version=VERSION, task=True, driver=True, policies=(path,))
    print(f"wrote {out}")
    return 0


ROBOTS = {"atrvjr": "ATRV-Jr", "husky": "Husky A200", "jackal": "Jackal J100"}
"""The shipped robots, as the tables name them."""


def _table(prefix: str) -> str:
    """The closed loop of each shipped robot's ``<prefix><robot>`` results: success over ROS 2 and under ``evaluate``
    on the same episodes, the paired difference and its 95 % interval, the episodes that ended identically, and the
    node's compute time per step at the 99th percentile."""
    rows = []
    for robot, name in ROBOTS.items():
        r = load_results(f"{prefix}{robot}.json")
        rows.append([name, f"{100 * r['ros_success']:.1f} %", f"{100 * r['evaluate_success']:.1f} %",
                     f"{100 * r['difference']:+.1f} ({100 * r['ci95'][0]:+.1f} to {100 * r['ci95'][1]:+.1f})",
                     f"{r['identical']} of {r['episodes']}", f"{r['compute_ms']['p99']:.1f} ms"])
    return markdown_table(["robot", "over ROS 2", "`evaluate`", "difference [points, 95 %]", "identical",
                           "node p99"], ["---"] + ["---:"] * 5, rows)


def deploy_closed_loop() -> str:
    """``deploy_closed_loop_<robot>.json``: each shipped ``nav_deploy_<robot>`` policy's goals through
    ``atrv-deploy`` (``NavigateToPose``'s policy) and under ``evaluate``."""
    return _table("deploy_closed_loop_")


def deploy_closed_loop_follow_path() -> str:
    """``deploy_closed_loop_follow_path_<robot>.json``: each shipped ``follow_path_<robot>`` policy's episodes in the
    office map through ``atrv-deploy``'s ``FollowPath`` and under ``evaluate``."""
    return _table("deploy_closed_loop_follow_path_")


def _ends(episodes: list[dict], *reasons: str) -> int:
    return sum(r["end_reason"] in reasons for r in episodes)


def deploy_closed_loop_zones() -> str:
    """``deploy_closed_loop_follow_path_zones_<robot>.json`` against ``deploy_closed_loop_follow_path_<robot>.json``:
    the same episodes over ROS 2 with the node's collision monitor (the zones its ``node_parameters`` name) and
    without: success, collisions and stalls (``no_progress``) each way, and the paired difference in success."""
    rows = []
    for robot, name in ROBOTS.items():
        off = load_results(f"deploy_closed_loop_follow_path_{robot}.json")["episodes_detail"]
        on = load_results(f"deploy_closed_loop_follow_path_zones_{robot}.json")["episodes_detail"]
        if [r["episode"] for r in on] != [r["episode"] for r in off]:
            raise ValueError(f"the {robot} runs with and without zones are not over the same episodes")
        d = paired_difference([r["end_reason"] == "success" for r in on], [r["end_reason"] == "success" for r in off])
        rows.append([name, f"{_ends(off, 'success')} → {_ends(on, 'success')}",
                     f"{_ends(off, 'obstacle', 'wall')} → {_ends(on, 'obstacle', 'wall')}",
                     f"{_ends(off, 'no_progress')} → {_ends(on, 'no_progress')}",
                     f"{100 * d['difference']:+.1f} ({100 * d['ci95'][0]:+.1f} to {100 * d['ci95'][1]:+.1f})"])
    return markdown_table(["robot", "reached", "collided", "stalled", "success with - without [points, 95 %]"],
                          ["---"] + ["---:"] * 4, rows)


TABLES = {
    "deploy_closed_loop": deploy_closed_loop,
    "deploy_closed_loop_follow_path": deploy_closed_loop_follow_path,
    "deploy_closed_loop_zones": deploy_closed_loop_zones,
}


if __name__ == "__main__":
    sys.exit(main())
