"""Terrain, obstacles and the laser scanner (issue 13): analytic answers, invariants, determinism."""

import math

import numpy as np
import pytest
import torch
import warp as wp

from atrv_warp.sim import ContactConfig, ObstacleConfig, RoverSim, checks
from atrv_warp.sim.scanner import LaserScanner, ScannerConfig
from atrv_warp.sim.terrain import HeightGrid, TerrainConfig
from atrv_warp.task.env import ATRVjrEnv
from atrv_warp.task.spec import EndReason

HALF = 15.0  # the reference arena's half size [m]


def _lrf(sim: RoverSim, world: int) -> np.ndarray:
    return sim.frame_pose("lrf_frame")[world, :3, 3].numpy()


def test_scan_ranges_match_analytic_distances():
    """A wall, a box and a cylinder at known poses, rover turned 30 deg: within 1 cm, no noise."""
    sim = RoverSim(3, obstacles=ObstacleConfig(slots=2))
    sim.obstacles.set(1, [("box", 4.0, 2.0, math.radians(30.0), 0.5, 1.0)])
    sim.obstacles.set(2, [("cylinder", 3.0, 3.0, 0.6)])
    yaw = math.radians(30.0)
    sim.reset(poses=[[0.0, 0.0, yaw]] * 3)
    scanner = LaserScanner(sim, ScannerConfig(beams=181))
    ranges = scanner.scan().numpy()
    forward = int(np.argmin(np.abs(scanner.cfg.angles)))
    direction = np.array([math.cos(yaw), math.sin(yaw)])
    # world 0: the +x wall along the beam at 30 deg
    o = _lrf(sim, 0)
    assert ranges[0, forward] == pytest.approx((HALF - o[0]) / direction[0], abs=0.01)
    # world 1: the box's near face, perpendicular to the beam (box yaw = rover yaw)
    o = _lrf(sim, 1)
    along = (np.array([4.0, 2.0]) - o[:2]) @ direction
    across = (np.array([4.0, 2.0]) - o[:2]) @ np.array([-direction[1], direction[0]])
    assert abs(across) < 1.0  # the beam meets the face, not the corner
    assert ranges[1, forward] == pytest.approx(along - 0.5, abs=0.01)
    # world 2: the cylinder, beam from the scanner toward its centre
    o = _lrf(sim, 2)
    to_c = np.array([3.0, 3.0]) - o[:2]
    beam_yaw = math.atan2(to_c[1], to_c[0]) - yaw
    b = int(np.argmin(np.abs(scanner.cfg.angles - beam_yaw)))
    d = np.array([math.cos(yaw + scanner.cfg.angles[b]), math.sin(yaw + scanner.cfg.angles[b])])
    proj = to_c @ d
    expected = proj - math.sqrt(0.6**2 - (to_c @ to_c - proj**2))
    assert ranges[2, b] == pytest.approx(expected, abs=0.01)
    assert (ranges >= scanner.cfg.min_range).all() and (ranges <= scanner.cfg.max_range).all()


def test_scan_sees_a_terrain_step_where_the_grid_rises_through_its_height():
    """Heights jump from 0 to 1 m over the cell [5.75, 6.0] m: the level forward beam at the scanner's
    height h above the ground crosses it at x = 5.75 + 0.25 h (bilinear)."""
    res = 0.25
    n = int(2 * HALF / res) + 1
    x = np.linspace(-HALF, HALF, n)
    heights = np.where(x[:, None] >= 6.0, 1.0, 0.0) * np.ones((1, n))
    sim = RoverSim(1, terrain=HeightGrid(heights[None].astype(np.float32), HALF, res))
    sim.reset()
    scanner = LaserScanner(sim, ScannerConfig(beams=181, march_step=0.5))
    r = scanner.scan().numpy()[0]
    o = _lrf(sim, 0)
    forward = int(np.argmin(np.abs(scanner.cfg.angles)))
    h = o[2] - sim.arena_cfg.ground_top
    assert r[forward] == pytest.approx(5.75 + res * h - o[0], abs=0.01)


def test_scan_noise_and_dropout_are_seeded():
    sim = RoverSim(4)
    sim.reset()
    cfg = ScannerConfig(beams=32, noise_std=0.05, dropout=0.1)
    a, b = LaserScanner(sim, cfg, seed=3), LaserScanner(sim, cfg, seed=3)
    first = [a.scan().clone() for _ in range(3)]
    assert all(torch.equal(f, b.scan()) for f in first)
    assert not torch.equal(first[0], first[1])  # a new draw every scan
    dropped = torch.stack(first) == cfg.max_range
    assert 0.02 < dropped.float().mean() < 0.25
    clean = LaserScanner(sim, ScannerConfig(beams=32), seed=3).scan()
    noise = (torch.stack(first) - clean)[~dropped]
    assert 0.03 < float(noise.std()) < 0.07


def test_scan_layouts_give_the_same_ranges_bit_for_bit():
    """A thread per beam (the GPU's layout) and a thread per world (the CPU's) on the nav scene, with
    noise and dropout, for all worlds and for a reset's mask; the wrong layout name is refused."""
    env = ATRVjrEnv(16, task="nav", seed=5)
    env.rollout(3, break_when_any_done=False)
    cfg = ScannerConfig(noise_std=0.05, dropout=0.1)
    by_beam, by_world = LaserScanner(env.sim, cfg, seed=7), LaserScanner(env.sim, cfg, seed=7)
    a, b = by_beam.scan(layout="beam").clone(), by_world.scan(layout="world").clone()
    assert torch.equal(a, b)
    assert (a < cfg.max_range).any() and (a == cfg.max_range).any()  # hits, and dropped beams
    mask = wp.array(np.arange(16) % 3 == 0, dtype=bool, device=env.sim.device)
    env.sim.step()
    assert torch.equal(by_beam.scan(mask, layout="beam"), by_world.scan(mask, layout="world"))
    assert torch.equal(by_world.ranges[1], b[1])  # unmasked worlds keep their ranges
    with pytest.raises(ValueError, match="layout"):
        by_world.scan(layout="rows")


@pytest.mark.parametrize("mu", [0.3, 0.5])
def test_parked_rover_holds_below_atan_mu_and_slides_above(mu):
    """Parked across a slope (axles downhill, motors braking): holds at 0.8 atan(mu), slides at 1.2 atan(mu)."""
    limit = math.degrees(math.atan(mu))
    held, slid = checks.parked_on_slope((0.8 * limit, 1.2 * limit), contact=ContactConfig(friction=mu))
    assert held < 0.01, held  # [m] in 5 s
    assert slid > 1.0, slid


def test_viscous_friction_creeps_on_a_slope():
    """Why the Coulomb law exists: under the 0.1.x viscous law a parked rover creeps down a slope well
    below atan(mu), at the rate its regularisation allows."""
    held = checks.parked_on_slope((0.8 * math.degrees(math.atan(0.3)),), contact=ContactConfig(friction_law="viscous"))
    assert held[0] > 0.05, held


def test_driving_over_a_bump_stays_finite_and_wheels_keep_contact():
    """A 12 cm Gaussian bump (sigma 0.5 m) across the path at x = 3 m, driven over at about 1.5 m/s."""
    res = 0.25
    n = int(2 * HALF / res) + 1
    x = np.linspace(-HALF, HALF, n)
    bump = 0.12 * np.exp(-((x - 3.0) ** 2) / (2 * 0.5**2))
    heights = (bump[:, None] * np.ones((1, n)))[None].astype(np.float32)
    sim = RoverSim(1, terrain=HeightGrid(heights, HALF, res))
    sim.reset()
    sim.set_commands([6.0, 6.0])
    wheels = list(sim.built.wheel_bodies)
    r = sim.rover_cfg.wheel_radius
    clearances, passed = [], False
    for _ in range(120):
        sim.step()
        q = sim.buffers.body_q.numpy().reshape(-1, 7)[wheels]
        ground = sim.terrain.height(q[:, 0], q[:, 1], worlds=[0] * len(wheels)).reshape(-1)
        clearances.append(q[:, 2] - ground - r)
        passed = passed or float(sim.root_pose[0, 0]) > 4.5
        assert torch.isfinite(sim.root_pose).all() and not bool(sim.nonfinite.any())
    clearances = np.array(clearances)
    assert passed, "the rover did not get over the bump"
    assert not bool(sim.body_ground_contact.any())
    assert (clearances < 0.01).mean() > 0.95  # every wheel on the ground (within 1 cm) 95 % of the time
    assert clearances.max() < 0.05  # no wheel ever far off it


def test_obstacle_contact_sets_only_that_worlds_flag():
    sim = RoverSim(3, obstacles=ObstacleConfig(slots=1))
    sim.obstacles.set(1, [("cylinder", 2.0, 0.0, 0.4)])
    sim.reset()
    sim.set_commands([8.0, 8.0])
    hit = torch.zeros(3, dtype=torch.bool)
    for _ in range(40):
        sim.step()
        hit |= sim.obstacle_contact
        assert not bool(sim.wall_contact.any())
    assert hit.tolist() == [False, True, False]


def test_nav_episode_ends_on_obstacle_with_its_own_reason():
    env = ATRVjrEnv(2, task="nav", seed=0, obstacles=1, obstacles_on_path=1, target_distance=(6.0, 6.0))
    td = env.reset()
    # drive straight at the target: the on-path obstacle is in the way
    from atrv_warp.task.baseline import scripted_policy

    policy = scripted_policy()
    reasons, rewards = torch.zeros(2, dtype=torch.long), torch.zeros(2)
    for _ in range(200):
        td = env.step(policy(td))
        ended = (reasons == 0) & td["next", "done"].reshape(-1)
        reasons = torch.where(ended, td["next", "end_reason"].reshape(-1), reasons)
        rewards = torch.where(ended, td["next", "reward"].reshape(-1), rewards)
        if bool((reasons != 0).all()):
            break
        td = env.step_mdp(td)
    assert (reasons == EndReason.OBSTACLE).any()
    assert (rewards[reasons == EndReason.OBSTACLE] == env.task_cfg.failure_reward).all()


def test_clearance_term_costs_how_far_the_nearest_obstacle_reaches_inside_the_radius():
    """The nav reward's clearance term against a torch computation from the obstacles' poses and sizes: the
    scripted driver heads into the on-path obstacle, so the term grows as it closes in; the reach task, with no
    obstacles, never has one."""
    from atrv_warp.task.baseline import scripted_policy

    env = ATRVjrEnv(64, task="nav", seed=3)
    c, obstacles, policy = env.task_cfg, env.sim.obstacles, scripted_policy()
    assert c.clearance_weight > 0
    td, seen = env.reset(), 0.0
    for _ in range(60):
        td, root = env.step_and_maybe_reset(policy(td))  # resets only the finished worlds
        nxt = td["next"]
        p = env.sim.root_pose[:, None, :2]
        kind, size = obstacles.kind, obstacles.size
        radius = torch.where(kind == 2, size[..., 0], size.norm(dim=-1))  # cylinder: r; box: half diagonal
        gap = torch.where(kind > 0, (obstacles.pose[..., :2] - p).norm(dim=-1) - radius, torch.inf)
        expected = -c.clearance_weight * (c.clearance_radius - gap.min(-1).values).clamp(min=0)
        running = nxt["end_reason"].reshape(-1) == EndReason.RUNNING
        got = nxt["reward_terms", "clearance"].reshape(-1)
        assert torch.allclose(got[running], expected[running], atol=1e-5)
        assert (got[~running] == 0).all()  # terminal steps have only their terminal term
        seen = min(seen, float(got.min()))
        td = root
    assert seen < -0.2  # the driver came well inside the radius of some obstacle
    reach = ATRVjrEnv(4).rollout(10)
    assert (reach["next", "reward_terms", "clearance"] == 0).all()


def test_same_seed_same_terrain_and_layout():
    assert np.array_equal(TerrainConfig(seed=4).generate(HALF).heights, TerrainConfig(seed=4).generate(HALF).heights)
    assert not np.array_equal(TerrainConfig(seed=4).generate(HALF).heights,
                              TerrainConfig(seed=5).generate(HALF).heights)
    a, b, c = (ATRVjrEnv(8, task="nav", seed=s) for s in (7, 7, 8))
    tds = [e.reset() for e in (a, b, c)]
    for key in ("kind", "pose", "size"):
        assert torch.equal(getattr(a.sim.obstacles, key), getattr(b.sim.obstacles, key))
    assert torch.equal(a.sim.terrain.tile, b.sim.terrain.tile)
    assert torch.equal(tds[0]["observation"], tds[1]["observation"])
    assert torch.equal(tds[0]["scan"], tds[1]["scan"])
    assert not torch.equal(a.sim.obstacles.pose, c.sim.obstacles.pose)


def test_starts_and_targets_keep_clear_of_obstacles():
    env = ATRVjrEnv(256, task="nav", seed=1)
    clearance = env.task_cfg.clearance
    for _ in range(3):
        env.reset()
        obs = env.sim.obstacles
        kind, pose, size = obs.kind, obs.pose, obs.size
        radius = torch.where(kind == 2, size[..., 0], size.norm(dim=-1))
        for point in (env.sim.root_pose[:, None, :2], env.target[:, None, :]):
            gap = (pose[..., :2] - point).norm(dim=-1) - radius
            assert (gap[kind != 0] > clearance - 1e-4).all()
        assert (kind != 0).sum(1).float().mean() > 5.0  # the layouts are not emptied by the rule
        on_path = kind[:, 0] != 0  # slot 0 stands across the start-target line
        assert on_path.float().mean() > 0.9


def test_nav_rollout_specs_and_finite():
    from torchrl.envs.utils import check_env_specs

    env = ATRVjrEnv(16, task="nav", seed=2)
    check_env_specs(env)
    td = env.rollout(60, break_when_any_done=False)
    space = env.observation_spec["observation"].space
    low, high = space.low[:, None], space.high[:, None]
    assert torch.isfinite(td["next", "observation"]).all()
    assert (td["next", "observation"] >= low - 1e-6).all() and (td["next", "observation"] <= high + 1e-6).all()
    assert td["next", "scan"].shape == (16, 60, 64)
    assert env.sim.nonfinite.sum() == 0


def test_gymnasium_nav_id_carries_the_scan():
    import gymnasium
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("atrv_warp.integrations.gymnasium:ATRVjrNav-v0")
    check_env(env.unwrapped)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (32,)  # the 10 fields, 16 scan sectors, the last 3 actions
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["scan"].shape == (64,)
    venv = gymnasium.make_vec("ATRVjrNav-v0", num_envs=2)
    venv.reset(seed=1)
    *_, info = venv.step(venv.action_space.sample())
    assert info["scan"].shape == (2, 64)
