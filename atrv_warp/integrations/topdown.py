"""Top-down geometry and colours shared by the drawings of a world: the evaluation videos
(:mod:`.video`), the Rerun recorder's terrain (:mod:`.recorder`) and ``docs/make_pictures.py``.

Everything here is plain numpy on snapshots; nothing reads the simulator.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

__all__ = ["OBSTACLE_BOX", "OBSTACLE_CYLINDER", "box_corners", "map_rectangles", "obstacle_shapes", "terrain_colors"]

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


def map_rectangles(mask: np.ndarray, resolution: float, origin: tuple[float, float]) -> np.ndarray:
    """The cells of a map's ``mask`` (rows, cols) as few axis-aligned rectangles (R, 4): x0, y0, x1, y1 [m]. Each
    row's runs of cells, a run merged with the same run of the rows after it (a thick wall or an unknown expanse is
    one rectangle, not a box a cell)."""
    mask = np.asarray(mask, dtype=bool)
    out, open_runs = [], {}  # (c0, c1) -> the row its rectangle started at
    for r in range(mask.shape[0] + 1):
        row = mask[r] if r < mask.shape[0] else np.zeros(mask.shape[1], dtype=bool)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], row.astype(np.int8), [0]])))
        runs = set(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
        for run in [k for k in open_runs if k not in runs]:
            out.append((open_runs.pop(run), r, *run))
        for run in runs:
            open_runs.setdefault(run, r)
    if not out:
        return np.zeros((0, 4))
    r0, r1, c0, c1 = np.array(out, dtype=float).T
    x, y = origin
    return np.stack([x + c0 * resolution, y + r0 * resolution, x + c1 * resolution, y + r1 * resolution], axis=-1)
