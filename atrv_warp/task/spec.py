"""The drive-to-target task's contract, declared once.

Everything that reads or writes the task's tensors derives from here: the environment's
specs, the Warp kernels (observation indices, bounds, end reasons, reward terms), the scripted
baseline, the Gymnasium spaces, the ROS goal mode and :func:`atrv_warp.task.reward.progress_reward`.

- :data:`OBSERVATION`: the arena observation's fields in order, each with its clip bound;
  :data:`ROBOT_OBSERVATION`: the robot observation's (what a robot's own stack publishes);
  :func:`observation_fields` picks the task's and adds its sensors' fields (its scan sectors: :func:`laser_fields`),
  then its last actions, after them.
- :data:`ACTIONS`: the action kinds (``torque``, ``twist``) and what each column means;
  :func:`action_to_torque` and :func:`action_to_twist` map an action in [-1, 1]² to the rover's input.
- :class:`EndReason`: why an episode ended (the ``end_reason`` entry).
- the reward's terms are the task's table (:data:`atrv_warp.task.terms.REWARD_TERMS`: the shipped tasks'); their
  sum is ``reward``, and each is reported per step as ``("reward_terms", name)``.
- :func:`action_to_torque`: action in [-1, 1]² to wheel torques.
- :func:`scan_sectors`: the observed scan sectors' angular edges (:class:`~atrv_warp.core.scan.ScanSectors`).
- :func:`policy_contract`: what a policy of a task observes and commands, as plain values (the task's part of an
  exported policy's contract, :func:`atrv_warp.rl.export.contract`, which
  :class:`~atrv_warp.core.observation.RobotObservation` reads).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import torch

from atrv_warp.core.scan import ScanSectors

__all__ = [
    "ACTIONS",
    "ACTION_DIM",
    "END_REASONS",
    "OBSERVATION",
    "OBSERVATION_KINDS",
    "OBSERVATION_NAMES",
    "OBS_DIM",
    "OBS_INDEX",
    "PATH_BOUND",
    "PATH_OBSERVATION",
    "PATH_POINTS",
    "PATH_REMAINING_BOUND",
    "PATH_SPACING",
    "ROBOT_OBSERVATION",
    "ActionKind",
    "EndReason",
    "ObservationField",
    "action_to_torque",
    "action_to_twist",
    "laser_fields",
    "observation_bounds",
    "observation_fields",
    "path_contract",
    "policy_contract",
    "register_observation",
    "scan_sectors",
]


@dataclass(frozen=True)
class ObservationField:
    """One entry of the observation vector."""

    name: str
    bound: float
    """The value is clipped to [-bound, bound] (or [:attr:`low`, bound]), in :attr:`unit`."""
    description: str
    unit: str
    """SI unit of the value (``-``: dimensionless)."""
    frame: str
    """The frame the value is expressed in (``-``: none)."""
    warp: object = None
    """For an observation kind of a task's own (:func:`register_observation`): the value's ``@wp.func``
    ``(params: Any, inputs: TermInputs, world: int) -> float``, clipped to the bound. None for the shipped kinds,
    whose kernels write them (:mod:`atrv_warp.task.kernels.observe`)."""
    low: float | None = None
    """The lower clip bound where it is not ``-bound`` (0 for a scan sector)."""


OBSERVATION: tuple[ObservationField, ...] = (
    ObservationField("target_x", 12.0, "target x", "m", "world (the arena's centre, z up)"),
    ObservationField("target_y", 12.0, "target y", "m", "world (the arena's centre, z up)"),
    ObservationField("rover_x", 30.0, "chassis origin x", "m", "world (the arena's centre, z up)"),
    ObservationField("rover_y", 30.0, "chassis origin y", "m", "world (the arena's centre, z up)"),
    ObservationField("rover_vx", 6.0, "chassis-origin velocity x", "m/s", "world (the arena's centre, z up)"),
    ObservationField("rover_vy", 6.0, "chassis-origin velocity y", "m/s", "world (the arena's centre, z up)"),
    ObservationField("roll", 0.25, "chassis roll (intrinsic Z-Y-X)", "rad", "chassis"),
    ObservationField("yaw_rate", 6.0, "chassis angular velocity about z", "rad/s", "world z"),
    ObservationField("sin_heading_error", 1.0, "sine of the angle from the heading to the target direction "
                     "(counter-clockwise positive)", "-", "chassis heading"),
    ObservationField("cos_heading_error", 1.0, "its cosine", "-", "chassis heading"),
)
"""The arena observation, in order (the reference task's fields and bounds): positions and velocities in the
arena's world frame, which only a simulator (or a motion-capture room) knows."""

ROBOT_OBSERVATION: tuple[ObservationField, ...] = (
    ObservationField("goal_distance", 30.0, "distance from the base to the goal, from wheel odometry and a goal in the "
                     "odometry frame (/odom pose, /goal_pose)", "m", "base_link"),
    ObservationField("sin_goal_bearing", 1.0, "sine of the goal's bearing from the base's +x (counter-clockwise "
                     "positive), from wheel odometry", "-", "base_link"),
    ObservationField("cos_goal_bearing", 1.0, "its cosine", "-", "base_link"),
    ObservationField("odom_linear", 3.0, "forward speed from the wheel encoders (/odom twist.linear.x)", "m/s",
                     "base_link"),
    ObservationField("odom_angular", 6.0, "yaw rate from the wheel encoders (/odom twist.angular.z)", "rad/s",
                     "base_link"),
    ObservationField("imu_roll", 1.0, "roll from the IMU's orientation (/imu orientation, intrinsic Z-Y-X)", "rad",
                     "imu (the URDF's cbimu_frame)"),
    ObservationField("imu_pitch", 1.0, "pitch from the IMU's orientation (/imu orientation)", "rad",
                     "imu (the URDF's cbimu_frame)"),
    ObservationField("imu_yaw_rate", 6.0, "angular velocity about the IMU's z (/imu angular_velocity.z)", "rad/s",
                     "imu (the URDF's cbimu_frame)"),
)
"""The robot observation, in order: only what a robot's own stack publishes (wheel odometry, an IMU, the goal in
the odometry frame; then the task's scan sectors and last actions). No arena coordinates."""

PATH_POINTS = 10
"""K: the points of the plan a path-following policy observes (:data:`PATH_OBSERVATION`)."""
PATH_SPACING = 0.4
"""[m] Their spacing along the plan: point k lies k x this past the robot's nearest point on the plan (k = 0 … K-1),
so the policy sees 3.6 m of the plan ahead, whatever the spacing of the path's own poses."""
PATH_BOUND = 5.0
"""[m] Each observed point's coordinates are clipped to ±this."""
PATH_REMAINING_BOUND = 10.0
"""[m] The observed length of the plan left is clipped to this."""

PATH_OBSERVATION: tuple[ObservationField, ...] = (
    *(ObservationField(f"path_{k}_{axis}", PATH_BOUND,
                       f"{axis} of the plan's point {k * PATH_SPACING:.1f} m past the base's nearest point on it "
                       "(point 0: that nearest point; past the plan's end, its end), from the localized pose (the "
                       "plan transformed through map -> odom -> base_link)", "m", "base_link")
      for k in range(PATH_POINTS) for axis in ("x", "y")),
    ObservationField("path_remaining", PATH_REMAINING_BOUND, "the plan's length from the base's nearest point on it to "
                     "its end (the goal)", "m", "-"),
    ObservationField("sin_goal_yaw", 1.0, "sine of the goal's heading less the base's (counter-clockwise positive): "
                     "the turn left to the goal's orientation", "-", "base_link"),
    ObservationField("cos_goal_yaw", 1.0, "its cosine", "-", "base_link"),
    *(f for f in ROBOT_OBSERVATION if f.name not in ("goal_distance", "sin_goal_bearing", "cos_goal_bearing")),
)
"""The path observation, in order: what Nav2's controller server hands its controller (the plan, as
``nav_msgs/Path`` from the planner, and the robot's localized pose), then the robot's own odometry twist and IMU;
then the task's scan sectors and last actions. The plan is read as :class:`~atrv_warp.core.path.PathTracker` reads it
(the nearest point searched forward from the last, :data:`PATH_POINTS` points :data:`PATH_SPACING` apart)."""

OBSERVATION_KINDS: dict[str, tuple[ObservationField, ...]] = {"arena": OBSERVATION, "robot": ROBOT_OBSERVATION,
                                                              "path": PATH_OBSERVATION}
"""``TaskConfig.observation`` -> the observation's leading fields (a task of your own adds its kind with
:func:`register_observation`)."""


def register_observation(kind: str, fields: tuple[ObservationField, ...]) -> tuple[ObservationField, ...]:
    """Add an observation kind of a task's own: its leading fields, each with the ``@wp.func`` that computes it
    (:attr:`ObservationField.warp`); the scan's sectors and the last actions follow them as for the shipped kinds.
    The domain randomization's sensor noise is the shipped kinds' only.

    Raises:
        ValueError: A shipped kind's name, no fields, a field without its function, or two of one name.
    """
    if kind in ("arena", "robot", "path"):
        raise ValueError(f"observation kind {kind!r} is a shipped one; name yours otherwise")
    names = [f.name for f in fields]
    if not fields or any(f.warp is None for f in fields) or len(set(names)) != len(names):
        raise ValueError(f"observation kind {kind!r}: needs fields of distinct names, each with its warp function")
    OBSERVATION_KINDS[kind] = tuple(fields)
    return OBSERVATION_KINDS[kind]


@dataclass(frozen=True)
class ActionKind:
    """What an action in [-1, 1]² commands."""

    name: str
    columns: tuple[str, str]
    unit: str
    description: str
    scales: tuple[tuple[str, str], tuple[str, str]]
    """Each column's scale: the :class:`~atrv_warp.task.config.TaskConfig` field that column 1.0 is worth, and its
    unit."""


ACTIONS: dict[str, ActionKind] = {
    "torque": ActionKind("torque", ("left", "right"), "N·m", "each side's wheel torque, x TaskConfig.action_scale",
                         (("action_scale", "N·m"), ("action_scale", "N·m"))),
    "twist": ActionKind("twist", ("linear", "angular"), "m/s, rad/s",
                        "a /cmd_vel: forward speed x TaskConfig.max_linear and yaw rate x TaskConfig.max_angular, "
                        "through the base's motor driver (atrv_warp.sim.driver)",
                        (("max_linear", "m/s"), ("max_angular", "rad/s"))),
}
"""``TaskConfig.action`` -> what the action means."""


def laser_fields(task, name: str = "scan", frame: str = "scanner (the URDF's lrf_frame)") -> tuple[ObservationField, ...]:
    """The observed sectors of a laser called ``name`` (its robot's ``links.laser`` is ``scan``; a robot file's
    ``[[sensors]]`` names the others): ``<name>_0 … <name>_{S-1}`` for ``task``'s ``scan_sectors`` (right to left),
    each in [0, 1]."""
    sectors = getattr(task, "scan_sectors", 0)
    return tuple(ObservationField(f"{name}_{i}", 1.0, f"nearest return in scan sector {i} of {sectors} (right to "
                                  "left, edges: scan_sectors(task)), min(range, scan_clip) / scan_clip; no return 1, "
                                  "too close 0", "-", frame, low=0.0) for i in range(sectors))


def observation_fields(task=None, sensors: tuple[ObservationField, ...] | None = None) -> tuple[ObservationField, ...]:
    """The observation of ``task`` (a :class:`~atrv_warp.task.config.TaskConfig`): :data:`OBSERVATION` (or
    :data:`ROBOT_OBSERVATION` for ``observation="robot"``), then the sensors' fields: ``sensors`` (every sensor's of the
    rover, in order: :func:`atrv_warp.task.sensors.sensor_fields`), or where ``None`` the scanner's alone,
    ``scan_0 … scan_{S-1}`` for its ``scan_sectors`` (:func:`laser_fields`), then
    ``last_action_1_left``, ``last_action_1_right`` … ``last_action_K_right`` for its ``action_history``
    (the actions chosen 1 … K steps before, newest first, in [-1, 1])."""
    history = getattr(task, "action_history", 0)
    scan = laser_fields(task) if sensors is None else tuple(sensors)
    columns = ACTIONS[getattr(task, "action", "torque")].columns
    actions = tuple(ObservationField(f"last_action_{k}_{side}", 1.0, f"the {side} action chosen {k} step(s) before "
                                     "(what a delayed rover has yet to apply), in [-1, 1]", "-", "-")
                    for k in range(1, history + 1) for side in columns)
    return OBSERVATION_KINDS[getattr(task, "observation", "arena")] + scan + actions


OBSERVATION_NAMES: tuple[str, ...] = tuple(f.name for f in OBSERVATION)
OBS_INDEX: dict[str, int] = {f.name: i for i, f in enumerate(OBSERVATION)}
OBS_DIM = len(OBSERVATION)
ACTION_DIM = 2
"""Two columns in [-1, 1]: [left, right] x ``TaskConfig.action_scale`` N·m per wheel (``torque``), or
[linear, angular] x (``max_linear``, ``max_angular``) (``twist``): :data:`ACTIONS`."""


class EndReason(IntEnum):
    """Why an episode ended (``end_reason``; ``RUNNING`` while it has not)."""

    RUNNING = 0
    SUCCESS = 1
    WALL = 2
    """A wall contact, or the chassis touching the ground."""
    FLIP = 3
    """|roll| beyond ``TaskConfig.flip_roll``."""
    TIMEOUT = 4
    """Truncated at ``TaskConfig.max_steps``."""
    NONFINITE = 5
    """The world's state stopped being finite; it is reset on its own."""
    OBSTACLE = 6
    """A rover shape touched an obstacle."""
    NO_PROGRESS = 7
    """The robot moved less than the task's ``progress_radius`` in ``progress_time`` (Nav2's progress checker: the
    controller server aborts the goal)."""


END_REASONS: tuple[str, ...] = tuple(r.name.lower() for r in EndReason)
"""``END_REASONS[end_reason]`` names an end reason."""

def observation_bounds(dtype: torch.dtype = torch.float32, task=None,
                       sensors: tuple[ObservationField, ...] | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(low, high) of the observation of ``task`` (default: the reference's, (OBS_DIM,) each; ``sensors``: as for
    :func:`observation_fields`)."""
    fields = observation_fields(task, sensors)
    high = torch.tensor([f.bound for f in fields], dtype=dtype)
    low = torch.tensor([-f.bound if f.low is None else f.low for f in fields], dtype=dtype)
    return low, high


def scan_sectors(task) -> ScanSectors | None:
    """The sectors a task observes of its scan (``None`` without them): ``scan_sectors`` equal sectors over the
    scanner's ``scan_fov`` plus one beam spacing, so that each holds ``scan_beams / scan_sectors`` of the
    simulated beams; any other scan (a real scanner's ``LaserScan``) reduces through the same edges."""
    if not getattr(task, "scan_sectors", 0):
        return None
    return ScanSectors.for_beams(task.scan_beams, task.scan_fov, task.scan_sectors, task.scan_clip)


def action_to_torque(action: torch.Tensor, action_scale: float, out: torch.Tensor | None = None) -> torch.Tensor:
    """Wheel torques [N·m] for actions: clipped to [-1, 1], times ``action_scale``."""
    return torch.mul(action.clamp(-1.0, 1.0), action_scale, out=out)


def action_to_twist(action: torch.Tensor, max_linear: float, max_angular: float) -> torch.Tensor:
    """(linear [m/s], angular [rad/s]) for actions (..., 2): clipped to [-1, 1], times the limits."""
    scale = torch.tensor([max_linear, max_angular], dtype=action.dtype, device=action.device)
    return action.clamp(-1.0, 1.0) * scale


BASE_LIMITS = (("linear_max_acceleration", "m/s²"), ("angular_max_acceleration", "rad/s²"))
"""The base's limits a task trains with (:class:`~atrv_warp.task.config.TaskConfig` fields, named as
``diff_drive_controller``'s), in an exported policy's contract: a robot's base should apply the same."""

_ACTION_COMMANDS = {
    "torque": "action[0] x scale[0] is the torque of every left wheel, action[1] x scale[1] of every right wheel [N·m]",
    "twist": "a geometry_msgs/Twist on /cmd_vel (base_link): linear.x = action[0] x scale[0] [m/s], angular.z = "
             "action[1] x scale[1] [rad/s], the other components 0",
}


def policy_contract(task) -> dict:
    """What a policy of ``task`` (a :class:`~atrv_warp.task.config.TaskConfig`) observes and commands, as plain
    values (JSON-ready): the task's part of an exported policy's contract.

    Keys: ``observation_kind`` (``arena`` | ``robot`` | ``path``); ``observation``, each field in order with ``name``,
    ``index``, ``low``, ``high``, ``bound``, ``unit``, ``frame``, ``description``; ``action``: ``kind`` (``torque``
    | ``twist``), ``names``, ``low``/``high`` (-1, 1), ``scale`` and ``units`` per column (what 1.0 is worth),
    ``limits`` (the :class:`~atrv_warp.task.config.TaskConfig` fields the scale comes from, by name, with units),
    ``base_limits`` (the :data:`BASE_LIMITS` the task's base applied to the command, by name, with units),
    ``command`` (what a robot does with it); ``scan``: ``{"sectors": ScanSectors.describe()}`` or ``None``;
    ``action_history``: ``steps``, ``columns`` and ``meaning``, or ``None``; ``path``: :func:`path_contract` for a
    path-following task, else ``None``.
    """
    fields = observation_fields(task)
    low, high = observation_bounds(task=task)
    kind = ACTIONS[task.action]
    sectors = scan_sectors(task)
    history = None
    if task.action_history:
        history = {"steps": task.action_history, "columns": list(kind.columns),
                   "meaning": f"last_action_k_<column>: the action (in [-1, 1], clipped) the policy chose k steps "
                              f"before this observation, newest first (k = 1 … {task.action_history}); zero after a "
                              "reset"}
    return {
        "observation_kind": task.observation,
        "observation": [{"name": f.name, "index": i, "low": float(lo), "high": float(hi), "bound": f.bound,
                         "unit": f.unit, "frame": f.frame, "description": f.description}
                        for i, (f, lo, hi) in enumerate(zip(fields, low.tolist(), high.tolist(), strict=True))],
        "observation_clipped": "each value is clipped to [low, high] before the policy sees it",
        "action": {"kind": kind.name, "names": list(kind.columns), "low": -1.0, "high": 1.0,
                   "scale": [float(getattr(task, f)) for f, _ in kind.scales], "units": [u for _, u in kind.scales],
                   "limits": {f: {"value": float(getattr(task, f)), "unit": u} for f, u in kind.scales},
                   "command": _ACTION_COMMANDS[kind.name], "meaning": kind.description + "; actions are clipped to "
                   "[-1, 1]",
                   "base_limits": {name: {"value": getattr(task, name), "unit": unit} for name, unit in BASE_LIMITS
                                   if getattr(task, name) is not None}},
        "scan": {"sectors": sectors.describe()} if sectors is not None else None,
        "action_history": history,
        "path": path_contract(task) if task.observation == "path" else None,
    }


def path_contract(task) -> dict:
    """How a path-following policy of ``task`` (a :class:`~atrv_warp.task.config.FollowPathConfig`) reads its plan
    and when its goal ends, as plain values: the :data:`PATH_OBSERVATION`'s points (count, spacing, the search for the
    nearest point), and Nav2's goal and progress checkers as the task judged them (named as Nav2's params file names
    them)."""
    return {"points": PATH_POINTS, "spacing_m": PATH_SPACING, "search_m": task.path_search,
            "frame": "the plan's poses and the base's pose in one frame (map, through map -> odom -> base_link); the "
                     "points observed in base_link",
            "meaning": "the nearest point of the plan to the base is searched from the last one forward, over "
                       f"{task.path_search:g} m of the plan (Nav2's max_robot_pose_search_dist), on its segments; a new "
                       "plan starts the search at its first pose. path_k is the point k x spacing_m further along the "
                       "plan (its end past the end); path_remaining the plan's length from the nearest point on. The "
                       "plan's orientations are not read but the goal's (its last pose's)",
            "goal_checker": {"plugin": "nav2_controller::SimpleGoalChecker", "xy_goal_tolerance": task.reach_radius,
                             "yaw_goal_tolerance": task.yaw_tolerance, "stateful": True},
            "progress_checker": {"plugin": "nav2_controller::SimpleProgressChecker",
                                 "required_movement_radius": task.progress_radius,
                                 "movement_time_allowance": task.progress_time}}
