"""A transform buffer for goals in any frame: the latest transform of each edge of the tf tree, and lookups along it.

What ``tf2_ros.Buffer`` does for a goal, without tf2_ros (which no package index provides): :meth:`TransformBuffer.add`
takes a ``tf2_msgs/TFMessage`` from ``/tf`` or ``/tf_static`` (read by its fields alone, so the tests pass plain
namespaces), keeps the latest transform of each parent-child edge, and :meth:`TransformBuffer.transform_point` carries
a point from one frame into another along the tree, through as many edges as join them (``map -> odom`` from a
localisation, or ``base_link -> laser`` from a robot's description). Lookups use the latest transforms: a goal held in
``map`` follows the localisation's correction as it moves. Plain Python, no torch, so the robot's node can use it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

__all__ = ["Transform", "TransformBuffer", "frame_id"]


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

    def add(self, msg) -> int:
        """Take a ``tf2_msgs/TFMessage``'s transforms (a later one replaces an earlier one of the same child);
        returns how many were taken. A transform with a non-finite value, a zero rotation, an empty frame name or a
        frame that is its own parent is skipped.
        """
        taken = 0
        for t in msg.transforms:
            parent, child = frame_id(t.header.frame_id), frame_id(t.child_frame_id)
            tr, rot = t.transform.translation, t.transform.rotation
            values = (tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w)
            if not parent or not child or parent == child or not all(math.isfinite(v) for v in values):
                continue
            norm = math.sqrt(rot.x**2 + rot.y**2 + rot.z**2 + rot.w**2)
            if norm < 1e-9:
                continue
            q = (rot.x / norm, rot.y / norm, rot.z / norm, rot.w / norm)
            self.edges[child] = (parent, Transform((float(tr.x), float(tr.y), float(tr.z)), q))
            taken += 1
        return taken

    def _path(self, target: str, source: str) -> list[tuple[str, str, bool]] | None:
        """The edges from ``source`` to ``target``: (from, to, up) where ``up`` walks child to parent."""
        links: dict[str, list[tuple[str, bool]]] = {}
        for child, (parent, _) in self.edges.items():
            links.setdefault(child, []).append((parent, True))
            links.setdefault(parent, []).append((child, False))
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
