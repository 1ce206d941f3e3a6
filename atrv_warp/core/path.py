"""How a path-following policy reads its plan, in torch: :class:`PathTracker`, the twin of the simulator's
``task/kernels/paths.py`` for a robot (its deploy node, a second engine).

Nav2's controller server hands its controller a plan (``nav_msgs/Path``, from the planner, about once a second) and
the robot's pose; a controller finds the robot's nearest point on the plan, searching forward from the last one
over a bounded stretch (RPP's and MPPI's ``max_robot_pose_search_dist``), and reads the plan ahead of it. The
tracker does the same, the same way every time:

- the nearest point is searched on the plan's segments, from the segment of the last one forward, over the segments
  that start within ``search`` metres of the plan from that segment's start (a new plan: from its first segment);
  the first of equally near points is kept;
- point ``k`` (k = 0 … K-1) lies ``k x spacing`` further along the plan (point 0 is the nearest point itself; past
  the plan's end, its end), in the base's frame: x forward, y left;
- the plan's length left is measured from the nearest point to the plan's end;
- the goal is the plan's last point, with the goal's heading (a plan's other orientations are not read).

K, the spacing and the search come from an exported policy's contract (its ``path`` entry: ``points``,
``spacing_m``, ``search_m``), so nothing here is declared. Example, one robot::

    tracker = PathTracker.from_contract(contract)       # an exported policy's atrv_warp.json
    tracker.set_path(xy, goal_yaw)                        # (L, 2) the plan's poses [m], and the goal's yaw [rad]
    fields = tracker(pose)                                # (x, y, yaw) in the plan's frame -> the path fields
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch

from atrv_warp.core.geometry import wrap_angle

__all__ = ["PathTracker"]


class PathTracker:
    """One robot's plan and where the robot is on it (stateful: the nearest point is searched forward from the
    last); calling it with the robot's pose gives the path observation's fields, by name."""

    def __init__(self, points: int, spacing: float, search: float):
        """
        Args:
            points: K, the points observed ahead.
            spacing: Their spacing along the plan [m].
            search: How far along the plan past the last nearest point the next is searched for [m].

        Raises:
            ValueError: A count below 1 or a spacing or search that is not a finite number > 0.
        """
        if not (isinstance(points, int) and points >= 1):
            raise ValueError(f"PathTracker: points must be a whole number >= 1, got {points!r}")
        for name, value in (("spacing", spacing), ("search", search)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"PathTracker: {name} must be a finite number > 0 [m], got {value!r}")
        self.points, self.spacing, self.search = points, float(spacing), float(search)
        self.path: torch.Tensor | None = None
        """(L, 2) float64 the plan's points [m], or ``None`` before the first."""
        self.goal_yaw = 0.0
        self.segment = 0
        """The segment the last nearest point lay on (the next search starts there)."""

    @classmethod
    def from_contract(cls, contract: Mapping) -> PathTracker:
        """From an exported policy's contract (its ``path`` entry).

        Raises:
            ValueError: The policy does not follow a plan (no ``path`` entry).
        """
        path = contract.get("path")
        if not isinstance(path, Mapping):
            raise ValueError("the policy's contract has no 'path' entry: it does not follow a plan (a policy of a "  # noqa: TRY004
                             "task with observation='path', e.g. follow_path)")
        try:
            return cls(int(path["points"]), float(path["spacing_m"]), float(path["search_m"]))
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"the contract's 'path' entry is malformed: {err}") from None

    def set_path(self, xy, goal_yaw: float) -> None:
        """A new plan: its points (L, 2) [m] in one frame with the poses the tracker is then called with, start to
        goal (L >= 1), and the goal's heading [rad]. The search starts again at its first segment.

        Raises:
            ValueError: No points, a shape other than (L, 2), or a non-finite value (the plan is not taken).
        """
        p = torch.as_tensor(xy, dtype=torch.float64)
        if p.ndim != 2 or p.shape[-1] != 2 or p.shape[0] < 1:
            raise ValueError(f"a plan is (L, 2) points with L >= 1, got shape {tuple(p.shape)}")
        if not (bool(torch.isfinite(p).all()) and math.isfinite(float(goal_yaw))):
            raise ValueError("a plan with non-finite points or goal heading is not followed")
        self.path, self.goal_yaw, self.segment = p, float(goal_yaw), 0

    def nearest(self, x: float, y: float) -> tuple[int, float, torch.Tensor, float]:
        """(segment, fraction along it, the point (2,), the distance [m]) of the plan's nearest point to (x, y), as
        searched from :attr:`segment`; :attr:`segment` moves there."""
        p, q = self._need(), torch.tensor([x, y], dtype=torch.float64)
        if len(p) == 1:
            return 0, 0.0, p[0], float((q - p[0]).norm())
        best, where, travelled = math.inf, (self.segment, 0.0), 0.0
        for i in range(self.segment, len(p) - 1):
            a, ab = p[i], p[i + 1] - p[i]
            length2 = float(ab @ ab)
            t = 0.0 if length2 == 0.0 else min(max(float((q - a) @ ab) / length2, 0.0), 1.0)
            d = float((q - (a + t * ab)).norm())
            if d < best:
                best, where = d, (i, t)
            travelled += math.sqrt(length2)
            if travelled > self.search:
                break
        self.segment = where[0]
        i, t = where
        return i, t, p[i] + t * (p[i + 1] - p[i]), best

    def __call__(self, pose) -> dict[str, float]:
        """The path fields for the robot at ``pose`` (x [m], y [m], yaw [rad], in the plan's frame): ``path_<k>_x``,
        ``path_<k>_y`` (base frame), ``path_remaining``, ``sin_goal_yaw``, ``cos_goal_yaw``, and ``path_offset``
        (the distance from the plan [m], which the policy does not observe); unclipped.

        Raises:
            ValueError: No plan set yet, or a pose that is not three finite numbers.
        """
        pose = torch.as_tensor(pose, dtype=torch.float64).reshape(-1)
        if pose.shape != (3,) or not bool(torch.isfinite(pose).all()):
            raise ValueError(f"pose: expected three finite numbers (x, y, yaw), got {pose.tolist()}")
        x, y, yaw = (float(v) for v in pose)
        p = self._need()
        segment, _, point, offset = self.nearest(x, y)
        last = len(p) - 1
        remaining = float((p[min(segment + 1, last)] - point).norm()) + float(
            (p[segment + 2:] - p[segment + 1:-1]).norm(dim=-1).sum()) if last else 0.0
        c, s = math.cos(yaw), math.sin(yaw)
        out = {}
        for k in range(self.points):
            if k:
                segment, point = self._advance(segment, point, self.spacing)
            dx, dy = float(point[0]) - x, float(point[1]) - y
            out[f"path_{k}_x"], out[f"path_{k}_y"] = c * dx + s * dy, -s * dx + c * dy
        turn = float(wrap_angle(torch.tensor(self.goal_yaw - yaw, dtype=torch.float64)))
        out.update(path_remaining=remaining, sin_goal_yaw=math.sin(turn), cos_goal_yaw=math.cos(turn),
                   path_offset=offset)
        return out

    def _advance(self, segment: int, point: torch.Tensor, distance: float) -> tuple[int, torch.Tensor]:
        """The point ``distance`` [m] further along the plan from ``point`` on ``segment`` (its end past the end)."""
        p, last = self.path, len(self.path) - 1
        while segment < last:
            end = p[segment + 1]
            left = float((end - point).norm())
            if distance <= left:
                return segment, point + (end - point) * (distance / left) if left > 0 else end
            distance -= left
            segment, point = segment + 1, end
        return last, p[last]

    def _need(self) -> torch.Tensor:
        if self.path is None:
            raise ValueError("no plan yet: set_path(xy, goal_yaw) first")
        return self.path
