"""A ``FollowPath`` goal as Nav2's controller server holds it, without ROS: the plan, where the robot is on it, and
Nav2's goal and progress checkers.

:func:`read_path` takes a ``nav_msgs/Path`` (or refuses it with the code Nav2 gives, :class:`PathRefused`);
:class:`FollowedPath` follows it. The semantics are the controller server's (``nav2_controller``): a new goal starts
the progress checker again, and every path handed over (a new goal, or the behaviour tree's replan that preempts the
active one) starts the goal checker again; the checkers are Nav2's ``SimpleGoalChecker`` (stateful: once within
the position tolerance, the position is kept while the heading turns) and ``SimpleProgressChecker`` (the robot must
leave a circle of ``required_movement_radius`` around where it last left one within ``movement_time_allowance``),
with the tolerances the policy trained with (its contract's ``path`` entry, :class:`~atrv_warp.deploy.contract.
PathSettings`). :class:`~atrv_warp.deploy.controller.Controller` drives by it.

Only torch and :mod:`atrv_warp.core` are imported here (``tests/test_layers.py`` holds it).
"""

from __future__ import annotations

import math

import torch

from atrv_warp.core.geometry import quat_to_yaw
from atrv_warp.core.tf import frame_id

__all__ = ["MAX_PATH_POSES", "TRANSFORM_TOLERANCE", "FollowedPath", "PathRefused", "read_path"]

MAX_PATH_POSES = 20_000
"""The most poses a path may have: a longer one is aborted (``INVALID_PATH``), not held in memory. Nav2's planners
give a pose per costmap cell: 20,000 is a 1 km path at 5 cm, or 100 m of a path that doubles back on itself in a
100 m x 100 m map, more than any plan a controller is handed."""


TRANSFORM_TOLERANCE = 0.3
"""How long [s] a path waits, the rover held, for ``/tf`` to join the odometry to its frame before it is aborted with
``TF_ERROR``: Nav2's costmap ``transform_tolerance`` default (ros-navigation/navigation2@7436bbe7
``nav2_costmap_2d/src/costmap_2d_ros.cpp``, Kilted). A transform that comes late (a path sent as the node starts,
before ``/tf_static`` reaches it) is waited for; one that never comes ends the goal."""


class PathRefused(ValueError):
    """A path the controller cannot follow: ``code`` is Nav2's ``FollowPath`` result code name (``INVALID_PATH``,
    ``TF_ERROR``), the message one line naming the problem."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


def read_path(msg, *, tf: bool, odom_frame: str) -> tuple[str, torch.Tensor, float]:
    """(its frame, its poses' positions (L, 2) float64 [m], the last pose's yaw [rad]) of a ``nav_msgs/Path``.

    The frame is the path's ``header.frame_id`` (or, where empty, its first pose's); the goal's heading is the last
    pose's orientation (a plan's other orientations are not read, as the policy trained).

    Raises:
        PathRefused: ``INVALID_PATH`` for no poses, more than :data:`MAX_PATH_POSES`, a non-finite position or
            orientation, or no frame; ``TF_ERROR`` for a frame other than ``odom_frame`` where no ``/tf`` comes.
    """
    poses = msg.poses
    count = len(poses)
    if count == 0:
        raise PathRefused("INVALID_PATH", "the path has no poses")
    if count > MAX_PATH_POSES:
        raise PathRefused("INVALID_PATH", f"the path has {count} poses, more than the {MAX_PATH_POSES} "
                                          "(MAX_PATH_POSES) the node holds")
    frame = frame_id(msg.header.frame_id or poses[0].header.frame_id or "")
    if not frame:
        raise PathRefused("INVALID_PATH", "the path names no frame (header.frame_id is empty)")
    if frame != odom_frame and not tf:
        raise PathRefused("TF_ERROR", f"the path is in frame {frame!r} and this node reads no /tf (tf2_msgs is not "
                                      f"installed: source the robot's ROS 2); send it in {odom_frame!r}")
    xy = torch.tensor([(p.pose.position.x, p.pose.position.y) for p in poses], dtype=torch.float64)
    o = poses[-1].pose.orientation
    q = torch.tensor([o.x, o.y, o.z, o.w], dtype=torch.float64)
    if not bool(torch.isfinite(xy).all()):
        bad = int((~torch.isfinite(xy).all(-1)).nonzero()[0])
        raise PathRefused("INVALID_PATH", f"pose {bad} of the path is not finite ({xy[bad].tolist()})")
    if not bool(torch.isfinite(q).all()) or float(q.norm()) < 1e-6:
        raise PathRefused("INVALID_PATH", f"the path's last orientation {q.tolist()} is not a rotation")
    return frame, xy, float(quat_to_yaw(q / q.norm()))


class FollowedPath:
    """One ``FollowPath`` goal being followed: its plan in its frame, the tracker that reads it, and the checkers.

    Args:
        settings: The policy's :class:`~atrv_warp.deploy.contract.PathSettings`.
        frame, xy, goal_yaw: :func:`read_path`'s output.
        now: ROS time the goal started [s].
    """

    def __init__(self, settings, frame: str, xy: torch.Tensor, goal_yaw: float, now: float):
        self.settings = settings
        self.tracker = settings.tracker()
        self.progress_at: tuple[float, float, float] | None = None
        """The progress checker's (x [m], y [m], time [s]): where and when the robot last left its circle."""
        self.started = now
        self.no_transform_since: float | None = None
        """When ``/tf`` last stopped joining the odometry to :attr:`frame` [s] (None: it joins them)."""
        self.replace(frame, xy, goal_yaw)

    def replace(self, frame: str, xy: torch.Tensor, goal_yaw: float) -> None:
        """A path handed over (a new goal, or a replan preempting this one): followed from its start, and the goal
        checker starts again (the progress checker does not: the robot drives on)."""
        self.frame = frame
        self.tracker.set_path(xy, goal_yaw)
        self.end = (float(xy[-1, 0]), float(xy[-1, 1]))
        """The goal's position [m] in :attr:`frame`."""
        self.goal_yaw = goal_yaw
        self.position_reached = False
        self.fields: dict[str, float] | None = None
        """The path fields at the robot's last pose (:class:`~atrv_warp.core.path.PathTracker`)."""

    def follow(self, pose: tuple[float, float, float]) -> dict[str, float]:
        """The path fields for the robot at ``pose`` (x, y, yaw in :attr:`frame`)."""
        self.fields = self.tracker(pose)
        return self.fields

    def goal_reached(self, pose: tuple[float, float, float]) -> bool:
        """Nav2's ``SimpleGoalChecker``, stateful: within ``xy_goal_tolerance`` of the goal (kept once true), then
        within ``yaw_goal_tolerance`` of its heading."""
        s = self.settings
        if not self.position_reached:
            self.position_reached = math.hypot(pose[0] - self.end[0], pose[1] - self.end[1]) <= s.xy_goal_tolerance
        turn = math.remainder(self.goal_yaw - pose[2], 2 * math.pi)
        return self.position_reached and abs(turn) <= s.yaw_goal_tolerance

    def stalled(self, pose: tuple[float, float, float], now: float) -> bool:
        """Nav2's ``SimpleProgressChecker``: False while the robot leaves a ``required_movement_radius`` circle
        around where it last left one within ``movement_time_allowance``; True once it has not."""
        s = self.settings
        at = self.progress_at
        if at is None or math.hypot(pose[0] - at[0], pose[1] - at[1]) > s.required_movement_radius:
            self.progress_at = (pose[0], pose[1], now)
            return False
        return now - at[2] > s.movement_time_allowance

    def transform_lost(self, found: bool, now: float) -> bool:
        """Whether the path's frame has been out of ``/tf``'s reach for more than :data:`TRANSFORM_TOLERANCE`, given
        whether it was ``found`` this period."""
        if found:
            self.no_transform_since = None
            return False
        if self.no_transform_since is None:
            self.no_transform_since = now
        return now - self.no_transform_since > TRANSFORM_TOLERANCE

    def held_too_long(self, now: float) -> bool:
        """While the rover is held (a sensor unusable): True once it has not left the progress checker's circle for
        ``movement_time_allowance`` (since the goal started, where the checker never ran), so a goal held for good
        ends as Nav2's would, not never."""
        since = self.progress_at[2] if self.progress_at is not None else self.started
        return now - since > self.settings.movement_time_allowance

    @property
    def remaining(self) -> float | None:
        """The plan's length from the robot's nearest point to its end [m] (None before the first period)."""
        return None if self.fields is None else self.fields["path_remaining"]
