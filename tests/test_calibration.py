"""Calibration from a recorded bag (#30): the simulator-config file, the bag reader's errors, the rollout's new
parameters and controller, and a fit that recovers a rover it is not told, recorded from the live ROS 2 node."""

from __future__ import annotations

import json
import random
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch

from atrv_warp.integrations.ros.bag import BagWriter
from atrv_warp.sim.config import SimConfig
from atrv_warp.sim.config_file import load_sim_config
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.sysid import (
    DEFAULT_FIT,
    BagError,
    CalibrationConfig,
    CalibrationError,
    read_drive_log,
)
from atrv_warp.sim.sysid.segments import make_segments
from atrv_warp.sim.urdf import load_rover

WHEELS = {w.joint: (w.side, w.drive_sign) for w in load_rover().wheels}
TRUTH = {"friction": 0.5, "payload_mass": 12.0, "torque_scale": 0.8, "wheel_radius": 0.125}
"""examples/calibration_truth.toml, which the hidden-truth test's bag is recorded with."""


def _stamp(t: float) -> dict:
    ns = round(t * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _odometry(t: float, x: float, y: float, yaw: float, v: float = 0.5) -> dict:
    vec = {"x": 0.0, "y": 0.0, "z": 0.0}
    return {"header": {"stamp": _stamp(t), "frame_id": "world"}, "child_frame_id": "base_link",
            "pose": {"pose": {"position": {"x": x, "y": y, "z": 0.1},
                              "orientation": {"x": 0.0, "y": 0.0, "z": np.sin(yaw / 2), "w": np.cos(yaw / 2)}},
                     "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": {**vec, "x": v}, "angular": vec}, "covariance": [0.0] * 36}}


def _joints(t: float, speed: float, names=tuple(WHEELS)) -> dict:
    return {"header": {"stamp": _stamp(t), "frame_id": ""}, "name": list(names),
            "position": [0.0] * len(names), "velocity": [WHEELS.get(n, (0, 1.0))[1] * speed for n in names],
            "effort": [0.0] * len(names)}


def _bag(path, seconds=20.0, *, skip=(), pose_type="nav_msgs/msg/Odometry", backwards_at=None, names=tuple(WHEELS)):
    """A kinematic drive at 0.5 m/s written with BagWriter (the simulator node's writer)."""
    w = BagWriter(str(path))
    for k in range(round(seconds / 0.05) + 1):
        t = k * 0.05
        if backwards_at is not None and k == backwards_at:
            t -= 1.0
        ns = round(t * 1e9)
        if "/cmd_vel" not in skip and k % 2 == 0:
            w.write("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.5, "y": 0.0, "z": 0.0},
                                                            "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}, ns)
        if "/ground_truth/odom" not in skip:
            if pose_type == "nav_msgs/msg/Odometry":
                w.write("/ground_truth/odom", pose_type, _odometry(t, 0.5 * t, 0.0, 0.0), ns)
            else:
                w.write("/ground_truth/odom", "geometry_msgs/msg/Twist",
                        {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}, ns)
        if "/joint_states" not in skip:
            w.write("/joint_states", "sensor_msgs/msg/JointState", _joints(t, 4.0, names), ns)
    w.close()
    return path


# ------------------------------------------------------------------ the simulator-config file
def test_sim_config_file_is_read_by_the_simulator_and_checked(tmp_path):
    from atrv_warp import RoverSim

    good = tmp_path / "rover.toml"
    good.write_text("[rover]\ntorque_scale = 0.8\npayload_mass = 12.0\n[contact]\nfriction = 0.5\n"
                    "[calibration]\nbag = 'x.mcap'\n")
    rover, contact = load_sim_config(good)
    assert (rover.torque_scale, rover.payload_mass, contact.friction) == (0.8, 12.0, 0.5)
    sim = RoverSim(1, sim_config=good)
    assert sim.params.friction.item() == pytest.approx(0.5)
    assert sim.params.torque_scale.item() == pytest.approx(0.8)
    assert sim.model.body_mass.numpy()[sim.layout.chassis_body] == pytest.approx(
        RoverSim(1).model.body_mass.numpy()[sim.layout.chassis_body] + 12.0)
    for text, words in (("[rover]\ntorque_scael = 1.0\n", ["torque_scael", "known"]),
                        ("[rover]\npayload_mass = -3.0\n", ["payload_mass", ">= 0"]),
                        ("[contact]\nfriction_rise = -0.5\n", ["friction_rise", ">= 0"]),
                        ("[contact]\nfriction = 'high'\n", ["friction"]),
                        ("[rover\nx = 1\n", ["not valid TOML"])):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(ValueError) as err:
            load_sim_config(bad)
        assert str(bad) in str(err.value) and all(w in str(err.value) for w in words), str(err.value)
    with pytest.raises(ValueError, match="cannot read"):
        load_sim_config(tmp_path / "missing.toml")
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (2 << 20))
    for path, message in ((Path("/dev/zero"), "not a regular file"), (big, "over the 1 MiB")):  # issue 70: read till
        with pytest.raises(ValueError, match=message):  # the kernel killed it at 3 GB
            load_sim_config(path)


def test_train_and_env_accept_sim_config(tmp_path):
    from atrv_warp.rl.command_line import parse_command
    from atrv_warp.task.env import ATRVjrEnv

    path = tmp_path / "cal.toml"
    path.write_text("[contact]\nfriction = 0.7\n")
    cmd = parse_command(["--sim-config", str(path), "max_minutes=0.1"])
    assert cmd.train.env.sim_config == str(path)
    assert dict(cmd.train.env.env_kwargs())["sim_config"] == str(path)
    env = ATRVjrEnv(2, **dict(cmd.train.env.env_kwargs()))
    assert env.sim.contact_cfg.friction == 0.7
    bad = tmp_path / "bad.toml"
    bad.write_text("[rover]\nwheel_radius = 0\n")
    with pytest.raises(ValueError, match="wheel_radius"):
        parse_command([f"sim_config={bad}"])


def test_evaluate_runs_on_a_sim_config_and_refuses_a_bad_one(tmp_path, run_module):
    path = tmp_path / "cal.toml"
    path.write_text("[contact]\nfriction = 0.7\n")
    proc = run_module("atrv_warp.evaluate", "--episodes", "4", "--sim-config", str(path))
    assert "success" in proc.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text("[contact]\nfriction = -1.0\n")
    proc = run_module("atrv_warp.evaluate", "--episodes", "4", "--sim-config", str(bad), check=False)
    assert proc.returncode == 2 and str(bad) in proc.stderr and "friction" in proc.stderr


# ------------------------------------------------------------------ the bag
def test_reader_reads_a_drive(tmp_path):
    log = read_drive_log(_bag(tmp_path / "ok.mcap"), WHEELS)
    assert log.duration == pytest.approx(20.0)
    assert np.allclose(log.wheel_speed, 4.0) and log.effort is not None
    assert log.pose[-1, 0] == pytest.approx(10.0) and np.allclose(log.body_velocity[:, 0], 0.5)
    assert len(log.cmd_time) == 201 and np.allclose(log.cmd[:, 0], 0.5)
    folder = tmp_path / "rosbag2"  # what `ros2 bag record -s mcap -o rosbag2` leaves: a folder with one .mcap
    folder.mkdir()
    (tmp_path / "ok.mcap").rename(folder / "rosbag2_0.mcap")
    assert read_drive_log(folder, WHEELS).duration == pytest.approx(20.0)
    (folder / "rosbag2_1.mcap").write_bytes(b"")
    with pytest.raises(BagError, match="2 .mcap files; give one of them"):
        read_drive_log(folder, WHEELS)


@pytest.mark.parametrize("case", ["not_mcap", "truncated", "no_joint_states", "wrong_type", "backwards",
                                  "missing_wheel", "too_short", "zeroed"])
def test_bad_bags_are_one_line_errors_naming_the_file(tmp_path, case):
    path = tmp_path / f"{case}.mcap"
    expect = {"not_mcap": "not an MCAP file", "truncated": "truncated", "no_joint_states": "no topic /joint_states",
              "wrong_type": "expected nav_msgs/msg/Odometry", "backwards": "timestamps go backwards",
              "missing_wheel": "lacks wheel joint", "too_short": "too short to fit",
              "zeroed": "corrupt near byte"}[case]
    if case == "not_mcap":
        path.write_text("this is a CSV file, not a bag\n1,2,3\n")
    elif case == "truncated":
        data = _bag(tmp_path / "full.mcap").read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif case == "no_joint_states":
        _bag(path, skip=("/joint_states",))
    elif case == "wrong_type":
        _bag(path, pose_type="geometry_msgs/msg/Twist")
    elif case == "backwards":
        _bag(path, backwards_at=100)
    elif case == "missing_wheel":
        _bag(path, names=tuple(WHEELS)[:3])
    elif case == "zeroed":  # 64 bytes zeroed in the (one) chunk: it does not decompress (it was a zstandard traceback)
        data = bytearray(_bag(tmp_path / "full.mcap").read_bytes())
        data[len(data) // 6:len(data) // 6 + 64] = bytes(64)
        path.write_bytes(bytes(data))
    else:
        _bag(path, seconds=3.0)
    with pytest.raises((BagError, CalibrationError)) as err:
        log = read_drive_log(path, WHEELS)
        make_segments(log, CalibrationConfig(), DriverConfig(wheel_radius=0.125, track_width=0.6))
    message = str(err.value)
    assert expect in message and str(path) in message and "\n" not in message, message
    if case == "no_joint_states":
        assert "/ground_truth/odom (nav_msgs/msg/Odometry)" in message  # lists what the bag has


def test_cli_bad_bag_writes_nothing(tmp_path, run_module):
    path = tmp_path / "notes.mcap"
    path.write_text("hello")
    out = tmp_path / "cal.toml"
    proc = run_module("atrv_warp.calibrate", str(path), "--out", str(out), check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "not an MCAP file" in proc.stderr and str(path) in proc.stderr
    assert list(tmp_path.iterdir()) == [path]
    good = _bag(tmp_path / "good.mcap")
    proc = run_module("atrv_warp.calibrate", str(good), "--out", str(tmp_path / "missing" / "cal.toml"), check=False)
    assert proc.returncode == 2 and "does not exist" in proc.stderr and str(tmp_path / "missing") in proc.stderr
    assert sorted(tmp_path.iterdir()) == sorted([path, good])
    taken = tmp_path / "taken.toml"  # an existing output is refused before the fit, unless --force
    taken.write_text("[rover]\n")
    for option in (["--out", str(taken)], ["--report", str(taken)], ["--plot", str(taken)]):
        proc = run_module("atrv_warp.calibrate", str(good), *option, check=False)
        assert proc.returncode == 2 and f"{taken} exists: pass --force to overwrite it" in proc.stderr, proc.stderr
    proc = run_module("atrv_warp.calibrate", str(good), "--out", "/proc/cal.toml", check=False)
    assert proc.returncode == 2 and "cannot write in /proc" in proc.stderr, proc.stderr
    proc = run_module("atrv_warp.calibrate", str(good), "--params", "friction,friction", check=False)
    assert proc.returncode == 2 and "['friction'] named more than once" in proc.stderr, proc.stderr
    assert taken.read_text() == "[rover]\n"


# ------------------------------------------------------------------ the rollout
def test_rollout_driver_matches_the_simulator():
    """/cmd_vel through the motor driver inside the differentiable rollout drives as the simulator's own step does
    (one kernel, two users), and its gradients agree with central differences."""
    from atrv_warp import RoverSim
    from atrv_warp.sim.diff import DiffRollout

    steps = 30
    sim = RoverSim(1, sim=SimConfig(mass_matrix_interval=1, use_tile_gemm=False, use_graph=False))  # as the rollout
    side = torch.tensor([w.side for w in sim.description.wheels])
    applied = torch.zeros(steps, 2)  # each side's mean motor torque in the step's last substep (the node's effort)
    for t in range(steps):
        sim.set_twist([0.8, 0.6])
        sim.step()
        applied[t] = torch.stack([sim.wheel_torque[0, side == s].mean() for s in (0, 1)])
    roll = DiffRollout(1, steps=steps, twist=True)
    twist = torch.tensor([0.8, 0.6]).expand(steps, 1, 2)
    poses, torques = roll(twist, wheel_torques=True)
    assert poses[-1, 0, :3].tolist() == pytest.approx(sim.root_pose[0, :3].tolist(), abs=2e-4)
    assert applied.abs().max() > 5.0  # the motors worked
    assert torques[:, 0].flatten().tolist() == pytest.approx(applied.flatten().tolist(), abs=0.05)
    # through the loop: d(final x)/d(a mid-rollout forward command) against central differences
    short = DiffRollout(1, steps=10, twist=True)
    a = torch.tensor([0.5, 0.5]).repeat(10, 1).view(10, 1, 2).requires_grad_(True)
    short(a)[-1, 0, 0].backward()
    h = 1e-2
    with torch.no_grad():
        for t, c in ((5, 0), (5, 1), (8, 0)):
            up, down = a.detach().clone(), a.detach().clone()
            up[t, 0, c] += h
            down[t, 0, c] -= h
            fd = float(short(up)[-1, 0, 0] - short(down)[-1, 0, 0]) / (2 * h)
            assert float(a.grad[t, 0, c]) == pytest.approx(fd, rel=0.05, abs=1e-4), (t, c)


def test_rollout_with_a_mass_matrix_per_step_drives_as_the_default_simulator():
    """``mass_matrix_interval=None`` (the calibration's replay) refreshes the mass matrix once per step, as a default
    RoverSim does: the same path, and gradients that agree with central differences."""
    from atrv_warp import RoverSim
    from atrv_warp.sim.diff import DiffRollout

    steps = 20
    sim = RoverSim(1)
    for _ in range(steps):
        sim.set_twist([0.8, 0.6])
        sim.step()
    roll = DiffRollout(1, steps=steps, twist=True, mass_matrix_interval=None)
    twist = torch.tensor([0.8, 0.6]).expand(steps, 1, 2)
    assert roll(twist)[-1, 0, :3].tolist() == pytest.approx(sim.root_pose[0, :3].tolist(), abs=2e-4)
    mu = torch.tensor([0.3], requires_grad=True)
    roll(twist, friction=mu)[-1, 0, 0].backward()
    with torch.no_grad():
        fd = float(roll(twist, friction=0.31)[-1, 0, 0] - roll(twist, friction=0.29)[-1, 0, 0]) / 0.02
    assert float(mu.grad) == pytest.approx(fd, rel=0.05, abs=1e-4)


def test_rollout_gradients_of_motor_and_wheel_parameters():
    """d(final x)/d(torque scale) and /d(wheel radius), per world, against central differences."""
    from atrv_warp.sim.diff import DiffRollout

    roll = DiffRollout(2, steps=10)
    actions = torch.full((10, 2, 2), 0.2)
    state = roll.initial_state(torch.tensor([[0.0, -2.0, 0.0], [0.0, 2.0, 0.0]]))
    for name, value, h in (("torque_scale", torch.tensor([1.0, 0.8]), 1e-2),
                           ("wheel_radius", torch.tensor([0.125, 0.13]), 5e-4)):
        v = value.clone().requires_grad_(True)
        (roll(actions, state, **{name: v})[-1, :, 0].sum()).backward()
        fd = [(roll(actions, state, **{name: value + h * e})[-1, i, 0]
               - roll(actions, state, **{name: value - h * e})[-1, i, 0]).item() / (2 * h)
              for i, e in enumerate(torch.eye(2))]
        assert v.grad.tolist() == pytest.approx(fd, rel=0.05), name
    # the motors' torques (what the fit matches to recorded efforts) carry the torque scale's gradient too
    scale = torch.tensor([1.0, 0.8])
    v = scale.clone().requires_grad_(True)
    roll(actions, state, torque_scale=v, wheel_torques=True)[1].sum().backward()
    fd = [(roll(actions, state, torque_scale=scale + 1e-2 * e, wheel_torques=True)[1][:, i].sum()
           - roll(actions, state, torque_scale=scale - 1e-2 * e, wheel_torques=True)[1][:, i].sum()).item() / 2e-2
          for i, e in enumerate(torch.eye(2))]
    assert v.grad.tolist() == pytest.approx(fd, rel=0.05)


def test_moving_state_sets_the_recorded_motion():
    from atrv_warp.sim.diff import DiffRollout

    roll = DiffRollout(1, steps=1)
    q, qd = roll.moving_state(torch.tensor([[1.0, 2.0, 0.7]]), torch.tensor([[0.6, 0.1]]), torch.tensor([0.4]),
                              torch.tensor([[3.0, 5.0]]))
    sim = roll.sim
    sim.set_joints(q.detach(), qd.detach())
    c, s = np.cos(0.7), np.sin(0.7)
    assert sim.lin_vel[0, :2].tolist() == pytest.approx([c * 0.6 - s * 0.1, s * 0.6 + c * 0.1], abs=1e-5)
    assert sim.ang_vel[0, 2].item() == pytest.approx(0.4, abs=1e-6)
    expected = [3.0 if w.side == 0 else 5.0 for w in sim.description.wheels]
    assert sim.wheel_speed[0].tolist() == pytest.approx(expected, abs=1e-5)
    # tilted and pitching, each wheel at its own speed; the yaw rate and the tilt's rates about the chassis' axes
    from atrv_warp.core.geometry import quat_to_matrix, quat_to_rpy

    each = torch.tensor([[2.0, 3.0, 4.0, 5.0]])
    q, qd = roll.moving_state(torch.tensor([[1.0, 2.0, 0.7]]), torch.tensor([[0.6, 0.1]]), torch.tensor([0.4]), each,
                              tilt=torch.tensor([[0.02, -0.05]]), tilt_rate=torch.tensor([[0.3, -0.2]]))
    sim.set_joints(q.detach(), qd.detach())
    pose = sim.root_pose[0].double()
    assert quat_to_rpy(pose[3:7]).tolist() == pytest.approx([0.02, -0.05, 0.7], abs=1e-6)
    body = quat_to_matrix(pose[3:7]).T @ sim.ang_vel[0].double()
    assert body.tolist() == pytest.approx([0.3, -0.2, 0.4], abs=1e-5)
    assert sim.wheel_speed[0].tolist() == pytest.approx(each[0].tolist(), abs=1e-5)


def test_a_replayed_rover_starts_at_the_rest_height_of_its_own_wheel_and_payload():
    """A worn wheel or a payload the fit tries starts where the recorded rover stood, not where the configured rover
    would: rolled out parked, it stays put, where the configured rover's height drops it a centimetre (that drop at
    every segment's start pulled the fitted radius and payload towards the nominal rover's)."""
    from atrv_warp.sim.diff import DiffRollout

    roll = DiffRollout(3, steps=6)
    sim = roll.sim
    assert sim.rest_height == pytest.approx(float(sim.rest_heights(sim.rover_cfg.wheel_radius, 0.0)), abs=1e-12)
    radius, payload = torch.tensor([0.115, 0.135, 0.125]), torch.tensor([0.0, 0.0, 25.0])
    rest = torch.zeros(3, 3)
    q, qd = roll.moving_state(rest, torch.zeros(3, 2), torch.zeros(3), torch.zeros(3, 2), wheel_radius=radius,
                              payload_mass=payload)
    z0 = q.view(3, -1)[:, sim.layout.chassis_coord + 2]
    assert z0.tolist() == pytest.approx(sim.rest_heights(radius, payload).tolist(), abs=1e-6)
    assert z0[0].item() == pytest.approx(sim.rest_height - 0.010, abs=1e-6)  # a 1 cm smaller wheel
    assert z0[2].item() < sim.rest_height - 1e-3  # a heavier rover sinks further
    chassis = roll.nominal_chassis_mass + payload
    own = roll(torch.zeros(6, 3, 2), (q, qd), chassis_mass=chassis, wheel_radius=radius)
    assert (own[:, :, 2] - own[:1, :, 2]).abs().max().item() < 1e-3
    configured = roll(torch.zeros(6, 3, 2), roll.moving_state(rest, torch.zeros(3, 2), torch.zeros(3),
                                                              torch.zeros(3, 2)), chassis_mass=chassis,
                      wheel_radius=radius)
    assert (configured[-1, 0, 2] - configured[0, 0, 2]).item() < -5e-3  # the worn wheel's rover falls


# ------------------------------------------------------------------ the driver the replay runs (#42)
@pytest.mark.parametrize("args", [["--driver-wheel-radius", "0"], ["--driver-wheel-radius", "nan"],
                                  ["--driver-track-width", "-0.5"], ["--driver-track-width", "inf", "--record-example"]])
def test_cli_refuses_a_bad_driver_radius_or_track_in_one_line_before_any_work(tmp_path, capsys, args):
    from atrv_warp.cli.calibrate import main

    option, value, *rest = args
    bag = tmp_path / "never_read.mcap"  # no such file: the bag is not read (that would be an error naming it)
    first = [str(tmp_path / "example.mcap")] if rest else [str(bag), "--out", str(tmp_path / "cal.toml")]
    assert main([*rest, *first, option, value]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and option in err and "finite number > 0" in err and str(bag) not in err, err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(CalibrationError, match="driver_wheel_radius must be a finite number > 0"):
        CalibrationConfig(driver_wheel_radius=float("nan"))
    with pytest.raises(ValueError, match="DriverConfig.track_width must be a finite number > 0"):
        DriverConfig(track_width=0.0)


def test_the_replay_runs_the_configured_driver_and_fits_the_physical_radius():
    """The fit's driver has the radius and track the user configured (default: the nominal rover's, as an unconfigured
    driver), and the replay's wheel-speed targets follow it while the physical radius stays the rover's: a driver
    configured at 0.121 m on a 0.125 m wheel spins it at 0.5 / 0.121 rad/s for 0.5 m/s, and the rover drives 3 %
    fast (the odometry's scale error a wrong configured radius leaves)."""
    from atrv_warp.sim.config import get_variant
    from atrv_warp.sim.diff import DiffRollout

    nominal = get_variant("realistic")
    default = DriverConfig().kinematics(load_rover(nominal), nominal)
    driver = CalibrationConfig().driver()
    assert (driver.wheel_radius, driver.track_width) == (default.wheel_radius, default.track_width) == (0.125, 0.5)
    driver = CalibrationConfig(driver_wheel_radius=0.121, driver_track_width=0.55, kp=2.0).driver()
    assert (driver.wheel_radius, driver.track_width, driver.kp) == (0.121, 0.55, 2.0)
    roll = DiffRollout(1, steps=30, twist=True, driver=CalibrationConfig(driver_wheel_radius=0.121).driver())
    assert roll.sim.rover_cfg.wheel_radius == 0.125  # the physical radius: the rollout's fitted parameter
    with torch.no_grad():
        poses, speeds = roll(torch.tensor([0.5, 0.0]).expand(30, 1, 2), wheel_speeds=True)
    assert speeds[-1, 0].tolist() == pytest.approx([0.5 / 0.121] * 2, rel=2e-3)
    assert float(poses[-1, 0, 0] - poses[-11, 0, 0]) / 0.5 == pytest.approx(0.5 * 0.125 / 0.121, rel=5e-3)


def test_segments_replay_the_configured_driver_and_the_outputs_record_it(tmp_path):
    """The driver's integral at each segment's start is the configured driver's: a drive at 4 rad/s for 0.5 m/s is on
    target at 0.125 m, behind it at 0.121 m. The report and the written config record the driver; the loader still
    reads the config."""
    from atrv_warp.sim.sysid import CalibrationResult
    from atrv_warp.sim.sysid.output import write_report, write_sim_config

    log = read_drive_log(_bag(tmp_path / "drive.mcap"), WHEELS)
    on = make_segments(log, CalibrationConfig(), CalibrationConfig().driver())
    worn = CalibrationConfig(driver_wheel_radius=0.121)
    behind = make_segments(log, worn, worn.driver())
    assert np.abs(on.integral[1:]).max() < 1e-3
    assert (behind.integral[1:] > 0.01).all()  # the PI integrates the 0.13 rad/s its wheels fall short
    record = {"wheel_radius": 0.121, "track_width": 0.5, "effective_track_factor": 1.56, "kp": 3.0, "ki": 30.0}
    n = len(behind)
    errors = {split: {"before": [0.1] * n, "after": [0.01] * n, "loss_before": 1.0, "loss_after": 0.1}
              for split in ("train", "held_out")}
    result = CalibrationResult(values={"wheel_radius": 0.121}, nominal={"wheel_radius": 0.125},
                               spread={"wheel_radius": 0.0}, standard_error={"wheel_radius": 1e-4}, starts=[],
                               errors=errors, converged=True, reason="converged", segments=behind, seconds=1.0,
                               compile_seconds=1.0, driver=record)
    write_report(tmp_path / "cal.report.json", result, "drive.mcap")
    assert json.loads((tmp_path / "cal.report.json").read_text())["driver"] == record
    from atrv_warp.sim.sysid.output import format_report

    table = format_report(result)  # the console prints the 95 % interval, as the README promises, and says so
    assert "95 % interval" in table.splitlines()[0] and "0.1208 to 0.1212" in table, table
    write_sim_config(tmp_path / "cal.toml", result, "drive.mcap")
    written = tomllib.loads((tmp_path / "cal.toml").read_text())
    assert written["calibration"]["driver"] == record and written["rover"] == {"wheel_radius": 0.121}
    rover, _ = load_sim_config(tmp_path / "cal.toml")
    assert rover.wheel_radius == 0.121
    # a randomization centred on the file reads the standard errors the calibration wrote: 0.121 +- 2 x 1e-4
    from atrv_warp.sim.config_file import read_sim_config
    from atrv_warp.task.randomization import AroundConfig, resolve_around

    assert read_sim_config(tmp_path / "cal.toml").standard_error == {"wheel_radius": 1e-4}
    around = resolve_around(AroundConfig(parameters=("wheel_radius",), fraction=0.0), tmp_path / "cal.toml")
    assert (around.wheel_radius.low, around.wheel_radius.high) == pytest.approx((0.1208, 0.1212))


def test_a_tiny_fit_runs_on_the_first_seconds_of_a_drive(tmp_path):
    """A smoke run of the fit on a short kinematic drive: ``duration`` keeps the drive's first seconds, both starts
    run, the report has every segment's errors, and the residuals' squares are the loss the fit reports."""
    from atrv_warp.sim.sysid import calibrate
    from atrv_warp.sim.sysid.fit import replay_errors

    log = read_drive_log(_bag(tmp_path / "drive.mcap", seconds=30.0), WHEELS)
    cfg = CalibrationConfig(params=("wheel_radius",), duration=16.0, iterations=2)
    seg = make_segments(log, cfg, cfg.driver())
    assert len(seg) == 8 and len(make_segments(log, CalibrationConfig(), cfg.driver())) == 15  # 2 s each
    result = calibrate(log, cfg)
    assert len(result.starts) == 2 and all(s["evaluations"] >= 1 for s in result.starts)
    assert 0.10 <= result.values["wheel_radius"] <= 0.16
    assert len(result.errors["train"]["after"]) + len(result.errors["held_out"]["after"]) == len(seg)
    # the errors the report gives are replay_errors' with the fitted values
    again = replay_errors(log, result.values, cfg)
    assert again["held_out"].tolist() == pytest.approx(result.errors["held_out"]["after"], abs=1e-6)
    with pytest.raises(CalibrationError, match="duration"):
        CalibrationConfig(duration=0.0)


def test_a_fitted_friction_rise_reaches_the_sim_config_and_the_simulator(tmp_path):
    """``--params ...,friction_rise`` (not a default): the fit stays in its bounds, the written config carries it
    under [contact], and a simulator built from that file has it in every world."""
    from atrv_warp import RoverSim
    from atrv_warp.sim.sysid import calibrate
    from atrv_warp.sim.sysid.config import DEFAULT_FIT, FIT_PARAMETERS
    from atrv_warp.sim.sysid.output import write_sim_config

    assert "friction_rise" not in DEFAULT_FIT
    log = read_drive_log(_bag(tmp_path / "drive.mcap", seconds=30.0), WHEELS)
    result = calibrate(log, CalibrationConfig(params=("friction_rise",), duration=16.0, iterations=1))
    rise = result.values["friction_rise"]
    assert FIT_PARAMETERS["friction_rise"].low <= rise <= FIT_PARAMETERS["friction_rise"].high
    write_sim_config(tmp_path / "cal.toml", result, "drive.mcap")
    _, contact = load_sim_config(tmp_path / "cal.toml")
    assert contact.friction_rise == pytest.approx(rise)
    sim = RoverSim(2, sim_config=tmp_path / "cal.toml")
    assert sim.params.physics.friction_rise.numpy().tolist() == pytest.approx([rise, rise])


def test_record_example_drives_a_worn_truth_with_the_nominal_driver(tmp_path, monkeypatch):
    """``--record-example --truth`` records a base whose driver is configured as the nominal rover (a real base whose
    tyre wore), unless ``--driver-wheel-radius`` says otherwise: the node's parameters it passes, built as the node
    builds its driver and simulator."""
    pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
    from atrv_warp import RoverSim
    from atrv_warp.cli.calibrate import main
    from atrv_warp.integrations.ros import drive
    from atrv_warp.integrations.ros.parameters import PARAMETERS, driver_config

    truth = tmp_path / "worn.toml"
    truth.write_text("[rover]\nwheel_radius = 0.121\n")
    seen = []

    def record(path, minutes, *, seed, parameters):  # the node's parameters, instead of a live node
        seen.append(parameters)
        Path(path).write_bytes(b"bag")

    monkeypatch.setattr(drive, "record_drive_bag", record)
    defaults = {p.name: p.default for p in PARAMETERS}
    for extra, configured in (([], 0.125), (["--driver-wheel-radius", "0.13"], 0.13)):
        assert main(["--record-example", str(tmp_path / "x.mcap"), "--truth", str(truth), "--force", *extra]) == 0
        params = {**defaults, **seen[-1]}
        sim = RoverSim(1, variant=params["variant"], sim_config=params["sim_config"], driver=driver_config(params))
        assert sim.rover_cfg.wheel_radius == 0.121 and sim.driver.kinematics.wheel_radius == configured


# ------------------------------------------------------------------ the whole thing, hidden truth
@pytest.fixture
def ros_env(monkeypatch):
    """A ROS domain of the test's own, discovery kept to this machine, in this process's environment: the recording
    node runs in the test's process (``--record-example`` spins it in its own, rclpy initialised and shut down)."""
    pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(random.randint(101, 200)))


@pytest.mark.slow  # a live ROS 2 node records the bag (about 30 s, in this process); the fit takes about 20 s
def test_fit_recovers_a_hidden_rover_from_a_recorded_bag(tmp_path, run_module, ros_env):
    bag, out = tmp_path / "drive.mcap", tmp_path / "calibrated.toml"
    run_module("atrv_warp.calibrate", "--record-example", str(bag), "--minutes", "4", "--truth",
               "examples/calibration_truth.toml", "--noise", "0.01", "--seed", "3")
    proc = run_module("atrv_warp.calibrate", str(bag), "--out", str(out), timeout=1500)
    fitted = tomllib.loads(out.read_text())
    values = {**fitted["rover"], **fitted["contact"]}
    for name, truth in TRUTH.items():
        # The base's driver holds its wheel speeds tightly (a loop every substep), so a payload shows only in the
        # wheel efforts of moderate accelerations, and the fit's loss is flat along friction x mass: the payload is
        # held to 25 %, the rest to 5 % (issue 42 sets the calibration's tolerances over a sweep of rovers).
        rel = 0.25 if name == "payload_mass" else 0.05
        assert values[name] == pytest.approx(truth, rel=rel), (name, values, proc.stdout[-3000:])
    report = json.loads(out.with_suffix(".report.json").read_text())
    assert report["converged"], report["reason"]
    held = report["error_summary"]["held_out"]
    # the nominal rover misses by more than 5 cm: cut it 4x; else the fit ends within 2 cm (issue 42's rule)
    assert held["reduction"] >= 4.0 if held["before_m"] > 0.05 else held["after_m"] <= 0.02, report["error_summary"]
    assert out.with_suffix(".png").stat().st_size > 10_000
    load_sim_config(out)  # what it wrote is a simulator config


@pytest.mark.slow  # a live ROS 2 node records a 90 s Jackal drive (about 15 s, in this process); the fit about 20 s
def test_another_robot_calibrates_from_its_own_bag(tmp_path, run_module, ros_env):
    """Every robot calibrates (issue 70): the fit's bounds are the robot's own (the Jackal's 0.098 m wheel was outside
    the ATRV-Jr's 0.10-0.16 m), the example bag is recorded on the robot named, and the hidden rover is found."""
    from atrv_warp.sim.sysid.config import FIT_PARAMETERS

    low, high = FIT_PARAMETERS["wheel_radius"].bounds("jackal")
    assert low < 0.098 < high and FIT_PARAMETERS["wheel_radius"].bounds("atrvjr") == (0.10, 0.16)
    bag, out = tmp_path / "jackal.mcap", tmp_path / "jackal.toml"
    run_module("atrv_warp.calibrate", "--record-example", str(bag), "--robot", "jackal", "--minutes", "1.5", "--truth",
               "examples/calibration_truth.toml", "--seed", "0")
    proc = run_module("atrv_warp.calibrate", str(bag), "--robot", "jackal", "--out", str(out), timeout=1500)
    report = json.loads(out.with_suffix(".report.json").read_text())
    assert report["converged"], report["reason"]
    fitted = tomllib.loads(out.read_text())
    values = {**fitted["rover"], **fitted["contact"]}
    for name, truth in {**TRUTH, "wheel_radius": 0.098}.items():  # the Jackal's own wheel; the rest the truth file's
        rel = 0.25 if name == "payload_mass" else 0.05
        assert values[name] == pytest.approx(truth, rel=rel), (name, values, proc.stdout[-3000:])


# ------------------------------------------------------------------ latency and the model check (issue 42, part 4)
def _drive_log(seconds: float, *, pose_noise: float, wheel_noise: float, seed: int = 0, commands=None):
    """A DriveLog of a smooth drive at 20 Hz with white noise on the reference position and the wheel speeds."""
    from atrv_warp.sim.sysid import DriveLog

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.05)
    x, y = 2.0 * np.sin(0.3 * t), 1.5 * np.cos(0.2 * t)
    pose = np.stack([x + rng.normal(0, pose_noise, len(t)), y + rng.normal(0, pose_noise, len(t)), 0.1 * t], -1)
    wheel = np.stack([4.0 + np.sin(0.5 * t), 4.0 - np.sin(0.5 * t)], -1) + rng.normal(0, wheel_noise, (len(t), 2))
    cmd = commands if commands is not None else np.stack([0.5 + 0.2 * np.sin(0.7 * t), 0.3 * np.cos(0.4 * t)], -1)
    return DriveLog(path="synthetic.mcap", pose_time=t, pose=pose, body_velocity=np.zeros((len(t), 3)),
                    joint_time=t, wheel_speed=wheel, effort=None, cmd_time=t, cmd=cmd, twist=False)


def test_the_recordings_noise_is_read_from_its_samples():
    """A 1 cm reference and 0.02 rad/s encoders on a smooth drive: each channel's noise within 10 %."""
    from atrv_warp.sim.sysid.fit import recording_noise

    noise = recording_noise(_drive_log(180.0, pose_noise=0.01, wheel_noise=0.02))
    assert noise["position"] == pytest.approx(0.01, rel=0.1)
    assert noise["wheel_speed"] == pytest.approx(0.02, rel=0.1)
    assert "effort" not in noise  # a bag without efforts has no effort channel


def test_a_latency_delays_the_replayed_commands_by_whole_steps():
    """Segments cut with a 0.1 s latency replay each command two steps later than at none, on the same segments."""
    log = _drive_log(30.0, pose_noise=0.0, wheel_noise=0.0)
    cfg = CalibrationConfig()
    now = make_segments(log, cfg, cfg.driver())
    late = make_segments(log, cfg, cfg.driver(), latency=0.1, like=now)
    assert late.t0.tolist() == now.t0.tolist() and late.latency == 0.1
    np.testing.assert_allclose(late.inputs[1:, 2:], now.inputs[1:, :-2], atol=1e-12)
    assert np.abs(late.inputs[1:, :2] - now.inputs[1:, :2]).max() > 1e-3
    with pytest.raises(CalibrationError, match="latency must be a finite number >= 0"):
        CalibrationConfig(latency=-0.05)


def test_the_model_check_flags_a_misfit_in_one_line():
    """Held-out errors at the recording's noise pass; a channel over twice its noise (or its floor) is named in one
    line, and so is a fit that made the held-out path worse."""
    from atrv_warp.sim.sysid.config import MISFIT_FLOOR
    from atrv_warp.sim.sysid.fit import _model_check

    noise = {"position": 0.01, "wheel_speed": 0.04, "effort": 0.01}  # a fine effort sensor: its floor counts

    def errors(rms, before=0.05, after=0.012):
        return {"held_out": {"rms_after": rms, "before": [before] * 3, "after": [after] * 3}}

    good = _model_check(errors({"position": 0.013, "wheel_speed": 0.05, "effort": 0.15}), noise, CalibrationConfig())
    assert not good["flagged"] and good["line"].startswith("model check:") and "\n" not in good["line"]
    assert good["ratio"]["effort"] == pytest.approx(0.15 / MISFIT_FLOOR["effort"])
    lag = _model_check(errors({"position": 0.013, "wheel_speed": 0.6, "effort": 1.4}), noise, CalibrationConfig())
    assert lag["flagged"] and lag["line"].startswith("MISFIT") and "\n" not in lag["line"]
    # over the floor where the noise is finer: 0.6 / 0.05
    assert "wheel speed 0.6 rad/s (12.0x its noise)" in lag["line"] and "held-out position" not in lag["line"]
    worse = _model_check(errors({"position": 0.015}, before=0.10, after=0.11), noise, CalibrationConfig())
    assert worse["flagged"] and "made the held-out path error worse" in worse["line"]


@pytest.mark.slow  # two live ROS 2 recordings of 2 min (about 15 s each) and their fits (about 30 s each)
def test_a_fit_finds_a_latency_and_flags_what_it_cannot_model(tmp_path, run_module, ros_env):
    """A base whose /cmd_vel reach its driver 0.1 s late: the fit finds the latency and the rover, and sees no misfit.
    Motors whose torque lags 0.1 s: the model check names the misfit in one line (issue 42, part 4)."""
    truth = "examples/calibration_truth.toml"
    for name, param in (("late", "cmd_vel_delay:=0.1"), ("lag", "motor_lag:=0.1")):
        bag, out = tmp_path / f"{name}.mcap", tmp_path / f"{name}.toml"
        run_module("atrv_warp.calibrate", "--record-example", str(bag), "--minutes", "2", "--truth", truth,
                   "--seed", "3", "-p", param)
        proc = run_module("atrv_warp.calibrate", str(bag), "--out", str(out), check=False, timeout=900)
        report = json.loads(out.with_suffix(".report.json").read_text())
        lines = [line for line in proc.stdout.splitlines() if "MISFIT" in line or line.startswith("model check")]
        assert len(lines) == 1, proc.stdout[-3000:]
        if name == "late":
            assert report["latency"]["seconds"] == pytest.approx(0.1) and report["latency"]["fitted"]
            assert not report["misfit"]["flagged"] and report["converged"], proc.stdout[-3000:]
            for param in ("friction", "torque_scale"):
                assert report["values"][param] == pytest.approx(TRUTH[param], rel=0.05), report["values"]
        else:
            assert report["misfit"]["flagged"] and lines[0].startswith("MISFIT"), proc.stdout[-3000:]
            assert max(report["misfit"]["ratio"].values()) > 2.0


def test_the_standard_error_adds_the_replays_fidelity_and_names_confounded_pairs():
    """Two parameters the residuals move almost alike are reported as confounded; each standard error is at least the
    replay's fidelity (issue 42, part 3)."""
    from atrv_warp.sim.sysid.config import CONFOUNDED, FIT_FIDELITY
    from atrv_warp.sim.sysid.solver import Start, sandwich_error

    rng = np.random.default_rng(0)
    base = rng.normal(size=(40, 30))
    jac = np.stack([base, base + 0.05 * rng.normal(size=(40, 30)), rng.normal(size=(40, 30))], -1)  # (S, R, P)
    start = Start(unit=np.full(3, 0.5), residuals=0.1 * rng.normal(size=(40, 30)), jacobian=jac, damping=0.0,
                   robust=None)
    names = ["torque_scale", "payload_mass", "friction"]
    statistical, correlation = sandwich_error(start, names, np.ones(3))
    assert abs(correlation[0, 1]) > CONFOUNDED > abs(correlation[0, 2])
    assert all(np.isfinite(v) and v > 0 for v in statistical.values())
    assert set(FIT_FIDELITY) >= set(DEFAULT_FIT) and all(v > 0 for v in FIT_FIDELITY.values())


def _recorded_drive(seconds: float = 24.0, seed: int = 3):
    """A drive of our simulator recorded as a bag records it, noise-free: the rover (µ 0.6, motor ×0.9, 10 kg) under
    smooth random ``/cmd_vel`` commands at 20 Hz; its reference pose (full orientation) and body twist, each wheel's
    speed and the side efforts after every step, the commands before it."""
    import dataclasses

    from atrv_warp import RoverSim
    from atrv_warp.core.geometry import quat_to_matrix, quat_to_rpy, quat_to_yaw
    from atrv_warp.sim.config import ContactConfig, get_variant
    from atrv_warp.sim.sysid import DriveLog

    g = torch.Generator().manual_seed(seed)
    steps = round(seconds / 0.05)
    knots = (torch.rand(steps // 12 + 2, 2, generator=g) * 2 - 1) * torch.tensor([0.9, 1.0])
    cmds = torch.nn.functional.interpolate(knots.T[None], size=steps, mode="linear", align_corners=True)[0].T
    rover = dataclasses.replace(get_variant("realistic"), payload_mass=10.0, torque_scale=0.9)
    sim = RoverSim(1, rover=rover, contact=ContactConfig(friction=0.6))
    for _ in range(10):  # settle at rest
        sim.step()
    side = torch.tensor([w.side for w in sim.description.wheels])
    rows = []
    for k in range(steps + 1):
        pose = sim.root_pose[0].double()
        rot = quat_to_matrix(pose[3:7])
        v, w = rot.T @ sim.lin_vel[0].double(), rot.T @ sim.ang_vel[0].double()
        speed, torque = sim.wheel_speed[0].double(), sim.wheel_torque[0].double()
        rows.append((pose[0], pose[1], quat_to_yaw(pose[3:7]), *quat_to_rpy(pose[3:7])[:2], v[0], v[1], w[2], w[0], w[1],
                     *(speed[side == s].mean() for s in (0, 1)), *(torque[side == s].mean() for s in (0, 1)),
                     *speed))
        if k < steps:
            sim.set_twist(cmds[k].tolist())
            sim.step()
    a = torch.tensor([[float(x) for x in r] for r in rows], dtype=torch.float64).numpy()
    t = 0.05 * np.arange(steps + 1)
    a[:, 2] = np.unwrap(a[:, 2])
    return DriveLog(path="recorded.mcap", pose_time=t, pose=a[:, 0:3], body_velocity=a[:, 5:8], joint_time=t,
                    wheel_speed=a[:, 10:12], effort=a[:, 12:14], cmd_time=t[:-1], cmd=cmds.double().numpy(),
                    tilt=a[:, 3:5], tilt_rate=a[:, 8:10], wheel_joints=tuple(w.joint for w in sim.description.wheels),
                    wheel_each=a[:, 14:])


def test_a_replay_starts_from_the_recorded_tilt_wheels_and_effort():
    """Replayed at the rover's own values, a recorded drive's segments follow it to about a millimetre: each starts
    at the recorded roll and pitch (a pitching rover restarted level rocks back), their rates, each wheel's speed,
    and the driver's integral worked out from the recorded effort. Without those (the driver's integral replayed on
    20 Hz wheel speeds, the chassis level) the replay drives too far, which a fit made up for with a smaller wheel."""
    import dataclasses

    from atrv_warp.sim.sysid.fit import replay_errors

    log = _recorded_drive()
    truth = {"friction": 0.6, "torque_scale": 0.9, "payload_mass": 10.0, "wheel_radius": 0.125}
    cfg = CalibrationConfig(segment_seconds=1.0, pose_smoothing=0.0, min_segments=4)
    full = replay_errors(log, truth, cfg)
    bare = replay_errors(dataclasses.replace(log, tilt=None, tilt_rate=None, wheel_each=None, effort=None), truth, cfg)
    full, bare = np.concatenate([full["train"], full["held_out"]]), np.concatenate([bare["train"], bare["held_out"]])
    assert np.mean(full) < 2e-3 and np.mean(bare) > 2.5 * np.mean(full), (np.mean(full), np.mean(bare))


def test_a_rollout_keeps_the_rover_configs_payload_unless_given_another():
    """A rover config's payload rides on the rollout's chassis whether or not a chassis mass is passed (a fit that
    leaves the payload out of ``--params`` replays the weighed rover of ``--sim-config``), and the replayed rover
    starts at that loaded rover's rest height."""
    import dataclasses

    from atrv_warp.sim.config import get_variant
    from atrv_warp.sim.diff import DiffRollout

    loaded = DiffRollout(2, steps=20, twist=True, rover=dataclasses.replace(get_variant("realistic"), payload_mass=20.0))
    empty = DiffRollout(2, steps=20, twist=True)
    assert loaded.nominal_chassis_mass == empty.nominal_chassis_mass  # the URDF's chassis
    twist = torch.tensor([1.0, 0.0]).expand(20, 2, 2)
    state = loaded.moving_state(torch.zeros(2, 3), torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, 2),
                                wheel_radius=0.125)
    z0 = state[0].view(2, -1)[0, loaded.sim.layout.chassis_coord + 2].item()
    assert z0 == pytest.approx(float(loaded.sim.rest_heights(0.125, 20.0)), abs=1e-6)
    with torch.no_grad():
        default = loaded(twist, state)
        given = loaded(twist, state, chassis_mass=loaded.nominal_chassis_mass + 20.0)
        none = loaded(twist, state, chassis_mass=loaded.nominal_chassis_mass)
    assert torch.equal(default, given)
    # 20 kg accelerate more slowly: 0.4 mm behind after 2 s under the implicit loop, whose rounding is 1e-7 m
    assert (default[-1, :, 0] - none[-1, :, 0]).abs().min().item() > 1e-4


def test_a_pause_in_a_bag_splits_it_and_costs_no_memory():
    """A drive with a day-long pause in the middle: the segments come from the two drives on either side (none
    straddles the pause), in the time and memory the data takes, and a drive without pauses is cut as before."""
    import dataclasses
    import time
    import tracemalloc

    from atrv_warp.sim.sysid.segments import drive_spans, make_segments

    cfg = CalibrationConfig()
    whole = _drive_log(60.0, pose_noise=0.0, wheel_noise=0.0)
    gap = 1e6
    later = {f: np.concatenate([getattr(whole, f), getattr(whole, f) + gap]) for f in ("pose_time", "joint_time",
                                                                                        "cmd_time")}
    twice = dataclasses.replace(whole, **later, **{f: np.concatenate([getattr(whole, f)] * 2) for f in (
        "pose", "body_velocity", "wheel_speed", "cmd")})
    assert drive_spans(twice, 0.0, float(twice.pose_time[-1])) == [(0.0, float(whole.pose_time[-1])),
                                                                   (gap, gap + float(whole.pose_time[-1]))]
    tracemalloc.start()
    t0 = time.perf_counter()
    seg = make_segments(twice, cfg, cfg.driver())
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    one = make_segments(whole, cfg, cfg.driver())
    assert len(seg.t0) == 2 * len(one.t0) and seconds < 5.0 and peak < 50e6, (len(seg.t0), seconds, peak)
    assert np.array_equal(seg.t0[: len(one.t0)], one.t0) and np.array_equal(seg.t0[len(one.t0):], one.t0 + gap)
    assert np.array_equal(seg.inputs[: len(one.t0)], one.inputs)  # the drive before the pause, cut as alone
    with pytest.raises(CalibrationError, match="duplicate|more than once"):
        CalibrationConfig(params=("friction", "friction"))
