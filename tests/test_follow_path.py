"""The ``follow_path`` task: its observation is the plan as a robot's controller reads it (the simulator's kernels
and the torch twin a robot runs, ``atrv_warp.core.path.PathTracker``, agree step by step through replans and
resets), its ends are Nav2's goal checker (stateful) and progress checker, its contract says how to read the plan,
and a snapshot restores it bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from atrv_warp.core.geometry import quat_to_yaw
from atrv_warp.core.path import PathTracker
from atrv_warp.task.env import RoverEnv
from atrv_warp.task.registry import get_task
from atrv_warp.task.spec import PATH_OBSERVATION, EndReason, policy_contract
from atrv_warp.world import OccupancyMap
from atrv_warp.world.nav2_map import FREE, OCCUPIED

LEAD = len(PATH_OBSERVATION)
PATH_NAMES = [f.name for f in PATH_OBSERVATION][:LEAD - 5]  # the points, the length left, the goal's heading


def hall() -> OccupancyMap:
    """20 m x 12 m at 0.1 m: two halls joined by a 2 m doorway (the robot must bend its way through)."""
    g = np.full((120, 200), FREE, np.int8)
    g[0, :] = g[-1, :] = g[:, 0] = g[:, -1] = OCCUPIED
    g[:, 100] = OCCUPIED
    g[80:100, 100] = FREE
    return OccupancyMap(cells=g, resolution=0.1, origin=(-10.0, -6.0), label="hall")


def _pose(env: RoverEnv, world: int) -> list[float]:
    p = env.sim.root_pose[world].double()
    return [float(p[0]), float(p[1]), float(quat_to_yaw(p[3:7]))]


def _twin_fields(tracker: PathTracker, pose) -> torch.Tensor:
    fields = tracker(pose)
    bounds = {f.name: f.bound for f in PATH_OBSERVATION}
    return torch.tensor([max(-bounds[n], min(bounds[n], fields[n])) for n in PATH_NAMES], dtype=torch.float64)


def test_the_observed_plan_is_what_a_robots_tracker_reads_through_replans_and_resets():
    """Under ``wide``: the plan is seen from the localized pose without noise; the odometry and IMU carry theirs."""
    import warp as wp

    n = 6
    env = RoverEnv(n, task="follow_path", maps=[hall()], seed=3, max_steps=40, randomization="wide")
    odom = [f.name for f in PATH_OBSERVATION].index("odom_linear")
    trackers = [PathTracker.from_contract(policy_contract(env.task_cfg)) for _ in range(n)]
    plans = [None] * n
    td = env.reset()
    g = torch.Generator().manual_seed(0)
    compared = replans = noisy = 0
    for step in range(90):
        obs = td["observation"].double()
        for w in range(n):
            plan = env.path[w, :int(env.path_length[w])].clone()
            if plans[w] is None or not torch.equal(plan, plans[w]):  # a new plan (a replan or a reset): set it
                replans += plans[w] is not None
                trackers[w].set_path(plan, float(env.target_yaw[w]))
                plans[w] = plan
            want = _twin_fields(trackers[w], _pose(env, w))
            assert torch.allclose(obs[w, :len(PATH_NAMES)], want, atol=2e-4), (step, w, obs[w, :len(PATH_NAMES)], want)
            compared += 1
        encoders = wp.to_torch(env.sim.driver.state.odom_twist)[:, 0] * env.odom_scale
        noisy += int((obs[:, odom] - encoders.double()).abs().gt(1e-6).sum())
        action = torch.rand(n, 2, generator=g) * 2 - 1
        action[:, 0] = action[:, 0].abs()
        out, td = env.step_and_maybe_reset(td.set("action", action))
        for w in torch.nonzero(out["next", "done"].flatten()).flatten().tolist():
            plans[w] = None  # a new episode: a new plan whatever its points
    assert compared == 90 * n and replans > 10 and noisy > 0.9 * compared


def test_the_goal_checker_keeps_the_position_once_reached_and_the_progress_checker_ends_a_stall():
    env = RoverEnv(2, task="follow_path", maps=[hall()], seed=0, obstacles=0, obstacles_on_path=0)
    # world 0 starts 0.2 m from its goal, turned 1.2 rad from the goal's heading, and drives away while turning to
    # it: a stateless checker would not end it. World 1 sits 3 m from its goal and does not move.
    env.set_worlds([0, 1], starts=[[-5.2, 0.0, 1.2], [-5.0, -3.0, 0.0]], targets=[[-5.0, 0.0], [-2.0, -3.0]],
                   target_yaws=[0.0, 0.0])
    dt = env.sim.sim_cfg.step_dt
    turn = -0.6 / env.task_cfg.max_angular
    ends, far = {}, None
    td = env.reset()
    for step in range(1, int(12.0 / dt) + 2):
        action = torch.tensor([[0.6, turn], [0.0, 0.0]])
        out, td = env.step_and_maybe_reset(td.set("action", action))
        reasons = out["next", "end_reason"].flatten().tolist()
        for w in (0, 1):
            if w not in ends and reasons[w]:
                ends[w] = (step, reasons[w])
                if w == 0:
                    far = float(out["next", "distance"][0])
        if len(ends) == 2:
            break
    assert ends[0][1] == EndReason.SUCCESS and far > env.task_cfg.reach_radius, (ends, far)
    stall = env.task_cfg.progress_time / dt  # Nav2 fails once the time since it last moved exceeds the allowance
    assert ends[1] == (math.floor(stall) + 1, EndReason.NO_PROGRESS), ends


def test_backing_up_costs_its_distance_but_near_the_goal():
    """The prefer-forward term (Nav2's MPPI ``PreferForwardCritic``): a step commanded backward costs the distance
    commanded, forward costs nothing, and within ``prefer_forward_threshold`` of the goal backing up is free."""
    env = RoverEnv(2, task="follow_path", maps=[hall()], seed=0, obstacles=0, obstacles_on_path=0)
    c = env.task_cfg
    assert c.prefer_forward_weight > 0 and c.prefer_forward_threshold == 0.5
    env.set_worlds([0, 1], starts=[[-5.0, -3.0, 0.0], [-5.3, 0.0, 0.0]], targets=[[-1.0, -3.0], [-5.0, 0.0]],
                   target_yaws=[0.0, 1.2])
    td = env.reset()
    per_step = c.max_linear * env.sim.sim_cfg.step_dt
    for linear, want in ((-0.5, [-0.5 * per_step, 0.0]), (0.7, [0.0, 0.0])):
        out, td = env.step_and_maybe_reset(td.set("action", torch.tensor([[linear, 0.0], [linear, 0.0]])))
        column = out["next", "reward_terms", "prefer_forward"].flatten()
        assert not out["next", "done"].any()
        assert column.tolist() == pytest.approx([c.prefer_forward_weight * w for w in want], abs=1e-6), linear


def test_the_contract_says_how_to_read_the_plan_and_a_bad_plan_is_named():
    config = get_task("follow_path")
    contract = policy_contract(config)
    assert contract["observation_kind"] == "path"
    assert [f["name"] for f in contract["observation"][:LEAD]] == [f.name for f in PATH_OBSERVATION]
    path = contract["path"]
    assert (path["points"], path["spacing_m"]) == (10, 0.4)
    assert path["goal_checker"] == {"plugin": "nav2_controller::SimpleGoalChecker", "xy_goal_tolerance": 0.25,
                                    "yaw_goal_tolerance": 0.25, "stateful": True}
    assert path["progress_checker"]["required_movement_radius"] == 0.5
    assert policy_contract(get_task("nav_deploy"))["path"] is None
    with pytest.raises(ValueError, match="no 'path' entry"):
        PathTracker.from_contract(policy_contract(get_task("nav_deploy")))
    tracker = PathTracker.from_contract(contract)
    with pytest.raises(ValueError, match="no plan yet"):
        tracker([0.0, 0.0, 0.0])
    for bad, match in (([], "shape"), ([[0.0, 0.0, 0.0]], "shape"), ([[0.0, math.nan]], "non-finite")):
        with pytest.raises(ValueError, match=match):
            tracker.set_path(bad, 0.0)
    tracker.set_path([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]], math.pi / 2)
    fields = tracker([0.5, 0.2, 0.0])  # beside the first segment, facing +x
    assert fields["path_0_x"] == pytest.approx(0.0) and fields["path_0_y"] == pytest.approx(-0.2)
    assert fields["path_2_x"] == pytest.approx(0.5) and fields["path_2_y"] == pytest.approx(0.1)  # round the corner
    assert fields["path_remaining"] == pytest.approx(3.5) and fields["sin_goal_yaw"] == pytest.approx(1.0)
    assert fields["path_9_x"] == pytest.approx(0.5) and fields["path_9_y"] == pytest.approx(2.8)  # the end, past it
    with pytest.raises(ValueError, match="maps"):
        RoverEnv(1, task="follow_path")


def test_a_snapshot_of_a_path_task_steps_on_bit_for_bit():
    env = RoverEnv(4, task="follow_path", maps=[hall()], seed=1)
    td = env.reset()
    g = torch.Generator().manual_seed(1)
    actions = [torch.rand(4, 2, generator=g) * 2 - 1 for _ in range(50)]
    for a in actions[:20]:
        _, td = env.step_and_maybe_reset(td.set("action", a))
    snapshot, root = env.state_dict(), td.clone()

    def run(td):
        seen = []
        for a in actions[20:]:
            out, td = env.step_and_maybe_reset(td.set("action", a))
            seen.append(out["next", "observation"].clone())
        return torch.stack(seen)

    first = run(root.clone())
    env.load_state_dict(snapshot)
    assert torch.equal(run(root.clone()), first)


def _cross_the_doorway(obstacle_layer: bool) -> tuple[dict, float]:
    """Regulated Pure Pursuit across the hall's doorway in two worlds, world 1 with a box on its plan past the
    doorway, unseen by the planner; the ends, and how near world 1's plans came to the box [m]."""
    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.pursuit import pursuit_policy

    env = RoverEnv(2, task="follow_path", maps=[hall()], seed=0, obstacles=1, obstacles_on_path=0,
                   planner=PlannerConfig(obstacle_layer=obstacle_layer))
    layout = {"starts": [[-6.0, -3.0, 0.0]] * 2, "targets": [[6.0, -3.0]] * 2, "target_yaws": [0.5, 0.5]}
    env.set_worlds([0, 1], **layout)
    plan = env.planner.points(0)
    assert len(plan) and plan[:, 1].max() > 2.0  # bent up through the doorway
    box = plan[int(0.8 * len(plan))]  # past the doorway, on the way down to the goal
    env.set_worlds([0, 1], **layout, obstacles=[[], [("box", float(box[0]), float(box[1]), 0.0, 0.3, 0.3)]])
    policy = pursuit_policy(env.task_cfg, env.robot)
    td, ends, nearest = env.reset(), {}, math.inf
    for _ in range(env.task_cfg.max_steps):
        out, td = env.step_and_maybe_reset(policy(td))
        for w, reason in enumerate(out["next", "end_reason"].flatten().tolist()):
            ends.setdefault(w, reason) if reason else None
        if 1 not in ends:  # the box's surface (Chebyshev: it is not turned), from world 1's plan as it is now
            gap = np.abs(env.planner.points(1) - box).max(axis=1) - 0.3
            nearest = min(nearest, float(gap.min()))
        if len(ends) == 2:
            break
    return ends, nearest


def test_the_pure_pursuit_baseline_follows_the_plan_and_goes_round_what_its_costmap_marks():
    ends, nearest = _cross_the_doorway(obstacle_layer=False)
    assert ends == {0: EndReason.SUCCESS, 1: EndReason.OBSTACLE} and nearest < 0, (ends, nearest)
    # with Nav2's obstacle layer the box is marked once the laser sees it, and the next plan goes round it
    ends, _ = _cross_the_doorway(obstacle_layer=True)
    assert ends == {0: EndReason.SUCCESS, 1: EndReason.SUCCESS}, ends


def test_evaluate_reports_each_path_episodes_end_time_detour_and_least_clearance(tmp_path, capsys):
    import json

    from atrv_warp.cli.evaluate import main
    from atrv_warp.world import save_map

    site = save_map(hall(), tmp_path / "hall.yaml")
    out = tmp_path / "rpp.json"
    assert main(["--baseline", "--task", "follow_path", "--map", str(site), "--episodes", "4", "--json",
                 str(out)]) == 0
    assert "regulated pure pursuit (follow_path)" in capsys.readouterr().out
    figures = json.loads(out.read_text())
    episodes = figures["episodes_path"]
    assert all(len(v) == 4 for v in episodes.values())
    assert sum(e == "obstacle" for e in episodes["end"]) == round(4 * figures["obstacle_rate"])
    assert all(0 < r < 3 for r in episodes["path_ratio"]) and all(s > 0 for s in episodes["seconds"])
    for end, least in zip(episodes["end"], episodes["least_clearance_m"], strict=True):
        # a body that touched came within its footprint's reach (0.43 m from the ATRV-Jr's origin); none went through
        assert 0 < least < (0.43 if end == "obstacle" else 6.0), (end, least)


def test_every_unmapped_obstacle_leaves_a_way_round_it():
    """In a map, no obstacle (the one on the plan included) stands closer to a wall than the robot's circumscribed
    diameter: one in a doorway would close it, and an episode without a way is no test of following a plan."""
    env = RoverEnv(64, task="follow_path", maps=["building:4"], seed=2)
    env.reset()
    passage, placed = 2 * env.sim.footprint_radii[1], 0
    obstacles = env.sim.obstacles
    for w in range(env.num_envs):
        site = env.sim.maps.maps[int(env.sim.maps.world_map[w])]
        rows, cols = np.nonzero(site.walls)
        walls = np.stack([site.origin[0] + (cols + 0.5) * site.resolution,
                          site.origin[1] + (rows + 0.5) * site.resolution], 1)
        for o in range(obstacles.kind.shape[1]):
            kind = int(obstacles.kind[w, o])
            if kind == 0:
                continue
            x, y = (float(v) for v in obstacles.pose[w, o, :2])
            size = obstacles.size[w, o].numpy()
            radius = float(size[0]) if kind == 2 else float(np.hypot(*size))
            gap = float(np.hypot(walls[:, 0] - x, walls[:, 1] - y).min()) - radius
            assert gap >= passage - site.resolution, (w, o, gap)  # the distance field's own half-cell
            placed += 1
    assert placed > 2 * env.num_envs  # most of the four slots find a place
