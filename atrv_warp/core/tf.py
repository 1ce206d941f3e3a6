"""A transform buffer for goals in any frame: the latest transform of each edge of the tf tree, and lookups along it.

What ``tf2_ros.Buffer`` does for a goal, without tf2_ros (which no package index provides): :meth:`TransformBuffer.add`
takes a ``tf2_msgs/TFMessage`` from ``/tf`` or ``/tf_static`` (read by its fields alone, so the tests pass plain
namespaces), keeps the latest transform of each parent-child edge, and :meth:`TransformBuffer.transform_point` carries
a point from one frame into another along the tree, through as many edges as join them (``map -> odom`` from a
localisation, or ``base_link -> laser`` from a robot's description). Lookups use the latest transforms: a goal held in
``map`` follows the localisation's correction as it moves. Plain Python, no torch, so the robot's node can use it.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass

__all__ = ["MAX_FRAMES", "MAX_PER_MESSAGE", "STALE_AFTER_S", "Transform", "TransformBuffer", "frame_id"]

MAX_FRAMES = 1000
"""The most frames a buffer keeps: a robot's tree has tens; a new frame past them is skipped (frames it holds still
update), so a flood of new names cannot grow it or slow a lookup."""
MAX_PER_MESSAGE = 200
"""The most transforms one message may add or update; the rest of a larger message is skipped."""
STALE_AFTER_S = 10.0
"""A ``/tf`` frame not updated for this long [s] is dropped (``/tf_static`` frames are kept): a flood's names age
out and free their places."""


@dataclass(frozen=True)
class Transform:
    """A child frame's pose in its parent frame: ``translation`` (x, y, z) [m] and ``rotation`` (x, y, z, w), unit."""

    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]

    def apply(self, point: tuple[float, float, float]) -> tuple[float, float, float]:
        """``point`` in the child frame, expressed in the parent frame."""
        x, y, z = _rotate(self.rotation, point)
        tx, ty, tz = self.translation
        return x + tx, y + ty, z + tz

    def inverse(self) -> Transform:
        """The parent's pose in the child frame."""
        qx, qy, qz, qw = self.rotation
        conj = (-qx, -qy, -qz, qw)
        tx, ty, tz = _rotate(conj, self.translation)
        return Transform((-tx, -ty, -tz), conj)


def _rotate(q: tuple[float, float, float, float], v: tuple[float, float, float]) -> tuple[float, float, float]:
    qx, qy, qz, qw = q
    vx, vy, vz = v
    # v + 2 w (q x v) + 2 q x (q x v)
    cx, cy, cz = qy * vz - qz * vy, qz * vx - qx * vz, qx * vy - qy * vx
    ccx, ccy, ccz = qy * cz - qz * cy, qz * cx - qx * cz, qx * cy - qy * cx
    return vx + 2 * (qw * cx + ccx), vy + 2 * (qw * cy + ccy), vz + 2 * (qw * cz + ccz)


def frame_id(name: str) -> str:
    """A tf frame id as tf2 reads it: without a leading slash."""
    return name.removeprefix("/")


class TransformBuffer:
    """The latest transform of each edge of a tf tree (``/tf`` and ``/tf_static``), looked up along the tree."""

    def __init__(self):
        self.edges: dict[str, tuple[str, Transform]] = {}
        """Each child frame's parent and its pose in it (tf: one parent per frame)."""
        self.updated: dict[str, float | None] = {}
        """When each child frame was last updated (``None``: static, never stale)."""
        self.skipped = 0
        """Transforms skipped because the buffer was full (:data:`MAX_FRAMES`) or a message too long."""
        self._links: dict[str, list[tuple[str, bool]]] | None = None
        """The tree's adjacency, built on the first lookup after the tree's shape changed."""

    def add(self, msg, now: float | None = None, *, static: bool = False) -> int:
        """Take a ``tf2_msgs/TFMessage``'s transforms (a later one replaces an earlier one of the same child);
        returns how many were taken. A transform with a non-finite value, a zero rotation, an empty frame name or a
        frame that is its own parent is skipped, as is a new frame past :data:`MAX_FRAMES` and any transform past
        :data:`MAX_PER_MESSAGE` of one message. ``now`` [s]: the time of a ``/tf`` message, whose frames go stale
        after :data:`STALE_AFTER_S` (``static``: ``/tf_static``'s, kept).
        """
        if now is not None:
            self._drop_stale(now)
        taken = 0
        transforms = list(itertools.islice(msg.transforms, MAX_PER_MESSAGE + 1))
        if len(transforms) > MAX_PER_MESSAGE:
            self.skipped += 1
            transforms = transforms[:MAX_PER_MESSAGE]
        for t in transforms:
            parent, child = frame_id(t.header.frame_id), frame_id(t.child_frame_id)
            tr, rot = t.transform.translation, t.transform.rotation
            values = (tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w)
            if not parent or not child or parent == child or not all(math.isfinite(v) for v in values):
                continue
            norm = math.sqrt(rot.x**2 + rot.y**2 + rot.z**2 + rot.w**2)
            if norm < 1e-9:
                continue
            q = (rot.x / norm, rot.y / norm, rot.z / norm, rot.w / norm)
            known = self.edges.get(child)
            if known is None and len(self.edges) >= MAX_FRAMES:
                self.skipped += 1
                continue
            if known is None or known[0] != parent:
                self._links = None  # the tree's shape changed
            self.edges[child] = (parent, Transform((float(tr.x), float(tr.y), float(tr.z)), q))
            self.updated[child] = None if static or now is None else now
            taken += 1
        return taken

    def _drop_stale(self, now: float) -> None:
        stale = [c for c, t in self.updated.items() if t is not None and now - t > STALE_AFTER_S]
        for child in stale:
            del self.edges[child], self.updated[child]
        if stale:
            self._links = None

    def _path(self, target: str, source: str) -> list[tuple[str, str, bool]] | None:
        """The edges from ``source`` to ``target``: (from, to, up) where ``up`` walks child to parent."""
        if self._links is None:
            self._links = {}
            for child, (parent, _) in self.edges.items():
                self._links.setdefault(child, []).append((parent, True))
                self._links.setdefault(parent, []).append((child, False))
        links = self._links
        seen, todo = {source: None}, deque([source])
        while todo:
            here = todo.popleft()
            if here == target:
                break
            for there, up in links.get(here, ()):
                if there not in seen:
                    seen[there] = (here, up)
                    todo.append(there)
        if target not in seen:
            return None
        path, here = [], target
        while seen[here] is not None:
            before, up = seen[here]
            path.append((before, here, up))
            here = before
        return path[::-1]

    def can_transform(self, target: str, source: str) -> bool:
        """Whether the tree joins ``source`` to ``target``."""
        return frame_id(target) == frame_id(source) or self._path(frame_id(target), frame_id(source)) is not None

    def transform_point(self, point: tuple[float, float, float], target: str, source: str
                        ) -> tuple[float, float, float] | None:
        """``point`` given in frame ``source``, expressed in frame ``target``; ``None`` where the tree does not join
        them (yet)."""
        target, source = frame_id(target), frame_id(source)
        if target == source:
            return point
        path = self._path(target, source)
        if path is None:
            return None
        for before, after, up in path:
            if up:  # before is the child: its point in its parent
                point = self.edges[before][1].apply(point)
            else:  # after is the child of before: the parent's point in the child
                point = self.edges[after][1].inverse().apply(point)
        return point

    def transform_pose2d(self, pose: tuple[float, float, float], target: str, source: str
                         ) -> tuple[float, float, float] | None:
        """A planar pose (x [m], y [m], yaw [rad]) given in frame ``source``, expressed in frame ``target`` (the
        heading carried as the point 1 m ahead of it); ``None`` where the tree does not join them (yet)."""
        x, y, yaw = pose
        here = self.transform_point((x, y, 0.0), target, source)
        ahead = self.transform_point((x + math.cos(yaw), y + math.sin(yaw), 0.0), target, source)
        if here is None or ahead is None:
            return None
        return here[0], here[1], math.atan2(ahead[1] - here[1], ahead[0] - here[0])
