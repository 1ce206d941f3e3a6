"""A laser scan's sectors: what a policy observes of a scan, declared by angles, read as REP 117 reads a scan.

The observation reduces a scan to a few sectors, each the nearest return within its angular edges, as
``min(range, clip) / clip`` in [0, 1]. The sectors are declared by their edges [rad] in the scanner's frame
(counter-clockwise from its +x, as ``sensor_msgs/LaserScan`` orders beams), not by beam index, so any scan
(the environment's 64 beams over 180 deg, the ROS node's 181, a 1,081-beam scanner over 270 deg) reduces
through the same edges. A beam belongs to the sector whose half-open interval [edge_k, edge_k+1) holds its
angle; beams outside the first and last edge are not observed.

A ``LaserScan``'s readings (REP 117):

- ``+inf``, or beyond ``range_max``: no return within range; the sector reads clear (1.0);
- ``-inf``, or below ``range_min``: an object too close to measure; the sector reads blocked (0.0);
- ``NaN``: an invalid beam, left out of its sector; a sector with no valid beam reads blocked (0.0).

The environment's kernel (``task/kernels/observe.py``'s ``write_scan_observation``) applies the same rule to the
simulated ranges through the beam ranges :meth:`ScanSectors.beam_bounds` gives; ``tests/test_core.py``
holds the two together.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import torch

__all__ = ["ScanSectors", "remount", "sector_readings"]


@dataclass(frozen=True)
class ScanSectors:
    """The observed sectors of a scan."""

    edges: tuple[float, ...]
    """S + 1 increasing angles [rad] in the scanner's frame: sector k spans [edges[k], edges[k + 1])."""
    clip: float
    """Ranges are observed as min(range, clip) / clip [m]."""

    def __post_init__(self):
        e = self.edges
        if len(e) < 2 or not all(math.isfinite(a) for a in e) or any(b <= a for a, b in itertools.pairwise(e)):
            raise ValueError(f"sector edges must be at least two finite, increasing angles [rad], got {e}")
        if not (math.isfinite(self.clip) and self.clip > 0):
            raise ValueError(f"scan clip must be a finite range > 0 [m], got {self.clip}")

    @classmethod
    def for_beams(cls, beams: int, fov: float, sectors: int, clip: float) -> ScanSectors:
        """``sectors`` equal sectors over a scan of ``beams`` evenly spaced beams across ``fov`` [rad] centred on
        +x, each beam owning an equal slice of angle: the sectors span ``fov`` plus one beam spacing, so that
        every beam lies inside one (and, when ``sectors`` divides ``beams``, each sector holds ``beams /
        sectors`` of them, its edges half a spacing from the nearest beams)."""
        if beams < 1 or sectors < 1 or not 0 < fov <= 2 * math.pi:
            raise ValueError(f"need beams >= 1, sectors >= 1 and 0 < fov <= 2 pi, got {beams}, {sectors}, {fov}")
        spacing = fov / (beams - 1) if beams > 1 else fov
        half = 0.5 * min(fov + spacing, 2 * math.pi)
        step = 2 * half / sectors
        return cls(tuple(-half + k * step for k in range(sectors)) + (half,), clip)

    @property
    def count(self) -> int:
        """Number of sectors S."""
        return len(self.edges) - 1

    def beam_sector(self, angles: torch.Tensor) -> torch.Tensor:
        """(B,) int64: the sector of each beam at ``angles`` [rad]; -1 outside the edges."""
        angles = torch.as_tensor(angles, dtype=torch.float64)
        edges = torch.tensor(self.edges, dtype=torch.float64)
        k = torch.searchsorted(edges, angles, right=True) - 1
        return torch.where((k >= 0) & (k < self.count), k, torch.full_like(k, -1))

    def beam_bounds(self, angles: torch.Tensor) -> torch.Tensor:
        """(S, 2) int64 [first, end) beam index of each sector, for beams at increasing ``angles`` [rad] (what the
        environment's kernel loops over); an empty sector has first == end."""
        k = self.beam_sector(angles)
        s = torch.arange(self.count).unsqueeze(-1)
        first = torch.searchsorted(k.where(k >= 0, torch.full_like(k, self.count)), torch.arange(self.count))
        end = first + (k == s).sum(-1)
        return torch.stack([first, end], -1)

    def covered_by(self, angle_min: float, angle_max: float) -> bool:
        """Whether a scan from ``angle_min`` to ``angle_max`` [rad] reaches into every sector (its first beam before
        the first sector's end and its last beam past the last sector's start)."""
        return angle_min < self.edges[1] and angle_max >= self.edges[-2]

    def describe(self) -> dict:
        """The sectors as plain values, for an exported policy's contract."""
        return {"edges_rad": list(self.edges), "clip_m": self.clip, "count": self.count,
                "reads": "min(range, clip) / clip of the nearest valid return in [edge_k, edge_k+1), scanner frame, "
                         "counter-clockwise from +x",
                "no_return": "+inf or beyond range_max reads 1.0 (clear)",
                "too_close": "-inf or below range_min reads 0.0 (blocked)",
                "invalid": "NaN beams are left out; a sector with no valid beam reads 0.0 (blocked)"}


def sector_readings(ranges: torch.Tensor, angles: torch.Tensor, sectors: ScanSectors, *, range_min: float,
                    range_max: float) -> torch.Tensor:
    """A scan's sectors as a policy observes them, by REP 117.

    Args:
        ranges: (..., B) ranges [m] as a ``LaserScan`` carries them (``+inf``, ``-inf`` and ``NaN`` allowed).
        angles: (B,) each beam's angle [rad] in the scanner's frame (``angle_min + i * angle_increment``), or
            (..., B), one per range (a remounted scan's bearings, :func:`remount`).
        sectors: The observed sectors.
        range_min: The scanner's ``range_min`` [m].
        range_max: The scanner's ``range_max`` [m].

    Returns:
        (..., S) readings in [0, 1] (1 clear, 0 blocked), float32.
    """
    r = torch.as_tensor(ranges, dtype=torch.float32)
    clip = sectors.clip
    # one reading per beam: clear beyond range (+inf included), blocked below it (-inf included), NaN invalid
    reading = torch.where(r > range_max, torch.ones_like(r), (r.clamp(max=clip) / clip))
    reading = torch.where(r < range_min, torch.zeros_like(r), reading)
    valid = ~torch.isnan(r)
    reading = torch.where(valid, reading, torch.full_like(r, math.inf))
    sector = sectors.beam_sector(angles).to(r.device)
    far = torch.full_like(reading, math.inf)
    readings = torch.stack([torch.where(sector == k, reading, far).amin(-1) for k in range(sectors.count)], -1)
    return torch.where(torch.isinf(readings), torch.zeros_like(readings), readings)  # no valid beam: blocked


def remount(ranges: torch.Tensor, angles: torch.Tensor, mount: tuple[float, float, float], *, range_min: float,
            range_max: float) -> tuple[torch.Tensor, torch.Tensor]:
    """A scan taken by a scanner mounted elsewhere, as the scanner the policy was trained with would read it.

    Each return becomes the point it hit, seen from the trained scanner: its range and bearing from there. A beam
    beyond ``range_max`` (no return) or below ``range_min`` (too close) keeps that meaning (``+inf``, ``-inf``) along
    its direction turned by the mount's yaw; an invalid beam (``NaN``) stays invalid. Where the two scanners see
    different things (behind an edge one of them cannot see round) the nearer one's view is not recovered.

    Args:
        ranges: (..., B) ranges [m] of the mounted scanner (REP 117).
        angles: (B,) its beams' angles [rad] in its own frame.
        mount: (x [m], y [m], yaw [rad]) of the mounted scanner in the trained scanner's frame.
        range_min: The mounted scanner's ``range_min`` [m].
        range_max: The mounted scanner's ``range_max`` [m].

    Returns:
        ((..., B) ranges [m], (..., B) bearings [rad] in the trained scanner's frame, in (-pi, pi]).
    """
    r = torch.as_tensor(ranges, dtype=torch.float64)
    a = torch.as_tensor(angles, dtype=torch.float64).to(r.device) + mount[2]
    r = torch.where(r > range_max, torch.full_like(r, math.inf), r)
    r = torch.where(r < range_min, torch.full_like(r, -math.inf), r)
    finite = torch.isfinite(r)
    hit = torch.where(finite, r, torch.zeros_like(r))
    x, y = mount[0] + hit * torch.cos(a), mount[1] + hit * torch.sin(a)
    seen = torch.where(finite, torch.hypot(x, y), r)
    bearing = torch.where(finite, torch.atan2(y, x), torch.atan2(torch.sin(a), torch.cos(a)).expand_as(r))
    return seen, bearing
