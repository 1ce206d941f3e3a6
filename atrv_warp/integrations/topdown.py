"""Top-down geometry and colours shared by the drawings of a world: the evaluation videos
(:mod:`.video`), the Rerun recorder's terrain (:mod:`.recorder`) and ``docs/make_pictures.py``.

Everything here is plain numpy on snapshots; nothing reads the simulator.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

__all__ = ["OBSTACLE_BOX", "OBSTACLE_CYLINDER", "box_corners", "obstacle_shapes", "terrain_colors"]

OBSTACLE_BOX, OBSTACLE_CYLINDER = 1, 2
"""Obstacle kinds as ``Obstacles.kind`` holds them (0 is an empty slot)."""


def terrain_colors(heights: np.ndarray) -> np.ndarray:
    """Colours (..., 3) uint8 of a height grid, green-brown from its lowest to its highest point."""
    t = (heights - heights.min()) / max(float(np.ptp(heights)), 1e-6)
    return np.stack([110 + 70 * t, 140 + 50 * t, 90 + 40 * t], axis=-1).astype(np.uint8)


def box_corners(x: float, y: float, yaw: float, half_x: float, half_y: float) -> np.ndarray:
    """The four corners (4, 2) [m] of a rectangle centred at (x, y), turned by ``yaw`` [rad]."""
    local = np.array([[half_x, half_y], [half_x, -half_y], [-half_x, -half_y], [-half_x, half_y]])
    c, s = np.cos(yaw), np.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + (x, y)


def obstacle_shapes(kind: np.ndarray, pose: np.ndarray, size: np.ndarray) -> Iterator[tuple[str, np.ndarray]]:
    """One world's obstacles as ``("box", corners (4, 2))`` or ``("cylinder", [x, y, radius])`` [m], from
    its rows of ``Obstacles.kind`` (slots,), ``.pose`` (slots, 3) and ``.size`` (slots, 2)."""
    for k, (x, y, yaw), (a, b) in zip(kind, pose, size):
        if k == OBSTACLE_BOX:
            yield "box", box_corners(x, y, yaw, a, b)
        elif k == OBSTACLE_CYLINDER:
            yield "cylinder", np.array([x, y, a])
