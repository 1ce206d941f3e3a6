"""The deploy node's ``FollowPath`` side without ROS: a plan-following policy is served, its observation is the plan as
:class:`~atrv_warp.core.path.PathTracker` reads it from the robot's pose carried into the path's frame, Nav2's goal
and progress checkers end it, a replan takes over without stopping, and a bad path is aborted with Nav2's code while
the rover stops. Messages are plain namespaces, as in ``test_deploy.py``."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import pytest
import torch
from test_deploy import fov_scan, imu_msg, odom_msg, task_contract, tf_msg, v3, write_policy

from atrv_warp.core.path import PathTracker
from atrv_warp.deploy.contract import load_deployable
from atrv_warp.deploy.controller import Controller, Settings
from atrv_warp.deploy.follow import MAX_PATH_POSES


@pytest.fixture(scope="module")
def path_policy(tmp_path_factory):
    return load_deployable(write_policy(tmp_path_factory.mktemp("follow") / "path.pt2", task_contract("follow_path")))


def pose_msg(x, y, yaw=0.0, frame=""):
    turn = NS(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    return NS(header=NS(frame_id=frame), pose=NS(position=v3(x, y), orientation=turn))


def path_msg(points, frame="map", yaw=0.0):
    """A ``nav_msgs/Path`` through ``points`` in ``frame``, its last pose turned ``yaw``."""
    return NS(header=NS(frame_id=frame), poses=[pose_msg(x, y, yaw if k == len(points) - 1 else 0.0)
                                                for k, (x, y) in enumerate(points)])


def sensors(c: Controller, now: float, x=0.0, y=0.0, yaw=0.0):
    """Fresh odometry (at x, y, yaw in ``odom``), IMU and a clear scan at ``now``."""
    c.on_odom(odom_msg(x, y, yaw), now)
    c.on_imu(imu_msg(), now)
    c.on_scan(fov_scan(181, math.pi), now)


def test_a_plan_policy_is_served_and_observes_the_plan_from_its_pose_in_the_paths_frame(path_policy):
    """``map -> odom`` is offset and turned: the observation's plan fields are the tracker's at the odometry pose
    carried into ``map``, and the goal checker (0.25 m, then 0.25 rad, stateful) ends it reached."""
    s = path_policy.path_settings
    assert (s.xy_goal_tolerance, s.yaw_goal_tolerance, s.required_movement_radius, s.movement_time_allowance) == (
        0.25, 0.25, 0.5, 10.0)
    assert "path observation" in path_policy.describe()
    c = Controller(path_policy, Settings(time_limit=0.0, odom_jump_margin=10.0), tf=True)  # the robot is put there
    c.on_tf(tf_msg(("map", "odom", 2.0, 1.0, math.pi / 2)), 0.0)  # odom's origin at (2, 1) in map, turned left
    sensors(c, 0.0)
    corner = [(2.0, 1.0), (2.0, 4.0), (0.0, 4.0)]  # up from the robot, then left: an L in map
    code, line = c.on_path(path_msg(corner, yaw=math.pi), 0.0)
    assert code is None and line.startswith("path (3 poses in map, to (0.00, 4.00))"), line
    tick = c.tick(0.2)
    assert tick.status["state"] == "active" and tick.command is not None
    twin = PathTracker(s.points, s.spacing, s.search)
    twin.set_path(corner, math.pi)
    want = twin((2.0, 1.0, math.pi / 2))  # the odometry's origin, heading along odom's x: map's y
    obs, names = c.last_observation, path_policy.observation.names
    bounds = {f.name: (f.low, f.high) for f in path_policy.observation.fields}
    for name in ("path_0_x", "path_0_y", "path_5_x", "path_5_y", "path_9_x", "path_9_y", "path_remaining",
                 "sin_goal_yaw", "cos_goal_yaw"):
        lo, hi = bounds[name]
        assert float(obs[names.index(name)]) == pytest.approx(min(max(want[name], lo), hi), abs=1e-5), name
    assert tick.status["distance"] == pytest.approx(5.0)
    # at the end (odom (3, 2) is map (0, 4)) but facing map's y: the position is kept while the heading turns
    sensors(c, 0.4, 3.0, 2.0, 0.0)
    assert c.tick(0.4).status["state"] == "active"
    sensors(c, 0.6, 2.5, 2.4, math.pi / 2)  # drifted 0.64 m off, turned to map's -x: the goal checker kept it
    tick = c.tick(0.6)
    assert tick.status["state"] == "reached" and "0.25 m and 0.25 rad" in tick.status["reason"], tick.status


def test_the_progress_checker_aborts_a_stall_and_a_replan_drives_on_with_it(path_policy):
    c = Controller(path_policy, Settings(time_limit=0.0, stale_timeout=1.0))
    sensors(c, 0.0)
    assert c.on_path(path_msg([(0.0, 0.0), (5.0, 0.0)], frame="odom"), 0.0)[0] is None
    t = 0.0
    for step in range(1, 60):
        t = 0.25 * step  # exact in binary: the checker's "more than 10 s" is met at one step
        sensors(c, t, x=0.1 * (t > 6.0))  # creeps 0.1 m at 6 s: not out of the 0.5 m circle
        if step % 4 == 0:  # the behaviour tree's replan every second: the checker is not started again
            code, line = c.on_path(path_msg([(0.1, 0.0), (5.0, 0.0)], frame="odom"), t, preempt=True)
            assert code is None and line.endswith("replanned: following"), line
        tick = c.tick(t)
        if tick.status["state"] != "active":
            break
    assert tick.status["state"] == "aborted" and tick.status["reason"].startswith("FAILED_TO_MAKE_PROGRESS"), tick
    assert tick.command == (0.0, 0.0) and t == 10.5  # Nav2's: first checked at 0.25 s, then more than 10 s later
    assert not c.active and c.tick(t + 0.2).command is None


@pytest.mark.parametrize(("path", "code", "words"), [
    (path_msg([]), "INVALID_PATH", "no poses"),
    (path_msg([(0.0, 0.0), (math.nan, 1.0)], frame="odom"), "INVALID_PATH", "pose 1 of the path is not finite"),
    (path_msg([(0.0, 0.0)] * (MAX_PATH_POSES + 1), frame="odom"), "INVALID_PATH", f"more than the {MAX_PATH_POSES}"),
    (path_msg([(1.0, 0.0)], frame=""), "INVALID_PATH", "names no frame"),
    (path_msg([(1.0, 0.0)], frame="map"), "TF_ERROR", "reads no /tf"),
])
def test_a_bad_path_is_aborted_with_nav2s_code_and_the_old_path_does_not_drive_on(path_policy, path, code, words):
    c = Controller(path_policy, Settings(time_limit=0.0))
    sensors(c, 0.0)
    assert c.on_path(path_msg([(0.0, 0.0), (4.0, 0.0)], frame="odom"), 0.0)[0] is None
    assert c.tick(0.2).status["state"] == "active"
    got, reason = c.on_path(path, 0.3, preempt=True)
    assert got == code and reason.startswith(f"{code}: ") and words in reason, reason
    tick = c.tick(0.4)
    assert tick.command == (0.0, 0.0) and tick.status["state"] == "aborted" and tick.status["reason"] == reason
    assert c.tick(0.6).command is None  # no goal: nothing drives
    sensors(c, 0.7)
    assert c.on_path(path_msg([(0.0, 0.0), (4.0, 0.0)], frame="odom"), 0.7)[0] is None  # a good path drives again
    assert c.tick(0.8).status["state"] == "active"


def test_a_path_waits_for_its_frames_transform_within_nav2s_tolerance_then_ends_with_tf_error(path_policy):
    """The rover holds while ``/tf`` does not join ``odom`` to the path's frame; a transform within 0.3 s (Nav2's
    costmap ``transform_tolerance``) is followed, none aborts with ``TF_ERROR``."""
    c = Controller(path_policy, Settings(time_limit=0.0), tf=True)
    sensors(c, 0.0)
    assert c.on_path(path_msg([(0.0, 0.0), (4.0, 0.0)], frame="map"), 0.0)[0] is None
    tick = c.tick(0.2)
    assert tick.status["state"] == "holding" and tick.command == (0.0, 0.0)
    assert "waiting for the transform" in tick.log[0]
    c.on_tf(tf_msg(("map", "odom", 0.0, 0.0, 0.0)), 0.3)  # late (as /tf_static for a node just started), in time
    sensors(c, 0.4)
    assert c.tick(0.4).status["state"] == "active"
    assert c.on_path(path_msg([(0.0, 0.0), (4.0, 0.0)], frame="elsewhere"), 0.5)[0] is None
    sensors(c, 0.6)
    assert c.tick(0.6).status["state"] == "holding"
    sensors(c, 0.8)
    assert c.tick(0.8).status["state"] == "holding"  # 0.2 s without it
    sensors(c, 1.0)
    tick = c.tick(1.0)
    assert tick.status["state"] == "aborted" and tick.command == (0.0, 0.0)
    assert tick.status["reason"] == ("TF_ERROR: no transform from 'odom' to the path's frame 'elsewhere' on /tf "
                                     "within 0.3 s")


def test_a_goal_seeking_policy_takes_no_path_and_the_observation_names_a_missing_plan(path_policy, tmp_path):
    goal_policy = load_deployable(write_policy(tmp_path / "goal.pt2", task_contract("nav_deploy")))
    with pytest.raises(ValueError, match="drives to a goal, not along a path"):
        Controller(goal_policy).on_path(path_msg([(1.0, 0.0)], frame="odom"), 0.0)
    with pytest.raises(ValueError, match="the policy follows a plan; pass path="):
        path_policy.observation(odom_pose=[0.0, 0.0, 0.0], odom_twist=[0.0, 0.0], imu_orientation=[0, 0, 0, 1.0],
                                imu_angular_velocity=[0.0, 0.0, 0.0], scan=None, last_actions=torch.zeros(3, 2))


def test_one_pose_a_10_km_path_a_replan_flood_and_stale_odometry_each_end_as_nav2s_would(path_policy):
    """A path of one pose is followed to it; one 10 km long (two poses) is followed, its fields clipped; 100 replans
    in a second keep one path in memory and the rover driving; odometry that goes stale holds the rover, and a goal
    held past the progress checker's allowance ends FAILED_TO_MAKE_PROGRESS instead of never."""
    c = Controller(path_policy, Settings(time_limit=0.0, stale_timeout=0.5))
    sensors(c, 0.0)
    assert c.on_path(path_msg([(1.0, 0.0)], frame="odom", yaw=0.0), 0.0)[0] is None
    assert c.tick(0.25).status["state"] == "active" and c.route.remaining == 0.0
    sensors(c, 0.5, x=0.9)
    assert c.tick(0.5).status["state"] == "reached"
    assert c.on_path(path_msg([(0.0, 0.0), (10_000.0, 0.0)], frame="odom"), 0.5)[0] is None
    tick = c.tick(0.75)
    assert tick.status["state"] == "active" and tick.status["distance"] == pytest.approx(10_000.0 - 0.9)
    remaining = c.last_observation[path_policy.observation.names.index("path_remaining")]
    assert float(remaining) == {f.name: f.high for f in path_policy.observation.fields}["path_remaining"]
    for k in range(100):  # a replan every 10 ms
        replan = path_msg([(0.0, 0.01 * k), (5.0, 0.0)], frame="odom")
        assert c.on_path(replan, 0.75 + 0.01 * k, preempt=True)[0] is None
    sensors(c, 1.75, x=0.9)
    assert c.tick(1.75).status["state"] == "active" and len(c.route.tracker.path) == 2
    t = 1.75
    while t < 20.0:  # the odometry stops coming; the IMU and scan go on
        t += 0.25
        c.on_imu(imu_msg(), t)
        c.on_scan(fov_scan(181, math.pi), t)
        tick = c.tick(t)
        if tick.status["state"] not in ("active", "holding"):  # active until the odometry is 0.5 s old
            break
    assert tick.status["state"] == "aborted" and tick.command == (0.0, 0.0), tick.status
    assert tick.status["reason"].startswith("FAILED_TO_MAKE_PROGRESS: held still for more than 10 s (/odom stale"), tick
