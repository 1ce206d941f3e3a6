"""The deploy node's collision monitor, without ROS (:mod:`atrv_warp.deploy.safety`): Nav2's stop and slow-down
polygons act on the scan's returns whatever the policy commands, say so once per event, and a bad zone is one line
naming its parameter. Messages are plain namespaces, as in ``test_deploy.py``."""

from __future__ import annotations

import dataclasses
import math

import pytest
from test_deploy import goal_msg, imu_msg, odom_msg, scan_msg, task_contract, write_policy

from atrv_warp.core.observation import Scan
from atrv_warp.core.parameters import ParameterError
from atrv_warp.deploy.contract import load_deployable
from atrv_warp.deploy.controller import Controller, Settings
from atrv_warp.deploy.safety import CollisionMonitor, parse_zone

STOP = "[[0.2, -0.2], [0.5, -0.2], [0.5, 0.2], [0.2, 0.2]]"
SLOW = "[[0.2, -0.3], [1.2, -0.3], [1.2, 0.3], [0.2, 0.3]]"


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return load_deployable(write_policy(tmp_path_factory.mktemp("safety") / "tiny.pt2", task_contract()))


def ahead(distance: float, beams: int = 11):
    """A 181-beam scan over 180 deg, clear (5 m) but for ``beams`` beams straight ahead at ``distance``."""
    ranges = [5.0] * 181
    for k in range(90 - beams // 2, 90 + beams // 2 + 1):
        ranges[k] = distance
    return scan_msg(ranges, -math.pi / 2, math.pi / 180)


def period(c: Controller, now: float, scan):
    c.on_odom(odom_msg(), now)
    c.on_imu(imu_msg(), now)
    c.on_scan(scan, now)
    return c.tick(now)


def test_the_stop_and_slowdown_zones_act_whatever_the_policy_commands_and_say_so_once(policy):
    c = Controller(policy, Settings(time_limit=0.0, stop_zone=STOP, slowdown_zone=SLOW))
    c.on_goal(goal_msg(6.0, 2.0), 0.0)
    lines = []
    for k, (scan, want) in enumerate([(ahead(3.0), "none"), (ahead(0.8), "slowdown"), (ahead(0.8), "slowdown"),
                                      (ahead(0.3), "stop"), (ahead(0.3), "stop"), (ahead(0.3, beams=3), "none"),
                                      (ahead(0.8), "slowdown")]):  # three returns: fewer than min_points (4)
        tick = period(c, 0.05 * (k + 1), scan)
        v, w = (max(-m, min(m, a * s)) for a, s, m in zip(c.last_action, policy.scale, c.limits, strict=True))
        assert abs(v) + abs(w) > 0  # the policy drives: the monitor has something to change
        expected = {"none": (v, w), "slowdown": (0.5 * v, 0.5 * w), "stop": (0.0, 0.0)}[want]
        assert tick.command == pytest.approx(expected), (k, want, tick.command)
        lines += [line for line in tick.log if line.startswith("collision monitor")]
    assert lines == ["collision monitor: 11 scan points in the slowdown zone: slowing to 0.5 x the command",
                     "collision monitor: 11 scan points in the stop zone: stopping",
                     "collision monitor: clear, the policy's command passes",
                     "collision monitor: 11 scan points in the slowdown zone: slowing to 0.5 x the command"], lines
    off = Controller(policy, Settings(time_limit=0.0, stop_zone=STOP, collision_monitor=False))
    off.on_goal(goal_msg(6.0, 2.0), 0.0)
    tick = period(off, 0.05, ahead(0.3))
    assert not off.monitor.active and abs(tick.command[0]) + abs(tick.command[1]) > 0


def test_returns_are_placed_from_the_trained_scanners_mount_and_a_moved_scanner_is_carried_there():
    m = CollisionMonitor(parse_zone("stop_zone", STOP), mount=(0.1, 0.0, 0.0))
    scan = Scan([0.3] * 5, -0.02, 0.01, 0.05, 10.0)  # 0.3 m ahead of a scanner 0.1 m ahead of the chassis origin
    x, _ = m.points(scan)
    assert x.tolist() == pytest.approx([0.1 + 0.3 * math.cos(0.01 * k) for k in range(-2, 3)])
    assert m.apply((0.5, 0.0), scan)[0] == (0.0, 0.0)  # 0.4 m ahead of the chassis origin: inside the stop zone
    moved = dataclasses.replace(scan, mount=(0.5, 0.0, 0.0))  # this scanner sits 0.5 m further ahead
    assert m.apply((0.5, 0.0), moved)[0] == (0.5, 0.0)  # its returns lie 0.9 m ahead: clear


def test_forward_only_zones_let_the_rover_turn_and_back_away_and_stop_it_driving_on():
    """``zone_motion`` forward (a Nav2 velocity polygon's forward zones): a wall inside the stop zone stops a command
    that drives forward, and passes one that turns in place or backs away, saying so once."""
    m = CollisionMonitor(parse_zone("stop_zone", STOP), parse_zone("slowdown_zone", SLOW), forward_only=True)
    wall = Scan([0.3] * 11, -0.05, 0.01, 0.05, 10.0)
    said = []
    for command, want in [((0.5, 0.2), (0.0, 0.0)), ((0.0, 1.0), (0.0, 1.0)), ((-0.2, 0.0), (-0.2, 0.0)),
                          ((0.0, -1.0), (0.0, -1.0)), ((0.3, 0.0), (0.0, 0.0))]:
        out, line = m.apply(command, wall)
        assert out == want, (command, out)
        said += [line] if line else []
    assert said == ["collision monitor: 11 scan points in the stop zone: stopping",
                    "collision monitor: the command turns or backs away from the zone: it passes",
                    "collision monitor: 11 scan points in the stop zone: stopping"], said
    assert CollisionMonitor(parse_zone("stop_zone", STOP)).apply((0.0, 1.0), wall)[0] == (0.0, 0.0)  # Nav2's polygon
    with pytest.raises(ParameterError, match=r"^parameter zone_motion must be one of"):
        Settings(zone_motion="backward")


@pytest.mark.parametrize("text", ["[[0, 0], [1, 0]]", "[0, 0, 1, 0, 1, 1]", "[[0, 0], [1, nan], [1, 1]]", "square"])
def test_a_bad_zone_is_one_line_naming_its_parameter(text):
    with pytest.raises(ParameterError, match=r"^parameter stop_zone must "):
        Settings(stop_zone=text)
    assert parse_zone("stop_zone", "") == ()
    assert parse_zone("slowdown_zone", SLOW)[1] == (1.2, -0.3)
