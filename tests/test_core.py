"""The light core (:mod:`atrv_warp.core`): each Warp ``@wp.func`` and kernel held to its torch twin, the skid-steer
kinematics, and a ``LaserScan`` read as REP 117 defines it, through sectors declared by angle."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import warp as wp

from atrv_warp import ATRVjrEnv
from atrv_warp.core import (
    ScanSectors,
    SkidSteer,
    matrix_to_quat,
    quat_to_matrix,
    quat_to_rpy,
    quat_to_yaw,
    rpy_to_quat,
    sector_readings,
    track_width,
    wrap_angle,
    yaw_to_quat,
)
from atrv_warp.core.robot import load_robot
from atrv_warp.sim.config import SENSOR_NOISE, get_variant
from atrv_warp.sim.kernels.rover import quat_to_rpy as wp_quat_to_rpy
from atrv_warp.sim.scanner import LaserScanner, ScannerConfig
from atrv_warp.sim.urdf import load_rover
from atrv_warp.task.kernels import ScanReading, write_scan_observation
from atrv_warp.task.kernels import wrap_angle as wp_wrap_angle
from atrv_warp.task.spec import OBS_DIM


def random_quats(n: int, seed: int = 0) -> torch.Tensor:
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q / q.norm(dim=-1, keepdim=True)


@wp.kernel
def _eval_quat_funcs(q: wp.array(dtype=wp.quat), rpy: wp.array(dtype=wp.vec3), rot: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    rpy[i] = wp_quat_to_rpy(q[i])
    rot[i] = wp.quat_to_matrix(q[i])  # what the friction solver turns a chassis pose into


@wp.kernel
def _eval_wrap(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp_wrap_angle(a[i])


def test_warp_funcs_agree_with_their_torch_twins():
    q = random_quats(1000)
    q[:3] = torch.tensor([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.7071068, 0.0, 0.7071068]])
    rpy, rot = wp.zeros(1000, dtype=wp.vec3), wp.zeros(1000, dtype=wp.mat33)
    wp.launch(_eval_quat_funcs, dim=1000, inputs=[wp.array(q.float().numpy(), dtype=wp.quat)], outputs=[rpy, rot])
    assert np.allclose(rpy.numpy(), quat_to_rpy(q).numpy(), atol=2e-3)  # float32 asin near +-90 deg pitch
    assert np.allclose(rpy.numpy()[:, 2], quat_to_yaw(q).numpy(), atol=2e-5)
    assert np.allclose(rot.numpy(), quat_to_matrix(q).numpy(), atol=1e-6)
    a = torch.linspace(-20.0, 20.0, 1001, dtype=torch.float64)
    out = wp.zeros(1001, dtype=float)
    wp.launch(_eval_wrap, dim=1001, inputs=[wp.array(a.float().numpy(), dtype=float)], outputs=[out])
    assert np.allclose(out.numpy(), wrap_angle(a).numpy(), atol=1e-5)


def test_quaternion_maths_round_trips():
    q = random_quats(500, seed=1)
    m = quat_to_matrix(q)
    assert torch.allclose(m @ m.transpose(-1, -2), torch.eye(3, dtype=torch.float64).expand(500, 3, 3), atol=1e-12)
    back = matrix_to_quat(m)
    assert torch.allclose(back, q * torch.sign(q[:, 3:]), atol=1e-9)  # the same rotation, w >= 0
    yaw = torch.linspace(-3.0, 3.0, 13, dtype=torch.float64)
    assert torch.allclose(quat_to_yaw(yaw_to_quat(yaw)), yaw, atol=1e-12)
    assert torch.allclose(quat_to_rpy(yaw_to_quat(yaw))[:, :2], torch.zeros(13, 2, dtype=torch.float64))
    assert wrap_angle(torch.tensor([2.5 * math.pi, -1.5 * math.pi])).tolist() == pytest.approx([0.5 * math.pi] * 2)
    rpy = quat_to_rpy(q)  # roll, pitch, yaw back to the same rotation
    assert torch.allclose(rpy_to_quat(rpy) * torch.sign(rpy_to_quat(rpy)[:, 3:]), q * torch.sign(q[:, 3:]), atol=1e-9)


def test_skid_steer_kinematics():
    desc, rover = load_rover(), get_variant("realistic")
    track = track_width(desc, rover)
    assert 0.4 < track < 0.8
    base = SkidSteer(wheel_radius=rover.wheel_radius, track_width=track)
    speeds = base.wheel_speeds(0.5, 0.8)
    assert speeds[1] > speeds[0] > 0  # a left turn: the right side runs faster
    linear, angular = base.twist(speeds)
    assert float(linear) == pytest.approx(0.5) and float(angular) == pytest.approx(0.8)
    # the effective track: a skid-steer turns slower than a differential drive on the same wheel speeds
    factor = load_robot("atrvjr").effective_track_factor  # the robot file's measured factor, the kinematics' default
    assert factor > 1.0
    assert float(SkidSteer(rover.wheel_radius, track, 1.0).twist(speeds)[1]) == pytest.approx(0.8 * factor)
    for bad in ({"wheel_radius": 0.0}, {"track_width": -1.0}, {"effective_track_factor": math.nan}):
        name = next(iter(bad))
        with pytest.raises(ValueError, match=f"{name} must be a finite number > 0"):
            SkidSteer(**{"wheel_radius": 0.125, "track_width": 0.6, **bad})


def test_sectors_are_declared_by_angle():
    s = ScanSectors.for_beams(64, math.pi, 16, 5.0)
    angles = torch.linspace(-math.pi / 2, math.pi / 2, 64, dtype=torch.float64)
    assert s.beam_sector(angles).tolist() == [k // 4 for k in range(64)]  # four of the env's beams each
    assert s.beam_bounds(angles).tolist() == [[4 * k, 4 * k + 4] for k in range(16)]
    wide = torch.linspace(-0.75 * math.pi, 0.75 * math.pi, 1081, dtype=torch.float64)
    k = s.beam_sector(wide)
    assert (k == -1).sum() > 0 and set(k[k >= 0].tolist()) == set(range(16))  # beams outside are left out
    assert s.covered_by(-0.75 * math.pi, 0.75 * math.pi) and not s.covered_by(-0.5, 0.5)
    with pytest.raises(ValueError, match="increasing"):
        ScanSectors((0.0, 0.0, 1.0), 5.0)
    with pytest.raises(ValueError, match="clip"):
        ScanSectors((0.0, 1.0), 0.0)


def test_laser_scan_readings_follow_rep_117():
    s = ScanSectors((-1.0, 0.0, 1.0, 2.0, 3.0), clip=5.0)
    angles = torch.tensor([-0.5, -0.4, 0.5, 0.6, 1.5, 1.6, 2.5, 2.6])
    inf, nan = math.inf, math.nan
    ranges = torch.tensor([[inf, 30.0,  # no return, beyond range_max: clear
                            -inf, 3.0,  # too close: blocked, whatever else the sector sees
                            nan, 2.5,  # an invalid beam is left out
                            nan, nan],  # no valid beam: blocked
                           [0.05, 8.0, 4.0, 1.0, 6.0, 7.0, 0.1, 20.0]])
    got = sector_readings(ranges, angles, s, range_min=0.1, range_max=20.0)
    assert torch.allclose(got, torch.tensor([[1.0, 0.0, 0.5, 0.0], [0.0, 0.2, 1.0, 0.02]]))


def test_the_env_kernel_reads_a_scan_as_the_torch_core_does():
    """``write_scan_observation`` on ranges with every REP 117 case, against ``sector_readings``."""
    g = torch.Generator().manual_seed(2)
    sectors = ScanSectors.for_beams(64, math.pi, 16, 5.0)
    angles = torch.linspace(-math.pi / 2, math.pi / 2, 64, dtype=torch.float64)
    ranges = torch.rand(32, 64, generator=g) * 25.0
    special = torch.tensor([math.inf, -math.inf, math.nan, 0.05, 21.0])
    pick = torch.randint(0, 5, (32, 64), generator=g)
    ranges = torch.where(torch.rand(32, 64, generator=g) < 0.3, special[pick], ranges)
    ranges[3, 8:12] = math.nan  # a sector without a valid beam
    bounds = sectors.beam_bounds(angles).to(torch.int32)
    reading = ScanReading()
    reading.first, reading.end = wp.array(bounds[:, 0].numpy()), wp.array(bounds[:, 1].numpy())
    reading.clip, reading.range_min, reading.range_max = 5.0, 0.1, 20.0
    obs = wp.zeros((32, 16), dtype=float)
    wp.launch(write_scan_observation, dim=(32, 16),
              inputs=[wp.array(ranges.numpy()), wp.zeros(32, dtype=wp.int32), 0, reading], outputs=[obs])
    want = sector_readings(ranges, angles, sectors, range_min=0.1, range_max=20.0)
    assert torch.equal(torch.from_numpy(obs.numpy()), want)
    assert want[3, 2] == 0.0


def test_a_dense_scan_of_the_same_world_gives_the_same_sectors():
    """A 1,081-beam scanner over 270 deg (a Hokuyo UTM-30LX's geometry) on the env's rovers, its ranges as a
    ``LaserScan`` carries them (no return: +inf), reduced by :func:`sector_readings`, against the env's own
    64-beam observation. A denser scan can only find nearer returns within a sector; where the env's four beams
    per sector straddle an obstacle's edge it finds one between them (a few percent of sectors). Flat ground and
    obstacles, noise off."""
    env = ATRVjrEnv(64, seed=5, task="nav", terrain="flat")
    td = env.reset()
    dense = LaserScanner(env.sim, ScannerConfig(beams=1081, fov=1.5 * math.pi))
    dense.scan()
    ranges = dense.ranges.clone()
    ranges[ranges >= dense.cfg.max_range] = math.inf
    own = env.scan_sectors.beam_bounds(torch.as_tensor(env.scanner.cfg.angles))
    assert own.tolist() == [[4 * k, 4 * k + 4] for k in range(16)]  # four of the env's own 64 beams each
    got = sector_readings(ranges, torch.as_tensor(dense.cfg.angles), env.scan_sectors,
                          range_min=dense.cfg.min_range, range_max=dense.cfg.max_range)
    env_sectors = td["observation"][:, OBS_DIM:OBS_DIM + env.scan_sectors.count]
    diff = (got - env_sectors) * env.scan_sectors.clip  # [m]
    assert (got < 1.0).float().mean() > 0.15  # the worlds' obstacles (within the 5 m clip) are seen
    assert diff.max() < 1e-4  # never farther
    noise = SENSOR_NOISE.scan_range
    assert diff.abs().median() <= noise and diff.abs().quantile(0.9) <= 2 * noise, diff.abs().quantile(0.9)
