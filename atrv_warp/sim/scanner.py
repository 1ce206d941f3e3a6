"""A 2-D laser range finder on every rover, after the ATRV-Jr's SICK LMS-class scanner.

One Warp ray cast per (world, beam) from the robot's laser frame (the ATRV-Jr's ``lrf_frame``) against the arena walls, the
ground or terrain, and the world's obstacles (``kernels/scan.py``). The ranges are a zero-copy
``(N, beams)`` torch view, refreshed by :meth:`LaserScanner.scan`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from atrv_warp.sim.kernels.scan import ScanParams, cast_scan
from atrv_warp.sim.simulator import RoverSim

__all__ = ["LaserScanner", "ScannerConfig"]


@dataclass(frozen=True)
class ScannerConfig:
    """The scanner's geometry and noise. Defaults after a SICK LMS 2xx: 180 deg, 0.1 … 20 m."""

    beams: int = 64
    """Beams across the field of view (64 for learning; 181 gives the LMS's 1 deg for ROS)."""
    fov: float = math.pi
    """Field of view [rad], centred on the frame's +x."""
    min_range: float = 0.1
    """[m]"""
    max_range: float = 20.0
    """[m]; a beam without a return (or dropped) reads this."""
    noise_std: float = 0.0
    """Gaussian range noise [m] (a SICK LMS: about 0.01)."""
    dropout: float = 0.0
    """Probability that a beam returns nothing [-]."""
    frame: str | None = None
    """URDF frame the beams start from; they lie in its x-y plane. ``None``: the robot's laser frame
    (:attr:`~atrv_warp.core.robot.Robot.laser_frame`, the ATRV-Jr's ``lrf_frame``)."""
    march_step: float = 1.0
    """Ray-marching step over terrain [m]; crossings are refined to 1/256 of it. A ray that dips into
    the ground and out again within one step is missed: keep it below the terrain's shortest
    feature (the presets' roughness wavelength is 1 m at 2-3 cm height, their hills 3-12 m)."""

    def __post_init__(self):
        if self.beams < 1 or not 0 < self.fov <= 2 * math.pi:
            raise ValueError(f"scanner needs beams >= 1 and 0 < fov <= 2 pi, got {self.beams}, {self.fov}")
        if not 0 <= self.min_range < self.max_range or self.noise_std < 0 or not 0 <= self.dropout <= 1:
            raise ValueError(f"bad scanner ranges or noise: {self}")
        if self.march_step <= 0:
            raise ValueError(f"march_step must be > 0, got {self.march_step}")

    @property
    def angles(self) -> np.ndarray:
        """(beams,) beam angles [rad], right to left (counter-clockwise), as ROS LaserScan orders them."""
        if self.beams == 1:
            return np.zeros(1)
        return np.linspace(-0.5 * self.fov, 0.5 * self.fov, self.beams)


class LaserScanner:
    """A scanner on every world's rover.

    Args:
        sim: The simulator whose rovers carry it.
        config: Geometry and noise.
        seed: Seed of the noise and dropout draws; scan k of a seed is the same in every run.

    Attributes:
        ranges: (N, beams) float32 torch view [m], written by :meth:`scan`.
        angles: (beams,) float32 beam angles [rad].
    """

    def __init__(self, sim: RoverSim, config: ScannerConfig | None = None, *, seed: int = 0):
        self.sim, self.cfg = sim, config or ScannerConfig()
        frames = {f.name: f.transform for f in sim.description.frames}
        self.frame = self.cfg.frame or sim.rover_cfg.robot_spec.laser_frame
        """The URDF frame the beams start from."""
        if self.frame not in frames:
            raise ValueError(f"scanner frame {self.frame!r} is not a frame of the rover; known: {sorted(frames)}")
        m = np.asarray(frames[self.frame], dtype=np.float64)
        rot = wp.mat33(*m[:3, :3].flatten().tolist())
        dev = sim.device
        p = ScanParams()
        p.mount = wp.transform(wp.vec3(*m[:3, 3].tolist()), wp.quat_from_matrix(rot))
        p.angles = wp.array(self.cfg.angles, dtype=float, device=dev)
        p.min_range, p.max_range = self.cfg.min_range, self.cfg.max_range
        p.noise_std, p.dropout, p.march_step = self.cfg.noise_std, self.cfg.dropout, self.cfg.march_step
        p.bodies_per_world, p.chassis_body = sim.layout.bodies_per_world, sim.layout.chassis_body
        self._params = p
        self._ranges = wp.zeros((sim.num_worlds, self.cfg.beams), dtype=float, device=dev)
        self.ranges = wp.to_torch(self._ranges)
        self.buffer = self._ranges
        """The Warp array behind :attr:`ranges`, for kernels (read-only)."""
        self.angles = wp.to_torch(p.angles)
        self._all = wp.full(sim.num_worlds, True, dtype=bool, device=dev)
        self.seed = int(seed) % 2**31
        self.count = 0
        """Scans taken since seeding (the noise stream's position)."""

    def reseed(self, seed: int) -> None:
        """Restart the noise stream."""
        self.seed, self.count = int(seed) % 2**31, 0

    def scan(self, mask: wp.array | None = None, *, layout: str | None = None) -> torch.Tensor:
        """Cast every beam of every world (or of the worlds where ``mask`` (N,) bool is set, e.g. the
        ones a reset just moved) from the current state; returns :attr:`ranges` (a view).

        ``layout``: ``"beam"`` (a thread per beam, the default on a GPU) or ``"world"`` (a thread per
        world looping over its beams, the default on the CPU, where threads run one after another: a
        full scan is faster and rescanning a few reset worlds costs almost nothing; the figures are in
        docs/tasks.md, from ``benchmarks/perf/nav_throughput.py``). Both give the same ranges bit for bit
        (tests/test_scene.py)."""
        if layout is None:
            layout = "world" if wp.get_device(self.sim.device).is_cpu else "beam"
        if layout not in ("beam", "world"):
            raise ValueError(f"layout must be 'beam' or 'world', got {layout!r}")
        per_thread = self.cfg.beams if layout == "world" else 1
        wp.launch(cast_scan, dim=(self.sim.num_worlds, -(-self.cfg.beams // per_thread)),  # ceil, as the kernel expects
                  inputs=[self._params, self.sim.contact.scene, self.sim.buffers.body_q, self.seed, self.count,
                          self._all if mask is None else mask, per_thread],
                  outputs=[self._ranges], device=self.sim.device)
        self.count += 1
        return self.ranges

    def points(self, worlds=None) -> np.ndarray:
        """World-frame hit points (len(worlds), beams, 3) [m] of the last scan (beams without a return
        end at ``max_range``), for drawing."""
        worlds = np.arange(self.sim.num_worlds) if worlds is None else np.asarray(worlds)
        frame = self.sim.frame_pose(self.frame).numpy()[worlds]
        r = self.ranges.detach().cpu().numpy()[worlds].astype(np.float64)
        a = self.cfg.angles
        local = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r), np.ones_like(r)], axis=-1)
        return np.einsum("wij,wbj->wbi", frame, local)[..., :3]
