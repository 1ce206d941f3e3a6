"""The rclpy node behind ``python -m atrv_warp.ros`` (imported only where rclpy is installed).

:class:`RoverSimNode` simulates ``num_rovers`` rovers in one simulator, each with its own topics
(under ``/rover_<k>`` when there is more than one), and steps them on an rclpy timer in (scaled)
real time; the executor serves the subscriptions between steps. Topics and parameters are listed in :mod:`atrv_warp.cli.ros`.
"""

from __future__ import annotations

import array
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rclpy
import torch
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import parameter_dict_from_yaml_file
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from atrv_warp.core.files import OutputPathError, check_output_path, fresh_path
from atrv_warp.core.geometry import quat_to_matrix
from atrv_warp.core.parameters import ParameterError, check_parameters, params_file_names
from atrv_warp.integrations.ros.bag import BagWriter
from atrv_warp.integrations.ros.frames import MAP_FRAME, WORLD_FRAME
from atrv_warp.integrations.ros.markers import scene_of, world_markers
from atrv_warp.integrations.ros.parameters import (
    PARAMETER_BY_NAME,
    PARAMETERS,
    VELOCITY,
    driver_config,
    publish_every,
    unknown_parameters,
)
from atrv_warp.integrations.ros.rover_io import RoverIO, ros_time, step_time_ns
from atrv_warp.task.spec import END_REASONS, action_to_torque, action_to_twist

__all__ = ["NodeConfigError", "RoverSimNode", "unknown_parameters"]


class NodeConfigError(ValueError):
    """A parameter value the node cannot run with (already logged by the node)."""


def _transform_msg(t: dict) -> TransformStamped:
    """A :func:`~.frames.transform_dict` as a ``geometry_msgs/TransformStamped``."""
    msg = TransformStamped()
    msg.header.stamp = Time(**t["header"]["stamp"])
    msg.header.frame_id, msg.child_frame_id = t["header"]["frame_id"], t["child_frame_id"]
    tr, rot = msg.transform.translation, msg.transform.rotation
    tr.x, tr.y, tr.z = (t["transform"]["translation"][k] for k in "xyz")
    rot.x, rot.y, rot.z, rot.w = (t["transform"]["rotation"][k] for k in "xyzw")
    return msg


class RoverSimNode(Node):
    """Simulated rovers of one robot as a ROS 2 base driver.

    Construction declares the parameters (with descriptions); :meth:`setup` checks them (a bad
    or unknown one is logged and raises :class:`NodeConfigError`), then builds the simulator
    and every rover's topics.
    """

    def __init__(self, args: list[str] | None = None):
        super().__init__("atrv_sim")
        # any type in (ROS's dynamic typing): the checks name a wrong one in one line, where rclpy would raise
        self.given = {p.name: self.declare_parameter(p.name, p.default, ParameterDescriptor(
            description=p.text, dynamic_typing=True)).value for p in PARAMETERS}
        self.params: dict = {}
        """The parameters as the node runs with them, once :meth:`setup` has checked them."""
        self.log = self.get_logger()
        self.args = args
        self.bag: BagWriter | None = None
        self.tf_pub = None
        """Live /tf's publisher, where tf2_msgs loads (parameter ``tf``)."""
        self.sim = None
        self.world_frame = WORLD_FRAME
        """The top of the frame tree: ``world``, or ``map`` in a map (parameter ``map``)."""
        self.scanner = None
        self.rovers: list[RoverIO] = []
        self.policy = None  # goal mode's (policy, TensorDict): a -p policy file once checked, else loaded on first use
        self.goal_refusal: str | None = None
        """Why goal mode cannot drive this robot (:meth:`goal_policy_refusal`), once decided."""
        self._goal_decided = False
        self._warned_other_robot = False
        self.commanded = False
        """A /cmd_vel came since the last state publication (``lockstep``)."""
        self.published_at = 0.0
        self.holding = False
        """``lockstep``: a replayed episode has ended; nothing steps until the next ``reset_episode``."""
        self.reset_ns = 0
        """ROS time the episode resets added to the simulation time [ns]: one period each."""
        self.steps = 0
        """Simulator steps taken (:meth:`on_step_timer`; ``cmd_vel_delay`` counts in them)."""
        self.delay_steps = 0
        """``cmd_vel_delay`` in whole steps."""
        self.stop_requested: Sequence = ()
        """Non-empty once the process has been asked to stop (:meth:`spin_simulation`'s ``stop_requested``)."""

    def setup(self) -> None:
        self._check_parameters()
        p = self.params
        k = p["num_rovers"]
        task = p["task"]
        if p["policy"]:  # the world runs the task the policy records (as it trained), not today's fit of its name
            from atrv_warp.policy import policy_record
            from atrv_warp.storage import FileFormatError

            try:
                task = policy_record(p["policy"]).task
            except (FileNotFoundError, FileFormatError, ValueError) as err:
                self._fail(f"parameter policy: {err}")
            if task.name != p["task"]:
                self._fail(f"parameter policy: {p['policy']} was trained on task {task.name!r}, not task={p['task']!r}")
        self.env = self._build_env(task)
        if p["sim_config"]:
            self.log.info(f"simulator config {p['sim_config']}: {self.env.sim.rover_cfg.torque_scale:g}x motor torque, "
                          f"{self.env.sim.rover_cfg.payload_mass:g} kg payload, friction "
                          f"{self.env.sim.contact_cfg.friction:g}, wheel radius {self.env.sim.rover_cfg.wheel_radius:g} m")
        self.sim = self.env.sim
        starts = [[p["x"], p["y"] + i * p["spacing"], p["yaw"]] for i in range(k)]
        if p["task"] != "reach" or p["map"]:  # terrain tiles, obstacles, a map's free space: the first episodes'
            self.env.reset()
            starts = self.sim.root_pose[:, :2].tolist()
            starts = [[x, y, float(yaw)] for (x, y), yaw in zip(starts, self.sim.rpy[:, 2].tolist())]
            self.log.info(f"task {p['task']}{' in ' + p['map'] if p['map'] else ''}: rovers start at their first "
                          "episodes' starts "
                          + ", ".join(f"({x:.1f}, {y:.1f})" for x, y, _ in starts))
        try:
            self.sim.reset(poses=starts)
        except ValueError as err:
            self._fail(f"parameters x, y, yaw, spacing: {err}")
        self.sim.driver.lag.fill_(p["motor_lag"])
        self.delay_steps = round(p["cmd_vel_delay"] / self.sim.sim_cfg.step_dt)
        if p["motor_lag"] or self.delay_steps or p["terrain"]:
            self.log.info(f"effects: /cmd_vel delayed {self.delay_steps} step(s), motor lag {p['motor_lag']:g} s, "
                          f"terrain {p['terrain'] or self.env.task_cfg.terrain}")
        if p["scan_beams"] > 0:
            from atrv_warp.sim.scanner import LaserScanner, ScannerConfig

            scan = ScannerConfig(beams=p["scan_beams"], noise_std=p["scan_noise"], dropout=p["scan_dropout"])
            self.scanner = LaserScanner(self.sim, scan, seed=int(p["seed"]))
        desc = self.sim.description
        self.every, rate_line = publish_every(p["publish_rate"], self.sim.sim_cfg.step_dt)
        if rate_line:  # topics come on steps: the rate they get is said
            self.log.warning(rate_line)
        self.frame_id = p["frame_id"] or desc.chassis
        self.odom_frame, self.base_frame, self.imu_frame = (p["odom_frame"], p["base_frame"],
                                                           self.sim.rover_cfg.robot_spec.imu_frame)
        self.joint_names = [w.joint for w in desc.wheels]
        self.side = torch.tensor([w.side for w in desc.wheels])
        self.wheel_sign = [float(w.drive_sign) for w in desc.wheels]
        self.noise = torch.Generator().manual_seed(int(p["seed"]))
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        urdf = Path(desc.path).read_text()
        self.create_publisher(String, "/robot_description", latched).publish(String(data=urdf))
        self.marker_pub = self.create_publisher(MarkerArray, "/visualization_marker_array", latched)
        self.rovers = [RoverIO(self, i, f"/rover_{i}" if k > 1 else "", qos) for i in range(k)]
        for rover, start in zip(self.rovers, starts):  # the odom frame starts at the start pose
            rover.start = tuple(float(v) for v in start)
        if p["map"]:
            self.world_frame = MAP_FRAME
            if p["publish_map"]:
                self.publish_map(latched)
        self.publish_markers()
        self.tf_pub = self.tf_message = None
        if p["tf"]:
            self._start_tf(latched)
        self.bag = None
        if p["bag"]:
            try:
                path, line = fresh_path(p["bag"])  # an existing bag is kept: the next free name is taken
            except OutputPathError as err:
                self._fail(f"parameter bag: {err}")
            if line:
                self.log.warning(line)
            self.bag = BagWriter(path)
        if self.bag is not None:  # what a 3D panel needs to draw the rover from the bag alone
            self.record("/robot_description", "std_msgs/msg/String", {"data": urdf})
            self.record("/tf_static", "tf2_msgs/msg/TFMessage",
                        {"transforms": [t for r in self.rovers for t in r.static_frames(self.stamp_ns())]})

    def _build_env(self, task):
        """The simulated world (``RoverEnv``) the parameters describe, on ``task``; a bad map, robot or simulator
        config is one logged line (:class:`NodeConfigError`)."""
        from atrv_warp.world import MapError
        from atrv_warp.world.places import read_map_files

        p = self.params
        try:  # a bad map file stops the node before Newton loads; a place (building:1@7) is drawn for the robot
            site = read_map_files([p["map"]] if p["map"] else [])
        except MapError as err:
            self._fail(f"parameter map: {err}")
        from atrv_warp.task.env import RoverEnv  # the simulator (Newton), once the parameters are good

        try:  # goal mode reads the policy's observation kernel
            return RoverEnv(p["num_rovers"], robot=p["robot"], variant=p["variant"], task=task, seed=int(p["seed"]),
                            sim_config=p["sim_config"] or None, driver=self.driver, maps=site,
                            **({"terrain": p["terrain"]} if p["terrain"] else {}))
        except MapError as err:  # the file and the problem
            self._fail(f"parameter map: {err}")
        except ValueError as err:
            self._fail(f"parameter sim_config: {err}" if p["sim_config"] else str(err))

    def _fail(self, message: str):
        self.log.error(message)
        raise NodeConfigError(message)

    def _check_parameters(self) -> None:
        try:
            unknown = unknown_parameters(self.args, params_file_names(self.args, self.get_fully_qualified_name(),
                                                                      parameter_dict_from_yaml_file))
            if unknown:
                raise ParameterError(f"unknown parameter(s) {', '.join(unknown)}; known: "
                                     f"{', '.join(sorted(PARAMETER_BY_NAME))}")
            self.params = p = check_parameters(PARAMETERS, self.given)
        except ParameterError as err:
            self._fail(str(err))
        from atrv_warp.core.robot import RobotFileError, load_robot
        from atrv_warp.sim.urdf import URDFError, read_urdf

        try:  # the robot file and its URDF's tree and numbers, before the simulator (Newton) is imported
            read_urdf(load_robot(p["robot"]).urdf)
        except (RobotFileError, URDFError) as err:
            self._fail(f"parameter robot: {err}")
        try:
            self.driver = driver_config(p)
        except ValueError as err:
            self._fail(str(err))
        from atrv_warp.task.registry import TASK_VARIANTS

        if p["task"] not in TASK_VARIANTS:
            self._fail(f"task={p['task']!r} is not a task; use one of {sorted(TASK_VARIANTS)}")
        if p["terrain"]:
            from atrv_warp.sim.terrain import TERRAIN_PRESETS

            if p["terrain"] not in TERRAIN_PRESETS:
                self._fail(f"terrain={p['terrain']!r} is not a terrain; use one of {sorted(TERRAIN_PRESETS)}")
        if p["bag"]:  # before the simulator is built: a bag it cannot write fails in one line, not after the compile
            try:
                check_output_path(p["bag"], "bag")
            except OutputPathError as err:
                self._fail(f"parameter bag: {err}")
        if p["policy"]:  # goal mode's policy: a file the task can run, checked before any rover starts
            from tensordict import TensorDict

            from atrv_warp.policy import load_policy
            from atrv_warp.storage import FileFormatError

            try:
                self.policy = (load_policy(p["policy"], task=p["task"]), TensorDict)
                self._check_policy_robot(p["policy"])
            except (FileNotFoundError, FileFormatError, ValueError) as err:
                self._fail(f"parameter policy: {err}")

    def goal_policy_refusal(self) -> str | None:
        """Why goal mode cannot drive this robot (the task's shipped policy was trained on another robot, and no
        ``-p policy:=`` gives one of its own), or ``None``; decided once."""
        if self.policy is not None or self.params["policy"]:
            return None
        if not self._goal_decided:
            from atrv_warp.policy import PolicyRobotMismatch, shipped_policy_for

            try:
                self._check_policy_robot(shipped_policy_for(self.params["task"], self.params["robot"]))
            except PolicyRobotMismatch as err:
                self.goal_refusal = f"{err}; or give one trained on it: -p policy:=FILE"
            self._goal_decided = True
        return self.goal_refusal

    def _check_policy_robot(self, policy) -> None:
        """A goal policy trained on another robot than the node's is refused, naming both."""
        from atrv_warp.core.robot import load_robot
        from atrv_warp.policy import check_policy_robot, policy_record

        warning = check_policy_robot(policy_record(policy), load_robot(self.params["robot"]), source=policy,
                                     allow=self.params["allow_other_robot"], allow_with="-p allow_other_robot:=true")
        if warning and not self._warned_other_robot:
            self.log.warning(f"{warning} (allow_other_robot:=true)")
            self._warned_other_robot = True

    def _start_tf(self, latched: QoSProfile) -> None:
        """Live /tf and /tf_static, where tf2_msgs loads (a ROS install's, or built from its definition on
        first use: :mod:`atrv_warp.core.ros_interfaces`); otherwise one line says why and the node goes on without."""
        from atrv_warp.core.ros_interfaces import TF2_MSGS, load_interface

        cls, where = load_interface(TF2_MSGS, "msg", "TFMessage")
        if cls is None:
            self.log.warning(f"no live /tf: {where}")
            return
        self.log.info(f"/tf and /tf_static from {where}")
        self.tf_message = lambda transforms: cls(transforms=[_transform_msg(t) for t in transforms])
        self.tf_pub = self.create_publisher(cls, "/tf", 100)
        ns = self.stamp_ns()
        self.create_publisher(cls, "/tf_static", latched).publish(
            self.tf_message([t for r in self.rovers for t in r.static_frames(ns)]))

    def publish_map(self, latched: QoSProfile) -> None:
        """The map as ``map_server`` serves it: ``nav_msgs/OccupancyGrid`` on /map in frame ``map``, transient local
        (a Nav2 stack's static layer and planner read it), once."""
        from nav_msgs.msg import OccupancyGrid

        site = self.sim.maps.maps[0]
        msg = OccupancyGrid()
        msg.header.stamp, msg.header.frame_id = ros_time(self.stamp_ns()), MAP_FRAME
        msg.info.map_load_time = msg.header.stamp
        msg.info.resolution = float(site.resolution)
        msg.info.height, msg.info.width = (int(n) for n in site.shape)
        msg.info.origin.position.x, msg.info.origin.position.y = (float(v) for v in site.origin)
        msg.info.origin.orientation.w = 1.0
        msg.data = array.array("b", site.cells.astype(np.int8).tobytes())  # row-major from the origin, as it is
        self.create_publisher(OccupancyGrid, "/map", latched).publish(msg)
        self.log.info(f"map {site.source or site.name}: {msg.info.width} x {msg.info.height} cells at "
                      f"{site.resolution:g} m on /map")

    def publish_markers(self) -> None:
        """The latched /visualization_marker_array (world frame): walls, each rover's obstacles, goal and
        terrain (:mod:`.markers`); a rover whose world holds a non-finite pose is left out, with one line."""
        several = len(self.rovers) > 1
        scenes = [scene_of(self.sim, r.index, ns=f"rover_{r.index}/" if several else "", goal=r.goal,
                           goal_radius=self.params["reach_radius"]) for r in self.rovers]
        msg, skipped = world_markers(self.sim.arena_cfg, scenes, self.world_frame, ros_time(self.stamp_ns()))
        for name in skipped:
            self.log.warning(f"markers of {name} not published: its world holds a non-finite pose")
        self.marker_pub.publish(msg)

    # ------------------------------------------------------------------ simulator reads
    def stamp_ns(self) -> int:
        """ROS time [ns], the stamp of everything the node publishes and its ``/clock``: the simulation time, plus one
        step per ``reset_episode`` (a reset takes a control period, so a controller timed on the clock acts on the
        reset state)."""
        return step_time_ns(self.sim.sim_time, self.sim.sim_cfg.step_dt) + self.reset_ns

    def record(self, topic: str, type_name: str, message: dict, stamp_ns: int | None = None) -> None:
        if self.bag is not None:
            self.bag.write(topic, type_name, message, self.stamp_ns() if stamp_ns is None else stamp_ns)

    def side_speeds(self) -> torch.Tensor:
        """(K, 2) mean left and right forward wheel speeds [rad/s]."""
        ws = self.sim.wheel_speed
        return torch.stack([ws[:, self.side == 0].mean(-1), ws[:, self.side == 1].mean(-1)], -1)

    def _wheel_view(self, array, index) -> list[float]:
        return array.view(self.sim.num_worlds, -1)[:, index].tolist()

    def wheel_positions(self, k: int) -> list[float]:
        import warp as wp

        b = self.sim.buffers
        return self._wheel_view(wp.to_torch(b.joint_q), wp.to_torch(b.layout.wheel_coord).long())[k]

    def wheel_velocities(self, k: int) -> list[float]:
        import warp as wp

        b = self.sim.buffers
        return self._wheel_view(wp.to_torch(b.joint_qd), wp.to_torch(b.layout.wheel_dof).long())[k]

    def chassis_rotation(self, k: int) -> torch.Tensor:
        """Rover ``k``'s chassis rotation matrix (world from body), float64."""
        return quat_to_matrix(self.sim.root_pose[k, 3:7].to(torch.float64))

    # ------------------------------------------------------------------ driving
    def goal_action(self, k: int) -> float:
        """Drive rover ``k`` by the policy toward its goal (its torques, or its ``/cmd_vel`` through the driver, as
        the task's action says) for the next step; returns the distance to the goal [m]."""
        if self.policy is None:
            from tensordict import TensorDict

            from atrv_warp.policy import load_policy, shipped_policy_for

            task = self.params["task"]  # the robot's shipped policy for the task (nav_deploy_husky), else the task's
            name = shipped_policy_for(task, self.params["robot"])
            self.policy = (load_policy(name, task=task), TensorDict)
            self._check_policy_robot(name)
        policy, td_cls = self.policy
        targets = self.sim.root_pose[:, :2].clone()  # rovers not in goal mode: their own position
        for rover in self.rovers:
            if rover.goal is not None:
                targets[rover.index] = torch.tensor(rover.goal)
        obs = self.env.observe(targets)
        action = policy(td_cls(observation=obs, batch_size=[self.sim.num_worlds]))["action"][k]
        task = self.env.task_cfg
        if task.action == "twist":
            self.sim.set_twist(action_to_twist(action, task.max_linear, task.max_angular), worlds=[k])
        else:
            self.sim.set_commands(action_to_torque(action, task.action_scale), worlds=[k])
        return float(self.env.target_distance[k])

    def step_once(self) -> bool:
        """Every rover's input for its mode and one simulator step; True when a replayed episode ended in it."""
        for rover in self.rovers:
            while rover.delayed and rover.delayed[0][0] <= self.steps:  # delayed /cmd_vel due at this step
                _, v, w = rover.delayed.popleft()
                self.sim.set_twist([v, w], worlds=[rover.index])
            rover.drive(self.goal_action)
        # what every rover commanded, as the policy's actions: a task that observes its last actions sees them
        task = self.env.task_cfg
        if task.action == "twist":
            self.env.record_actions(self.sim.driver.twist / torch.tensor([task.max_linear, task.max_angular]))
        else:
            self.env.record_actions(self.sim.commands / task.action_scale)
        for rover in self.rovers:
            rover.prev_vel = self.sim.lin_vel[rover.index].clone()
        if any(r.episode is not None for r in self.rovers):
            return self.step_episode()
        self.sim.step()
        return False

    def start_episode(self, rover: RoverIO) -> None:
        """Put ``rover`` in evaluation episode ``rover.pending_episode`` of ``episode_seed`` (the world, start and
        goal ``python -m atrv_warp.evaluate`` gives that episode: :meth:`RoverEnv.reset_to_episodes`), its odometry
        frame at the new start, still; publish ``episode`` ``{"event": "start", "episode", "seed", "start": [x, y,
        yaw], "goal": [x, y], "goal_yaw"}`` (world frame = the odometry frame at the start), the episode's plan on
        ``plan`` (a path task in a map; again at each replan) and the state."""
        k, seed = rover.pending_episode, int(self.params["episode_seed"])
        rover.pending_episode = None
        self.reset_ns += round(self.sim.sim_cfg.step_dt * 1e9)
        self.env.reset_to_episodes([rover.index], [k], seed=seed)
        self.sim.set_twist([0.0, 0.0], worlds=[rover.index])
        rover.delayed.clear()  # a delayed /cmd_vel of the last episode is not this one's
        self.sim.driver.lag[rover.index] = self.params["motor_lag"]  # the episode's reset drew the env's lag
        # the odometry frame where the environment puts it (the start as drawn, not the settled chassis's pose: on a
        # slope their yaws differ by a fraction of a degree), so the goal is seen as evaluate's policy sees it
        rover.start = tuple(float(v) for v in self.env.episode_start[rover.index].tolist())
        rover.goal = tuple(self.env.target[rover.index].tolist())
        rover.episode, rover.mode, rover.pending, rover.unanswered = k, VELOCITY, VELOCITY, 0
        rover.publish_episode({"event": "start", "episode": k, "seed": seed, "start": list(rover.start),
                               "goal": list(rover.goal), "goal_yaw": float(self.env.target_yaw[rover.index])})
        if rover.plan_pub is not None:
            rover.publish_plan(self.stamp_ns())
        self.publish_markers()

    def step_episode(self) -> bool:
        """One environment step of the replayed episode, the rover's last /cmd_vel as its action (so the episode
        ends as ``evaluate``'s do: reached, wall, flip, obstacle, timeout); at its end ``episode`` ``{"event": "end",
        "episode", "end_reason", "steps"}`` and the rover stops. True when the episode ended."""
        from tensordict import TensorDict

        task = self.env.task_cfg
        action = (self.sim.driver.twist / torch.tensor([task.max_linear, task.max_angular])).clamp(-1.0, 1.0)
        out = self.env.step(TensorDict(action=action, batch_size=[self.sim.num_worlds]))["next"]
        ended = False
        for rover in self.rovers:  # every rover whose episode ended in this step says so, not only the first
            if rover.episode is not None and bool(out["done"][rover.index]):
                reason = END_REASONS[int(out["end_reason"][rover.index])]
                rover.publish_episode({"event": "end", "episode": rover.episode, "end_reason": reason,
                                       "steps": int(self.env.step_count[rover.index]),
                                       "unanswered": rover.unanswered})
                self.log.info(f"episode {rover.episode}: {reason}")
                rover.episode = None
                self.sim.set_twist([0.0, 0.0], worlds=[rover.index])
                ended = True
            elif rover.episode is not None and rover.plan_pub is not None and bool(self.env.replanned[rover.index]):
                rover.publish_plan(self.stamp_ns())
        return ended

    def publish_state(self) -> None:
        self.commanded, self.published_at = False, time.monotonic()
        ns = self.stamp_ns()
        if self.scanner is not None:
            self.scanner.scan()
        frames = self.sim.frame_pose(self.imu_frame)
        dt = self.sim.sim_cfg.step_dt
        for rover in self.rovers:
            accel = (self.sim.lin_vel[rover.index] - rover.prev_vel) / dt
            rover.publish_state(ns, frames[rover.index], accel)

    def spin_simulation(self, executor=None, stop_requested: Sequence = ()) -> None:
        """Step on a timer (period ``step_dt / real_time_factor``; 0 = as fast as possible) until
        ``duration`` of sim time, shutdown, or ``stop_requested`` is non-empty (checked before each step: a
        signal handler's list); the executor serves the subscriptions between steps (``executor``: one that
        also serves other nodes of this process, e.g. a scripted driver)."""
        p, sim = self.params, self.sim
        self.stop_requested = stop_requested
        first = self.rovers[0].pose_pub
        while (p["wait_for_subscribers"] > 0 and rclpy.ok() and not stop_requested
               and first.get_subscription_count() < p["wait_for_subscribers"]):
            rclpy.spin_once(self, timeout_sec=0.05)
        if stop_requested:
            return
        self.log.info(f"simulating {sim} ({len(self.rovers)} rover(s)) at real-time factor {p['real_time_factor']}, "
                      f"publishing every {self.every * sim.sim_cfg.step_dt:.3f} s of sim time, mode {p['mode']}")
        self.deadline = p["duration"] if p["duration"] > 0 else math.inf
        self.steps = 0
        self.finished = Future()
        self.publish_state()
        period = sim.sim_cfg.step_dt / p["real_time_factor"] if p["real_time_factor"] > 0 else 0.0
        self.step_timer = self.create_timer(period, self.on_step_timer)
        if executor is None:
            rclpy.spin_until_future_complete(self, self.finished)
        else:
            executor.spin_until_future_complete(self.finished)

    def on_step_timer(self) -> None:
        """One simulator step; state topics every ``publish_rate``, then ``/clock`` (so that a node timed on the
        clock reads this step's sensors); finish at the deadline. ``reset_episode`` requests start first, and
        ``lockstep`` holds the step until a ``/cmd_vel`` has come.

        In ``lockstep``, a replayed episode pairs each step with the controller's answer to the state before it, as
        ``evaluate`` pairs each action with its observation: the reset state comes one period of ``/clock`` after
        the last, so the controller acts on it (its command is the episode's first action); the episode's last
        state goes out without ``/clock`` (nothing is left to act on), and nothing steps until the next
        ``reset_episode``, so a controller given its next goal meanwhile acts first on that episode's reset state."""
        if self.stop_requested:
            self.finish()
            return
        for rover in self.rovers:
            if rover.pending_episode is not None:
                self.start_episode(rover)
                self.holding = False
                self.publish_state()
                self.clock_pub.publish(Clock(clock=ros_time(self.stamp_ns())))
                return
        if self.holding:
            return
        if (self.params["lockstep"] and not self.commanded
                and time.monotonic() - self.published_at < self.params["lockstep_timeout"]):
            return
        if self.sim.sim_time < self.deadline - 1e-9:
            if self.params["lockstep"] and not self.commanded:
                for rover in self.rovers:
                    rover.unanswered += rover.episode is not None
            ended = self.step_once()
            self.steps += 1
            if self.steps % self.every == 0:
                self.publish_state()
            self.holding = ended and self.params["lockstep"]
            if not self.holding:
                self.clock_pub.publish(Clock(clock=ros_time(self.stamp_ns())))
        if self.sim.sim_time >= self.deadline - 1e-9:
            self.finish()

    def finish(self) -> None:
        """End :meth:`spin_simulation`: no more steps."""
        if not self.finished.done():
            self.step_timer.cancel()
            self.finished.set_result(True)

    def close(self) -> None:
        """Close the bag and destroy the node."""
        if self.bag is not None:
            self.bag.close()
        if self.sim is not None:
            self.log.info(f"stopped at sim time {self.sim.sim_time:.2f} s")
        self.destroy_node()
