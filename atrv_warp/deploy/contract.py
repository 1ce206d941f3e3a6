"""The exported policy the deploy node runs: :func:`load_deployable` opens a ``.pt2`` (``python -m atrv_warp.export``)
and refuses, in one line, a file or a contract the node cannot serve: a missing or garbage file, no contract, another
contract format, a ``torque`` policy (it commands wheel torques, not ``/cmd_vel``) or an ``arena`` observation (it
observes what only the simulator knows). A ``robot`` observation's policy drives to a goal; a ``path`` one
(``follow_path``) follows Nav2's plan, read as its contract's ``path`` entry says (:class:`Deployable.path_settings`).

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from atrv_warp.core.contract import EXPORT_FORMAT, read_exported
from atrv_warp.core.files import ExportedFileError
from atrv_warp.core.observation import RobotObservation
from atrv_warp.core.path import PathTracker

__all__ = ["EXPORT_FORMAT", "RATE_RANGE_HZ", "Deployable", "PathSettings", "PolicyRefused", "load_deployable"]


class PolicyRefused(ValueError):
    """A policy file or contract the node cannot serve; the message is one line naming the file and the problem."""


@dataclass(frozen=True)
class PathSettings:
    """How a plan-following policy reads its plan and when Nav2's checkers end it (its contract's ``path`` entry)."""

    points: int
    spacing: float
    """[m]"""
    search: float
    """[m]"""
    xy_goal_tolerance: float
    """The goal checker's (``SimpleGoalChecker``, stateful) position tolerance [m]."""
    yaw_goal_tolerance: float
    """Its heading tolerance [rad]."""
    required_movement_radius: float
    """The progress checker's (``SimpleProgressChecker``) radius [m]."""
    movement_time_allowance: float
    """[s]"""

    @classmethod
    def from_contract(cls, contract: dict) -> PathSettings:
        """Raises ``ValueError`` where the ``path`` entry is missing, malformed or not finite and positive."""
        tracker = PathTracker.from_contract(contract)  # names a missing or malformed entry
        path = contract["path"]
        try:
            goal, progress = path["goal_checker"], path["progress_checker"]
            values = (float(goal["xy_goal_tolerance"]), float(goal["yaw_goal_tolerance"]),
                      float(progress["required_movement_radius"]), float(progress["movement_time_allowance"]))
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"the contract's path entry lacks its goal or progress checker ({err!r})") from None
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise ValueError(f"the contract's goal and progress checker settings must be finite and > 0, got {values}")
        return cls(tracker.points, tracker.spacing, tracker.search, *values)

    def tracker(self) -> PathTracker:
        """A fresh :class:`~atrv_warp.core.path.PathTracker` reading the plan as the policy trained."""
        return PathTracker(self.points, self.spacing, self.search)


@dataclass(frozen=True)
class Deployable:
    """An exported policy the node can run: a ``twist`` action from the ``robot`` observation (to a goal) or the
    ``path`` one (along a plan)."""

    path: str
    """The ``.pt2`` file."""
    module: torch.nn.Module
    """The exported program's module: observation (B, D) float32 -> action (B, 2) in [-1, 1]."""
    contract: dict
    """Its ``atrv_warp.json`` (:func:`atrv_warp.rl.export.contract`)."""
    observation: RobotObservation
    """Builds its input from the robot's messages (the contract's fields, sectors and action history)."""
    scale: tuple[float, float]
    """What an action of 1.0 commands: linear.x [m/s], angular.z [rad/s] (the trained limits)."""
    rate_hz: float
    """The control rate it was trained at [Hz] (1 / the simulator's ``step_dt``)."""
    path_settings: PathSettings | None = None
    """How it reads its plan and when Nav2's checkers end it (a ``path`` policy); ``None``: it drives to a goal."""

    @property
    def period(self) -> float:
        """The control period [s]."""
        return 1.0 / self.rate_hz

    @property
    def reach_radius(self) -> float | None:
        """The distance from the goal within which the policy's task counted it reached [m] (its contract's
        ``reach_radius_m``; ``None`` for a file exported before it was kept)."""
        radius = self.contract.get("reach_radius_m")
        ok = isinstance(radius, int | float) and not isinstance(radius, bool) and math.isfinite(radius) and radius > 0
        return float(radius) if ok else None

    @property
    def robot(self) -> str | None:
        """The robot it was trained on (its contract's ``robot.name``; ``None`` for a policy exported before robots had
        files, which trained on the ATRV-Jr)."""
        robot = self.contract.get("robot")
        name = robot.get("name") if isinstance(robot, dict) else None
        return name if isinstance(name, str) and name else None

    def describe_robot(self) -> str:
        """One line: the robot it was trained on, and that robot's published limits."""
        robot = self.contract.get("robot")
        if not isinstance(robot, dict):
            return "trained on the ATRV-Jr (exported before policies recorded their robot)"
        lim = robot.get("limits") if isinstance(robot.get("limits"), dict) else {}  # a file's contract: any shape
        parts = [f"{lim[k]:g} {u}" for k, u in (("linear_velocity", "m/s"), ("angular_velocity", "rad/s"),
                                                ("linear_acceleration", "m/s²"), ("angular_acceleration", "rad/s²"))
                 if isinstance(lim.get(k), (int, float))]
        return f"trained on {self.robot} ({robot.get('title')!s}), whose limits are {', '.join(parts) or 'not recorded'}"

    def describe(self) -> str:
        """One line: what the policy observes and commands, at what rate."""
        s = self.observation.sectors
        scan = f", {s.count} scan sectors over [{s.edges[0]:.3f}, {s.edges[-1]:.3f}] rad" if s else ""
        kind = "path" if self.path_settings else "robot"
        return (f"{self.path}: task {self.contract.get('task', '?')}, {kind} observation "
                f"({len(self.observation.fields)},){scan}, twist action x ({self.scale[0]:g} m/s, {self.scale[1]:g} "
                f"rad/s) at {self.rate_hz:.3g} Hz{self.base_limits()}")

    def base_limits(self) -> str:
        """The limits its training's base applied to /cmd_vel (the contract's ``base_limits``), for the robot's
        ``diff_drive_controller`` to apply too: ``""`` where none, else e.g. ``"; trained on a base with
        linear.x.max_acceleration 1 m/s²"``."""
        limits = (self.contract.get("action") or {}).get("base_limits") or {}
        names = {"linear_max_acceleration": "linear.x.max_acceleration",
                 "angular_max_acceleration": "angular.z.max_acceleration"}
        cells = [f"{names.get(k, k)} {v['value']:g} {v['unit']}" for k, v in limits.items()]
        return f"; trained on a base with {', '.join(cells)}" if cells else ""


RATE_RANGE_HZ = (1.0, 200.0)
"""The control rates [Hz] the node serves: a contract outside them is refused (a robot's base takes commands at
tens of Hz; 10⁻⁶ Hz would never command, 10⁹ Hz would flood the bus)."""

def load_deployable(path: str | Path) -> Deployable:
    """Open an exported policy and check that the node can serve its contract.

    The file is read by :func:`atrv_warp.core.contract.read_exported` (checked before torch loads it: nothing
    in it can run code), and the program is run once on a zero observation of the contract's width.

    Raises:
        PolicyRefused: One line naming the file and the problem: missing, not a ``torch.export`` archive, refused
            by the check, no or another contract format, a ``torque`` action, an ``arena`` observation (its fields
            named), a contract the observation builder cannot read (or a ``path`` one without its checkers), a rate
            outside :data:`RATE_RANGE_HZ`, or a program that does not take the contract's observation to a (1, 2)
            action.
    """
    path = str(path)
    if not Path(path).is_file():
        raise PolicyRefused(f"{path}: no such policy file (export one: python -m atrv_warp.export POLICY OUT.pt2)")
    try:
        program, contract = read_exported(path)
    except ExportedFileError as err:
        raise PolicyRefused(str(err)) from None
    action = contract.get("action") or {}
    if action.get("kind") != "twist":
        raise PolicyRefused(f"{path}: a {action.get('kind')!r} policy ({', '.join(map(str, action.get('names', [])))} "
                            f"[{', '.join(map(str, action.get('units', [])))}]); the node commands /cmd_vel and serves "
                            "'twist' policies only (task nav_deploy)")
    kind = contract.get("observation_kind", "arena")
    if kind not in ("robot", "path"):
        names = [f.get("name") if isinstance(f, dict) else f for f in contract.get("observation", [])]
        raise PolicyRefused(f"{path}: the policy observes the {kind!r} observation ({', '.join(map(str, names[:8]))}"
                            f"{', …' if len(names) > 8 else ''}), which a robot does not publish; the node serves "
                            "'robot' and 'path' observations (tasks nav_deploy and follow_path)")
    try:
        observation = RobotObservation.from_contract(contract)
        path_settings = PathSettings.from_contract(contract) if kind == "path" else None
        scale = tuple(float(v) for v in action["scale"])
        rate = float(contract["rate_hz"])
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise PolicyRefused(f"{path}: a contract the node cannot read ({type(err).__name__}: {err})") from None
    if len(scale) != 2 or not all(math.isfinite(v) and v > 0 for v in scale):
        raise PolicyRefused(f"{path}: action scale {list(scale)} must be two finite numbers > 0")
    low, high = RATE_RANGE_HZ
    if not (math.isfinite(rate) and low <= rate <= high):
        raise PolicyRefused(f"{path}: control rate {rate:.3g} Hz is outside the {low:g}-{high:g} Hz the node serves")
    step_dt = contract.get("step_dt")
    if step_dt is not None and not (isinstance(step_dt, (int, float)) and math.isclose(rate * step_dt, 1.0,
                                                                                         rel_tol=1e-6)):
        raise PolicyRefused(f"{path}: rate_hz {rate:g} disagrees with step_dt {step_dt!r} s (the period, 1 / rate_hz)")
    module = program.module()
    width = len(observation.fields)
    try:
        with torch.no_grad():
            out = module(torch.zeros(1, width))
    except Exception as err:  # noqa: BLE001 - any failure here is a program that does not fit its contract
        raise PolicyRefused(f"{path}: the contract lists {width} observation fields, but the program refuses a "
                            f"(1, {width}) input ({type(err).__name__}: {' '.join(str(err).split())[:120]})") from None
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (1, 2) or not bool(torch.isfinite(out).all()):
        got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise PolicyRefused(f"{path}: the program maps a (1, {width}) observation to {got}, not a finite (1, 2) "
                            "action")
    return Deployable(path, module, contract, observation, scale, rate, path_settings)
