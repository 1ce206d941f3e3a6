"""Safety that does not depend on the policy: the deploy node's collision monitor, without ROS.

As Nav2's ``collision_monitor`` configures its ``polygon`` zones (``action_type`` ``stop`` and ``slowdown``, each
``points`` in the base frame, ``min_points`` and ``slowdown_ratio``: ros-navigation/navigation2@7436bbe7
``nav2_collision_monitor/src/polygon.cpp``, Kilted): every period the scan's returns are counted inside each zone; with
at least ``min_points`` in the stop zone the command is zero, else with as many in the slowdown zone it is scaled by
``slowdown_ratio``, whatever the policy commanded. The zones are the robot file's ``[deploy]`` ``stop_zone`` and
``slowdown_zone`` (node parameters of those names, Nav2's ``points`` text: ``"[[x, y], [x, y], ...]"``). A stack that
runs Nav2's own collision monitor sets ``collision_monitor:=false``.

The returns are placed as the policy's scanner sees them: the scanner's mount on the chassis from the policy's
contract (``scan.mount``), and a scanner mounted elsewhere carried there first (the controller's ``/tf`` check). The
zones are in that chassis frame.

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import torch

from atrv_warp.core.observation import Scan
from atrv_warp.core.parameters import ParameterError
from atrv_warp.core.scan import remount

__all__ = ["ACTIONS", "CollisionMonitor", "parse_zone"]

ACTIONS = ("none", "away", "slowdown", "stop")
"""What the monitor does to a command, mildest first (``away``: a command the zones do not act on, forward only)."""


def parse_zone(name: str, text: str) -> tuple[tuple[float, float], ...]:
    """A zone as Nav2 writes a polygon's ``points``: ``"[[x, y], [x, y], [x, y], ...]"`` [m] (``""``: none).

    Raises:
        ParameterError: Not that form, fewer than three points, or a non-finite number (one line naming ``name``).
    """
    if not text.strip():
        return ()
    try:
        points = json.loads(text)
        zone = tuple((float(x), float(y)) for x, y in points)
    except (ValueError, TypeError) as err:
        raise ParameterError(f"parameter {name} must be a polygon as Nav2 writes its points, "
                             f"\"[[x, y], [x, y], [x, y]]\" "
                         f"[m], got {text!r} ({type(err).__name__})") from None
    if len(zone) < 3 or not all(math.isfinite(v) for p in zone for v in p):
        raise ParameterError(f"parameter {name} must have at least three finite points [m], got {text!r}")
    return zone


def _inside(x: torch.Tensor, y: torch.Tensor, zone: tuple[tuple[float, float], ...]) -> torch.Tensor:
    """Which points (x, y) lie inside the polygon ``zone`` (even-odd rule, as Nav2's ``Polygon::isPointInside``)."""
    inside = torch.zeros_like(x, dtype=torch.bool)
    for (x1, y1), (x2, y2) in zip(zone, zone[1:] + zone[:1], strict=True):
        crosses = (y1 > y) != (y2 > y)
        at = (x2 - x1) * (y - y1) / (y2 - y1 if y2 != y1 else 1e-300) + x1
        inside ^= crosses & (x < at)
    return inside


@dataclass
class CollisionMonitor:
    """The zones and what they do (:func:`apply` each period)."""

    stop_zone: tuple[tuple[float, float], ...] = ()
    slowdown_zone: tuple[tuple[float, float], ...] = ()
    slowdown_ratio: float = 0.5
    """Nav2's default."""
    min_points: int = 4
    """Nav2's default (Jazzy on): the least returns inside a zone that act."""
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The policy's scanner on the chassis (x [m], y [m], yaw [rad])."""
    forward_only: bool = False
    """The zones act only on commands that drive forward (``zone_motion`` forward): turning in place and backing away
    pass, as under a Nav2 ``VelocityPolygon`` whose forward sub-polygons are these zones (Jazzy on; Nav2's answer to
    a stop zone that holds a robot for good, ros-navigation/navigation2#3313). Nav2's ``Polygon`` acts on every
    command."""
    action: str = "none"
    """What the last period did (:data:`ACTIONS`): a line is said when it changes."""

    @property
    def active(self) -> bool:
        return bool(self.stop_zone or self.slowdown_zone)

    def points(self, scan: Scan) -> tuple[torch.Tensor, torch.Tensor]:
        """The scan's returns (valid ranges) as points (x, y) in the chassis frame [m]."""
        ranges = torch.as_tensor(scan.ranges, dtype=torch.float64).reshape(-1)
        angles = scan.angles()
        if scan.mount is not None and any(scan.mount):
            ranges, angles = remount(ranges, angles, scan.mount, range_min=scan.range_min, range_max=scan.range_max)
        valid = torch.isfinite(ranges) & (ranges >= scan.range_min) & (ranges <= scan.range_max)
        r, a = ranges[valid], angles[valid]
        mx, my, myaw = self.mount
        return mx + r * torch.cos(a + myaw), my + r * torch.sin(a + myaw)

    def apply(self, command: tuple[float, float], scan: Scan | None) -> tuple[tuple[float, float], str | None]:
        """(the command to publish, a line to log where the action changed). Without a scan nothing is judged (the
        controller holds the rover on a missing or stale scan itself)."""
        if not self.active or scan is None:
            return command, None
        x, y = self.points(scan)
        counts = {name: int(_inside(x, y, zone).sum()) if zone else 0
                  for name, zone in (("stop", self.stop_zone), ("slowdown", self.slowdown_zone))}
        action = next((a for a in ("stop", "slowdown") if counts[a] >= self.min_points), "none")
        if self.forward_only and action != "none" and command[0] <= 0.0:
            action = "away"
        said, self.action = self.action, action
        line = None
        if action != said:
            line = ("collision monitor: clear, the policy's command passes" if action == "none" else
                    "collision monitor: the command turns or backs away from the zone: it passes" if action == "away"
                    else f"collision monitor: {counts[action]} scan points in the {action} zone: "
                    + ("stopping" if action == "stop" else f"slowing to {self.slowdown_ratio:g} x the command"))
        if action == "stop":
            return (0.0, 0.0), line
        if action == "slowdown":
            return (command[0] * self.slowdown_ratio, command[1] * self.slowdown_ratio), line
        return command, line
