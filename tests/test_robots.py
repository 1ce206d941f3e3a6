"""A robot is one file: the shipped robots load and check, a bad file is refused naming its field and the link or
joint, a URDF in the ROS conventions becomes a robot file with ``python -m atrv_warp.robot new`` and drives."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
import shutil
from pathlib import Path

import pytest
import torch

from atrv_warp.core.robot import ROBOTS, RobotFileError, load_robot, robot_from_record, robot_record
from atrv_warp.sim.config import RoverConfig, replace_checked

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "atrv_warp" / "robots"
DATA = Path(__file__).resolve().parent / "data"

ROS_URDF = """<?xml version="1.0"?>
<robot name="rosbot">
  <link name="base_footprint"/>
  <link name="base_link">
    <inertial><origin xyz="0 0 0.05"/><mass value="12.0"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.25"/></inertial>
    <collision><origin xyz="0 0 0.06"/><geometry><box size="0.5 0.3 0.12"/></geometry></collision>
  </link>
  <joint name="base_footprint_joint" type="fixed">
    <parent link="base_footprint"/><child link="base_link"/><origin xyz="0 0 0.08"/>
  </joint>
  {wheels}
  <link name="imu_link"/>
  <joint name="imu_joint" type="fixed"><parent link="base_link"/><child link="imu_link"/><origin xyz="0 0 0.1"/></joint>
  <link name="laser"/>
  <joint name="laser_joint" type="fixed"><parent link="base_link"/><child link="laser"/>
    <origin xyz="0.2 0 0.2" rpy="{laser_rpy}"/></joint>
</robot>
"""
WHEEL = """
  <link name="{name}_wheel"><inertial><mass value="0.8"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.0036" iyz="0" izz="0.002"/></inertial>
    <collision><origin rpy="1.5708 0 0"/><geometry><cylinder radius="0.1" length="0.05"/></geometry></collision>
  </link>
  <joint name="{name}_wheel_joint" type="continuous"><parent link="base_link"/><child link="{name}_wheel"/>
    <origin xyz="{x} {y} 0.02"/><axis xyz="0 1 0"/></joint>"""


def ros_urdf(folder: Path, *, sides=(1, -1), laser_rpy="0 0 0") -> Path:
    """A URDF as ROS robots write them: base_footprint above base_link, wheel joints about +y, a laser ahead and up."""
    wheels = "".join(WHEEL.format(name=f"{fr}_{'left' if s > 0 else 'right'}", x=0.15 if fr == "front" else -0.15,
                                  y=0.2 * s) for fr in ("front", "rear") for s in sides)
    path = folder / "rosbot.urdf"
    path.write_text(ROS_URDF.format(wheels=wheels, laser_rpy=laser_rpy))
    return path


def test_three_robots_ship_and_check():
    from atrv_warp.sim.robot_check import check_robot

    assert set(ROBOTS) >= {"atrvjr", "jackal", "husky"}
    for name in ROBOTS:
        robot, description = check_robot(name)
        assert robot.name == name and len(description.wheels) == 4
        assert {w.side for w in description.wheels} == {0, 1}
        for field in ("linear_velocity", "angular_velocity"):  # every limit cites where it comes from
            assert f"limits.{field}" in robot.sources, (name, field)
    jackal, husky = load_robot("jackal"), load_robot("husky")
    assert (jackal.limits.linear_velocity, jackal.limits.angular_velocity) == (2.0, 4.0)
    assert (husky.limits.linear_velocity, husky.limits.angular_velocity) == (1.0, 1.0)
    assert load_robot("atrvjr").limits.linear_velocity == 0.5


def test_a_rover_config_is_its_robots_unless_set():
    assert RoverConfig().chassis_link == "center_link" and RoverConfig().wheel_radius == 0.125
    jackal = RoverConfig(robot="jackal")
    assert (jackal.chassis_link, jackal.wheel_radius, jackal.wheel_speed_limit) == ("chassis_link", 0.098, 40.0)
    worn = RoverConfig(robot="jackal", wheel_radius=0.095, payload_mass=2.0)
    assert worn.wheel_radius == 0.095
    husky = replace_checked(worn, robot="husky")  # the new robot's values where it held the old one's
    assert (husky.chassis_link, husky.wheel_radius, husky.payload_mass) == ("base_link", 0.095, 2.0)
    assert replace_checked(jackal, robot="husky") == RoverConfig(robot="husky")


def test_the_simulator_takes_the_robots_driver():
    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.driver import DriverConfig

    sim = RoverSim(1, robot="husky")
    husky = load_robot("husky")
    assert (sim.driver_cfg.kp, sim.driver_cfg.ki, sim.driver_cfg.torque_limit) == (husky.kp, husky.ki,
                                                                                   husky.torque_limit)
    assert sim.driver.kinematics.effective_track_factor == husky.effective_track_factor
    assert RoverSim(1, robot="husky", driver=DriverConfig(kp=1.0)).driver_cfg.kp == 1.0
    with pytest.raises(ValueError, match="differ"):
        RoverSim(1, robot="husky", rover=RoverConfig(robot="jackal"))


def test_the_explicit_loops_gain_rule_gives_the_atrvjrs_tuned_gains():
    """The explicit loop's rule (``GAIN_RATIO``) is the ATRV-Jr's tuned 3.0 at the 0.01 s substep."""
    from atrv_warp.sim.robot_check import check_robot, driver_gains

    assert driver_gains(check_robot("atrvjr")[1], implicit=False) == (3.0, 30.0)


def test_the_implicit_loops_gain_rule_answers_every_loaded_wheel_alike_within_its_cap():
    """``kp = (J + mass / wheels x r²) / LOOP_TIME``, the default loop's and every shipped robot's: the ATRV-Jr's 58 kg
    on 0.125 m wheels give 4.92, the Jackal's light wheels 0.933 (``kp x dt / J`` 3.9, under the cap of 4); a light
    wheel under a heavy robot is capped."""
    from atrv_warp.sim.robot_check import IMPLICIT_GAIN_CAP, check_robot, driver_gains, wheel_inertia

    assert driver_gains(check_robot("atrvjr")[1]) == (4.92, 49.2) == (load_robot("atrvjr").kp, load_robot("atrvjr").ki)
    _, jackal = check_robot("jackal")
    assert driver_gains(jackal) == (0.933, 9.33)
    for name in ROBOTS:
        robot, description = check_robot(name)
        assert driver_gains(description, wheel_radius=robot.wheel_radius) == (robot.kp, robot.ki)
    heavy = dataclasses.replace(jackal, chassis_inertial=dataclasses.replace(jackal.chassis_inertial, mass=200.0))
    kp, _ = driver_gains(heavy)
    assert kp == pytest.approx(IMPLICIT_GAIN_CAP * wheel_inertia(jackal) / 0.01, rel=0.01)


def test_a_record_reads_back_as_the_robot():
    for name in ROBOTS:
        robot = load_robot(name)
        assert robot_from_record(robot_record(robot), "a checkpoint") == robot


def test_a_record_keeps_a_per_side_motor_and_an_older_record_reads_without_one():
    assert load_robot("husky").motor_per_side and load_robot("jackal").motor_per_side
    assert not load_robot("atrvjr").motor_per_side
    assert "per_side" not in robot_record(load_robot("atrvjr"))["motor"]  # the records made before the key
    assert robot_record(load_robot("husky"))["motor"]["per_side"] is True


def side_wheel_speeds(robot, seconds: float = 2.0) -> torch.Tensor:
    """(2, 2) each side's [front, rear] wheel speed [rad/s] after ``seconds`` of a skid turn on flat ground."""
    from atrv_warp.sim.simulator import RoverSim

    sim = RoverSim(1, robot=robot)
    sim.commands[:] = torch.tensor([[-0.3, 1.0]]) * sim.driver_cfg.torque_limit
    for _ in range(round(seconds / sim.sim_cfg.step_dt)):
        sim.step()
    speeds = sim.wheel_speed[0]
    sides = [[k for k, w in enumerate(sim.description.wheels) if w.side == side] for side in (0, 1)]
    return torch.stack([speeds[s] for s in sides])


def test_a_per_side_motor_turns_its_sides_wheels_at_one_speed(tmp_path):
    """In a skid turn the front and rear wheels of a side slip differently: free, they part; geared (the Husky's
    chain), they turn together."""
    path = _copy(tmp_path, "husky")
    path.write_text(path.read_text().replace("per_side = true", "per_side = false"))
    free, geared = side_wheel_speeds(path), side_wheel_speeds("husky")
    spread = lambda s: float((s[:, 0] - s[:, 1]).abs().max())
    assert spread(free) > 1.0, free
    assert spread(geared) < 0.1 * spread(free), (free, geared)


def _copy(tmp_path: Path, name: str = "jackal") -> Path:
    for suffix in (".toml", ".urdf"):
        shutil.copy(ROBOTS_DIR / f"{name}{suffix}", tmp_path / f"{name}{suffix}")
    return tmp_path / f"{name}.toml"


@pytest.mark.parametrize(("edit", "message"), [
    (lambda t: t.replace('title = "Clearpath Jackal J100"', 'title = "J"\ncolour = "yellow"'),
     r"unknown field\(s\) \['colour'\]"),
    (lambda t: t.replace("[motor]", "[motor]\npeak_torque = 3.0"), r"unknown field\(s\) \['motor.peak_torque'\]"),
    (lambda t: t.replace("linear_velocity = 2.0\n", ""), "missing limits.linear_velocity"),
    (lambda t: re.sub(r"^kp = .*$", "kp = -1.0", t, count=1, flags=re.MULTILINE), "driver.kp must be > 0"),
    (lambda t: t.replace("per_side = true", 'per_side = "yes"'), "motor.per_side must be true or false"),
    (lambda t: t.replace('chassis = "chassis_link"', 'chassis = "body"'), r"links.chassis \(body\).*not found"),
    (lambda t: t.replace('imu = "imu_0_link"', 'imu = "imu_link"'), r"links.imu \(imu_link\).*not found"),
    (lambda t: t.replace("radius = 0.098", "radius = 0.12"),
     r"wheels.radius \(front_left_wheel_link\): the file says 0.12 m, the URDF's wheel cylinder 0.098 m"),
    (lambda t: t.replace('laser = "lidar2d_0_laser"', 'laser = "front_left_wheel_link"'),
     r"links.laser \(front_left_wheel_link\): .*must be fixed to 'chassis_link'"),
    (lambda t: t.replace("[links]", '[links]\nleft_wheels = ["front_left_wheel_link"]'),
     "name the wheels of both sides, or neither"),
])
def test_a_bad_robot_file_names_its_field(tmp_path, edit, message):
    from atrv_warp.sim.robot_check import check_robot

    path = _copy(tmp_path)
    path.write_text(edit(path.read_text()))
    with pytest.raises(RobotFileError, match=message):
        check_robot(path)


def test_a_wheel_joint_about_the_wrong_axis_and_wheels_on_one_side_are_named(tmp_path):
    from atrv_warp.sim.robot_check import check_robot

    path = _copy(tmp_path)
    urdf = tmp_path / "jackal.urdf"
    text = urdf.read_text()
    urdf.write_text(text.replace('<origin xyz="0.131 0.187795 0.0345" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>',
                                 '<origin xyz="0.131 0.187795 0.0345" rpy="0 0 0"/>\n    <axis xyz="1 0 0"/>'))
    path.write_text(path.read_text().replace("[links]", '[links]\nleft_wheels = ["front_left_wheel_link", '
                                             '"rear_left_wheel_link"]\nright_wheels = ["front_right_wheel_link", '
                                             '"rear_right_wheel_link"]'))
    with pytest.raises(RobotFileError, match=r"links.left_wheels \(front_left_wheel_joint\): .*not lateral"):
        check_robot(path)
    urdf.write_text(text)
    path.write_text(path.read_text().replace('right_wheels = ["front_right_wheel_link", "rear_right_wheel_link"]',
                                             'right_wheels = ["rear_left_wheel_link"]'))
    with pytest.raises(RobotFileError, match="on both sides"):
        check_robot(path)


def test_an_unknown_robot_lists_the_shipped_ones():
    with pytest.raises(RobotFileError, match="unknown robot 'husk'; shipped robots: atrvjr, husky, jackal"):
        load_robot("husk")
    with pytest.raises(RobotFileError, match="robot file not found"):
        load_robot("no/such/robot.toml")


def test_a_ros_urdf_becomes_a_robot_that_drives(tmp_path, capsys):
    """The newcomer's path: ``robot new`` on a URDF in the ROS conventions, the limits set, ``check --static``, and the
    robot drives its limits through ``/cmd_vel``."""
    from atrv_warp.cli.robot import main
    from atrv_warp.sim import RoverSim

    urdf = ros_urdf(tmp_path)
    assert main(["new", str(urdf), "--name", "rosbot"]) == 0
    path = tmp_path / "rosbot.toml"
    text = path.read_text()
    assert 'chassis = "base_link"' in text and 'imu = "imu_link"' in text and 'laser = "laser"' in text
    from atrv_warp.core.robot import FIELDS

    for field in FIELDS:  # every field a robot file has, the optional ones as comments
        assert f"\n{field.split('.')[-1]} = " in text or f"\n# {field.split('.')[-1]} = " in text, field
    for field in ("motor.torque_limit", "motor.no_load_speed", "limits.linear_velocity", "limits.angular_acceleration"):
        assert load_robot(path).sources[field].startswith("not published")
    path.write_text(text.replace("linear_velocity = 1.0", "linear_velocity = 0.8"))
    assert main(["check", str(path), "--static"]) == 0
    assert "ok (rosbot: chassis base_link, 4 wheels" in capsys.readouterr().out
    assert main(["new", str(urdf), "--name", "rosbot"]) == 2  # never overwrites without --force
    robot = load_robot(path)
    sim = RoverSim(2, robot=str(path))
    sim.reset(poses=[[0.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    twist = torch.tensor([[robot.limits.linear_velocity, 0.0], [0.0, robot.limits.angular_velocity]])
    for _ in range(60):
        sim.set_twist(twist)
        sim.step()
    assert sim.lin_vel[0, :2].norm() == pytest.approx(0.8, rel=0.1)
    assert sim.ang_vel[1, 2] == pytest.approx(1.0, rel=0.15)
    assert {f.name for f in sim.description.frames} >= {"base_footprint", "imu_link", "laser"}


@pytest.mark.parametrize(("name", "wheels"), [("sixwheel", 6), ("eightwheel", 8)])
def test_six_and_eight_wheel_robots_check_and_drive_their_limits(name, wheels):
    """Test robots in ``tests/data`` (written by ``robot new``, measured by ``check --write``) with three and four
    wheels a side: every wheel is in the friction solve, and ``/cmd_vel`` at the robot's limits is met."""
    from atrv_warp.sim import RoverSim
    from atrv_warp.sim.robot_check import check_robot

    robot, description = check_robot(DATA / f"{name}.toml")
    assert len(description.wheels) == wheels and sum(w.side == 0 for w in description.wheels) == wheels // 2
    sim = RoverSim(2, robot=robot.path)
    sim.reset(poses=[[-5.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    lim = robot.limits
    twist = torch.tensor([[lim.linear_velocity, 0.0], [0.0, lim.angular_velocity]])
    for _ in range(round(3.0 / sim.sim_cfg.step_dt)):
        sim.set_twist(twist)
        sim.step()
    assert sim.lin_vel[0, :2].norm() == pytest.approx(lim.linear_velocity, rel=0.05)
    assert sim.ang_vel[1, 2] == pytest.approx(lim.angular_velocity, rel=0.15)
    impulses = sim.contact.impulses.numpy().reshape(2, wheels, 3)
    assert (abs(impulses[1]).sum(-1) > 0).all(), "a wheel of the turning rover carries no friction"


def test_the_check_turns_to_the_robots_limits_fits_the_factor_within_the_grip_and_judges_settling():
    from atrv_warp.sim.robot_check import (
        SETTLE_TARGET,
        settle_misses,
        track_factor_rule,
        turn_commands,
        within_grip,
    )

    jackal = load_robot("jackal")  # 2 m/s, 4 rad/s
    assert turn_commands(jackal) == ((0.0, 0.5), (0.0, 1.0), (0.0, 2.0), (0.0, 4.0), (1.0, 1.0), (1.0, -2.0),
                                     (2.0, 1.0), (2.0, 2.0))
    turns = [{"linear": 0.0, "angular": 4.0, "friction": 0.3, "chi": 1.5},
             {"linear": 0.5, "angular": 1.0, "friction": 0.3, "chi": 1.2},
             {"linear": 2.0, "angular": 1.0, "friction": 0.3, "chi": 0.5}]  # 2 m/s² > 0.25 x 0.3 g: sliding
    assert [within_grip(t) for t in turns] == [True, True, False]
    f = track_factor_rule(turns)  # least squares of f / chi - 1 over the first two
    assert f == pytest.approx((1 / 1.5 + 1 / 1.2) / (1 / 1.5**2 + 1 / 1.2**2))
    assert f / 1.5 - 1 == pytest.approx(-(f / 1.2 - 1), rel=0.3)  # errors of both signs, neither side favoured
    steps = [{"linear": 0.0, "angular": 0.5, "friction": 0.3, "settle": 0.4},
             {"linear": 0.3, "angular": 0.3, "friction": 0.8, "settle": 0.75},
             {"linear": 0.0, "angular": 0.5, "friction": 0.8, "settle": math.inf},
             {"linear": 1.0, "angular": 0.2, "friction": 0.8, "settle": 2.0}]  # reported, not judged
    assert settle_misses(steps) == ["arc 0.3 m/s, 0.3 rad/s at µ 0.8: 0.75 s", "in place 0.5 rad/s at µ 0.8: never"]
    assert SETTLE_TARGET == 0.5


def test_check_of_a_six_wheel_robot_prints_each_turns_error_and_its_verdict(tmp_path, capsys):
    import json

    from atrv_warp.cli.robot import main

    for name in ("sixwheel.toml", "sixwheel.urdf"):
        shutil.copy(DATA / name, tmp_path / name)
    out = tmp_path / "report.json"
    assert main(["check", str(tmp_path / "sixwheel.toml"), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "in place 2 rad/s" in printed and "arc 1.5 m/s, 1 rad/s" in printed  # turns to its limits, 1.5 and 2
    assert "settling (in place and the 0.3 m/s arc, target 0.5 s): met" in printed
    report = json.loads(out.read_text())
    assert len(report["turns"]) == 16 and all(abs(t["yaw_error"]) < 0.25 for t in report["turns"])
    assert report["settle_misses"] == [] and report["top_speed"] <= 20.0 * 0.15


def test_unpaired_or_too_many_wheels_are_refused_naming_the_count(tmp_path):
    from atrv_warp.sim.robot_check import check_robot

    def urdf_with(extra: list[tuple[str, float, float]]) -> Path:
        path = ros_urdf(tmp_path)
        wheels = "".join(WHEEL.format(name=n, x=x, y=y) for n, x, y in extra)
        path.write_text(path.read_text().replace("</robot>", wheels + "\n</robot>"))
        return path

    path = tmp_path / "rosbot.toml"
    path.write_text(starter_file_for(urdf_with([("middle_left", 0.0, 0.2)])))
    with pytest.raises(RobotFileError, match=r"3 left and 2 right wheels .*as many on each side, 8 at most"):
        check_robot(path)
    path.write_text(starter_file_for(urdf_with([(f"m{i}_{side}", 0.1 * i - 0.1, y)
                                                for i in range(3) for side, y in (("left", 0.2), ("right", -0.2))])))
    with pytest.raises(RobotFileError, match=r"5 left and 5 right wheels .*8 at most"):
        check_robot(path)
    text = starter_file_for(ros_urdf(tmp_path)).replace(
        "[links]", '[links]\nleft_wheels = ["front_left_wheel", "rear_left_wheel"]\nright_wheels = ["rear_right_wheel"]')
    path.write_text(text)
    with pytest.raises(RobotFileError, match=r"links: 2 left and 1 right wheels; .*as many on each side"):
        load_robot(path)


def starter_file_for(urdf: Path) -> str:
    from atrv_warp.cli.robot import starter_file

    return starter_file(urdf, "rosbot")


def test_a_turned_laser_or_imu_is_refused(tmp_path):
    from atrv_warp.cli.robot import starter_file
    from atrv_warp.sim.robot_check import check_robot

    urdf = ros_urdf(tmp_path, laser_rpy="3.14159 0 0")  # mounted upside down
    path = tmp_path / "rosbot.toml"
    path.write_text(starter_file(urdf, "rosbot"))
    with pytest.raises(RobotFileError, match=r"links.laser \(laser\): the frame is turned 180.0 deg"):
        check_robot(path)
    one_side = ros_urdf(tmp_path, sides=(1,))
    path.write_text(starter_file(one_side, "rosbot"))
    with pytest.raises(RobotFileError, match="wheels on one side only"):
        check_robot(path)


def test_check_write_puts_the_measured_values_in_the_file(tmp_path):
    from atrv_warp.cli.robot import write_measured

    path = _copy(tmp_path, "husky")
    before = path.read_text()
    report = {"gains": {"kp": 6.5, "ki": 65.0}, "effective_track_factor": 1.913, "wheel_inertia": 0.04411,
              "loaded_inertia": 0.4298,
              "turns": [{}] * 14, "file": {"kp": 6.78, "ki": 67.8, "effective_track_factor": 1.97}}
    assert write_measured(path, report) == ["kp", "ki", "effective_track_factor"]
    robot = load_robot(path)
    assert (robot.kp, robot.ki, robot.effective_track_factor) == (6.5, 65.0, 1.91)
    assert "measured by `python -m atrv_warp.robot check`" in robot.sources["driver.effective_track_factor"]
    assert "kp = J_loaded / 0.05 s" in robot.sources["driver.kp"] and "0.4298 kg m²" in robot.sources["driver.kp"]
    untouched = [line for line in before.splitlines() if not line.startswith(("kp", "ki", "effective", '"driver.'))]
    assert all(line in path.read_text().splitlines() for line in untouched)
    assert math.isclose(robot.limits.linear_velocity, 1.0)


@pytest.mark.parametrize(("robot", "linear", "angular", "period"), [
    ("atrvjr", 0.5, 1.0, 0.2), ("jackal", 2.0, 4.0, 0.05), ("husky", 1.0, 1.0, 0.1)])
def test_a_twist_task_is_fitted_to_the_robot(robot, linear, angular, period):
    """Its action 1 is the robot's limits, its base the robot's accelerations, its period long enough that an episode
    covers the distance it did at 2 m/s, its radii the margin they had over the ATRV-Jr's footprint."""
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.scaling import REFERENCE_FOOTPRINT, REFERENCE_SPEED, REFERENCE_STEP_DT

    env = RoverEnv(1, robot=robot, task="nav_deploy", seed=0)
    c, declared, lim = env.task_cfg, resolve_task("nav_deploy").config, load_robot(robot).limits
    assert (c.max_linear, c.max_angular, c.control_period) == (linear, angular, pytest.approx(period))
    assert (c.linear_max_acceleration, c.angular_max_acceleration) == (lim.linear_acceleration, lim.angular_acceleration)
    assert env.sim.sim_cfg.step_dt == pytest.approx(period) and env.sim.driver_cfg.linear_max_acceleration == \
        lim.linear_acceleration
    reach = declared.max_steps * REFERENCE_STEP_DT * REFERENCE_SPEED  # metres an episode drove at 2 m/s
    assert c.max_steps * c.control_period * c.max_linear == pytest.approx(reach)
    from atrv_warp.task.scaling import footprint_radius

    grow = footprint_radius(env.sim.description, env.sim.rover_cfg) - REFERENCE_FOOTPRINT
    assert c.clearance_radius == pytest.approx(declared.clearance_radius + grow, abs=2e-3)
    assert c.reach_radius == pytest.approx(declared.reach_radius + grow, abs=2e-3)


def test_the_atrvjrs_torque_tasks_are_as_declared_and_others_take_their_torque():
    from atrv_warp.task.env import RoverEnv
    from atrv_warp.task.registry import resolve_task

    for task in ("reach", "nav"):
        env = RoverEnv(1, task=task)
        assert env.task_cfg == resolve_task(task).config and env.sim.sim_cfg.step_dt == 0.05
    assert RoverEnv(1, robot="husky", task="nav").task_cfg.action_scale == load_robot("husky").torque_limit
    from atrv_warp.task.config import TaskConfig

    given = TaskConfig(action_scale=7.0)  # a config given directly is used as it is, on any robot
    assert RoverEnv(1, robot="husky", task=given).task_cfg == given


def test_a_preset_randomization_follows_the_robots_size():
    from atrv_warp.task.randomization import RANDOMIZATION_PRESETS, get_randomization

    wide = RANDOMIZATION_PRESETS["wide"]
    assert get_randomization("wide", rover=RoverConfig()) == wide
    jackal = get_randomization("wide", rover=RoverConfig(robot="jackal"))
    assert jackal.payload_mass.high == pytest.approx(wide.payload_mass.high * 18.432 / 58.0, rel=1e-3)
    assert jackal.wheel_radius.low == pytest.approx(wide.wheel_radius.low * 0.098 / 0.125)
    assert jackal.friction == wide.friction and jackal.latency == wide.latency


def test_a_saved_policy_records_its_task_and_robot_and_export_reads_them(tmp_path):
    """Export writes the contract from the policy's record, not from today's task: a Husky policy says 1 m/s at
    10 Hz on the Husky, and a format-1 file is read as what it was."""
    import dataclasses

    from atrv_warp.policy import (
        PolicyRobotMismatch,
        check_policy_robot,
        make_actor,
        policy_payload,
        policy_record,
        run_record,
    )
    from atrv_warp.rl.export import contract
    from atrv_warp.storage import atomic_save
    from atrv_warp.task.env import RoverEnv

    env = RoverEnv(1, robot="husky", task="nav_deploy")
    actor = make_actor(16, 1, obs_dim=env.obs_dim)
    payload = policy_payload(actor, width=16, depth=1, meta={"task": "nav_deploy"}, task=env.task,
                             record=run_record(env.task, env.robot))
    path = tmp_path / "husky.pt"
    atomic_save(payload, path)
    record = policy_record(path)
    assert record.recorded and record.robot == load_robot("husky") and record.task.config == env.task_cfg
    spec = contract(path, payload)
    assert spec["robot"]["name"] == "husky" and spec["robot"]["limits"]["linear_velocity"] == 1.0
    assert spec["action"]["scale"] == [1.0, 1.0] and spec["rate_hz"] == pytest.approx(10.0)
    assert check_policy_robot(record, load_robot("husky"), source=path) is None
    with pytest.raises(PolicyRobotMismatch, match=r"trained on husky \(Clearpath Husky A200\) but this is jackal"
                       r".*allow another on purpose \(--allow-other-robot\)$"):
        check_policy_robot(record, load_robot("jackal"), source=path)
    with pytest.raises(PolicyRobotMismatch, match=r"on purpose \(-p allow_other_robot:=true\)$"):  # a node's way
        check_policy_robot(record, load_robot("jackal"), source=path, allow_with="-p allow_other_robot:=true")
    assert "trained on husky" in check_policy_robot(record, load_robot("jackal"), source=path, allow=True)
    # a task whose declared limits change later does not move the record
    changed = dataclasses.replace(record.task.config, max_linear=9.0)
    assert policy_record(path).task.config != changed
    old = {k: v for k, v in payload.items() if k not in ("task_record", "robot")}  # format 1
    old["format"] = "atrv_warp.policy/1"
    was = policy_record(old)
    assert not was.recorded and was.robot.name == "atrvjr" and was.task.config.max_linear == 2.0


def test_each_robot_has_its_shipped_nav_policy_and_commands_default_to_it():
    """The shipped ``nav_deploy_<robot>`` files exist, each records its own robot and the task fitted to it (as
    ``RoverEnv`` fits it today), and a command that names no policy takes the robot's own."""
    from atrv_warp.policy import SHIPPED_POLICIES, policy_record, shipped_policy_for
    from atrv_warp.task.env import RoverEnv

    for robot in ROBOTS:
        name = shipped_policy_for("nav_deploy", robot)
        assert name == f"nav_deploy_{robot}" and SHIPPED_POLICIES[name].task == "nav_deploy"
        record = policy_record(name)
        assert record.recorded and record.robot == load_robot(robot)
        assert record.task.config == RoverEnv(1, robot=robot, task="nav_deploy").task_cfg, robot
    assert shipped_policy_for("nav_deploy") == "nav_deploy"  # the 2 m/s study, where no robot is named
    # the robots folder names them: no robot's policy is listed by hand, none is missing
    assert {n for n in SHIPPED_POLICIES if n.startswith("nav_deploy_")} - {"nav_deploy_plain"} == {
        f"nav_deploy_{robot}" for robot in ROBOTS}
    assert shipped_policy_for("nav", "husky") == "nav" and shipped_policy_for("mine", "husky") == "reach"


def test_a_recorded_robot_is_found_again_by_its_shipped_name_or_not_at_all(tmp_path):
    """``robot_spec``: a recorded shipped robot by its name, wherever it was recorded; a robot from a file of one's
    own, or a shipped one whose file or URDF has changed since, by none (``None``: the commands then ask for its file, ``--robot FILE``)."""
    import dataclasses

    from atrv_warp.core.robot import robot_spec

    assert robot_spec(robot_from_record(robot_record(load_robot("husky")), "a test")) == "husky"
    # a record made on another machine (its URDF's path is that machine's) is the same robot, by its URDF's text
    elsewhere = robot_record(load_robot("husky")) | {"urdf": "/elsewhere/husky.urdf"}
    assert robot_spec(robot_from_record(elsewhere, "a test")) == "husky"
    assert robot_spec(robot_from_record({k: v for k, v in elsewhere.items() if k != "urdf_sha256"}, "a test")) is None
    copy = load_robot(_copy(tmp_path))
    assert copy.path != load_robot("jackal").path and robot_spec(copy) == "jackal"  # the same file, copied
    urdf = tmp_path / "jackal.urdf"
    urdf.write_text(urdf.read_text().replace('<mass value="16.523"/>', '<mass value="17.0"/>'))
    assert robot_spec(load_robot(tmp_path / "jackal.toml")) is None  # its URDF edited since: a robot of one's own
    assert robot_spec(dataclasses.replace(load_robot("husky"), torque_limit=30.0)) is None


def test_a_task_on_a_robot_has_a_fingerprint_that_moves_with_its_declaration(tmp_path, monkeypatch):
    """:func:`~atrv_warp.task.fingerprints.task_robot_fingerprint`: the same for the same task and robot, different
    for another task or robot; it moves with a task field and a robot file's value, and not with the task module's
    description (issue 69, part 6)."""
    import dataclasses

    from atrv_warp.task import registry
    from atrv_warp.task.fingerprints import task_robot_fingerprint

    now = task_robot_fingerprint("nav_deploy", "jackal")
    assert now == task_robot_fingerprint("nav_deploy", "jackal") and len(now) == 16
    assert len({now, task_robot_fingerprint("nav", "jackal"), task_robot_fingerprint("nav_deploy", "husky")}) == 3
    copied = _copy(tmp_path)
    assert task_robot_fingerprint("nav_deploy", copied) == now  # the same file elsewhere
    copied.write_text(copied.read_text().replace("linear_velocity = 2.0\n", "linear_velocity = 1.9\n"))
    assert task_robot_fingerprint("nav_deploy", copied) != now
    shipped = registry.resolve_task("nav_deploy")
    monkeypatch.setitem(registry.TASKS, "nav_deploy", dataclasses.replace(shipped, description="said otherwise"))
    assert task_robot_fingerprint("nav_deploy", "jackal") == now
    changed = dataclasses.replace(shipped, config=dataclasses.replace(shipped.config, max_steps=shipped.config.max_steps + 1))
    monkeypatch.setitem(registry.TASKS, "nav_deploy", changed)
    assert task_robot_fingerprint("nav_deploy", "jackal") != now


def test_the_deploy_table_is_where_the_robot_runs_not_what_it_is(tmp_path):
    """A robot file's ``[deploy]`` table (issue 69, part 3) is read and checked like every table, and is no part of
    the robot's identity: equality, a saved policy's record and the file's identity hash leave it out, so every
    shipped and golden policy still finds its robot equal."""
    from atrv_warp.core.robot import robot_file_sha256
    from atrv_warp.policy import SHIPPED_POLICIES, policy_record, shipped_policy_path

    path = _copy(tmp_path)
    text = path.read_text()
    jackal = load_robot(path)
    assert jackal.deploy["scan_topic"] == "sensors/lidar2d_0/scan" and jackal.deploy["tf_in_namespace"] is True
    bare = tmp_path / "bare" / "jackal.toml"
    bare.parent.mkdir()
    shutil.copy(tmp_path / "jackal.urdf", bare.parent / "jackal.urdf")
    bare.write_text(text.split("\n[deploy]\n")[0])  # the file as it was before its [deploy] table
    without = load_robot(bare)
    assert without.deploy == {} and without == jackal

    def record(robot):
        return {k: v for k, v in robot_record(robot).items() if k != "urdf"}  # (the URDF's path: where it lies)

    assert record(without) == record(jackal)
    assert robot_file_sha256(path) == robot_file_sha256(bare) == hashlib.sha256(bare.read_bytes()).hexdigest()
    path.write_text(text.replace('cmd_vel_topic = "cmd_vel"', 'cmd_vel_topic = "cmd_vel_policy"'))
    assert robot_file_sha256(path) == robot_file_sha256(bare)  # where it runs changed, not what it is
    path.write_text(text + "max_linear = 1.5\n")  # a number: not a name or a switch
    with pytest.raises(RobotFileError, match=r"\[deploy\] must be a table of names \(non-empty text\) and switches"):
        load_robot(path)
    from atrv_warp.deploy.launching import robot_parameters  # the node's parameters: the deploy layer checks them

    for edit, message in ((lambda t: t + "colour = 'yellow'\n", r"\[deploy\]: unknown parameter\(s\) \['colour'\]"),
                          (lambda t: t.replace("tf_in_namespace = true", 'tf_in_namespace = "yes"'),
                           r"\[deploy\]: tf_in_namespace must be true or false"),
                          (lambda t: t.replace('odom_frame = "odom"', 'odom_frame = "/odom"'),
                           r"\[deploy\]: parameter odom_frame must be a tf frame id")):
        path.write_text(edit(text))
        with pytest.raises(ValueError, match=message):
            robot_parameters(str(path))
    golden = sorted((ROBOTS_DIR.parent.parent / "tests" / "data").glob("golden_*.pt"))
    shipped = [shipped_policy_path(name) for name in SHIPPED_POLICIES]
    assert len(golden) == 2 and len(shipped) == len(SHIPPED_POLICIES)
    for policy in (*shipped, *golden):
        record = policy_record(policy)
        assert record.robot == load_robot(record.robot.name), policy


def test_robot_new_and_check_refuse_bad_input_in_one_line_before_any_work(tmp_path, capsys):
    """Issue 70: ``robot new`` refuses a name that is not a name (a path, a quote: it wrote a file), an ``--out``
    folder that does not exist and wheels without ``<inertial>`` (a traceback before); a robot file's name follows the
    same rule; ``check --json`` into a missing folder is refused before the measured drive."""
    import re

    from atrv_warp.cli.robot import main

    urdf = ros_urdf(tmp_path)
    for args, message in ((["--name", "../evil"], "--name must be letters, digits, '_' and '-'"),
                          (["--name", 'a"b'], "--name must be letters, digits, '_' and '-'"),
                          (["--name", "ok", "--out", str(tmp_path / "none" / "ok.toml")], "does not exist")):
        assert main(["new", str(urdf), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == [urdf.name]  # nothing written
    bare = tmp_path / "bare.urdf"
    bare.write_text(re.sub(r'(<link name="\w+_wheel">)\s*<inertial>.*?</inertial>', r"\1", urdf.read_text(),
                           flags=re.DOTALL))
    assert main(["new", str(bare), "--name", "bare"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "have no <inertial>" in err[0], err
    assert main(["new", str(urdf), "--name", "rosbot"]) == 0
    path = tmp_path / "rosbot.toml"
    path.write_text(path.read_text().replace('name = "rosbot"', 'name = "ros bot"'))
    with pytest.raises(RobotFileError, match="name must be letters, digits, '_' and '-'"):
        load_robot(path)
    latin = tmp_path / "latin.toml"  # a robot file saved as latin-1: one line naming the byte (a UnicodeDecodeError)
    latin.write_bytes(path.read_bytes().replace(b'title = "rosbot"', 'title = "rosbot à"'.encode("latin-1")))
    with pytest.raises(RobotFileError, match=r"not UTF-8 text .*: byte \d+ is b'\\xe0'"):
        load_robot(latin)
    import os

    os.mkfifo(tmp_path / "pipe.toml")  # it hung robot check and RoverSim until killed
    for special in (tmp_path / "pipe.toml", Path("/dev/zero")):
        with pytest.raises(RobotFileError, match="the robot file is not a regular file"):
            load_robot(special)
    assert main(["check", "jackal", "--json", str(tmp_path / "none" / "r.json")]) == 2
    captured = capsys.readouterr()
    assert "--json" in captured.err and "does not exist" in captured.err and "..." not in captured.out


BAD_NUMBERS = ("nan", "inf", "-inf", "0", "-1", "1e30")
"""What a careless or hostile robot file or URDF puts in a number (issue 70, part 5)."""


def _finite_rollout(robot_path: Path) -> None:
    """The robot drives 20 steps of a turning twist and every pose stays finite."""
    from atrv_warp.sim import RoverSim

    sim = RoverSim(1, robot=str(robot_path))
    for _ in range(20):
        sim.set_twist(torch.tensor([[0.5, 0.5]]))
        sim.step()
    assert torch.isfinite(sim.root_pose).all() and not sim.nonfinite.any(), robot_path


def test_no_bad_number_in_a_robot_file_or_its_urdf_reaches_the_physics(tmp_path):
    """Every number of a robot file, and a URDF's masses, inertias, origins and axes, swept with NaN, ±inf, 0, -1 and
    1e30: each is refused, naming its field (or link or joint), or the robot drives with every pose finite."""
    import re

    from atrv_warp.core.robot import PHYSICAL_RANGE, robot_file
    from atrv_warp.sim.urdf import URDFError

    shipped = robot_file("jackal")
    text, urdf = shipped.read_text(), shipped.with_suffix(".urdf").read_text()
    (tmp_path / "jackal.urdf").write_text(urdf)
    driven = []
    for field in PHYSICAL_RANGE:
        table, key = field.split(".")
        for value in BAD_NUMBERS:
            path = tmp_path / f"{table}_{key}_{value}.toml"
            pattern = rf"(\[{table}\][^\[]*?\n){key} = [^\n]*"
            changed = re.sub(pattern, rf"\g<1>{key} = {value}", text, count=1, flags=re.DOTALL)
            if changed == text:  # an optional field the Jackal's file leaves out: add it to its table
                changed = text.replace(f"[{table}]\n", f"[{table}]\n{key} = {value}\n", 1)
            path.write_text(changed)
            try:
                load_robot(path)
            except RobotFileError as err:
                assert field in str(err) and "\n" not in str(err), (field, value, str(err))
                continue
            driven.append(path)
    urdf_cases = {"wheel mass": ('<mass value="0.477"/>', '<mass value="{}"/>'),
                  "chassis inertia": ('ixx="0.3136"', 'ixx="{}"'),
                  "wheel origin": ('<origin xyz="0.131 0.187795 0.0345"', '<origin xyz="{} 0.187795 0.0345"'),
                  "wheel axis": ('<axis xyz="0 1 0"/>', '<axis xyz="0 {} 0"/>')}
    for case, (old, new) in urdf_cases.items():
        for value in BAD_NUMBERS:
            name = f"{case.replace(' ', '_')}_{value}"
            (tmp_path / f"{name}.urdf").write_text(urdf.replace(old, new.format(value), 1))
            path = tmp_path / f"{name}.toml"
            path.write_text(text.replace('urdf = "jackal.urdf"', f'urdf = "{name}.urdf"'))
            try:
                from atrv_warp.sim.config import nominal_rover_config
                from atrv_warp.sim.urdf import load_rover

                load_rover(nominal_rover_config(str(path)))
            except URDFError as err:
                assert str(err).count(str(tmp_path)) >= 1 and "\n" not in str(err), (case, value, str(err))
                assert re.search(r"link '|joint '|wheel '", str(err)), (case, value, str(err))  # named
                continue
            driven.append(path)
    assert {p.stem for p in driven} == {"wheels_offset_0", "driver_ki_0", "wheel_origin_0", "wheel_origin_-1",
                                        "wheel_axis_-1", "wheel_axis_1e30"}, sorted(p.stem for p in driven)
    for path in driven:
        _finite_rollout(path)


def test_each_robot_has_its_shipped_follow_path_policy_with_the_places_it_trained_in():
    """``follow_path_<robot>`` (issue 72, part 8): each file records its robot, the task fitted to it as ``RoverEnv``
    fits it today, and the procedural places its run trained in; a command that names no robot takes the ATRV-Jr's."""
    from atrv_warp.policy import SHIPPED_POLICIES, policy_record, shipped_policy_for
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.task.env import RoverEnv

    preset = load_train_config("follow_path", {})
    for robot in ROBOTS:
        name = shipped_policy_for("follow_path", robot)
        assert name == f"follow_path_{robot}" and SHIPPED_POLICIES[name].task == "follow_path"
        record = policy_record(name)
        assert record.recorded and record.robot == load_robot(robot)
        assert record.task.config == RoverEnv(1, robot=robot, task="follow_path", maps=["building:1"]).task_cfg, robot
        assert record.sites["entries"] == list(preset.env.map) and len(record.sites["maps"]) == 64
        assert all(m["file"] is None and len(m["sha256"]) == 64 for m in record.sites["maps"])
    assert shipped_policy_for("follow_path") == "follow_path_atrvjr"
