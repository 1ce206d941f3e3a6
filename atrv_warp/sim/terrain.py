"""Terrain: seeded heightfields the rovers drive on, in place of the flat ground plane.

A terrain is a set of ``tiles``, height grids over the whole arena (``HeightGrid``). Each world
drives on one tile; a task may switch a world's tile when it resets it (the navigation task draws
one per episode), so a few tiles give many different episodes at a fixed memory cost.

Heights are relative to the flat ground's top (``ArenaConfig.ground_top``) and interpolated
bilinearly. Contact samples the surface under each wheel's rim (``kernels/terrain.py``) with the
same Hunt–Crossley law and friction as the flat ground; the scanner ray-marches it. Why our own
kernel and not Newton's heightfield shape: docs/tasks.md, "Navigation".

Presets (``TERRAIN_PRESETS``): ``rolling``, ``rough``, ``hills``, ``slope``; ``None`` is the flat
arena, the default, which keeps the reference task bit-identical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TERRAIN_PRESETS", "HeightGrid", "TerrainConfig", "get_terrain"]


@dataclass(frozen=True)
class TerrainConfig:
    """A seeded procedural terrain: rolling hills, small-scale roughness, bumps and an incline.

    The undulating part (hills, roughness, bumps) is scaled down if its steepest slope on the grid
    would exceed ``max_slope``; the incline is added after that, exactly.
    """

    amplitude: float = 0.15
    """Peak height of the rolling hills [m] (a sum of ``waves`` random-direction sinusoids)."""
    wavelength: float = 6.0
    """Mean wavelength of the hills [m]; each wave's is drawn in [0.6, 1.4] x this."""
    waves: int = 6
    """Sinusoids summed for the hills."""
    roughness: float = 0.02
    """Amplitude of the small-scale roughness [m] (same construction, wavelength ``roughness_wavelength``)."""
    roughness_wavelength: float = 1.0
    """[m]"""
    bumps: int = 0
    """Gaussian bumps per tile."""
    bump_height: float = 0.1
    """[m]"""
    bump_radius: float = 0.5
    """Standard deviation of each bump [m]."""
    incline: float = 0.0
    """Constant slope, uphill toward +x [rad]."""
    max_slope: float = math.radians(12.0)
    """Steepest slope allowed for the undulating part [rad]."""
    resolution: float = 0.25
    """Grid spacing [m]; a wheel (radius 0.125 m) spans about one cell."""
    tiles: int = 16
    """Distinct terrains generated; world w starts on tile w mod ``tiles``."""
    seed: int = 0
    """Seed of the generator (same seed, same terrain)."""

    def generate(self, half_size: float) -> HeightGrid:
        """The ``tiles`` height grids over [-half_size, half_size]² [m]."""
        if self.resolution <= 0 or self.tiles < 1:
            raise ValueError(f"terrain needs resolution > 0 and tiles >= 1, got {self.resolution}, {self.tiles}")
        if not 0.0 <= self.max_slope < math.pi / 2 or abs(self.incline) >= math.pi / 2:
            raise ValueError(f"max_slope and incline must lie in [0, 90) deg, got {self.max_slope}, {self.incline}")
        n = round(2 * half_size / self.resolution) + 1
        axis = np.linspace(-half_size, half_size, n)
        x, y = np.meshgrid(axis, axis, indexing="ij")
        rng = np.random.default_rng(self.seed)
        tiles = np.empty((self.tiles, n, n), dtype=np.float64)
        for t in range(self.tiles):
            h = _waves(rng, x, y, self.amplitude, self.wavelength, self.waves)
            h += _waves(rng, x, y, self.roughness, self.roughness_wavelength, self.waves)
            for _ in range(self.bumps):
                cx, cy = rng.uniform(-half_size, half_size, 2)
                h += self.bump_height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * self.bump_radius**2))
            steepest = float(np.max(np.hypot(*np.gradient(h, self.resolution)))) if h.any() else 0.0
            limit = math.tan(self.max_slope)
            if steepest > limit:
                h *= limit / steepest
            tiles[t] = h - h.mean() + math.tan(self.incline) * x
        return HeightGrid(tiles.astype(np.float32), half_size, self.resolution)


def _waves(rng: np.random.Generator, x, y, amplitude: float, wavelength: float, count: int) -> np.ndarray:
    """Sum of ``count`` random-direction sinusoids with peak height ``amplitude``."""
    h = np.zeros_like(x)
    if amplitude <= 0 or count <= 0:
        return h
    for _ in range(count):
        angle, phase = rng.uniform(0, 2 * np.pi, 2)
        k = 2 * np.pi / (wavelength * rng.uniform(0.6, 1.4))
        h += np.sin(k * (np.cos(angle) * x + np.sin(angle) * y) + phase)
    return h * (amplitude / max(float(np.abs(h).max()), 1e-9))


@dataclass(frozen=True, eq=False)
class HeightGrid:
    """Terrain given as samples: ``heights[tile, i, j]`` [m] above the flat ground's top at
    x = -half_size + i·resolution, y = -half_size + j·resolution (x index first).

    Build one from a digital elevation model to drive on real ground; outside the grid the edge
    heights continue.
    """

    heights: np.ndarray
    """(tiles, n, n) float32 [m]."""
    half_size: float
    """The grid spans [-half_size, half_size]² [m]."""
    resolution: float
    """Grid spacing [m]."""

    def __post_init__(self):
        h = self.heights
        if h.ndim != 3 or h.shape[1] != h.shape[2] or h.shape[1] < 2:
            raise ValueError(f"heights must have shape (tiles, n, n) with n >= 2, got {h.shape}")
        if not np.isfinite(h).all():
            raise ValueError("heights contain NaN/inf")
        if not math.isclose((h.shape[1] - 1) * self.resolution, 2 * self.half_size, rel_tol=1e-6):
            raise ValueError(f"{h.shape[1]} samples at {self.resolution} m do not span 2 x {self.half_size} m")

    @property
    def tiles(self) -> int:
        return self.heights.shape[0]

    def height(self, tile, x, y) -> np.ndarray:
        """Bilinear height [m] of ``tile`` at (x, y) [m], as the kernels compute it (tile, x and y broadcast
        against each other, element by element)."""
        n = self.heights.shape[1]
        fx = np.clip((np.asarray(x, dtype=np.float64) + self.half_size) / self.resolution, 0.0, n - 1 - 1e-6)
        fy = np.clip((np.asarray(y, dtype=np.float64) + self.half_size) / self.resolution, 0.0, n - 1 - 1e-6)
        i, j = np.floor(fx).astype(int), np.floor(fy).astype(int)
        u, v = fx - i, fy - j
        t, h = np.asarray(tile), self.heights
        h00, h10 = h[t, i, j], h[t, i + 1, j]
        h01, h11 = h[t, i, j + 1], h[t, i + 1, j + 1]
        return (1 - u) * (1 - v) * h00 + u * (1 - v) * h10 + (1 - u) * v * h01 + u * v * h11


TERRAIN_PRESETS: dict[str, TerrainConfig | None] = {
    "flat": None,
    "rolling": TerrainConfig(),
    "rough": TerrainConfig(amplitude=0.08, wavelength=3.0, roughness=0.03, bumps=8, bump_height=0.08,
                           bump_radius=0.4, max_slope=math.radians(15.0)),
    "hills": TerrainConfig(amplitude=0.5, wavelength=12.0, roughness=0.02, max_slope=math.radians(15.0)),
    "slope": TerrainConfig(amplitude=0.0, roughness=0.0, incline=math.radians(10.0), tiles=1),
}
"""Named terrains. ``flat``: the reference arena. ``rolling``: gentle 15 cm hills, 6 m apart.
``rough``: short 8 cm undulations, roughness and bumps, up to 15 deg. ``hills``: 0.5 m hills, 12 m
apart. ``slope``: a plain 10 deg incline (uphill toward +x)."""


def get_terrain(name: str) -> TerrainConfig | None:
    """The preset called ``name`` (``None`` for ``flat``)."""
    try:
        return TERRAIN_PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown terrain {name!r}; known: {sorted(TERRAIN_PRESETS)}") from None
